"""A linear filter (``scipy.signal.lfilter`` with zero initial conditions)
that does not import :mod:`scipy.signal`.

Importing :mod:`scipy.signal` costs about 1 s (it pulls in ``scipy.stats``,
``scipy.interpolate`` and the spline and peak-finding code) and even
:mod:`scipy.linalg` about 0.15 s, many times what ``condmon estimate`` spends on
its work. So the recursion is run by the C routine behind
``scipy.signal.lfilter`` (``scipy.signal._sigtools._linear_filter``), its
extension module loaded on its own (about 1 ms; it needs only numpy), or taken
from :mod:`scipy.signal` when that is already imported. The routine is
private to scipy: it is checked on a known impulse response when loaded, and
when it is missing, fails to load or answers wrongly, the same filter runs in
plain numpy instead (:func:`numpy_lfilter`).

The numpy filter runs the recursion ``a[0] y[k] + a[1] y[k-1] + ... = b[0]
x[k] + b[1] x[k-1] + ...`` in blocks of ``L`` samples: within a block the
output is the block's input through the first ``L`` samples of the impulse
response of ``1/a`` (one batched matrix product for all blocks and columns)
plus the free response to the last ``n`` outputs of the block before, carried
from block to block by an ``n x n`` recursion. The arithmetic is that of the
difference equation, only summed in another order.

Example
-------
>>> import numpy as np
>>> y = lfilter([1.0], [1.0, -0.5], np.ones(4))
>>> np.allclose(y, [1.0, 1.5, 1.75, 1.875])
True
"""

from __future__ import annotations

import functools
import importlib.machinery
import importlib.util
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["lfilter", "numpy_lfilter", "c_filter"]

FloatArray = NDArray[np.float64]

_SIGTOOLS = "scipy.signal._sigtools"


@functools.cache
def c_filter() -> Callable[..., Any] | None:
    """scipy's C ``_linear_filter(b, a, x, axis)``, or None when it cannot be
    had (then :func:`lfilter` runs in numpy). Loaded once per process."""
    try:
        module = sys.modules.get(_SIGTOOLS)
        if module is None:
            spec = importlib.util.find_spec("scipy")   # finds, does not import, scipy
            if spec is None or spec.origin is None:
                return None
            folder = Path(spec.origin).parent / "signal"
            found = [folder / f"_sigtools{suffix}"
                     for suffix in importlib.machinery.EXTENSION_SUFFIXES]
            path = next((f for f in found if f.is_file()), None)
            if path is None:
                return None
            loader = importlib.machinery.ExtensionFileLoader(_SIGTOOLS, str(path))
            ext = importlib.util.spec_from_file_location(_SIGTOOLS, path, loader=loader)
            if ext is None:
                return None
            module = importlib.util.module_from_spec(ext)
            loader.exec_module(module)
        run: Callable[..., Any] = module._linear_filter
        # the routine is private: trust it only on a known answer (y = x + 0.5 y[-1],
        # along the first axis of a 2-column array)
        got = run(np.array([1.0]), np.array([1.0, -0.5]), np.eye(3, 2), 0)
        want = np.array([[1.0, 0.0], [0.5, 1.0], [0.25, 0.5]])
        if not (isinstance(got, np.ndarray) and got.shape == (3, 2)
                and np.allclose(got, want, rtol=0.0, atol=1e-15)):
            return None
        return run
    except Exception:   # a missing, changed or broken private routine: numpy does the work
        return None


def _impulse(a: FloatArray, length: int) -> FloatArray:
    """The first ``length`` samples of the impulse response of ``1 / a`` (a[0] = 1)."""
    n = a.size - 1
    h = [0.0] * length
    coef = [float(c) for c in a[1:]]
    for k in range(length):
        acc = 1.0 if k == 0 else 0.0
        for i in range(1, min(n, k) + 1):
            acc -= coef[i - 1] * h[k - i]
        h[k] = acc
    return np.asarray(h, dtype=np.float64)


#: Lower-triangular Toeplitz index of each block length used: row i, column j
#: reads h[i - j] (h padded with a trailing 0 that fills the upper triangle).
_TOEPLITZ: dict[int, NDArray[np.intp]] = {}


def _toeplitz_index(length: int) -> NDArray[np.intp]:
    idx = _TOEPLITZ.get(length)
    if idx is None:
        lag = np.subtract.outer(np.arange(length), np.arange(length))
        idx = np.where(lag >= 0, lag, length)
        _TOEPLITZ[length] = idx
    return idx


def _all_pole(a: FloatArray, v: FloatArray) -> FloatArray:
    """Solve ``a(q^-1) y = v`` from rest for every column of ``v`` (rows: time)."""
    n = a.size - 1
    rows, cols = v.shape
    # a block of 16 (at least 4n) samples: the Toeplitz product costs the block's
    # length per sample, the scan log2 of the blocks; 16 was the fastest of
    # 8 .. 64 on a 4,000 x 6 record of order 2 (270 against 360 us at 64)
    length = int(min(rows, max(16, 4 * n)))
    h = _impulse(a, length)
    hmat = np.append(h, 0.0)[_toeplitz_index(length)]  # lower Toeplitz
    # free response to the n outputs before a block (y[-1], ..., y[-n]): the
    # zero-state response to the terms of the recursion that reach back there
    w = np.zeros((length, n))
    for m in range(1, n + 1):
        for k in range(0, min(n - m + 1, length)):
            w[k, m - 1] = -a[k + m]
    free = hmat @ w  # (length, n)
    blocks = -(-rows // length)
    padded = np.zeros((blocks * length, cols))
    padded[:rows] = v
    # every block of every column through the Toeplitz matrix in one product;
    # layout (time within the block, block, column)
    by_block = padded.reshape(blocks, length, cols).transpose(1, 0, 2).reshape(length, -1)
    zero_state = (hmat @ by_block).reshape(length, blocks, cols)
    if blocks > 1:  # then length >= n: a block holds the n outputs the next needs
        # after block k: s_k = c_k + F s_(k-1), c_k its zero-state last outputs;
        # solved for all k by a doubling scan (log2(blocks) products)
        step = free[length - n:][::-1]  # F: the block's last n outputs from y[-1..-n]
        s = zero_state[length - n:][::-1].copy()  # (n, blocks, cols)
        power, d = step, 1
        while d < blocks:
            s[:, d:] += (power @ s[:, :-d].reshape(n, -1)).reshape(n, blocks - d, cols)
            power, d = power @ power, 2 * d
        carry = np.zeros((n, blocks, cols))  # y[-1], ..., y[-n] before each block
        carry[:, 1:] = s[:, :-1]
        zero_state += (free @ carry.reshape(n, -1)).reshape(length, blocks, cols)
    y = zero_state.transpose(1, 0, 2).reshape(blocks * length, cols)[:rows]
    return np.asarray(y, dtype=np.float64)


#: Values filtered in one pass at most (beyond, column by column): the pass
#: holds a few work copies of what it filters.
_COLUMNS_AT_ONCE = 1 << 20


def lfilter(b: ArrayLike, a: ArrayLike, x: ArrayLike, axis: int = -1, *,
            overwrite_x: bool = False) -> FloatArray:
    """Filter ``x`` along ``axis`` by the rational filter ``b(q^-1) / a(q^-1)``
    from rest; ``scipy.signal.lfilter(b, a, x, axis)``, run by scipy's C
    routine where it loads (:func:`c_filter`), else by :func:`numpy_lfilter`.
    Parameters, result and errors are those of :func:`numpy_lfilter`.
    """
    run = c_filter()
    bb = np.atleast_1d(np.asarray(b, dtype=np.float64))
    aa = np.atleast_1d(np.asarray(a, dtype=np.float64))
    if (run is None or bb.ndim != 1 or aa.ndim != 1 or aa.size < 2 or bb.size == 0
            or aa[0] == 0.0):   # FIR, empty or bad coefficients: numpy's (and its errors)
        return numpy_lfilter(bb, aa, x, axis, overwrite_x=overwrite_x)
    xa = np.asarray(x, dtype=np.float64)
    if xa.size == 0:
        return xa.copy()
    in_place = (overwrite_x and isinstance(x, np.ndarray) and x.dtype == np.float64
                and (x.flags.c_contiguous or x.flags.f_contiguous) and x.flags.writeable
                and x.ndim == 2 and axis in (0, -2) and bb.size == 1 and bb[0] == 1.0)
    if not in_place:
        return np.asarray(run(bb, aa, xa, axis), dtype=np.float64)
    assert isinstance(x, np.ndarray)
    if x.flags.c_contiguous and x.size <= _COLUMNS_AT_ONCE:
        x[...] = run(bb, aa, x, 0)
    else:   # columns in a row (Fortran order), or a long record: a column's work copy at a time
        for c in range(x.shape[1]):
            x[:, c] = run(bb, aa, x[:, c], 0)
    return x


def numpy_lfilter(b: ArrayLike, a: ArrayLike, x: ArrayLike, axis: int = -1, *,
                  overwrite_x: bool = False) -> FloatArray:
    """Filter ``x`` along ``axis`` by the rational filter ``b(q^-1) / a(q^-1)``
    from rest in plain numpy; the same result as
    ``scipy.signal.lfilter(b, a, x, axis)`` to rounding.

    Parameters
    ----------
    b, a : array_like
        Numerator and denominator coefficients in powers of ``q^-1``;
        ``a[0]`` must be non-zero.
    x : array_like
        The signal, any number of dimensions.
    axis : int
        The axis along which to filter (default the last).
    overwrite_x : bool
        Filter ``x`` in place when it allows (a C- or Fortran-ordered float64
        array filtered along its first axis by ``b = [1]``): the result is
        ``x`` itself, and a long record needs no second copy.

    Returns
    -------
    ndarray
        The filtered signal, float64, the shape of ``x``.

    Raises
    ------
    ValueError
        Coefficients not 1-D, or ``a[0]`` zero.
    """
    bb = np.atleast_1d(np.asarray(b, dtype=np.float64))
    aa = np.atleast_1d(np.asarray(a, dtype=np.float64))
    last = np.flatnonzero(aa) if aa.ndim == 1 else np.arange(aa.size)
    aa = aa[:last[-1] + 1] if last.size else aa[:0]  # trailing zeros off
    if bb.ndim != 1 or aa.ndim != 1 or aa.size == 0 or aa[0] == 0.0:
        raise ValueError("filter coefficients must be 1-D with a[0] non-zero")
    bb, aa = bb / aa[0], aa / aa[0]
    xm = np.moveaxis(np.asarray(x, dtype=np.float64), axis, 0)
    shape = xm.shape
    n = shape[0]
    cols = xm.reshape(n, -1)
    in_place = (overwrite_x and isinstance(x, np.ndarray) and x.dtype == np.float64
                and (x.flags.c_contiguous or x.flags.f_contiguous)
                and axis in (0, -x.ndim) and bb.size == 1
                and bb[0] == 1.0 and np.shares_memory(cols, x))
    poles = aa.size > 1 and n > 0 and cols.shape[1] > 0
    if (not in_place and poles and bb.size == 1 and bb[0] == 1.0
            and cols.size <= _COLUMNS_AT_ONCE):   # all-pole: no work copy of the input
        return np.moveaxis(_all_pole(aa, cols).reshape(shape), 0, axis)
    if in_place:
        out = cols
    else:
        out = bb[0] * cols if bb.size else np.zeros(cols.shape, dtype=np.float64)
        for i, bi in enumerate(bb[1:n], start=1):  # the moving-average part, b is short
            if bi != 0.0:
                out[i:] += bi * cols[:n - i]
    if poles:
        if out.size <= _COLUMNS_AT_ONCE:
            out[...] = _all_pole(aa, out)
        else:   # a long record: a column at a time, so the work arrays stay one column's
            for c in range(out.shape[1]):
                out[:, c] = _all_pole(aa, out[:, c:c + 1])[:, 0]
    return np.moveaxis(out.reshape(shape), 0, axis)
