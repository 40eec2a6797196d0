"""Simplified refined instrumental variable (SRIV) estimation.

Written for condmon because no maintained Python package provides it (it lives in
MATLAB's CAPTAIN toolbox and R's hydromad). For white output noise SRIV is
asymptotically equivalent to the output-error maximum-likelihood estimate, at
the cost of a few linear solves.

Each iteration: (1) prefilter input, outputs and instruments with ``1/Â`` (Â
stabilised), (2) simulate the auxiliary model ``x̂_j = B̂_j/Â u_i`` as the
noise-free instrument, (3) solve the weighted IV normal equations over all
outputs with their common denominator, (4) re-estimate each output's noise
variance from its simulation residual. Stops when the relative change of the
parameters falls below ``tol`` or at ``max_iter``.

References
----------
.. [1] P. C. Young, "The instrumental variable method: a practical approach to
   identification and system parameter estimation", IFAC Proceedings 18(5), 1985.
.. [2] P. C. Young, *Recursive Estimation and Time-Series Analysis*, 2nd ed.,
   Springer, 2011, ch. 7.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike
from scipy.signal import lfilter

from condmon.errors import ConvergenceWarning
from condmon.identify._common import (
    TFEstimate, normal_equations, prepare, simulate_outputs, solve, stabilise, to_model,
)
from condmon.identify.closed_loop import noise_free_input
from condmon.identify.ls import _names, arx_theta, output_error_variance

__all__ = ["sriv"]


def sriv(u: ArrayLike, y: ArrayLike, order: int, *, dt: float = 1.0,
         excitation: ArrayLike | None = None, outputs: tuple[str, ...] | None = None,
         input_name: str = "u", tol: float = 1e-6, max_iter: int = 30,
         warn: bool = True) -> TFEstimate:
    """SRIV estimate of a common-denominator transfer function.

    Parameters
    ----------
    u : array_like, shape (N,)
        Input. [input unit]
    y : array_like, shape (N,) or (N, m)
        Outputs sharing the denominator. [output units]
    order : int
        Number of poles n (numerators: n coefficients, one sample delay).
    dt : float
        Sample time. [s]
    excitation : array_like, shape (N,) or (N, n_r), optional
        External excitation signals of a closed-loop test (e.g. ``yd``, ``ud``).
        Given, every instrument is built from the part of ``u`` they explain, so
        the noise fed back through the controller does not bias the estimate.
        Omitted, ``u`` is taken as noise-free (direct approach; stated in
        ``notes``).
    outputs : tuple of str, optional
        Output names.
    input_name : str
        Input name.
    tol : float
        Convergence threshold on ``|Δθ| / |θ|``.
    max_iter : int
        Iteration cap.
    warn : bool
        Issue a :class:`ConvergenceWarning` when the cap is reached.

    Returns
    -------
    TFEstimate
        With ``iterations``, ``converged`` and the covariance
        ``R⁻¹ S R⁻ᵀ`` (``R = Σ w ζφᵀ``, ``S = Σ w ζζᵀ``, ``w = 1/σ²``).

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(4000)
    >>> y = lfilter([0, 0.5, 0.2], [1, -1.2, 0.5], u) + 0.2 * rng.standard_normal(4000)
    >>> est = sriv(u, y, 2)
    >>> bool(np.allclose(est.theta, [-1.2, 0.5, 0.5, 0.2], atol=0.02)), est.converged
    (True, True)
    """
    u_a, y_a = prepare(u, y, order)
    m = y_a.shape[1]
    closed = excitation is not None
    u_i = u_a if excitation is None else noise_free_input(u_a, excitation)

    theta = arx_theta(u_a, y_a, order)
    sig2 = output_error_variance(theta, order, u_a, y_a)
    converged = False
    it = 0
    R = S = np.eye(theta.size)
    for it in range(1, max_iter + 1):
        den = stabilise(np.r_[1.0, theta[:order]])
        theta_s = np.r_[den[1:], theta[order:]]
        x = simulate_outputs(theta_s, order, u_i, m)
        # One filter call for every signal: [y, u, x, u_i] -> prefiltered by 1/Â.
        sig = lfilter([1.0], den, np.column_stack([y_a, u_a, x, u_i]), axis=0)
        weights = 1.0 / np.maximum(sig2, 1e-300)
        R, r, S, _ = normal_equations(sig, m, order, weights)
        new = solve(R, r)
        change = float(np.linalg.norm(new - theta)) / max(float(np.linalg.norm(new)), 1e-300)
        theta = new
        sig2 = output_error_variance(theta, order, u_a, y_a)
        if change < tol:
            converged = True
            break
    Ri = np.linalg.inv(R)
    cov = Ri @ S @ Ri.T
    notes: list[str] = []
    if not closed:
        notes.append("direct approach: input taken as noise-free")
    if not converged:
        notes.append(f"not converged after {max_iter} iterations")
        if warn:
            warnings.warn(f"SRIV did not converge in {max_iter} iterations",
                          ConvergenceWarning, stacklevel=2)
    return TFEstimate(to_model(theta, order, dt, _names(outputs, m), input_name), theta,
                      cov, sig2, "sriv", iterations=it, converged=converged,
                      closed_loop_instruments=closed, n_samples=u_a.size,
                      notes=tuple(notes))
