"""Simplified refined instrumental variable (SRIV) estimation.

Written for condmon because no maintained Python package provides it (it lives in
MATLAB's CAPTAIN toolbox and R's hydromad). For white output noise SRIV is
asymptotically equivalent to the output-error maximum-likelihood estimate, at
the cost of a few linear solves.

Each iteration: (1) prefilter input, outputs and instruments with ``1/Â`` (Â
stabilised), (2) simulate the auxiliary model ``x̂_j = B̂_j/Â u_i`` as the
noise-free instrument, (3) solve the weighted IV normal equations over all
outputs with their common denominator, (4) re-estimate each output's noise
variance from its simulation residual. Stops when the iterate is known to
within a small fraction of its own standard errors (below), when the relative
change of the parameters falls below ``tol``, or at ``max_iter``.

The stop relative to the error bars: SRIV's iterates approach their fixed point
geometrically (on the actuator's records each step is 0.01-0.02 times the one
before). From the last two steps, the distance still to go is about
``|Δθ_k| ρ / (1 - ρ)`` with ``ρ = |Δθ_k| / |Δθ_(k-1)|``; when that is below
``se_fraction`` (default a thousandth) of every parameter's standard error (the
white-noise ``R⁻¹ S R⁻ᵀ`` of the iteration, which is formed anyway), further
iterations cannot move the estimate by anything its error bar can show. On
those records this ends at the third iteration where ``tol`` = 1e-6 ran four or
five, and the estimate stays within 3e-4 standard errors of the fixed point.

Robustness: the start (least squares) and every iterate have their
denominator stabilised by reflecting poles into the unit circle, so no
auxiliary model or prefilter can diverge. An iteration that fails (singular
equations, non-finite output) ends the loop at the best iterate so far (the
lowest output-error criterion ``Σ log σ_j²``). When the loop fails or does not
converge, the output-error refinement (:mod:`condmon.identify.refine`) takes
over from that iterate and the route is reported (``path`` "sriv -> oe").

References
----------
.. [1] P. C. Young, "The instrumental variable method: a practical approach to
   identification and system parameter estimation", IFAC Proceedings 18(5), 1985.
.. [2] P. C. Young, *Recursive Estimation and Time-Series Analysis*, 2nd ed.,
   Springer, 2011, ch. 7.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon._filter import lfilter
from condmon.errors import ConvergenceWarning, EstimationError
from condmon.identify._common import (
    TFEstimate, delayed_sum, log_oe_cost, monic, normal_equations, prepare, robust_covariance,
    signals, solve_and_invert, stabilise, to_model,
)
from condmon.identify.closed_loop import noise_free_input
from condmon.identify.ls import _names, arx_theta, output_error_variance
from condmon.identify.refine import refine_output_error

__all__ = ["sriv", "sriv_iterations", "SrivIterations"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SrivIterations:
    """Outcome of the SRIV iterations (before any fallback).

    Attributes
    ----------
    theta : ndarray
        The last iterate if converged, else the best one (lowest ``Σ log σ_j²``).
    covariance : ndarray or None
        ``R⁻¹ S R⁻ᵀ`` of ``theta`` (None when it could not be formed).
    noise_variance : ndarray
        Output-error variance per output. [output unit^2]
    iterations : int
        Iterations run.
    converged : bool
        Whether ``|Δθ|/|θ| < tol``, or the stop relative to the standard
        errors (module docstring), was met.
    failure : str or None
        Why the loop stopped early (singular equations, non-finite output).
    """

    theta: FloatArray
    covariance: FloatArray | None
    noise_variance: FloatArray
    iterations: int
    converged: bool
    failure: str | None


_NONE: FloatArray = np.empty((0, 0))   # a released simulation


def _stable_theta(theta: FloatArray, n: int) -> FloatArray:
    out = theta.copy()
    out[:n] = stabilise(monic(theta[:n]))[1:]
    return out


#: Stop when the distance still to go is below this fraction of every
#: parameter's standard error (module docstring).
SE_FRACTION = 1e-3


def _near_enough(step: FloatArray, before: FloatArray | None, Ri: FloatArray, S: FloatArray,
                 se_fraction: float) -> bool:
    """Whether the geometric tail of the steps ``before`` -> ``step`` is below
    ``se_fraction`` of every standard error of ``R⁻¹ S R⁻ᵀ`` (``Ri`` = ``R⁻¹``;
    False when undecided)."""
    if before is None:
        return False
    size, last = float(np.max(np.abs(step))), float(np.max(np.abs(before)))
    if not (0.0 < last and size < 0.5 * last):     # not (yet) contracting
        return size == 0.0
    rho = size / last
    with np.errstate(all="ignore"):
        se = np.sqrt(np.einsum("ij,jk,ik->i", Ri, S, Ri))   # diag(R⁻¹ S R⁻ᵀ)
    to_go = np.abs(step) * rho / (1.0 - rho)
    return bool(np.all(np.isfinite(se)) and np.all(to_go < se_fraction * se))


def sriv_iterations(u: FloatArray, y: FloatArray, order: int, u_i: FloatArray, *,
                    tol: float = 1e-6, max_iter: int = 30,
                    se_fraction: float = SE_FRACTION) -> SrivIterations:
    """The SRIV loop on prepared arrays (``u`` (N,), ``y`` (N, m), instrument input ``u_i``);
    ``se_fraction`` 0 stops on ``tol`` alone.

    Raises
    ------
    EstimationError
        Only when not even the least-squares start exists.
    """
    m = y.shape[1]
    theta = _stable_theta(arx_theta(u, y, order), order)
    same = u_i is u

    def simulated(th: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The output error's variance per output (``y - B/A u``) and the
        inputs through ``1/A``: ``w = [u, u_i] / A`` (N, 2; one column when
        ``u_i`` is ``u``), from which the next iteration's prefiltered input,
        instrument input and instruments ``B/A u_i`` are all made."""
        B = th[order:].reshape(m, order)
        with np.errstate(all="ignore"):
            w = lfilter([1.0], monic(th[:order]), signals(u) if same else signals(u, u_i),
                        axis=0, overwrite_x=True)
            var = np.empty(m)
            for j in range(m):   # np.var of the error past the first n samples, in place
                e = delayed_sum(B[j], w[:, 0])
                tail = np.subtract(y[:, j], e, out=e)[order:]
                tail -= float(np.sum(tail)) / tail.size
                var[j] = float(tail @ tail) / tail.size
        return np.asarray(np.where(np.isfinite(var), var, np.inf), dtype=np.float64), w

    sig2, w = simulated(theta)
    best: tuple[float, FloatArray, FloatArray, tuple[FloatArray, FloatArray] | None] = (  # (R⁻¹, S)
        log_oe_cost(sig2), theta, sig2, None)
    converged = False
    failure: str | None = None
    it = 0
    step_before: FloatArray | None = None
    # The prefiltered signals [y, u, x, u_i] / Â, x = B/Â u_i the instruments, in
    # one buffer of the record's length, Fortran order (each column written whole)
    buffer = np.empty((u.size, 2 * m + 2), order="F")
    for it in range(1, max_iter + 1):
        den = monic(theta[:order])
        B = theta[order:].reshape(m, order)
        # The simulation's pass already gave u/Â and u_i/Â (w, for this very Â), and
        # x/Â = B (u_i/Â)/Â: only y and u_i/Â go through the filter (m + 1 columns,
        # in place), x/Â is B applied to the second, and u/Â, u_i/Â are copied in
        buffer[:, :m] = y
        buffer[:, m] = w[:, -1]
        with np.errstate(all="ignore"):
            lfilter([1.0], den, buffer[:, :m + 1], axis=0, overwrite_x=True)
            for j in range(m):
                buffer[:, m + 1 + j] = delayed_sum(B[j], buffer[:, m])
        buffer[:, m], buffer[:, -1] = w[:, 0], w[:, -1]
        w = _NONE   # a long record: one pass held at a time
        sig = buffer   # (the last iteration's is the one the covariance reads)
        weights = 1.0 / np.maximum(sig2, 1e-300)
        try:
            # (a finite sum is finite values, without a mask the record's size)
            with np.errstate(over="ignore", invalid="ignore"):
                total = float(np.sum(sig))
            if not np.isfinite(total) and not np.all(np.isfinite(sig)):
                raise EstimationError("the prefiltered signals are not finite")
            R, r, S = normal_equations(sig, m, order, weights)
            raw, Ri = solve_and_invert(R, r)
            new = _stable_theta(raw, order)
            last = (R, sig, raw, weights, Ri)
        except EstimationError as err:
            failure = f"iteration {it}: {err}"
            break
        step = new - theta
        change = float(np.linalg.norm(step)) / max(float(np.linalg.norm(new)), 1e-300)
        near = se_fraction > 0.0 and _near_enough(step, step_before, Ri, S, se_fraction)
        step_before = step
        theta = new
        sig2, w = simulated(theta)
        cost = log_oe_cost(sig2)
        if cost < best[0]:
            best = (cost, theta, sig2, (Ri, S))
        if change < tol or near:
            converged = True
            break
    w = _NONE   # not needed past the iterations (a long record: its memory back)
    if converged:
        # the reported covariance is the one that also holds under coloured noise
        R, sig, raw, weights, Ri = last
        cov, _ = robust_covariance(R, sig, m, order, raw, weights, inverse=Ri)
        return SrivIterations(theta, cov, sig2, it, True, None)
    kept = None if best[3] is None else best[3][0] @ best[3][1] @ best[3][0].T   # R⁻¹ S R⁻ᵀ
    return SrivIterations(best[1], kept, best[2], it, False, failure)


def sriv(u: ArrayLike, y: ArrayLike, order: int, *, dt: float = 1.0,
         excitation: ArrayLike | None = None, outputs: tuple[str, ...] | None = None,
         input_name: str = "u", tol: float = 1e-6, max_iter: int = 30,
         refine: bool = True, warn: bool = True) -> TFEstimate:
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
    refine : bool
        When the iterations fail or do not converge, refine the best iterate by
        output-error minimisation (the default). False: return the best iterate
        as it is (noted, and warned when ``warn``).
    warn : bool
        Issue a :class:`ConvergenceWarning` when the cap is reached and no
        refinement is made.

    Returns
    -------
    TFEstimate
        With ``iterations``, ``converged``, the covariance ``R⁻¹ S R⁻ᵀ``
        (``R = Σ w ζφᵀ``, ``w = 1/σ²``, ``S`` the long-run covariance of the
        scores ``w ζ e``, which holds under coloured noise and is ``Σ w ζζᵀ`` on
        average under white noise; :mod:`condmon.identify.long_run`) and ``path``: "sriv",
        or "sriv -> oe" when the refinement took over (the reason in ``notes``).

    Raises
    ------
    EstimationError
        When neither the iterations nor the refinement give a model.

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
    excitation = None   # the instruments are built: a long record's memory back
    names = _names(outputs, m)
    its = sriv_iterations(u_a, y_a, order, u_i, tol=tol, max_iter=max_iter)
    notes: list[str] = []
    if not closed:
        notes.append("direct approach: input taken as noise-free")
    if its.converged and its.covariance is not None:
        return TFEstimate(to_model(its.theta, order, dt, names, input_name), its.theta,
                          its.covariance, its.noise_variance, "sriv",
                          iterations=its.iterations, converged=True,
                          closed_loop_instruments=closed, n_samples=u_a.size,
                          notes=tuple(notes), path="sriv")
    why = its.failure or f"not converged after {max_iter} iterations"
    if not refine:
        if its.covariance is None:
            raise EstimationError(f"SRIV failed ({why})")
        notes.append(why)
        if warn:
            warnings.warn(f"SRIV: {why}", ConvergenceWarning, stacklevel=2)
        return TFEstimate(to_model(its.theta, order, dt, names, input_name), its.theta,
                          its.covariance, its.noise_variance, "sriv",
                          iterations=its.iterations, converged=False,
                          closed_loop_instruments=closed, n_samples=u_a.size,
                          notes=tuple(notes), path="sriv")
    try:
        fit = refine_output_error(u_a, y_a, order, its.theta)
    except EstimationError as err:
        raise EstimationError(f"SRIV failed ({why}) and so did the output-error "
                              f"refinement ({err})") from None
    notes.append(f"SRIV {why}; output-error refinement (measured input) from its best "
                 f"iterate ({fit.evaluations} evaluations)")
    return TFEstimate(to_model(fit.theta, order, dt, names, input_name), fit.theta,
                      fit.covariance, output_error_variance(fit.theta, order, u_a, y_a),
                      "sriv", iterations=its.iterations, converged=fit.success,
                      closed_loop_instruments=closed, n_samples=u_a.size,
                      notes=tuple(notes), path="sriv -> oe")
