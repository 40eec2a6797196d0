"""Least squares over a route's stacked equations, estimating only what they identify.

The inverse-model and steady routes both end in ``Σ θ_k φ_k = known`` over
one or more equations (blocks of rows). :func:`identified_lstsq` solves it:

1. weights per block: given (the steady route's standard errors per window),
   or from the residual of a first pass (each equation's residual standard
   deviation, two passes, as the inverse route always did);
2. the unknowns the weighted rows identify
   (:func:`~condmon.identify.identifiability.assess_identifiability` on the
   columns scaled by each unknown's typical value); the others are held at
   their given values and moved to the known side;
3. the weighted least-squares estimate of the identifiable ones and its
   covariance ``(Xᵀ W X)⁻¹``; with weights from the residuals, each variance
   is widened to the Newey–West sandwich ``A⁻¹ S A⁻¹`` where that is larger
   (``S`` the long-run covariance of the rows' scores,
   :mod:`condmon.identify.long_run`). The inverse route's rows are filtered and
   differentiated signals, so its residuals are correlated over about the
   filter's impulse response even under white sensor noise, and the white
   bound alone is too small (6.8–12.7× on the EMPS record).

Written for condmon (a few lines of numpy around the identifiability choice).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from condmon.errors import EstimationError
from condmon.identify.identifiability import Identifiability, assess_identifiability
from condmon.identify.long_run import widened
from condmon.models.plausibility import IdentifiabilityLimits

__all__ = ["IdentifiedFit", "identified_lstsq"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class IdentifiedFit:
    """Outcome of :func:`identified_lstsq`.

    Attributes
    ----------
    values : dict of str to float
        Every unknown: estimated, or held at its given value. [SI]
    covariance : ndarray, shape (p, p)
        Covariance of all unknowns in their order; rows and columns of a held
        unknown are zero. [SI²]
    identifiability : Identifiability
    residuals : list of ndarray
        Each block's unweighted residual ``known - Σ θ φ``.
    weights : ndarray
        The weight of each block's rows (one per block, or per row).
    widening : float
        The largest factor by which the residuals' correlation widened a
        standard error over the white-noise bound (1: none, or weights given). [-]
    bandwidth : float
        The Bartlett bandwidth of that widening (0: not computed). [rows]
    """

    values: dict[str, float]
    covariance: FloatArray
    identifiability: Identifiability
    residuals: list[FloatArray]
    weights: list[FloatArray]
    widening: float = 1.0
    bandwidth: float = 0.0


def _stack(blocks: Sequence[FloatArray], rhs: Sequence[FloatArray],
           w: Sequence[FloatArray]) -> tuple[FloatArray, FloatArray]:
    X = np.vstack([b * wi[:, None] for b, wi in zip(blocks, w)])
    y = np.concatenate([r * wi for r, wi in zip(rhs, w)])
    return X, y


def identified_lstsq(blocks: Sequence[FloatArray], rhs: Sequence[FloatArray],
                     names: Sequence[str], scales: Mapping[str, float],
                     hold: Mapping[str, float], *, source: str,
                     limits: IdentifiabilityLimits | None = None,
                     absent: Mapping[str, str] | None = None,
                     weights: Sequence[FloatArray] | None = None) -> IdentifiedFit:
    """Weighted least squares of the identifiable unknowns, the others held.

    Parameters
    ----------
    blocks : sequence of ndarray, each (n_i, p)
        Regressors of each equation.
    rhs : sequence of ndarray, each (n_i,)
        Known side of each equation.
    names : sequence of str
        The unknowns (columns), in order of preference.
    scales : mapping of str to float
        A typical magnitude of each unknown (held or nominal value): the
        columns are compared for a relative change. An unknown with no
        typical magnitude (0, an offset) is scaled by the value whose term
        would be as large as the known side (RMS ratio). [SI]
    hold : mapping of str to float
        Value of each unknown when it is not identifiable. [SI]
    source : str
        The record(s), named in messages.
    limits : IdentifiabilityLimits, optional
    absent : mapping of str to str, optional
        Unknowns known not to enter these equations, with the reason.
    weights : sequence of ndarray, optional
        The inverse standard deviation of each block's rows (per row); None:
        from each block's residual standard deviation (two passes).

    Returns
    -------
    IdentifiedFit
        When nothing is identifiable, ``identifiability.identifiable`` is
        empty, every value held and the covariance zero.

    Raises
    ------
    EstimationError
        Regressors that are not finite.

    Example
    -------
    >>> x = np.linspace(1.0, 2.0, 50)
    >>> fit = identified_lstsq([np.column_stack([x, np.ones(50)])], [3.0 * x + 1.0],
    ...                        ("a", "b"), {"a": 1.0, "b": 1.0}, {"a": 0.0, "b": 0.0},
    ...                        source="demo", weights=[np.full(50, 1e3)])
    >>> round(fit.values["a"], 6), round(fit.values["b"], 6), fit.identifiability.identifiable
    (3.0, 1.0, ('a', 'b'))
    """
    p = len(names)
    lim = limits or IdentifiabilityLimits()
    if not all(np.all(np.isfinite(b)) for b in blocks) or \
            not all(np.all(np.isfinite(r)) for r in rhs):
        raise EstimationError(f"{source}: the regressors are not finite")
    scale = np.array([abs(float(scales.get(n, 0.0))) for n in names])
    if np.any(scale == 0):
        X0, y0 = _stack(blocks, rhs, [np.ones(len(r)) for r in rhs])
        rms_y = float(np.sqrt(np.mean(y0 ** 2))) if y0.size else 0.0
        rms_x = np.sqrt(np.mean(X0 ** 2, axis=0)) if X0.size else np.zeros(p)
        with np.errstate(divide="ignore", invalid="ignore"):
            natural = np.where(rms_x > 0, rms_y / rms_x, 1.0)
        scale = np.where(scale > 0, scale, np.where(natural > 0, natural, 1.0))
    held_at = np.array([float(hold.get(n, 0.0)) for n in names])
    given = weights is not None
    w = [np.asarray(x, dtype=np.float64) for x in weights] if weights is not None else \
        [np.ones(len(r)) for r in rhs]
    theta = held_at.copy()
    # given weights (per window): the collinearity is judged on the windows with
    # one weight per equation (see assess_identifiability's ``design``)
    design = _stack(blocks, rhs, [np.full(len(x), float(np.mean(x))) for x in w])[0] * scale \
        if given and all(len(x) for x in w) else None
    idf = assess_identifiability(np.zeros((1, p)), names, limits=lim, absent=absent)
    # Given weights: one pass. Otherwise two, each re-weighting every block by
    # the inverse standard deviation of its residual (the covariance takes the
    # weights of the second pass's residual).
    passes = 1 if given else 2
    for k in range(passes):
        X, y = _stack(blocks, rhs, w)
        # without an estimate of the noise yet, only the collinearity decides
        first = (not given and k == 0)
        pass_limits = IdentifiabilityLimits(lim.max_collinearity, np.inf) if first else lim
        idf = assess_identifiability(X * scale, names, limits=pass_limits, absent=absent,
                                     design=design)
        chosen = [names.index(n) for n in idf.identifiable]
        theta = held_at.copy()
        if chosen:
            free = X[:, chosen] * scale[chosen]
            fixed = [j for j in range(p) if j not in chosen]
            y_adj = y - X[:, fixed] @ held_at[fixed] if fixed else y
            theta[chosen] = np.linalg.lstsq(free, y_adj, rcond=None)[0] * scale[chosen]
        if not given:
            resid = [r - b @ theta for b, r in zip(blocks, rhs)]
            sig = [max(float(np.std(e)), 1e-300) for e in resid]
            w = [np.full(len(e), 1.0 / s) for e, s in zip(resid, sig)]
    cov = np.zeros((p, p))
    chosen = [names.index(n) for n in idf.identifiable]
    if chosen:
        X, _ = _stack(blocks, rhs, w)
        Xc = X[:, chosen]
        try:
            cov_c = np.linalg.inv(Xc.T @ Xc)
        except np.linalg.LinAlgError:
            raise EstimationError(f"{source}: the regression is singular although its "
                                  "unknowns were judged identifiable") from None
        cov[np.ix_(chosen, chosen)] = cov_c
    resid = [r - b @ theta for b, r in zip(blocks, rhs)]
    widening, bandwidth = 1.0, 0.0
    if chosen and not given:
        cov, widening, bandwidth = _widened(cov, chosen, blocks, resid, w)
    return IdentifiedFit(dict(zip(names, map(float, theta))), cov, idf, resid, w,
                         widening, bandwidth)


def _widened(cov: FloatArray, chosen: Sequence[int], blocks: Sequence[FloatArray],
             resid: Sequence[FloatArray], w: Sequence[FloatArray]
             ) -> tuple[FloatArray, float, float]:
    """:func:`~condmon.identify.long_run.widened` on the estimated unknowns.
    Blocks of one length are equations over the same rows (their scores add
    per row); otherwise the blocks' rows follow each other."""
    scores = [(b[:, chosen] * wi[:, None]) * (wi * e)[:, None]
              for b, e, wi in zip(blocks, resid, w)]
    same = len({g.shape[0] for g in scores}) == 1
    g = sum(scores[1:], scores[0]) if same else np.vstack(scores)
    C, factor, bandwidth = widened(cov[np.ix_(chosen, chosen)], g)
    out = cov.copy()
    out[np.ix_(chosen, chosen)] = C
    return out, factor, bandwidth
