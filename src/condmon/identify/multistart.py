"""Bounded least squares on simulations: one run, or several starts in lockstep.

A simulation-error fit spends its time in passes over the record
(:func:`condmon.simulate.recorded.simulate_copies`), and a pass costs about
the same for one copy of the model as for forty: the work per sample is the
interpreter's and numpy's per-call overhead, not arithmetic (the cascaded
tanks' derivatives take 34 µs for one copy and 36 µs for 44). So the starts of
a multi-start fit run together. Each start's optimiser (scipy's
``least_squares``) runs in a thread of its own and asks for its residuals; a
round takes the request of every start still running and simulates them all
in one pass. The rounds are fixed by the starts alone (a round waits for every
start still running), so the figures do not depend on the threads' timing,
and each column of a pass is computed on its own: a start reaches what it
would reach alone.

Why by hand: ``least_squares`` solves one problem and asks for its function
synchronously; no maintained package batches the evaluations of several.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numpy.typing import NDArray

from condmon.errors import EstimationError

__all__ = ["Evaluate", "Jacobian", "solve", "solve_starts"]

FloatArray = NDArray[np.float64]
#: Residual columns (rows, B) of unknowns' columns (n_z, B).
Evaluate = Callable[[FloatArray], FloatArray]
#: The Jacobian (rows, n_z) at ``z``, its simulations through the evaluator given.
Jacobian = Callable[[FloatArray, Evaluate], FloatArray]
_FAR = 1e100           # residuals beyond this are a diverged run (their squares would overflow)


def solve(evaluate: Evaluate, jacobian: Jacobian, z0: FloatArray, lo: FloatArray,
          hi: FloatArray, max_nfev: int, n_out: int) -> tuple[FloatArray, float, int]:
    """One bounded least-squares run from ``z0``.

    Parameters
    ----------
    evaluate : callable
        Residual columns of unknowns' columns (normalised, dimensionless).
    jacobian : callable
        ``jacobian(z, evaluate)``: the residuals' Jacobian at ``z``.
    z0, lo, hi : ndarray
        Start and bounds of the unknowns. [their units]
    max_nfev : int
        Most evaluations of the residuals.
    n_out : int
        The residuals that are output errors (the first ``n_out``; the others
        are the shooting segments' jumps).

    Returns
    -------
    tuple
        The optimum, the RMS of its normalised output errors (``inf`` when the
        start does not simulate) and the simulations it took.

    Example
    -------
    >>> f = lambda z: z - 3.0
    >>> jac = lambda z, ev: np.eye(1)
    >>> z, cost, n = solve(f, jac, np.zeros(1), np.full(1, -10.0), np.full(1, 10.0), 20, 1)
    >>> round(float(z[0]), 6), cost
    (3.0, 0.0)
    """
    from scipy.optimize import least_squares  # ~0.25 s of imports: only when fitting

    def fun(z: FloatArray) -> FloatArray:
        # a run that left the numbers, or went so far that its squared sum would
        # overflow, is a step the optimiser refuses (it shrinks its trust region)
        r = evaluate(z[:, None])[:, 0]
        ok = np.all(np.isfinite(r)) and float(np.max(np.abs(r), initial=0.0)) < _FAR
        return r if ok else np.full(r.size, np.inf)

    r0 = fun(z0)
    if not np.all(np.isfinite(r0)):
        return z0, math.inf, 1
    try:
        sol = least_squares(fun, z0, jac=lambda z: jacobian(z, evaluate), bounds=(lo, hi),
                            method="trf", x_scale="jac", max_nfev=max_nfev)
    except (ValueError, np.linalg.LinAlgError) as err:
        raise EstimationError(f"simulation-error route failed: {err}") from None
    z = np.asarray(sol.x, dtype=np.float64)
    return z, float(np.sqrt(np.mean(sol.fun[:n_out] ** 2))), int(sol.nfev + sol.njev)


class _Stopped(Exception):
    """The rounds ended under a start (another start's pass failed)."""


class _Rounds:
    """The requests of the starts still running, served one pass per round."""

    def __init__(self, evaluate: Evaluate, starts: int) -> None:
        self._evaluate = evaluate
        self._cv = threading.Condition()
        self._asked: dict[int, FloatArray] = {}
        self._given: dict[int, FloatArray] = {}
        self._live = starts
        self._stopped = False

    def ask(self, k: int, zc: FloatArray) -> FloatArray:
        """Start ``k``'s residual columns of ``zc``, from the next round."""
        with self._cv:
            self._asked[k] = zc
            self._cv.notify_all()
            while k not in self._given:
                if self._stopped:
                    raise _Stopped
                self._cv.wait()
            return self._given.pop(k)

    def leave(self) -> None:
        """Start ``k`` has ended: the rounds no longer wait for it."""
        with self._cv:
            self._live -= 1
            self._cv.notify_all()

    def serve(self) -> None:
        """Rounds until every start has ended; on any failure, the starts stop."""
        try:
            while True:
                with self._cv:
                    while self._live > 0 and len(self._asked) < self._live:
                        self._cv.wait()
                    if self._live == 0:
                        return
                    order = sorted(self._asked)
                    batch = [self._asked.pop(k) for k in order]
                r = self._evaluate(np.hstack(batch))
                cuts = np.cumsum([b.shape[1] for b in batch])[:-1]
                with self._cv:
                    self._given.update(zip(order, np.hsplit(r, cuts)))
                    self._cv.notify_all()
        except BaseException:
            with self._cv:
                self._stopped = True
                self._cv.notify_all()
            raise


def solve_starts(evaluate: Evaluate, jacobian: Jacobian, starts: Sequence[FloatArray],
                 lo: FloatArray, hi: FloatArray, max_nfev: int, n_out: int
                 ) -> list[tuple[FloatArray, float, int]]:
    """:func:`solve` from each of ``starts``, their simulations batched.

    Returns what :func:`solve` returns for each start, in order; the first
    error of any start is raised once every start has ended.

    Example
    -------
    >>> f = lambda zc: zc ** 2 - 4.0
    >>> jac = lambda z, ev: np.diag(2.0 * z)
    >>> runs = solve_starts(f, jac, [np.ones(1), np.full(1, 5.0)],
    ...                     np.zeros(1), np.full(1, 9.0), 50, 1)
    >>> [round(float(z[0]), 6) for z, _, _ in runs]
    [2.0, 2.0]
    """
    if len(starts) == 1:
        return [solve(evaluate, jacobian, starts[0], lo, hi, max_nfev, n_out)]
    rounds = _Rounds(evaluate, len(starts))

    def run(k: int, z0: FloatArray) -> tuple[FloatArray, float, int]:
        try:
            return solve(lambda zc: rounds.ask(k, zc), jacobian, z0, lo, hi, max_nfev, n_out)
        finally:
            rounds.leave()

    with ThreadPoolExecutor(max_workers=len(starts), thread_name_prefix="start") as pool:
        futures = [pool.submit(run, k, z) for k, z in enumerate(starts)]
        rounds.serve()
        return [f.result() for f in futures]
