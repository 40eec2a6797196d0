"""Instruments for data gathered in closed loop.

In closed loop the input ``u`` (the drive voltage) is correlated with the
measurement noise fed back through the controller, so an instrument built from
``u`` itself is not independent of the noise. When the external excitation
signals ``r`` (e.g. the demand perturbation ``yd`` and voltage perturbation ``ud``)
are recorded, the noise-free part of the input is estimated from them — the first
stage of the two-stage / tailor-made closed-loop IV methods — and every instrument
is generated from that estimate instead.

References
----------
.. [1] M. Gilson, P. Van den Hof, "Instrumental variable methods for closed-loop
   system identification", Automatica 41 (2005) 241-249.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon._filter import lfilter
from condmon.errors import DataError, EstimationError
from condmon.identify._common import lagged_gram, schur_stable, signals

__all__ = ["noise_free_input"]

FloatArray = NDArray[np.float64]


def _lagged(r: FloatArray, n: int, start: int) -> FloatArray:
    """Columns r_i(k - d) for d = start..n-1+start, rows k = 0..N-1 (zeros before 0)."""
    N, nr = r.shape
    cols = []
    for i in range(nr):
        for d in range(start, start + n):
            c = np.zeros(N)
            c[d:] = r[: N - d, i]
            cols.append(c)
    return np.column_stack(cols)


@functools.lru_cache(maxsize=16)
def _regressor_columns(n: int, nr: int) -> NDArray[np.intp]:
    """Columns of the lagged Gram matrix of ``[u, r_1..r_nr]`` that hold the
    regressors ``-u(k-1..k-n)`` and ``r_i(k..k-n)`` (made once per shape)."""
    ns = 1 + nr
    cols = np.array([d * ns for d in range(1, n + 1)]
                    + [d * ns + 1 + i for d in range(n + 1) for i in range(nr)], dtype=np.intp)
    cols.flags.writeable = False
    return cols


def noise_free_input(u: ArrayLike, r: ArrayLike, order: int = 8) -> FloatArray:
    """Estimate the part of the input ``u`` explained by the excitation signals ``r``.

    Fits ``C(q^-1) u(k) = sum_i D_i(q^-1) r_i(k) + v(k)`` by least squares (an ARX
    model whose order is high enough to absorb the coloured loop noise) and
    returns the simulated ``D_i/C r_i``, a function of ``r`` alone. Falls back to a
    finite impulse response model if ``C`` is not stable.

    Parameters
    ----------
    u : array_like, shape (N,)
        Plant input measured in closed loop. [input unit]
    r : array_like, shape (N,) or (N, n_r)
        External excitation signals, independent of the noise.
    order : int
        Order of ``C`` and of each ``D_i`` (``D_i`` has a direct term).

    Returns
    -------
    ndarray, shape (N,)
        Noise-free estimate of ``u``. [input unit]

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> r = rng.standard_normal(2000)
    >>> u = lfilter([1.0, 0.5], [1.0, -0.7], r) + 0.1 * rng.standard_normal(2000)
    >>> u_hat = noise_free_input(u, r)
    >>> bool(np.std(u - u_hat) < 0.12)
    True
    """
    u_arr = np.asarray(u, dtype=np.float64)
    r_arr = np.asarray(r, dtype=np.float64)
    if r_arr.ndim == 1:
        r_arr = r_arr[:, None]
    if r_arr.shape[0] != u_arr.size:
        raise DataError(f"excitation has {r_arr.shape[0]} samples, input has {u_arr.size}")
    # (np.std == 0, column by column: a reduction along the rows of a few
    # interleaved columns is ten times slower than one over each column)
    if any(float(np.max(c)) == float(np.min(c)) for c in r_arr.T):
        raise DataError("an excitation signal is constant: it cannot build instruments")
    N = u_arr.size
    n = order
    # Rows k = n..N-1 of [-u(k-1..k-n), r_i(k..k-n)] and u(k): their Gram matrix
    # from lag products (no lagged copy: memory bounded by the signals themselves).
    # The lagged columns of [u, -r_1, ...] hold -u(k-d) (d >= 1) and -r(k-d)
    # (d >= 0) and, at d = 0, u(k) itself: one Gram matrix gives both sides.
    sig = signals(-u_arr, r_arr)
    C = lagged_gram(sig, n)
    cols = _regressor_columns(n, r_arr.shape[1])
    XtX, Xty = C[np.ix_(cols, cols)], -C[cols, 0]
    # Normal equations (10x faster than an SVD solve). A loop without noise, or
    # an excitation column that copies the input, makes them exactly singular:
    # the minimum-norm least-squares solution is then taken instead.
    try:
        with np.errstate(all="ignore"):
            sol = np.linalg.solve(XtX, Xty)
        if not np.all(np.isfinite(sol)):
            raise np.linalg.LinAlgError("non-finite solution")
    except np.linalg.LinAlgError:
        X = np.hstack([-u_arr[n - d: N - d, None] for d in range(1, n + 1)]
                      + [r_arr[n - d: N - d] for d in range(n + 1)])
        try:
            sol = np.linalg.lstsq(X, u_arr[n:], rcond=None)[0]
        except np.linalg.LinAlgError:
            raise EstimationError("the excitation signals cannot build instruments "
                                  "(the input-excitation regression failed)") from None
    nr = r_arr.shape[1]
    # back to per-input blocks: theta = [c_1..c_n, d_1(0..n), d_2(0..n), ...]
    theta = np.r_[sol[:n], sol[n:].reshape(n + 1, nr).T.ravel()]
    c = np.r_[1.0, theta[:n]]
    # every pole inside radius 0.999: the polynomial of the poles / 0.999 is stable
    if schur_stable(c * 0.999 ** -np.arange(c.size)):
        # sum of D_i r_i through 1/C once (the recursion is linear)
        moving = np.zeros(N)
        for i in range(r_arr.shape[1]):   # D_i r_i from rest: the first N of the convolution
            moving += np.convolve(r_arr[:, i], theta[n + i * (n + 1): n + (i + 1) * (n + 1)])[:N]
        return lfilter([1.0], c, moving)
    # Unstable ARX denominator: a long FIR model is always stable.
    m = 60
    Xf = _lagged(r_arr, m, 0)
    try:
        g, *_ = np.linalg.lstsq(Xf, u_arr, rcond=None)
    except np.linalg.LinAlgError:
        raise EstimationError("the excitation signals cannot build instruments "
                              "(FIR regression did not converge)") from None
    return np.asarray(Xf @ g, dtype=np.float64)
