"""Output-error (maximum-likelihood) refinement of a discrete transfer function.

Used by :func:`condmon.identify.oe` and as the fallback of
:func:`condmon.identify.sriv` when its iterations fail or do not converge.

Minimises ``Σ_j Σ_k (y_j(k) - B_j/A u(k))² / σ_j²`` — the Gaussian likelihood of
white output noise — over the common-denominator model with
``scipy.optimize.least_squares`` (trust-region reflective), started from an IV
estimate. The sensitivities are exact and cost one filter call per output:
``∂x_j/∂b_ji = q^-i u/A`` and ``∂x_j/∂a_i = -q^-i x_j/A``. A trial step whose
denominator leaves the unit circle returns an infinite residual, so the solver
shrinks its trust region instead of simulating an unstable model. The noise
variances are re-estimated once from the first optimum and the fit repeated.

Why by hand: no maintained Python package fits a common-denominator
multi-output output-error model (SIPPY's OE treats each output alone and
is slow; see benchmarks/bench_peers.py); only the optimiser is borrowed.

In closed loop the criterion uses the measured input (the direct approach):
with white sensor noise the controller acts on past noise only and the
estimate is consistent; the two-stage alternative (simulating from the input
part explained by the excitation) inherits the first stage's approximation
error, a bias of several percent on the reference rig.

References
----------
.. [1] L. Ljung, *System Identification: Theory for the User*, 2nd ed., 1999,
   sec. 4.2 and 10.2 (output-error model, prediction-error minimisation).
.. [2] U. Forssell, L. Ljung, "Closed-loop identification revisited",
   Automatica 35 (1999) 1215-1241 (the direct approach).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon._filter import lfilter
from condmon.errors import EstimationError
from condmon.identify._common import schur_stable, stabilise
from condmon.identify.long_run import long_run_covariance
from condmon.identify.ls import output_error_variance

__all__ = ["OutputErrorFit", "refine_output_error"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class OutputErrorFit:
    """Result of :func:`refine_output_error`.

    Attributes
    ----------
    theta : ndarray, shape (n_params,)
        ``[a_1..a_n, b_11..b_1n, ..., b_m1..b_mn]``.
    covariance : ndarray, shape (n_params, n_params)
        ``I⁻¹ S I⁻¹`` at the optimum, ``I = ψᵀ W ψ`` (W = diag 1/σ_j²) and
        ``S`` the long-run covariance of the weighted scores
        (:mod:`condmon.identify.long_run`); ``I⁻¹`` on average for white noise.
    noise_variance : ndarray, shape (n_outputs,)
        Variance of each output's simulation residual. [output unit^2]
    evaluations : int
        Residual evaluations used.
    success : bool
        Whether the optimiser met a convergence test.
    """

    theta: FloatArray
    covariance: FloatArray
    noise_variance: FloatArray
    evaluations: int
    success: bool


def _stable(theta: FloatArray, n: int) -> bool:
    return bool(np.all(np.isfinite(theta))) and schur_stable(np.r_[1.0, theta[:n]])


def _lag(x: FloatArray, d: int) -> FloatArray:
    out = np.zeros_like(x)
    out[d:] = x[: x.size - d]
    return out


class _Problem:
    """Residuals and Jacobian of the weighted output-error criterion."""

    def __init__(self, u: FloatArray, y: FloatArray, n: int, sigma: FloatArray) -> None:
        self.u, self.y, self.n, self.sigma = u, y, n, sigma
        self.m = y.shape[1]

    def residuals(self, theta: FloatArray) -> FloatArray:
        n, m = self.n, self.m
        if not _stable(theta, n):
            return np.full(self.y.size, np.inf)
        with np.errstate(all="ignore"):
            w = lfilter([1.0], np.r_[1.0, theta[:n]], self.u)
            res = np.empty((m, self.u.size))
            for j in range(m):
                x = lfilter(np.r_[0.0, theta[n * (1 + j): n * (2 + j)]], [1.0], w)
                res[j] = (self.y[:, j] - x) / self.sigma[j]
        out = res.ravel()
        return out if np.all(np.isfinite(out)) else np.full(out.size, np.inf)

    def jacobian(self, theta: FloatArray) -> FloatArray:
        n, m, N = self.n, self.m, self.u.size
        a = np.r_[1.0, theta[:n]]
        with np.errstate(all="ignore"):
            w = lfilter([1.0], a, self.u)
            jac = np.zeros((m * N, theta.size))
            for j in range(m):
                b = np.r_[0.0, theta[n * (1 + j): n * (2 + j)]]
                xf = lfilter([1.0], a, lfilter(b, [1.0], w))
                rows = slice(j * N, (j + 1) * N)
                for i in range(1, n + 1):
                    jac[rows, i - 1] = _lag(xf, i) / self.sigma[j]
                    jac[rows, n * (1 + j) + i - 1] = -_lag(w, i) / self.sigma[j]
        if not np.all(np.isfinite(jac)):
            jac = np.nan_to_num(jac, nan=0.0, posinf=0.0, neginf=0.0)
        return jac


def refine_output_error(u: ArrayLike, y: ArrayLike, order: int, theta0: ArrayLike, *,
                        max_nfev: int = 200) -> OutputErrorFit:
    """Minimise the output error from a starting estimate.

    Parameters
    ----------
    u : array_like, shape (N,)
        Measured input driving the simulation. [input unit]
    y : array_like, shape (N, m)
        Measured outputs. [output units]
    order : int
        Number of poles n.
    theta0 : array_like, shape (n (1 + m),)
        Starting parameters; an unstable denominator is reflected first.
    max_nfev : int
        Cap on residual evaluations per pass (two passes).

    Returns
    -------
    OutputErrorFit

    Raises
    ------
    EstimationError
        When no stable model with finite residuals is found or the
        sensitivity matrix is singular.

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(3000)
    >>> y = lfilter([0, 0.5, 0.2], [1, -1.2, 0.5], u) + 0.2 * rng.standard_normal(3000)
    >>> fit = refine_output_error(u, y[:, None], 2, [-1.0, 0.3, 0.4, 0.1])
    >>> bool(np.allclose(fit.theta, [-1.2, 0.5, 0.5, 0.2], atol=0.03)), fit.success
    (True, True)
    """
    from scipy.optimize import least_squares  # ~0.25 s of imports: only when refining
    u_a = np.asarray(u, dtype=np.float64)
    y_a = np.asarray(y, dtype=np.float64)
    if y_a.ndim == 1:
        y_a = y_a[:, None]
    n = order
    theta = np.array(theta0, dtype=np.float64)
    theta[:n] = stabilise(np.r_[1.0, theta[:n]])[1:]
    sig2 = output_error_variance(theta, n, u_a, y_a)
    if not np.all(np.isfinite(sig2)):
        raise EstimationError("output-error refinement: the starting model does not "
                              "simulate (non-finite output)")
    nfev = 0
    success = False
    for _ in range(2):  # second pass with the noise variances of the first optimum
        prob = _Problem(u_a, y_a, n, np.sqrt(np.maximum(sig2, 1e-300)))
        try:
            sol = least_squares(prob.residuals, theta, jac=prob.jacobian, method="trf",
                                x_scale="jac", max_nfev=max_nfev)
        except (ValueError, np.linalg.LinAlgError, FloatingPointError) as err:
            raise EstimationError(f"output-error refinement failed: {err}") from None
        nfev += int(sol.nfev)
        success = bool(sol.success)
        if not _stable(sol.x, n):
            raise EstimationError("output-error refinement ended on an unstable model")
        theta = np.asarray(sol.x, dtype=np.float64)
        sig2 = output_error_variance(theta, n, u_a, y_a)
    prob = _Problem(u_a, y_a, n, np.sqrt(np.maximum(sig2, 1e-300)))
    jac = prob.jacobian(theta)
    info = jac.T @ jac
    with np.errstate(all="ignore"):
        cond = float(np.linalg.cond(info)) if np.all(np.isfinite(info)) else np.inf
    if not (np.isfinite(cond) and cond < 1e14):
        raise EstimationError(f"output-error refinement: the sensitivities are singular "
                              f"(condition number {cond:.3g}); the data do not determine "
                              "the model")
    inv = np.linalg.solve(info, np.eye(theta.size))
    # sandwich with the scores' long-run covariance: holds under coloured noise
    # and equals ``inv`` on average under white noise
    res = prob.residuals(theta)
    scores = (jac * res[:, None]).reshape(prob.m, u_a.size, theta.size).sum(axis=0)
    S, _ = long_run_covariance(scores)
    cov = inv @ S @ inv
    return OutputErrorFit(theta, np.asarray(cov, dtype=np.float64), sig2, nfev, success)
