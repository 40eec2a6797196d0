"""A linear filter (``scipy.signal.lfilter`` with zero initial conditions)
without importing :mod:`scipy.signal`.

Written here because ``import scipy.signal`` costs about 1 s (it pulls in
``scipy.stats``, ``scipy.interpolate`` and the spline and peak-finding code),
ten times what ``condmon estimate`` spends on its work, while every filter the
estimators use is a short difference equation run from rest. The recursion
``a[0] y[k] + a[1] y[k-1] + ... = b[0] x[k] + b[1] x[k-1] + ...`` is a lower
triangular banded Toeplitz system, solved by LAPACK's banded triangular solver
(``dtbtrs``, forward substitution, O(N * len(a)) per column), every column of
a 2-D input in one call.

Example
-------
>>> import numpy as np
>>> y = lfilter([1.0], [1.0, -0.5], np.ones(4))
>>> np.allclose(y, [1.0, 1.5, 1.75, 1.875])
True
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import lapack

__all__ = ["lfilter"]


def lfilter(b: ArrayLike, a: ArrayLike, x: ArrayLike, axis: int = -1) -> NDArray[np.float64]:
    """Filter ``x`` along ``axis`` by the rational filter ``b(q^-1) / a(q^-1)``
    from rest; the same result as ``scipy.signal.lfilter(b, a, x, axis)``.

    Parameters
    ----------
    b, a : array_like
        Numerator and denominator coefficients in powers of ``q^-1``;
        ``a[0]`` must be non-zero.
    x : array_like
        The signal, any number of dimensions.
    axis : int
        The axis along which to filter (default the last).

    Returns
    -------
    ndarray
        The filtered signal, float64, the shape of ``x``.
    """
    bb = np.atleast_1d(np.asarray(b, dtype=np.float64))
    aa = np.trim_zeros(np.atleast_1d(np.asarray(a, dtype=np.float64)), "b")
    if bb.ndim != 1 or aa.ndim != 1 or aa.size == 0 or aa[0] == 0.0:
        raise ValueError("filter coefficients must be 1-D with a[0] non-zero")
    bb, aa = bb / aa[0], aa / aa[0]
    xm = np.moveaxis(np.asarray(x, dtype=np.float64), axis, 0)
    shape = xm.shape
    n = shape[0]
    cols = xm.reshape(n, -1)
    out = np.zeros(cols.shape, dtype=np.float64, order="F")
    for i, bi in enumerate(bb[:n]):  # the moving-average part, b is short
        if bi != 0.0:
            out[i:] += bi * cols[:n - i]
    kd = min(aa.size - 1, n - 1)
    if kd > 0 and out.shape[1] > 0:
        band = np.asfortranarray(np.repeat(aa[:kd + 1, None], n, axis=1))
        out, info = lapack.dtbtrs(band, out, uplo="L", overwrite_b=1)
        if info != 0:  # cannot happen with a unit diagonal; never return garbage
            raise ValueError(f"banded solve failed (LAPACK info {info})")
    return np.moveaxis(np.asarray(out).reshape(shape), 0, axis)
