"""Shared pieces of the linear-in-the-parameters estimators.

Model (single input u, outputs y_j, common denominator, one sample of delay)::

    A(q^-1) y_j(k) = B_j(q^-1) u(k) + e_j(k)
    A = 1 + a_1 q^-1 + ... + a_n q^-n,   B_j = b_j1 q^-1 + ... + b_jn q^-n

Parameter vector ``theta = [a_1..a_n, b_11..b_1n, ..., b_m1..b_mn]``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon._filter import lfilter
from condmon.errors import DataError, EstimationError, ModelError
from condmon.identify._products import gram, lag_products
from condmon.identify.long_run import long_run_covariance_of
from condmon.models.transfer import DiscreteTF

__all__ = ["TFEstimate", "prepare", "normal_equations", "lagged_gram", "signals", "monic",
           "to_model", "stabilise", "simulate_outputs", "delayed_sum", "schur_stable", "covariance",
           "robust_covariance", "log_oe_cost"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class TFEstimate:
    """A discrete transfer-function estimate with its uncertainty.

    Attributes
    ----------
    model : DiscreteTF
        The estimated model (common denominator over all outputs).
    theta : ndarray, shape (n_params,)
        ``[a_1..a_n, b_11..b_1n, ..., b_m1..b_mn]``.
    covariance : ndarray, shape (n_params, n_params)
        Asymptotic covariance of ``theta``.
    noise_variance : ndarray, shape (n_outputs,)
        Variance of each output's residual (output error for IV methods,
        equation error for least squares). [output unit^2]
    method : str
        Estimator name ("arx", "iv", "sriv", "rls", "riv").
    iterations : int
        Iterations used (1 for one-shot estimators).
    converged : bool
        Whether the convergence test was met (True for one-shot estimators).
    closed_loop_instruments : bool
        Whether instruments were built from external excitation signals.
    n_samples : int
        Samples used.
    notes : tuple of str
        Anything the user should know about this estimate.
    path : str
        The route that produced the estimate, e.g. ``"sriv"`` or
        ``"sriv -> oe"`` when the output-error refinement took over (the reason
        is in ``notes``). Empty means ``method``.
    """

    model: DiscreteTF
    theta: FloatArray
    covariance: FloatArray
    noise_variance: FloatArray
    method: str
    iterations: int = 1
    converged: bool = True
    closed_loop_instruments: bool = False
    n_samples: int = 0
    notes: tuple[str, ...] = field(default=())
    path: str = ""

    @property
    def route(self) -> str:
        """The route taken (``path``, or ``method`` for one-step estimators)."""
        return self.path or self.method

    @property
    def std_errors(self) -> FloatArray:
        """Standard errors of ``theta``."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {
            "method": self.method,
            "path": self.route,
            "theta": self.theta.tolist(),
            "std_errors": self.std_errors.tolist(),
            "noise_variance": dict(zip(self.model.outputs, self.noise_variance.tolist())),
            "iterations": self.iterations,
            "converged": self.converged,
            "closed_loop_instruments": self.closed_loop_instruments,
            "n_samples": self.n_samples,
            "notes": list(self.notes),
            **self.model.to_dict(),
        }


def prepare(u: ArrayLike, y: ArrayLike, order: int) -> tuple[FloatArray, FloatArray]:
    """Check and shape the data: ``u`` (N,), ``y`` (N, n_outputs)."""
    u_arr = np.asarray(u, dtype=np.float64)
    y_arr = np.asarray(y, dtype=np.float64)
    if y_arr.ndim == 1:
        y_arr = y_arr[:, None]
    if u_arr.ndim != 1:
        raise DataError(f"input u must be 1-D, got shape {u_arr.shape}")
    if y_arr.ndim != 2:
        raise DataError(f"outputs y must be 1-D or 2-D, got shape {y_arr.shape}")
    if y_arr.shape[0] != u_arr.size:
        raise DataError(f"u has {u_arr.size} samples but y has {y_arr.shape[0]}")
    if not isinstance(order, (int, np.integer)) or order < 1:
        raise ModelError(f"order must be a positive integer, got {order!r}")
    n_par = order * (1 + y_arr.shape[1])
    if u_arr.size < 10 * n_par:
        raise DataError(f"{u_arr.size} samples are too few for {n_par} parameters "
                        f"(order {order}); need at least {10 * n_par}")
    if not (np.all(np.isfinite(u_arr)) and np.all(np.isfinite(y_arr))):
        raise DataError("data contain NaN or inf")
    return u_arr, y_arr


def signals(*parts: FloatArray) -> FloatArray:
    """Signals side by side, shape (N, k), each column contiguous (Fortran
    order): the lag products of :func:`lagged_gram` run twice as fast on
    them as on ``np.column_stack``'s rows."""
    cols = [p[:, None] if p.ndim == 1 else p for p in parts]
    out = np.empty((cols[0].shape[0], sum(c.shape[1] for c in cols)), order="F")
    at = 0
    for c in cols:
        out[:, at: at + c.shape[1]] = c
        at += c.shape[1]
    return out


def normal_equations(sig: FloatArray, m: int, order: int, weights: FloatArray
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Weighted IV normal equations of the common-denominator SIMO model.

    Parameters
    ----------
    sig : ndarray, shape (N, 2m+2)
        Columns ``[y_1..y_m, u, z_1..z_m, z_u]``: outputs and input build the
        regressors φ_j = [-y_j lags, u lags], the instrument signals build
        ζ_j = [-z_j lags, z_u lags] (pass ``z = y``, ``z_u = u`` for least squares).
    m : int
        Number of outputs.
    order : int
        Model order n.
    weights : ndarray, shape (m,)
        Weight of each output's equations (1/σ_j²).

    Returns
    -------
    R, r, S : ndarray
        ``Σ w ζφᵀ``, ``Σ w ζ y`` and ``Σ w ζζᵀ``.
    """
    # Every cross product comes from one Gram matrix of the lagged signals:
    # one matrix product instead of 4m small ones. Lag-major layout: column
    # d*ns + s holds signal s delayed by d samples.
    return _assemble(lagged_gram(sig, order), m, order, weights, sig.shape[1])


def least_squares_equations(y: FloatArray, u: FloatArray, order: int, weights: FloatArray
                            ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`normal_equations` of ``signals(y, u, y, u)`` (least squares: the
    instruments are the regressors themselves) from the lagged Gram matrix of
    ``[y, u]`` alone, a quarter of the products."""
    m = y.shape[1]
    C = lagged_gram(signals(y, u), order)
    idx = _twice(m, order)
    return _assemble(C[np.ix_(idx, idx)], m, order, weights, 2 * m + 2)


@functools.lru_cache(maxsize=32)
def _twice(m: int, n: int) -> NDArray[np.intp]:
    """Lagged-Gram columns of ``[y, u]`` that hold those of ``[y, u, y, u]``."""
    idx = np.array([d * (m + 1) + s % (m + 1) for d in range(n + 1) for s in range(2 * m + 2)],
                   dtype=np.intp)
    idx.flags.writeable = False
    return idx


def _assemble(C: FloatArray, m: int, n: int, weights: FloatArray, ns: int
              ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``R, r, S`` of :func:`normal_equations` from the lagged Gram matrix ``C``."""
    p = n * (1 + m)
    sign, outer, per_output = _layout(m, n, ns)
    R = np.zeros((p, p))
    S = np.zeros((p, p))
    r = np.zeros(p)
    for j, (into, zp, zz, zeta) in enumerate(per_output):
        sw = weights[j] * outer
        R[into] += sw * C[zp]
        S[into] += sw * C[zz]
        r[into[0][:, 0]] += weights[j] * sign * C[zeta, j]
    return R, r, S


@functools.lru_cache(maxsize=32)
def _layout(m: int, n: int, ns: int) -> tuple[FloatArray, FloatArray, tuple[Any, ...]]:
    """The normal equations' index arrays for ``m`` outputs, order ``n`` and
    ``ns`` signals (made once: building them took a tenth of a short estimate)."""
    lag = np.arange(1, n + 1) * ns
    sign = np.r_[-np.ones(n), np.ones(n)]
    out = []
    for j in range(m):
        phi = np.r_[lag + j, lag + m]
        zeta = np.r_[lag + m + 1 + j, lag + 2 * m + 1]
        idx = np.r_[0:n, n * (1 + j): n * (2 + j)]
        entry = (*np.ix_(idx, idx), *np.ix_(zeta, phi), *np.ix_(zeta, zeta), zeta)
        for a in (sign, *entry):
            a.flags.writeable = False   # shared by every later call
        out.append((entry[0:2], entry[2:4], entry[4:6], entry[6]))
    outer = np.outer(sign, sign)
    outer.flags.writeable = False
    return sign, outer, tuple(out)


def lagged_gram(sig: FloatArray, n: int) -> FloatArray:
    """``GᵀG`` of the lagged signals ``G = [sig(k), sig(k-1), ..., sig(k-n)]``
    over rows ``k = n..N-1`` (lag-major columns: ``d*ns + s`` is signal ``s``
    delayed ``d`` samples).

    Formed without a lagged copy of the record: block ``(d1, d2)`` is the lag
    product ``P_δ = Σ_j sig(j+δ) sig(j)ᵀ`` (``δ = d2 - d1``, transposed below
    the diagonal) of the record as it is, less the terms that fall outside
    rows ``n..N-1``: those of the ``n`` rows before ``n`` and after ``N - 1``,
    which are the Gram matrices of two ``n``-row lagged matrices (the signal
    taken as zero beyond the record).
    """
    N, ns = sig.shape
    if N <= n:
        return np.zeros(((n + 1) * ns,) * 2)
    if n == 0:
        return gram(sig)
    P = lag_products(sig, n)   # (n+1, ns, ns)
    lag = np.arange(n + 1)
    delta = lag[None, :] - lag[:, None]                             # d2 - d1
    both = np.concatenate([P, P.transpose(0, 2, 1)])
    C = both[np.where(delta >= 0, delta, n + 1 - delta)]            # (d1, d2, ns, ns)
    C = C.transpose(0, 2, 1, 3).reshape((n + 1) * ns, (n + 1) * ns)
    back = np.arange(n)[:, None] - lag[None, :]                     # row k, lag d: k - d
    zeros = np.zeros((n, ns))
    head = np.concatenate([zeros, sig[:n]])[n + back].reshape(n, -1)       # rows 0 .. n-1
    tail = np.concatenate([sig[N - n:], zeros])[n + back].reshape(n, -1)   # rows N .. N+n-1
    C -= head.T @ head + tail.T @ tail
    return C


def solve(R: FloatArray, r: FloatArray) -> FloatArray:
    """Solve the normal equations, refusing a singular or non-finite system."""
    return solve_and_invert(R, r)[0]


#: Largest condition number accepted in normal equations (the 1-norm one,
#: within a factor of their size of the 2-norm one): beyond it the solution
#: has no significant digit left in double precision.
MAX_CONDITION = 1e14


def solve_and_invert(R: FloatArray, r: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The normal equations' solution and ``R⁻¹`` (which a covariance needs),
    refusing a singular or non-finite system: one whose 1-norm condition
    number ``‖R‖₁ ‖R⁻¹‖₁`` reaches :data:`MAX_CONDITION` (from the inverse
    at hand, where the 2-norm one costs a singular-value decomposition)."""
    Ri = _inverse(R) if np.all(np.isfinite(r)) else None
    if Ri is None:
        with np.errstate(all="ignore"):
            try:
                cond = float(np.linalg.cond(R)) if np.all(np.isfinite(R)) else float("inf")
            except np.linalg.LinAlgError:
                cond = float("inf")
        raise EstimationError(
            f"normal equations are singular (condition number {cond:.3g}): the input "
            "does not excite the model, or the order is too high"
        )
    return np.asarray(np.linalg.solve(R, r), dtype=np.float64), Ri


def _inverse(R: FloatArray) -> FloatArray | None:
    """``R⁻¹`` when ``R`` is finite and its 1-norm condition number is below
    :data:`MAX_CONDITION`, else None."""
    with np.errstate(all="ignore"):
        if not np.all(np.isfinite(R)):
            return None
        try:
            Ri = np.asarray(np.linalg.inv(R), dtype=np.float64)
        except np.linalg.LinAlgError:
            return None
        cond = float(np.linalg.norm(R, 1)) * float(np.linalg.norm(Ri, 1))
    return Ri if cond < MAX_CONDITION else None   # (False for a NaN too)


def to_model(theta: FloatArray, order: int, dt: float, outputs: tuple[str, ...],
             input_name: str) -> DiscreteTF:
    """Build the :class:`DiscreteTF` of a parameter vector."""
    n = order
    den = monic(theta[:n])
    nums = np.zeros((len(outputs), n + 1))
    for j in range(len(outputs)):
        nums[j, 1:] = theta[n * (1 + j): n * (2 + j)]
    return DiscreteTF(den, nums, dt, outputs, input_name)


#: Largest pole radius a stabilised denominator keeps (a pole reflected onto or
#: beyond it is pulled just inside the unit circle).
MAX_RADIUS = 1.0 - 1e-6


def stabilise(den: FloatArray) -> FloatArray:
    """Reflect roots outside the unit circle into it (keeps the prefilter stable).

    A root ``r`` with ``|r| >= 1`` becomes ``1/conj(r)``, the root with the same
    spectral magnitude inside the circle; a root on the circle (an integrator)
    is pulled to radius :data:`MAX_RADIUS`.

    Raises
    ------
    EstimationError
        When the coefficients are not finite (a diverged iterate).
    """
    if not np.all(np.isfinite(den)):
        raise EstimationError("the estimate diverged (non-finite denominator)")
    if schur_stable(den):
        return den
    roots = np.roots(den)
    mag = np.abs(roots)
    if np.all(mag < 1.0):
        return den
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = np.where(mag >= 1.0, 1.0 / np.conj(roots), roots)
    mag_in = np.abs(inside)
    inside = np.where(mag_in > MAX_RADIUS, inside * (MAX_RADIUS / np.maximum(mag_in, 1e-300)),
                      inside)
    return np.asarray(np.real(np.poly(inside)) * den[0], dtype=np.float64)


def schur_stable(den: FloatArray) -> bool:
    """Whether every root of ``den`` lies strictly inside the unit circle, by
    the Schur-Cohn step-down recursion (every reflection coefficient below 1 in
    magnitude): a few scalar operations where ``np.roots`` costs an eigenvalue
    problem. False also when undecided (a coefficient at or near 1)."""
    a = [float(c) for c in den]
    if a[0] == 0.0:
        return False
    a = [c / a[0] for c in a]
    while len(a) > 1:
        k = a[-1]
        if not abs(k) < 1.0 - 1e-12:
            return False
        scale = 1.0 - k * k
        a = [(a[i] - k * a[len(a) - 1 - i]) / scale for i in range(len(a) - 1)]
    return True


def covariance(R: FloatArray, S: FloatArray, inverse: FloatArray | None = None) -> FloatArray:
    """IV covariance ``R⁻¹ S R⁻ᵀ``, refusing a singular ``R`` (``inverse``:
    ``R⁻¹`` from :func:`solve_and_invert`, which checked it)."""
    Ri = inverse if inverse is not None else _inverse(R)
    if Ri is None:
        raise EstimationError("the instrumental-variable matrix is singular: the data "
                              "do not determine the model")
    return np.asarray(Ri @ S @ Ri.T, dtype=np.float64)


def iv_scores(sig: FloatArray, m: int, order: int, theta: FloatArray,
              weights: FloatArray) -> FloatArray:
    """The per-sample terms ``g_t = Σ_j w_j ζ_jt e_jt`` whose sum the normal
    equations of :func:`normal_equations` set to zero (same ``sig`` layout),
    ``e_jt`` the equation error of output ``j`` at ``theta``; shape (N - n, p),
    each column contiguous (Fortran order)."""
    n = order
    N = sig.shape[0]
    g = np.zeros((n * (1 + m), N - n))   # one row per score: written whole

    def lag(col: int, d: int) -> FloatArray:   # a view: no copy of the record
        return sig[n - d: N - d, col]

    for j in range(m):
        a, b = theta[:n], theta[n * (1 + j): n * (2 + j)]
        # the equation error y + Σ a_d y(k-d) - Σ b_d u(k-d), from rest, rows n..N-1
        e = np.convolve(sig[:, j], monic(a))[n:N]
        e -= delayed_sum(b, sig[:, m])[n:]
        e *= weights[j]
        for d in range(1, n + 1):   # ζ = [-z_j lags, z_u lags]
            g[d - 1] -= lag(m + 1 + j, d) * e
            np.multiply(lag(2 * m + 1, d), e, out=g[n * (1 + j) + d - 1])
    return g.T


def robust_covariance(R: FloatArray, sig: FloatArray, m: int, order: int, theta: FloatArray,
                      weights: FloatArray, inverse: FloatArray | None = None
                      ) -> tuple[FloatArray, float]:
    """IV covariance ``R⁻¹ S R⁻ᵀ`` with ``S`` the long-run covariance of the
    scores (:mod:`condmon.identify.long_run`): it holds when the noise is
    coloured and equals the white-noise ``R⁻¹ (Σ w ζζᵀ) R⁻ᵀ`` on average when it
    is white. Returns the covariance and the bandwidth used [samples]
    (``inverse`` as for :func:`covariance`)."""
    S, bandwidth = long_run_covariance_of(
        lambda a, b: iv_scores(sig[a: b + order], m, order, theta, weights),
        sig.shape[0] - order)
    return covariance(R, S, inverse), bandwidth


def log_oe_cost(sig2: FloatArray) -> float:
    """Output-error criterion ``Σ_j log σ_j²`` (Gaussian likelihood, unknown
    variance per output; independent of the outputs' units). inf when not finite."""
    v = 0.0
    for s2 in sig2.tolist():   # (a few outputs: plain floats)
        v += math.log(max(s2, 1e-300)) if s2 == s2 else math.nan   # (s2 == s2: not NaN)
    return v if math.isfinite(v) else float("inf")


def simulate_outputs(theta: FloatArray, order: int, u: FloatArray, m: int) -> FloatArray:
    """Noise-free outputs ``B_j/A u`` of a parameter vector, shape (N, m)."""
    n = order
    # An unstable iterate overflows: the caller sees inf/NaN and handles it.
    with np.errstate(all="ignore"):
        x = lfilter([1.0], monic(theta[:n]), u)
        B = theta[n:].reshape(m, n)
        return np.column_stack([delayed_sum(B[j], x) for j in range(m)])


def delayed_sum(b: FloatArray, x: FloatArray) -> FloatArray:
    """``Σ_d b[d-1] x(k-d)``, ``d = 1..len(b)``, from rest: a numerator with
    one sample of delay applied to ``x`` (1-D), without a lag matrix (the
    first ``N`` samples of one convolution)."""
    kernel = np.zeros(b.size + 1)
    kernel[1:] = b
    return np.convolve(x, kernel)[: x.size]


def monic(coefficients: FloatArray) -> FloatArray:
    """``[1, c_1, ..., c_n]``: a denominator from its free coefficients
    (``np.r_[1.0, c]`` at a third of its cost, in the estimators' loops)."""
    out = np.empty(coefficients.size + 1)
    out[0] = 1.0
    out[1:] = coefficients
    return out
