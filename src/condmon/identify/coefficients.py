"""The physical parameters whose transfer-function coefficients are given.

The linear route (:mod:`condmon.identify.greybox`) estimates a continuous
model's coefficients; here the unknowns are solved from the declaration's
symbolic coefficient map: by (Gauss-)Newton where the map is square and of
full rank, by generalised least squares where the coefficients outnumber the
unknowns or the map is short of rank (a structure that fixes a relation
among the coefficients). Written for condmon: the map is the declaration's
own, and scipy's ``least_squares`` is only the fall-back search (imported
where needed, so the linear route's fast path stays free of it).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConversionError
from condmon.models.machine import LinearStructure

__all__ = ["solve_coefficients", "rank_short"]

FloatArray = NDArray[np.float64]


def solve_coefficients(lin: LinearStructure, target: FloatArray, start: FloatArray,
                        known: FloatArray, weight: FloatArray | None = None,
                        exact: bool | None = None) -> FloatArray:
    """The unknowns whose coefficients are ``target``: exactly when as many
    as the coefficients (``exact``, by default), else by generalised least
    squares with ``weight`` (``W``, ``WᵀW`` the inverse of the coefficients'
    covariance), so a coefficient the record barely determines cannot pull
    the others."""
    if weight is None:
        weight = np.diag(1.0 / np.where(target != 0, np.abs(target), 1.0))

    def res(p: FloatArray) -> FloatArray:
        with np.errstate(all="ignore"):  # far from the solution: inf, judged by the caller
            return np.asarray(weight @ (lin.values(p, known) - target), dtype=np.float64)

    def jac(p: FloatArray) -> FloatArray:
        with np.errstate(all="ignore"):
            return np.asarray(weight @ lin.jacobian(p, known), dtype=np.float64)

    # Newton (Gauss-Newton when over-determined) from the declared values, then
    # from their mirror image: a record with an inverted sign maps to negative
    # parameters, which the plausibility check then names, rather than to a
    # spurious far-away solution. A bounded trust-region search is the fallback.
    best: FloatArray | None = None
    best_cost = np.inf
    exact = target.size == start.size if exact is None else exact
    settled = False   # over-determined: a least-squares solution found (a misfit remains)
    for x0 in (start, -start):
        p = _newton(res, jac, x0)
        if not exact and p is not None and _stationary(res, jac, p):
            settled = True
        elif settled:   # (over-determined, a solution in hand: this start's as Newton left it)
            if p is None:
                continue
        # the search where Newton failed, or left an exact system unsolved, or
        # (over-determined) stopped short of a stationary point
        elif p is None or _squares(res(p)) > 1e-20:
            from scipy.optimize import least_squares

            try:
                with np.errstate(all="ignore"):
                    sol = least_squares(res, x0, jac=jac, method="trf",
                                        x_scale=np.where(x0 != 0, np.abs(x0), 1.0),
                                        xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200)
            except (ValueError, np.linalg.LinAlgError):
                continue
            x = np.asarray(sol.x, dtype=np.float64)
            polished = _newton(res, jac, x, steps=3)
            found = polished if polished is not None else x
            if p is None or _squares(res(found)) < _squares(res(p)):
                p = found
        with np.errstate(all="ignore"):
            r = res(p)
        cost = float(r @ r) if np.all(np.isfinite(r)) else np.inf
        if cost < best_cost:
            best, best_cost = p, cost
        if cost < 1e-20:
            break
    if best is None or not np.all(np.isfinite(best)):
        raise ConversionError("the coefficient map has no finite solution")
    if exact and best_cost > 1e-12:
        raise ConversionError("no parameter values reproduce the estimated coefficients "
                              f"(relative mismatch {np.sqrt(best_cost):.2g})")
    return best


def rank_short(J: FloatArray) -> bool:
    """Whether the column-scaled Jacobian ``J`` of the coefficient map is short
    of full column rank (its smallest singular value below 1e-9 of its largest,
    a structural zero rather than a weak record).

    Examples
    --------
    >>> import numpy as np
    >>> rank_short(np.array([[1.0, 2.0], [2.0, 4.0], [0.5, 1.0]]))
    True
    >>> rank_short(np.eye(2))
    False
    """
    with np.errstate(all="ignore"):
        if J.size == 0 or not np.all(np.isfinite(J)):
            return False
        sv = np.linalg.svd(J, compute_uv=False)
    return bool(sv[-1] <= 1e-9 * sv[0]) if J.shape[0] >= J.shape[1] else True


def _stationary(res: Any, jac: Any, p: FloatArray) -> bool:
    """Whether ``p`` is a stationary point of ``Σ res²``: the gradient ``Jᵀr``
    within 1e-8 of ``‖J‖ ‖r‖`` (where Gauss-Newton has converged)."""
    with np.errstate(all="ignore"):
        r, J = res(p), jac(p)
        g = float(np.linalg.norm(J.T @ r))
        scale = float(np.linalg.norm(J)) * float(np.linalg.norm(r))
    return bool(np.isfinite(g) and np.isfinite(scale) and g <= 1e-8 * scale)


def _squares(r: FloatArray) -> float:
    """``Σ r²`` (a dot product: the misfit of a few coefficients, in loops)."""
    return float(r @ r)


def _newton(res: Any, jac: Any, x0: FloatArray, steps: int = 30) -> FloatArray | None:
    """Damped (Gauss-)Newton on ``res(p) = 0``: the last iterate, or None when
    the misfit or its Jacobian stops being finite or the step cannot be solved."""
    p = np.array(x0, dtype=np.float64)
    with np.errstate(all="ignore"):
        r = res(p)
        cost = float(r @ r)
        for _ in range(steps):
            if not np.isfinite(cost):
                return None
            if cost < 1e-26:
                return p
            J = jac(p)
            if not np.all(np.isfinite(J)):
                return None
            try:
                step = (np.linalg.solve(J, -r) if J.shape[0] == J.shape[1]
                        else np.linalg.lstsq(J, -r, rcond=None)[0])
            except np.linalg.LinAlgError:
                return None
            t = 1.0
            for _ in range(20):  # halve the step until the misfit falls
                q = p + t * step
                rq = res(q)
                cq = float(rq @ rq)
                if np.isfinite(cq) and cq < cost:
                    break
                t *= 0.5
            else:  # no descent: a (least-squares) stationary point
                return p
            if cost - cq < 1e-30:  # no further progress: converged
                return q
            p, r, cost = q, rq, cq
    return p
