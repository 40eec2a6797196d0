"""Shared fixtures: simulated records with known parameters."""

from __future__ import annotations

import atexit
import dataclasses
import os
import shutil
import signal
import tempfile
from collections.abc import Callable, Iterable, Iterator
from typing import Any
from pathlib import Path

import pandas as pd
import pytest

from hypothesis import settings as hypothesis_settings

from condmon.simulate import ActuatorRig, load_actuator_rig, simulate_actuator

# Property tests draw the same examples at every run (a failure is reproducible,
# a pass is not luck), and keep no example database between runs.
hypothesis_settings.register_profile("condmon", derandomize=True, database=None)
hypothesis_settings.load_profile("condmon")

# A run started in the background by a shell without job control (a CI script's
# `cmd &`) inherits Ctrl-C ignored, and so would every command a test starts:
# the tests of what Ctrl-C does would then wait on commands that cannot hear it.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# The derived-structure cache of this run: a fresh folder (the structures are
# derived once, then restored, as on a user's machine), never the user's own.
if "CONDMON_CACHE_DIR" not in os.environ:
    os.environ["CONDMON_CACHE_DIR"] = tempfile.mkdtemp(prefix="condmon-test-cache-")
    atexit.register(shutil.rmtree, os.environ["CONDMON_CACHE_DIR"], True)


def pytest_collection_finish(session: pytest.Session) -> None:
    """The run's own garbage collector: what collection imported (numpy, scipy,
    sympy, pandas, SQLAlchemy, every test module: about 190,000 objects) is
    frozen out of the collector's passes, and a young generation collected
    every 20,000 allocations instead of 700. A test run keeps far more live
    objects than a command does, and scanning them took a tenth of its CPU:
    the tests of the first nine files took 100 s of CPU with Python's defaults
    and 84-89 s with these. Nothing under test changes: the settings are this
    process's, and the commands the tests start keep the defaults."""
    import gc

    gc.collect()
    gc.freeze()
    gc.set_threshold(20_000, 20, 20)


@pytest.fixture(scope="session", autouse=True)
def _one_blas_thread() -> Iterator[None]:
    """The whole run on one BLAS thread, as every command and API entry point
    runs (:mod:`condmon._threads`): the tests also call inner functions, where
    OpenBLAS's spinning threads would spend a fifth of the run's CPU for nothing."""
    from condmon._threads import small_blas

    with small_blas():
        yield


@dataclasses.dataclass(frozen=True)
class DemoRun:
    """``condmon demo`` as a user runs it: its result, what it printed, its folder."""

    result: Any   # condmon.workflows.demo.DemoResult
    printed: str
    folder: Path


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory: pytest.TempPathFactory) -> DemoRun:
    """``condmon demo --out FOLDER`` run once for the whole run (about 15 s of CPU),
    through the command line, with the workflow's result kept for the tests that
    read it."""
    import contextlib
    import io

    import condmon.workflows.demo as demo_module
    from condmon.cli.main import main

    folder = tmp_path_factory.mktemp("demo") / "demo"
    kept: list[Any] = []
    real = demo_module.run_demo

    def keep(*args: Any, **kwargs: Any) -> Any:
        kept.append(real(*args, **kwargs))
        return kept[-1]

    printed = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(printed):
        mp.setattr(demo_module, "run_demo", keep)
        mp.setenv("COLUMNS", "80")
        assert main(["demo", "--out", str(folder)]) == 0
    assert len(kept) == 1
    return DemoRun(kept[0], printed.getvalue(), folder)


@pytest.fixture(scope="session")
def rig() -> ActuatorRig:
    return load_actuator_rig()


@pytest.fixture(scope="session")
def noise_free_record(rig: ActuatorRig) -> pd.DataFrame:
    quiet = dataclasses.replace(rig, noise_I=0.0, noise_omega=0.0)
    return simulate_actuator(quiet, seed=11, linear=True)


@pytest.fixture(scope="session")
def noisy_record(rig: ActuatorRig) -> pd.DataFrame:
    return simulate_actuator(rig, seed=5)


RecordFiles = Callable[[Path, Iterable[int]], list[str]]


@pytest.fixture(scope="session")
def record_files() -> RecordFiles:
    """``record_files(folder, seeds)``: one simulated actuator record per seed,
    written to ``folder/h0.csv``, ``h1.csv``, ...; their paths."""
    def write(folder: Path, seeds: Iterable[int]) -> list[str]:
        files = []
        for k, seed in enumerate(seeds):
            path = folder / f"h{k}.csv"
            simulate_actuator(seed=seed).to_csv(path, index=False)
            files.append(str(path))
        return files

    return write


@pytest.fixture(scope="session")
def demo_rig(rig: ActuatorRig) -> ActuatorRig:
    """The rig of `condmon demo`: nonlinear effects on."""
    from condmon.workflows.demo import load_demo_config

    return dataclasses.replace(rig, **load_demo_config().get("rig", {}))


def _postgres_url() -> str | None:
    import os

    url = os.environ.get("CONDMON_TEST_POSTGRES_URL")
    if url is None and os.environ.get("CONDMON_REQUIRE_POSTGRES") == "1":
        pytest.fail("CONDMON_REQUIRE_POSTGRES=1 but CONDMON_TEST_POSTGRES_URL is not set")
    return url


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    """A fresh, empty history database URL on each back-end."""
    import sqlalchemy as sa

    from condmon.store import schema

    if request.param == "sqlite":
        yield str(tmp_path / "history.db")
        return
    url = _postgres_url()
    if url is None:
        pytest.skip("no PostgreSQL server (set CONDMON_TEST_POSTGRES_URL; .ci/run starts one)")
    engine = sa.create_engine(url.replace("postgresql://", "postgresql+psycopg://", 1))
    schema.metadata.drop_all(engine)
    engine.dispose()
    yield url
    engine = sa.create_engine(url.replace("postgresql://", "postgresql+psycopg://", 1))
    schema.metadata.drop_all(engine)
    engine.dispose()


@pytest.fixture(scope="session")
def wearing(tmp_path_factory: pytest.TempPathFactory, demo_rig: ActuatorRig) -> tuple[Path, float]:
    """A unit whose friction (viscous and Coulomb alike, as a brake) rises
    linearly by 20 % of its healthy value a day: +600 % (no-go, r2) about day
    30; 15 dated checks stored; a unit wearing at half that pace (SLOW) and a
    stable unit. Shared by the modules that read a wearing history; a test that
    writes works on a copy."""
    from condmon.store import open_store
    from condmon.workflows.checks import check_test
    from condmon.workflows.monitoring import add_baseline_tests

    db = tmp_path_factory.mktemp("forecast") / "h.db"
    with open_store(str(db)) as store:
        add_baseline_tests(store, "WEAR", [simulate_actuator(demo_rig, seed=s) for s in (1, 2, 3)],
                           test_date="2026-01-01")
        add_baseline_tests(store, "STABLE", [simulate_actuator(demo_rig, seed=s)
                                             for s in (4, 5, 6)], test_date="2026-01-01")
        add_baseline_tests(store, "SLOW", [simulate_actuator(demo_rig, seed=s)
                                           for s in (7, 8, 9)], test_date="2026-01-01")
        for k in range(1, 16):
            f = 1.0 + 0.2 * k
            rig = demo_rig.with_faults([f"D=*{f}", f"coulomb_friction=*{f}"])
            check_test(store, "WEAR", simulate_actuator(rig, seed=100 + k),
                       test_date=f"2026-01-{1 + k:02d}")
            f = 1.0 + 0.1 * k
            rig = demo_rig.with_faults([f"D=*{f}", f"coulomb_friction=*{f}"])
            check_test(store, "SLOW", simulate_actuator(rig, seed=300 + k),
                       test_date=f"2026-01-{1 + k:02d}")
            check_test(store, "STABLE", simulate_actuator(demo_rig, seed=200 + k),
                       test_date=f"2026-01-{1 + k:02d}")
        # the truth: the day the unit's check turns no-go (dry runs, nothing stored)
        for k in range(16, 46):
            f = 1.0 + 0.2 * k
            rig = demo_rig.with_faults([f"D=*{f}", f"coulomb_friction=*{f}"])
            later = check_test(store, "WEAR", simulate_actuator(rig, seed=100 + k),
                               dry_run=True)
            if later.status == "no-go":
                return db, float(k - 15)
    raise AssertionError("the unit never turned no-go")
