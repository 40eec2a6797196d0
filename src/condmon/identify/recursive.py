"""Recursive least squares and recursive instrumental variables (single output).

A prior parameter vector ``theta0`` and covariance ``P0`` may be given. A
near-zero prior variance holds a parameter at its prior value: this is how the
two-step scheme of the reference application fixes the denominator found by
SRIV (V -> omega) while the V -> I numerator is estimated recursively.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon._filter import lfilter
from condmon.errors import ModelError
from condmon.identify._common import TFEstimate, prepare, simulate_outputs, to_model
from condmon.identify.ls import _names, output_error_variance

__all__ = ["RecursiveEstimate", "rls", "riv"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class RecursiveEstimate:
    """Final estimate and the parameter trajectory of a recursive estimator.

    Attributes
    ----------
    final : TFEstimate
        Estimate after the last sample (covariance = the recursion's P scaled by
        the residual variance).
    history : ndarray, shape (N, n_params)
        Parameter vector after each sample (rows before the first update hold
        ``theta0``).
    """

    final: TFEstimate
    history: FloatArray


def _recursion(y: FloatArray, phi: FloatArray, zeta: FloatArray, theta0: FloatArray,
               P0: FloatArray, forgetting: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    theta = theta0.copy()
    P = P0.copy()
    hist = np.empty((y.size, theta.size))
    lam = forgetting
    for k in range(y.size):
        f = phi[k]
        z = zeta[k]
        Pz = P @ z
        denom = lam + f @ Pz
        gain = Pz / denom
        theta = theta + gain * (y[k] - f @ theta)
        P = (P - np.outer(gain, f @ P)) / lam
        hist[k] = theta
    return theta, P, hist


def _regressors(y: FloatArray, u: FloatArray, n: int) -> FloatArray:
    N = y.size
    out = np.zeros((N, 2 * n))
    for d in range(1, n + 1):
        out[d:, d - 1] = -y[: N - d]
        out[d:, n + d - 1] = u[: N - d]
    return out


def _prior(order: int, theta0: ArrayLike | None, P0: ArrayLike | None
           ) -> tuple[FloatArray, FloatArray]:
    p = 2 * order
    t0 = np.zeros(p) if theta0 is None else np.asarray(theta0, dtype=np.float64)
    if t0.shape != (p,):
        raise ModelError(f"theta0 must have {p} elements [a_1..a_n, b_1..b_n], got {t0.shape}")
    if P0 is None:
        P = 1e6 * np.eye(p)
    else:
        P = np.asarray(P0, dtype=np.float64)
        if P.ndim == 1:
            P = np.diag(P)
        if P.shape != (p, p):
            raise ModelError(f"P0 must be ({p}, {p}) or a diagonal of {p}, got {P.shape}")
    return t0, P


def rls(u: ArrayLike, y: ArrayLike, order: int, *, dt: float = 1.0,
        theta0: ArrayLike | None = None, P0: ArrayLike | None = None,
        forgetting: float = 1.0, output: str = "y", input_name: str = "u"
        ) -> RecursiveEstimate:
    """Recursive least squares for ``A y = B u + e`` (single output).

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Input and output.
    order : int
        Number of poles n.
    dt : float
        Sample time. [s]
    theta0 : array_like, shape (2n,), optional
        Prior ``[a_1..a_n, b_1..b_n]`` (default zeros).
    P0 : array_like, shape (2n, 2n) or (2n,), optional
        Prior covariance, in units of the noise variance (default 1e6 I: no prior).
    forgetting : float
        Forgetting factor in (0, 1]; 1 weights all data equally.
    output, input_name : str
        Names.

    Returns
    -------
    RecursiveEstimate

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(2000)
    >>> y = lfilter([0, 0.5], [1, -0.8], u)
    >>> np.round(rls(u, y, 1).final.theta, 4)
    array([-0.8,  0.5])
    """
    u_a, y2 = prepare(u, y, order)
    y_a = y2[:, 0]
    if not 0 < forgetting <= 1:
        raise ModelError(f"forgetting factor must be in (0, 1], got {forgetting}")
    t0, P = _prior(order, theta0, P0)
    phi = _regressors(y_a, u_a, order)
    theta, Pn, hist = _recursion(y_a, phi, phi, t0, P, forgetting)
    e = y_a - phi @ theta
    sig2 = float(np.var(e[order:]))
    return RecursiveEstimate(
        TFEstimate(to_model(theta, order, dt, (output,), input_name), theta, sig2 * Pn,
                   np.array([sig2]), "rls", n_samples=u_a.size), hist)


def riv(u: ArrayLike, y: ArrayLike, order: int, *, dt: float = 1.0,
        theta0: ArrayLike | None = None, P0: ArrayLike | None = None,
        auxiliary: ArrayLike | None = None, prefilter: ArrayLike | None = None,
        forgetting: float = 1.0, output: str = "y", input_name: str = "u"
        ) -> RecursiveEstimate:
    """Recursive instrumental variables (single output).

    Instruments are the lags of the auxiliary-model output ``x = B̂/Â u`` and of
    ``u``; the auxiliary model is ``auxiliary`` (a parameter vector), or
    ``theta0`` if that is given, else a recursive LS pass.

    Parameters
    ----------
    u, y, order, dt, theta0, P0, forgetting, output, input_name
        As for :func:`rls`.
    auxiliary : array_like, shape (2n,), optional
        Parameter vector of the auxiliary model that generates the instrument.
    prefilter : array_like, optional
        Denominator ``C`` of a prefilter ``1/C`` applied to ``u``, ``y`` and the
        instrument first (SRIV-style; e.g. the held denominator).

    Returns
    -------
    RecursiveEstimate

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(4000)
    >>> y = lfilter([0, 0.5], [1, -0.8], u) + 0.3 * rng.standard_normal(4000)
    >>> bool(abs(riv(u, y, 1).final.theta[0] + 0.8) < 0.03)
    True
    """
    u_a, y2 = prepare(u, y, order)
    y_a = y2[:, 0]
    if not 0 < forgetting <= 1:
        raise ModelError(f"forgetting factor must be in (0, 1], got {forgetting}")
    t0, P = _prior(order, theta0, P0)
    if auxiliary is not None:
        aux = np.asarray(auxiliary, dtype=np.float64)
    elif theta0 is not None:
        aux = t0
    else:
        aux = rls(u_a, y_a, order).final.theta
    x = simulate_outputs(aux, order, u_a, 1)[:, 0]
    uf, yf, xf = u_a, y_a, x
    if prefilter is not None:
        c = np.asarray(prefilter, dtype=np.float64)
        uf, yf, xf = (lfilter([1.0], c, s) for s in (u_a, y_a, x))
    phi = _regressors(yf, uf, order)
    zeta = _regressors(xf, uf, order)
    theta, Pn, hist = _recursion(yf, phi, zeta, t0, P, forgetting)
    sig2 = output_error_variance(theta, order, u_a, y2)
    return RecursiveEstimate(
        TFEstimate(to_model(theta, order, dt, _names((output,), 1), input_name), theta,
                   float(sig2[0]) * Pn, sig2, "riv", n_samples=u_a.size), hist)
