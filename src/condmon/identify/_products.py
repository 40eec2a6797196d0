"""Products ``aᵀb`` of tall, narrow matrices at the speed of the cache.

The estimators' cross products have a record's length as their inner
dimension and a few signals as their outer ones. Two things make BLAS slow on
them (OpenBLAS on one thread, 6 columns, measured):

- numpy hands ``x.T @ x`` of one array to the symmetric rank-k update (syrk):
  7.7 ns per row, against 2.9 for the same matrix from two general products;
- past about 50,000 rows any of these products costs 7.7 ns per row, against
  2.2 ns below: the rows no longer fit the cache.

:func:`product` and :func:`gram` therefore sum the products of blocks of
:data:`ROWS` rows, and form ``xᵀx`` from general products. Written here
because no library chooses the blocking by shape.

Example
-------
>>> x = np.arange(12.0).reshape(4, 3)
>>> bool(np.allclose(gram(x), x.T @ x)), bool(np.allclose(product(x, x[:, :2]), x.T @ x[:, :2]))
(True, True)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["gram", "product", "lag_products", "ROWS"]

FloatArray = NDArray[np.float64]

#: Rows per block of a product (16,384 rows of 6 signals: 0.8 MB an operand).
ROWS = 16384


def product(a: FloatArray, b: FloatArray) -> FloatArray:
    """``aᵀb`` (k1, k2) of ``a`` (N, k1) and ``b`` (N, k2), summed over
    blocks of :data:`ROWS` rows."""
    out = np.asarray(a[:ROWS].T @ b[:ROWS], dtype=np.float64)
    for s in range(ROWS, a.shape[0], ROWS):
        out += a[s: s + ROWS].T @ b[s: s + ROWS]
    return out


def gram(x: FloatArray) -> FloatArray:
    """``xᵀx`` (k, k) of ``x`` (N, k), summed over blocks of :data:`ROWS`
    rows, each from two general products (its first columns' rows, then the
    others'); one product per block for a single column."""
    out = _gram(x[:ROWS])
    for s in range(ROWS, x.shape[0], ROWS):
        out += _gram(x[s: s + ROWS])
    return out


def lag_products(sig: FloatArray, n: int) -> FloatArray:
    """The lag products ``P_d = Σ_k sig(k) sig(k-d)ᵀ`` (``k = d..N-1``) for
    ``d = 0..n``, shape (n+1, k, k), in one pass over blocks of :data:`ROWS`
    rows: every lag of a block while it is in the cache (a record that does
    not fit the cache is read once, not n + 1 times)."""
    N, k = sig.shape
    P = np.zeros((n + 1, k, k))
    for s in range(0, N, ROWS):
        e = min(N, s + ROWS)
        P[0] += _gram(sig[s:e])
        for d in range(1, n + 1):
            lo = max(s, d)
            if lo < e:   # rows lo..e-1 and the rows d before them (the block's or the last one's)
                P[d] += sig[lo:e].T @ sig[lo - d: e - d]
    return P


def _gram(x: FloatArray) -> FloatArray:
    k = x.shape[1]
    if k < 2:
        return np.asarray(x.T @ x, dtype=np.float64)
    out = np.empty((k, k))
    half = k // 2
    # different shapes, or a different first element: numpy takes the general product
    np.matmul(x[:, :half].T, x, out=out[:half])
    np.matmul(x[:, half:].T, x, out=out[half:])
    return out
