"""Fingerprints of records: what makes two files "the same test".

A test is recognised by its *content*: the parsed, canonical column values,
not the file's bytes. The same data re-saved with CRLF line ends, a trailing
newline, another delimiter or as Parquet/MATLAB has the same
:func:`content_hash`; the file's own SHA-256 (:func:`file_hash`) is kept as
information.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from condmon.io.columns import Columns, column_values

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["content_hash", "file_hash", "fingerprint", "same_content", "fingerprint_prefix",
           "SIGNIFICANT_BITS", "FINGERPRINT_RTOL"]

#: Mantissa bits kept when hashing values (about 10 significant digits), so
#: that one text parser's last-digit rounding does not make a copy look new.
SIGNIFICANT_BITS = 33

#: Two fingerprints are of the same content when each figure of every shared
#: column agrees within this fraction of the column's scale: a float32 copy
#: (7 digits) or a re-export at 12 digits is caught, while two different tests'
#: noise differs by orders of magnitude more.
FINGERPRINT_RTOL = 1e-6

# Values sampled per column in a fingerprint, evenly over the record.
_SAMPLES = 8

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


def _numeric(dtype: Any) -> bool:
    import pandas as pd

    return bool(pd.api.types.is_numeric_dtype(dtype))


def _data_columns(df: pd.DataFrame | Columns, columns: Iterable[str] | None) -> list[str]:
    """The record's numeric data columns (or those of ``columns`` it has), sorted."""
    if columns is None:
        names = [str(c) for c in df.columns
                 if str(c) not in _INDEX_LIKE and not str(c).startswith("Unnamed: ")
                 and (isinstance(df, Columns) or _numeric(df[c].dtype))]
    else:
        names = [str(c) for c in columns if c in df.columns]
    return sorted(set(names))


def content_hash(df: pd.DataFrame | Columns, columns: Iterable[str] | None = None) -> str:
    """SHA-256 of a record's canonical content (hex).

    The numeric columns (or ``columns``), sorted by name, each as its name and
    its float64 values rounded to about 10 significant digits. Row order
    matters; column order, the file format, line ends and how numbers were
    written do not.

    Parameters
    ----------
    df : DataFrame or Columns
        A parsed record (canonical column names, after any column mapping).
    columns : iterable of str, optional
        Only these columns (the ones a model uses); default every numeric
        column except a saved index.

    Example
    -------
    >>> import pandas as pd
    >>> a = pd.DataFrame({"t": [0.0, 0.001], "V": [1.0, 2.0]})
    >>> b = a[["V", "t"]].copy()
    >>> b.loc[0, "V"] = 1.0 + 1e-15         # a parser's last-digit difference
    >>> content_hash(a) == content_hash(b)
    True
    >>> content_hash(a) == content_hash(a.assign(V=[1.0, 2.5]))
    False
    """
    h = hashlib.sha256()
    h.update(str(len(df)).encode())
    for name in _data_columns(df, columns):
        h.update(b"\x00" + name.encode("utf-8") + b"\x00")
        h.update(_quantised(column_values(df, name)).tobytes())
    return h.hexdigest()


def fingerprint_prefix(rows: int) -> str:
    """How every :func:`fingerprint` of a record of ``rows`` rows starts (a
    database can select the candidates of a comparison with ``LIKE``)."""
    return f'{{"n":{int(rows)},'


def fingerprint(df: pd.DataFrame | Columns, columns: Iterable[str] | None = None) -> str:
    """A record's content as a few figures per column (JSON text), for
    recognising a copy whose values were rounded differently (a float32
    Parquet file, a re-export with fewer digits) or that has a column more or
    fewer; compare two with :func:`same_content`.

    Each numeric column gives its mean, its standard deviation and 8 values
    evenly spread over the rows; the row count comes first.

    Example
    -------
    >>> import pandas as pd
    >>> a = pd.DataFrame({"t": [0.0, 0.001, 0.002], "V": [1.0, 2.0, 1.5],
    ...                   "I": [0.1, 0.3, 0.2]})
    >>> b = a.astype("float32").assign(extra=[7, 8, 9])
    >>> same_content(fingerprint(a), fingerprint(b))
    True
    >>> same_content(fingerprint(a), fingerprint(a.assign(V=[1.0, 2.0, 1.6])))
    False
    """
    n = len(df)
    # sorted(set()), not np.unique: that imports numpy.ma (a start-up cost)
    idx = np.array(sorted(set(np.linspace(0, max(n - 1, 0), _SAMPLES).round().astype(np.intp)
                              .tolist())), dtype=np.intp)
    if n == 0:
        idx = idx[:0]
    cols: dict[str, list[float | None]] = {}
    for name in _data_columns(df, columns):
        x = column_values(df, name)
        finite = x[np.isfinite(x)]
        # values near the float64 limit (a corrupt column, refused by the
        # record's validation after this) overflow the mean and std: an inf
        # figure is kept as None, as a NaN one is, without numpy's warning
        with np.errstate(over="ignore", invalid="ignore"):
            figures = [float(finite.mean()) if finite.size else math.nan,
                       float(finite.std()) if finite.size else math.nan, *map(float, x[idx])]
        cols[name] = [v if math.isfinite(v) else None for v in figures]
    return fingerprint_prefix(n) + json.dumps({"columns": cols}, separators=(",", ":"))[1:]


def same_content(a: str | None, b: str | None, rtol: float = FINGERPRINT_RTOL) -> bool:
    """Whether two :func:`fingerprint` texts are of the same record content.

    Same row count; at least three columns, and at least half of the larger
    record's columns, in common; and every figure of every common column equal
    within ``rtol`` times that column's scale (largest absolute mean or
    standard deviation of the two). Columns only one record has do not count.
    """
    if not a or not b:
        return False
    try:
        da, db = json.loads(a), json.loads(b)
        if int(da["n"]) != int(db["n"]) or int(da["n"]) == 0:
            return False
        ca, cb = dict(da["columns"]), dict(db["columns"])
    except (ValueError, KeyError, TypeError):  # not a fingerprint: never the same
        return False
    shared = set(ca) & set(cb)
    if len(shared) < max(3, (max(len(ca), len(cb)) + 1) // 2):
        return False
    for name in shared:
        x = np.array([np.nan if v is None else v for v in ca[name]], dtype=np.float64)
        y = np.array([np.nan if v is None else v for v in cb[name]], dtype=np.float64)
        if x.shape != y.shape:
            return False
        head = np.r_[x[:2], y[:2]]
        head = head[np.isfinite(head)]
        scale = float(np.max(np.abs(head))) if head.size else 0.0
        if np.any(np.isnan(x) != np.isnan(y)):
            return False
        there = ~np.isnan(x)
        if np.any(np.abs(x[there] - y[there]) > rtol * scale):
            return False
    return True
