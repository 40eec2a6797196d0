"""Long-run (autocorrelation-consistent) covariance of an estimator's scores.

An instrumental-variable estimate solves ``Σ_t ζ_t e_t = 0``; its covariance is
``R⁻¹ S R⁻ᵀ`` with ``S`` the variance of ``Σ_t g_t``, ``g_t = ζ_t e_t``. The
white-noise bound takes ``S = σ² Σ ζζᵀ``, which holds only when the residuals
``e_t`` are uncorrelated in time. Sensor noise that is filtered (anti-alias
filters, a drifting reference, vibration) is not, and then the bound is too
small by the noise's long-run variance ratio: 2–4× on the standard error of an
actuator's parameters under AR(1) noise with coefficient 0.9.

Here ``S`` is the Bartlett-kernel (Newey and West 1987) estimate
``Γ₀ + Σ_l (1 - l/b)(Γ_l + Γ_lᵀ)`` with the bandwidth ``b`` from Andrews'
(1991, eq. 6.4) AR(1) plug-in rule, so it adapts to the noise: for white
residuals ``b`` is about 1 and ``S`` is White's (1980) heteroscedasticity-robust
sum, which equals the bound on average.

Written here rather than taken from a library: the one library that has it
(statsmodels' ``cov_hac``) is not a dependency, costs about 1 s to import, and
takes a regression result object rather than the scores.

Example
-------
>>> rng = np.random.default_rng(0)
>>> g = rng.standard_normal((4000, 2))
>>> S, b = long_run_covariance(g)
>>> bool(np.allclose(S / 4000, np.eye(2), atol=0.08)), b < 5
(True, True)
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from condmon.identify._products import gram, product

__all__ = ["long_run_covariance", "long_run_covariance_of", "andrews_bandwidth", "MAX_RHO",
           "widened", "normalised_inverse"]

FloatArray = NDArray[np.float64]

#: Largest lag-1 autocorrelation the bandwidth rule takes from the scores
#: (Andrews 1991 truncates the plug-in the same way, at 0.97, to keep the
#: bandwidth finite when the scores look like a random walk).
MAX_RHO = 0.97


def _bandwidth(den: FloatArray, cross: FloatArray, sq1: FloatArray, T: int) -> float:
    """Andrews' bandwidth from each column's sums over consecutive pairs of the
    demeaned scores: ``Σ x0²``, ``Σ x0 x1`` and ``Σ x1²`` (on plain floats: a
    handful of columns, where numpy's per-call cost is most of the work)."""
    num = dsum = 0.0
    for d, c, q in zip(den.tolist(), cross.tolist(), sq1.tolist()):
        rho = min(max(c / d, -MAX_RHO), MAX_RHO) if d > 0 else 0.0
        # the AR(1) innovations' variance, mean of (x1 - rho x0)^2, from the sums
        s2 = max(q - 2 * rho * c + rho * rho * d, 0.0) / max(T - 1, 1)
        num += 4 * rho * rho * s2 * s2 / ((1 - rho) ** 6 * (1 + rho) ** 2)
        dsum += s2 * s2 / (1 - rho) ** 4
    alpha = num / dsum if dsum > 0 else 0.0
    return float(min(max(1.1447 * (alpha * T) ** (1.0 / 3.0), 1.0), T / 2))


def andrews_bandwidth(g: FloatArray) -> float:
    """Bartlett bandwidth ``1.1447 (α̂ T)^{1/3}`` from AR(1) fits to each
    column of the (demeaned) scores ``g`` (T, p) (Andrews 1991, eq. 6.4).

    Returns
    -------
    float
        The bandwidth [samples], at least 1 and at most ``T / 2``.
    """
    x0, x1 = g[:-1], g[1:]
    return _bandwidth(np.einsum("ij,ij->j", x0, x0), np.einsum("ij,ij->j", x0, x1),
                      np.einsum("ij,ij->j", x1, x1), g.shape[0])


def long_run_covariance(g: FloatArray) -> tuple[FloatArray, float]:
    """The Bartlett-kernel long-run covariance of ``Σ_t g_t``.

    Parameters
    ----------
    g : ndarray, shape (T, p)
        Scores, one row per sample (demeaned here, not in place).

    Returns
    -------
    S : ndarray, shape (p, p)
        Estimated covariance of the scores' sum [score unit²].
    bandwidth : float
        The Bartlett bandwidth used [samples].
    """
    return long_run_covariance_of(lambda a, b: g[a:b], g.shape[0])


#: Rows of scores formed at a time (a long record's scores are never whole).
BLOCK = 65536


def long_run_covariance_of(rows: Callable[[int, int], FloatArray], T: int, *,
                           block: int = BLOCK) -> tuple[FloatArray, float]:
    """:func:`long_run_covariance` of scores made on demand, ``rows(a, b)``
    giving rows ``a..b-1`` (T in all), so that memory is bounded by a block.

    Three passes: the mean; the lag-1 sums the bandwidth needs; and the sum
    of the lag products within the bandwidth, each block carrying the rows
    before it that its first rows reach back to.
    """
    if T <= block:   # one block: made once, not once a pass
        return _from_whole(rows(0, T))
    return _from_rows(rows, T, block)


def _from_whole(g: FloatArray) -> tuple[FloatArray, float]:
    """:func:`_from_rows` on scores held whole, in fewer passes: demeaned
    once, and the bandwidth's lag-1 sums taken from the lag-0 and lag-1
    products that the sum needs anyway (matrix products, not reductions)."""
    T = g.shape[0]
    if T < 2:   # no consecutive pair
        return _from_rows(lambda a, b: g[a:b], T, BLOCK)
    x = g - (np.ones(T) @ g) / T
    G0 = gram(x)
    G1 = product(x[1:], x[:-1])    # Σ x_t x_{t-1}ᵀ
    total = np.diag(G0)
    # Σ x0², Σ x0 x1, Σ x1² over the consecutive pairs: all rows but the last, or the first
    b = _bandwidth(total - x[-1] ** 2, np.diag(G1).copy(), total - x[0] ** 2, T)
    S = G0.copy()
    for lag in range(1, math.ceil(b)):   # lags 1 .. ceil(b) - 1 have weight > 0
        gamma = G1 if lag == 1 else product(x[lag:], x[:-lag])
        S += (1.0 - lag / b) * (gamma + gamma.T)
    return S, b


def _from_rows(rows: Callable[[int, int], FloatArray], T: int, block: int
               ) -> tuple[FloatArray, float]:
    """The three passes of :func:`long_run_covariance_of`."""
    total = np.zeros(0)
    for a in range(0, T, block):
        part = rows(a, min(T, a + block)).sum(axis=0)
        total = part if not total.size else total + part
    mean = total / max(T, 1)
    p = mean.size
    den, cross, sq1 = np.zeros(p), np.zeros(p), np.zeros(p)
    for a in range(0, T, block):
        g = rows(max(a - 1, 0), min(T, a + block)) - mean
        x0, x1 = g[:-1], g[1:]
        den += np.einsum("ij,ij->j", x0, x0)
        cross += np.einsum("ij,ij->j", x0, x1)
        sq1 += np.einsum("ij,ij->j", x1, x1)
    b = _bandwidth(den, cross, sq1, T)
    reach = math.ceil(b) - 1   # lags 1 .. ceil(b) - 1 have weight > 0
    S = np.zeros((p, p))
    for a in range(0, T, block):
        lo = max(a - reach, 0)
        g = rows(lo, min(T, a + block)) - mean
        own = g[a - lo:]
        S += gram(own)
        for lag in range(1, reach + 1):
            first = max(a, lag) - lo   # rows of this block with a row ``lag`` before them
            if first >= g.shape[0]:
                break
            gamma = product(g[first:], g[first - lag: g.shape[0] - lag])
            S += (1.0 - lag / b) * (gamma + gamma.T)
    return S, b


def widened(cov: FloatArray, scores: FloatArray) -> tuple[FloatArray, float, float]:
    """A least-squares covariance ``cov`` (the white-noise bound ``A⁻¹``) with
    each variance widened to the Newey–West sandwich ``A⁻¹ S A⁻¹`` where that
    is larger, the correlations kept: the standard errors hold when the
    residuals are correlated in time, and stay the bound when they are white.

    Parameters
    ----------
    cov : ndarray, shape (p, p)
        ``A⁻¹``, ``A`` the information of the normalised residuals.
    scores : ndarray, shape (T, p)
        Each sample's score (the normalised residual times its row of the
        normalised Jacobian, summed over the outputs), in time order.

    Returns
    -------
    cov : ndarray
    widening : float
        The largest factor on a standard error (1: none). [-]
    bandwidth : float
        The Bartlett bandwidth (0: too few samples to estimate one). [samples]
    """
    if scores.shape[0] < 10:
        return cov, 1.0, 0.0
    S, bandwidth = long_run_covariance(scores)
    robust = cov @ S @ cov
    with np.errstate(all="ignore"):
        ratio = np.sqrt(np.clip(np.diag(robust), 0.0, None) / np.diag(cov))
    s = np.where(np.isfinite(ratio), np.maximum(ratio, 1.0), 1.0)
    return cov * s[:, None] * s[None, :], float(np.max(s)), float(bandwidth)


def normalised_inverse(info: FloatArray) -> tuple[FloatArray | None, float]:
    """The inverse of an information matrix ``JᵀJ`` and its condition number,
    both on the columns normalised: a parameter in henry beside one in N m/rad
    is no ill-conditioning (1.3e14 unscaled on a two-mass drive whose every
    unknown the record fixed). None (and inf) where a column is zero or not
    finite.

    Example
    -------
    >>> info = np.diag([1e-12, 1e12])
    >>> inv, cond = normalised_inverse(info)
    >>> cond, bool(np.allclose(inv, np.diag([1e12, 1e-12])))
    (1.0, True)
    """
    if not np.all(np.isfinite(info)):
        return None, math.inf
    norms = np.sqrt(np.clip(np.diag(info), 0.0, None))
    if not np.all(norms > 0):
        return None, math.inf
    with np.errstate(all="ignore"):
        scaled = info / np.outer(norms, norms)
        cond = float(np.linalg.cond(scaled)) if np.all(np.isfinite(scaled)) else math.inf
    if not (math.isfinite(cond) and cond < 1e300):
        return None, math.inf
    return np.asarray(np.linalg.inv(scaled) / np.outer(norms, norms), dtype=np.float64), cond
