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

import numpy as np
from numpy.typing import NDArray

__all__ = ["long_run_covariance", "andrews_bandwidth", "MAX_RHO"]

FloatArray = NDArray[np.float64]

#: Largest lag-1 autocorrelation the bandwidth rule takes from the scores
#: (Andrews 1991 truncates the plug-in the same way, at 0.97, to keep the
#: bandwidth finite when the scores look like a random walk).
MAX_RHO = 0.97


def andrews_bandwidth(g: FloatArray) -> float:
    """Bartlett bandwidth ``1.1447 (α̂ T)^{1/3}`` from AR(1) fits to each
    column of the (demeaned) scores ``g`` (T, p) (Andrews 1991, eq. 6.4).

    Returns
    -------
    float
        The bandwidth [samples], at least 1 and at most ``T / 2``.
    """
    T = g.shape[0]
    x0, x1 = g[:-1], g[1:]
    den = np.einsum("ij,ij->j", x0, x0)
    cross = np.einsum("ij,ij->j", x0, x1)
    with np.errstate(all="ignore"):
        rho = np.where(den > 0, cross / np.where(den > 0, den, 1.0), 0.0)
    rho = np.clip(rho, -MAX_RHO, MAX_RHO)
    # mean of (x1 - rho x0)^2 from the sums, without a copy of the scores
    sq1 = np.einsum("ij,ij->j", x1, x1)
    s2 = np.maximum(sq1 - 2 * rho * cross + rho**2 * den, 0.0) / max(T - 1, 1)
    num = np.sum(4 * rho**2 * s2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2))
    dsum = np.sum(s2**2 / (1 - rho) ** 4)
    alpha = float(num / dsum) if dsum > 0 else 0.0
    return float(min(max(1.1447 * (alpha * T) ** (1.0 / 3.0), 1.0), T / 2))


def long_run_covariance(g: FloatArray) -> tuple[FloatArray, float]:
    """The Bartlett-kernel long-run covariance of ``Σ_t g_t``.

    Parameters
    ----------
    g : ndarray, shape (T, p)
        Scores, one row per sample (demeaned here).

    Returns
    -------
    S : ndarray, shape (p, p)
        Estimated covariance of the scores' sum [score unit²].
    bandwidth : float
        The Bartlett bandwidth used [samples].
    """
    g = g - g.mean(axis=0)   # one copy; the caller's scores stay as they were
    b = andrews_bandwidth(g)
    S = g.T @ g
    for lag in range(1, math.ceil(b)):
        gamma = g[lag:].T @ g[:-lag]
        S += (1.0 - lag / b) * (gamma + gamma.T)
    return np.asarray(S, dtype=np.float64), b
