"""Small matrices, one BLAS thread: every estimation entry point limits the BLAS, and gives it back."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import importlib

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from condmon import estimate
from condmon.cli.main import main
from condmon.errors import ConfigError
from condmon.simulate import simulate_actuator


def _blas_threads() -> list[int]:
    return [int(i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"]


@pytest.fixture(autouse=True)
def two_threads() -> Iterator[None]:
    """Two BLAS threads around each test (the run itself keeps one), so that
    "limited, and given back" can be told from "one all along"."""
    with threadpool_limits(limits=2, user_api="blas"):
        assert _blas_threads() and all(n == 2 for n in _blas_threads())
        yield


@pytest.fixture
def seen(monkeypatch: pytest.MonkeyPatch) -> list[list[int]]:
    """The BLAS threads at the heart of an estimate (where its routes are chosen)."""
    found: list[list[int]] = []
    E = importlib.import_module("condmon.identify.estimate")  # the module, not its function
    real = E.choose_route

    def spy(*args: Any, **kwargs: Any) -> Any:
        found.append(_blas_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(E, "choose_route", spy)
    return found


def test_an_estimate_runs_on_one_blas_thread_and_gives_them_back(
        rig, seen: list[list[int]], monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.delenv("CONDMON_BLAS_THREADS", raising=False)
    before = _blas_threads()
    estimate(simulate_actuator(rig, seed=1), "dc-motor")
    assert seen and all(n == 1 for n in seen[-1])
    assert _blas_threads() == before == [2] * len(before)


def test_a_user_may_ask_for_more_or_leave_it_be(rig, seen: list[list[int]],  # type: ignore[no-untyped-def]
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    before = _blas_threads()
    monkeypatch.setenv("CONDMON_BLAS_THREADS", "auto")
    estimate(simulate_actuator(rig, seed=1), "dc-motor")
    assert seen[-1] == before
    monkeypatch.setenv("CONDMON_BLAS_THREADS", "none")
    with pytest.raises(ConfigError, match="CONDMON_BLAS_THREADS='none': a number of threads"):
        estimate(simulate_actuator(rig, seed=1), "dc-motor")


def test_the_command_line_limits_and_refuses_in_one_line(
        tmp_path, rig, seen: list[list[int]], monkeypatch: pytest.MonkeyPatch,  # type: ignore[no-untyped-def]
        capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "r.csv"
    simulate_actuator(rig, seed=2).to_csv(rec, index=False)
    monkeypatch.delenv("CONDMON_BLAS_THREADS", raising=False)
    assert main(["estimate", str(rec), "--json"]) == 0
    assert all(n == 1 for n in seen[-1])
    monkeypatch.setenv("CONDMON_BLAS_THREADS", "0")
    capsys.readouterr()
    assert main(["estimate", str(rec)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "error: CONDMON_BLAS_THREADS='0': a number of threads >= 1, or 'auto'"


def test_a_simulation_runs_on_one_blas_thread_and_gives_them_back(
        rig, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    """OpenBLAS's idle threads spin: a simulated test took twice its CPU on two."""
    A = importlib.import_module("condmon.simulate.actuator")
    found: list[list[int]] = []
    real = A._zoh_matrices

    def spy(*args: Any, **kwargs: Any) -> Any:
        found.append(_blas_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(A, "_zoh_matrices", spy)
    monkeypatch.delenv("CONDMON_BLAS_THREADS", raising=False)
    simulate_actuator(rig, seed=3)
    assert found and all(n == 1 for n in found[-1])
    assert all(n == 2 for n in _blas_threads())
