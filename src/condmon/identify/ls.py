"""Least squares (ARX) and basic instrumental-variable estimators."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon._filter import lfilter
from condmon.identify._common import (
    TFEstimate, least_squares_equations, normal_equations, prepare, robust_covariance, signals,
    simulate_outputs, solve, stabilise, to_model,
)
from condmon.identify.closed_loop import noise_free_input

__all__ = ["arx", "iv"]

FloatArray = NDArray[np.float64]


def _names(outputs: tuple[str, ...] | None, m: int) -> tuple[str, ...]:
    return tuple(outputs) if outputs is not None else tuple(f"y{j}" for j in range(m))


def arx(u: ArrayLike, y: ArrayLike, order: int, *, dt: float = 1.0,
        excitation: ArrayLike | None = None, outputs: tuple[str, ...] | None = None,
        input_name: str = "u") -> TFEstimate:
    """Least-squares estimate of the common-denominator ARX model.

    ``A(q^-1) y_j(k) = B_j(q^-1) u(k) + e_j(k)``; consistent only when the
    equation error is white, biased by output (measurement) noise.

    Parameters
    ----------
    u : array_like, shape (N,)
        Input. [input unit]
    y : array_like, shape (N,) or (N, m)
        Outputs sharing the denominator. [output units]
    order : int
        Number of poles n (each numerator has n coefficients, one sample delay).
    dt : float
        Sample time. [s]
    outputs : tuple of str, optional
        Output names.
    input_name : str
        Input name.
    excitation : array_like, optional
        Accepted for a signature common with :func:`iv` and :func:`sriv`; least
        squares cannot use instruments, so it is ignored (and said in ``notes``).

    Returns
    -------
    TFEstimate

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(1000)
    >>> y = lfilter([0, 0.5], [1, -0.8], u)
    >>> np.round(arx(u, y, 1).theta, 6)
    array([-0.8,  0.5])
    """
    u_a, y_a = prepare(u, y, order)
    m = y_a.shape[1]
    # First pass with unit weights gives the residual variances, the second weights
    # each output by 1/sigma_j^2 (a generalised LS over outputs with unequal noise).
    theta = arx_theta(u_a, y_a, order)
    sig2 = _equation_error_variance(theta, order, u_a, y_a)
    weights = 1.0 / np.maximum(sig2, 1e-300)
    R, r, _ = least_squares_equations(y_a, u_a, order, weights)
    theta = solve(R, r)
    sig2 = _equation_error_variance(theta, order, u_a, y_a)
    cov = np.asarray(np.linalg.solve(R, np.eye(R.shape[0])), dtype=np.float64)
    notes = ("least squares: input taken as noise-free"
             + ("; excitation signals ignored" if excitation is not None else ""),)
    return TFEstimate(to_model(theta, order, dt, _names(outputs, m), input_name), theta,
                      cov, sig2, "arx", n_samples=u_a.size, notes=notes)


def arx_theta(u: FloatArray, y: FloatArray, order: int) -> FloatArray:
    """Unweighted least-squares parameter vector (a starting point for IV methods)."""
    m = y.shape[1]
    R, r, _ = least_squares_equations(y, u, order, np.ones(m))
    return solve(R, r)


def _equation_error_variance(theta: FloatArray, n: int, u: FloatArray,
                             y: FloatArray) -> FloatArray:
    m = y.shape[1]
    e = lfilter(np.r_[1.0, theta[:n]], [1.0], y, axis=0) - simulate_fir(theta, n, u, m)
    dof = max(y.shape[0] - n - 2 * n, 1)
    return np.asarray(np.sum(e[n:] ** 2, axis=0) / dof, dtype=np.float64)


def simulate_fir(theta: FloatArray, n: int, u: FloatArray, m: int) -> FloatArray:
    """``B_j(q^-1) u`` for every output, shape (N, m)."""
    N = u.size
    U = np.zeros((N, n))
    for d in range(1, n + 1):
        U[d:, d - 1] = u[: N - d]
    return np.asarray(U @ theta[n:].reshape(m, n).T, dtype=np.float64)


def output_error_variance(theta: FloatArray, n: int, u: FloatArray,
                          y: FloatArray) -> FloatArray:
    """Variance of ``y - B/A u`` per output (the simulation residual)."""
    with np.errstate(all="ignore"):
        e = y - simulate_outputs(theta, n, u, y.shape[1])
        v = np.var(e[n:], axis=0)
    return np.asarray(np.where(np.isfinite(v), v, np.inf), dtype=np.float64)


def iv(u: ArrayLike, y: ArrayLike, order: int, *, dt: float = 1.0,
       excitation: ArrayLike | None = None, outputs: tuple[str, ...] | None = None,
       input_name: str = "u") -> TFEstimate:
    """Basic instrumental-variable estimate (instruments from an ARX auxiliary model).

    One pass: the ARX estimate simulates noise-free outputs ``x = B/A u_i``, whose
    lags (with those of ``u_i``) are the instruments. ``u_i`` is ``u`` itself in open
    loop, or its noise-free part estimated from ``excitation`` in closed loop.

    Parameters
    ----------
    u, y, order, dt, outputs, input_name
        As for :func:`arx`.
    excitation : array_like, shape (N,) or (N, n_r), optional
        External excitation signals (closed loop). Without them the input is
        taken as noise-free (direct approach).

    Returns
    -------
    TFEstimate

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(5000)
    >>> y = lfilter([0, 0.5], [1, -0.8], u) + 0.1 * rng.standard_normal(5000)
    >>> bool(abs(iv(u, y, 1).theta[0] + 0.8) < 0.02)
    True
    """
    u_a, y_a = prepare(u, y, order)
    m = y_a.shape[1]
    closed = excitation is not None
    u_i = u_a if excitation is None else noise_free_input(u_a, excitation)
    first = arx_theta(u_a, y_a, order)
    # The auxiliary model must simulate: reflect an unstable least-squares pole.
    first = np.r_[stabilise(np.r_[1.0, first[:order]])[1:], first[order:]]
    x = simulate_outputs(first, order, u_i, m)
    weights = 1.0 / np.maximum(_equation_error_variance(first, order, u_a, y_a), 1e-300)
    sig = signals(y_a, u_a, x, u_i)
    R, r, S = normal_equations(sig, m, order, weights)
    theta = solve(R, r)
    sig2 = output_error_variance(theta, order, u_a, y_a)
    weights = 1.0 / np.maximum(sig2, 1e-300)
    R, _, _ = normal_equations(sig, m, order, weights)
    cov, _ = robust_covariance(R, sig, m, order, theta, weights)
    notes = () if closed else ("direct approach: input taken as noise-free",)
    return TFEstimate(to_model(theta, order, dt, _names(outputs, m), input_name), theta,
                      cov, sig2, "iv", closed_loop_instruments=closed,
                      n_samples=u_a.size, notes=notes)

