"""Fingerprints of records: what makes two files "the same test".

A test is recognised by its *content*: the parsed, canonical column values,
not the file's bytes. The same data re-saved with CRLF line ends, a trailing
newline, another delimiter or as Parquet/MATLAB has the same
:func:`content_hash`; the file's own SHA-256 (:func:`file_hash`) is kept as
information.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["content_hash", "file_hash", "SIGNIFICANT_BITS"]

#: Mantissa bits kept when hashing values (about 10 significant digits), so
#: that one text parser's last-digit rounding does not make a copy look new.
SIGNIFICANT_BITS = 33

# Columns a conversion adds on its own (a saved pandas index), never test data.
_INDEX_LIKE = {"index", "__index_level_0__"}


def file_hash(path: str | Path) -> str:
    """SHA-256 of a file's bytes (hex).

    Example
    -------
    >>> import tempfile, os
    >>> with tempfile.NamedTemporaryFile(delete=False) as fh:
    ...     _ = fh.write(b"abc")
    >>> file_hash(fh.name)[:16]
    'ba7816bf8f01cfea'
    >>> os.unlink(fh.name)
    """
    h = hashlib.sha256()
    with Path(path).open("rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _quantised(values: np.ndarray) -> np.ndarray:
    """float64 values with the mantissa rounded to :data:`SIGNIFICANT_BITS` bits."""
    x = np.asarray(values, dtype=np.float64)
    mant, expo = np.frexp(x)
    scale = float(2 ** SIGNIFICANT_BITS)
    out = np.ldexp(np.round(mant * scale) / scale, expo)
    out[x == 0] = 0.0  # -0.0 and 0.0 are the same reading
    return np.asarray(out, dtype="<f8")


def content_hash(df: pd.DataFrame, columns: Iterable[str] | None = None) -> str:
    """SHA-256 of a record's canonical content (hex).

    The numeric columns (or ``columns``), sorted by name, each as its name and
    its float64 values rounded to about 10 significant digits. Row order
    matters; column order, the file format, line ends and how numbers were
    written do not.

    Parameters
    ----------
    df : DataFrame
        A parsed record (canonical column names, after any column mapping).
    columns : iterable of str, optional
        Only these columns (the ones a model uses); default every numeric
        column except a saved index.

    Example
    -------
    >>> a = pd.DataFrame({"t": [0.0, 0.001], "V": [1.0, 2.0]})
    >>> b = a[["V", "t"]].copy()
    >>> b.loc[0, "V"] = 1.0 + 1e-15         # a parser's last-digit difference
    >>> content_hash(a) == content_hash(b)
    True
    >>> content_hash(a) == content_hash(a.assign(V=[1.0, 2.5]))
    False
    """
    if columns is None:
        names = [str(c) for c in df.columns
                 if str(c) not in _INDEX_LIKE and not str(c).startswith("Unnamed: ")
                 and pd.api.types.is_numeric_dtype(df[c].dtype)]
    else:
        names = [str(c) for c in columns if c in df.columns]
    h = hashlib.sha256()
    h.update(str(len(df)).encode())
    for name in sorted(set(names)):
        h.update(b"\x00" + name.encode("utf-8") + b"\x00")
        h.update(_quantised(df[name].to_numpy(dtype=np.float64, na_value=np.nan)).tobytes())
    return h.hexdigest()
