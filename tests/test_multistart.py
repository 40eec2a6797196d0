"""Several starts in lockstep: the same optimum as each start alone, their
simulations batched, and a failure stops every start without a hang."""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np
import pytest

from condmon.errors import EstimationError
from condmon.identify.multistart import Evaluate, solve, solve_starts

T = np.linspace(0.0, 4.0, 60)
TRUE = np.array([2.0, 0.7])   # amplitude, decay rate [1/s]
Y = TRUE[0] * np.exp(-TRUE[1] * T) + 0.01 * np.random.default_rng(3).standard_normal(T.size)
LO, HI = np.array([0.0, 0.0]), np.array([10.0, 5.0])


def _residuals(widths: list[int]) -> Evaluate:
    def evaluate(zc: np.ndarray) -> np.ndarray:
        widths.append(zc.shape[1])
        return np.asarray(Y[:, None] - zc[0] * np.exp(-np.outer(T, zc[1])))
    return evaluate


def _jacobian(z: np.ndarray, evaluate: Evaluate) -> np.ndarray:
    cols = np.column_stack([z] + [z + 1e-7 * np.eye(2)[i] for i in range(2)])
    r = evaluate(cols)
    return np.asarray((r[:, 1:] - r[:, :1]) / 1e-7)


STARTS = [np.array([1.0, 0.1]), np.array([5.0, 3.0]), np.array([0.5, 1.5])]


def _guarded(fn: Callable[[], object]) -> object:
    """Run ``fn`` in a thread that must end within 20 s (a deadlock fails, not hangs)."""
    out: dict[str, object] = {}

    def target() -> None:
        try:
            out["value"] = fn()
        except BaseException as err:  # noqa: BLE001 - handed to the test
            out["error"] = err

    t = threading.Thread(target=target, daemon=True)
    t.start()
    t.join(20)
    assert not t.is_alive(), "the starts did not end"
    if "error" in out:
        raise out["error"]  # type: ignore[misc]
    return out["value"]


def test_starts_together_reach_what_each_reaches_alone_in_fewer_passes() -> None:
    alone_widths: list[int] = []
    alone = [solve(_residuals(alone_widths), _jacobian, z, LO, HI, 50, T.size) for z in STARTS]
    widths: list[int] = []
    together = _guarded(lambda: solve_starts(_residuals(widths), _jacobian, STARTS, LO, HI, 50,
                                             T.size))
    assert isinstance(together, list)
    for (z1, c1, n1), (z2, c2, n2) in zip(alone, together):
        assert np.array_equal(z1, z2) and c1 == c2 and n1 == n2
        assert z2 == pytest.approx(TRUE, rel=0.02)   # the known truth
    # the first round carries every start's first request; no column is lost or doubled
    assert widths[0] == len(STARTS)
    assert sum(widths) == sum(alone_widths)
    assert len(widths) < len(alone_widths)
    assert not any(t.name.startswith("start") for t in threading.enumerate())


def test_a_failed_pass_stops_every_start_and_is_raised() -> None:
    calls = []

    def evaluate(zc: np.ndarray) -> np.ndarray:
        calls.append(zc.shape[1])
        if len(calls) == 3:
            raise EstimationError("the pass failed")
        return np.asarray(Y[:, None] - zc[0] * np.exp(-np.outer(T, zc[1])))

    with pytest.raises(EstimationError, match="the pass failed"):
        _guarded(lambda: solve_starts(evaluate, _jacobian, STARTS, LO, HI, 50, T.size))
    assert not any(t.name.startswith("start") for t in threading.enumerate())


def test_a_start_that_fails_is_raised_after_the_others_end() -> None:
    def jac(z: np.ndarray, evaluate: Evaluate) -> np.ndarray:
        if z[0] > 4.0:   # the second start's first Jacobian
            raise EstimationError("this start failed")
        return _jacobian(z, evaluate)

    with pytest.raises(EstimationError, match="this start failed"):
        _guarded(lambda: solve_starts(_residuals([]), jac, STARTS, LO, HI, 50, T.size))
    assert not any(t.name.startswith("start") for t in threading.enumerate())


def test_a_start_that_does_not_simulate_costs_inf_and_the_others_go_on() -> None:
    def evaluate(zc: np.ndarray) -> np.ndarray:
        r = Y[:, None] - zc[0] * np.exp(-np.outer(T, zc[1]))
        r[:, zc[0] > 4.9] = np.nan   # a run that left the numbers
        return np.asarray(r)

    runs = _guarded(lambda: solve_starts(evaluate, _jacobian, STARTS, LO, HI, 50, T.size))
    assert isinstance(runs, list)
    assert runs[1][1] == np.inf and runs[1][2] == 1
    assert runs[0][0] == pytest.approx(TRUE, rel=0.02)
