"""What every file reader shares: the record as read, before canonical names.

A reader returns a :class:`RawRecord`: the columns under the file's own names,
the constants found beside them, the absolute start time when the file gives
one, and the names it left out with the reason. :func:`select_vectors` keeps
the vectors of the record's length (the most common one) out of a file's
variables or channels; :func:`time_to_seconds` turns a column of date-times
into seconds from its first sample.
"""

from __future__ import annotations

import re
import warnings
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from condmon.errors import DataError, DataWarning

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["RawRecord", "select_vectors", "time_to_seconds", "describe_shape", "one_line"]

AnyArray = np.ndarray[Any, Any]

#: Date/time formats accepted only if they carry a day or an hour.
_DATE_OR_TIME = ("%d", "%H")
_FRACTION_COMMA = re.compile(r"(\d{2}:\d{2}:\d{2}),(\d+)")
_ISO_DATE = re.compile(r"^\d{4}-\d{2}-\d{2}")
_TIME_OF_DAY = re.compile(r"^\d{1,2}:\d{2}:\d{2}([.,]\d+)?$")


@dataclass
class RawRecord:
    """A record as a reader found it, before the column mapping.

    Attributes
    ----------
    frame : pandas.DataFrame
        One column per file column, variable or channel, under the file's names.
    constants : dict of str to float, optional
        Scalars stored beside the signals (a MATLAB file's 1x1 variables).
    start_time : str, optional
        Absolute time at ``t = 0`` (ISO 8601), when the file gives it.
    ignored : dict of str to str
        Names left out of ``frame`` and why, for messages.
    """

    frame: pd.DataFrame
    constants: dict[str, float] | None = None
    start_time: str | None = None
    ignored: dict[str, str] = field(default_factory=dict)


def one_line(err: BaseException | str, limit: int | None = 200) -> str:
    """An exception's message (or a text) on one line, shortened to ``limit``
    characters (None: not shortened).

    Example
    -------
    >>> one_line(ValueError("Error tokenizing data.\\nC error: line 5"))
    'Error tokenizing data. C error: line 5'
    """
    text = " ".join(str(err).split())
    if not text and isinstance(err, BaseException):
        text = type(err).__name__
    return text if limit is None or len(text) <= limit else text[: limit - 3] + "..."


def describe_shape(shape: tuple[int, ...]) -> str:
    """``(3, 2)`` -> ``'3x2'``, as MATLAB writes a size.

    Example
    -------
    >>> describe_shape((24841, 1))
    '24841x1'
    """
    return "x".join(str(n) for n in shape) or "1x1"


def _is_real_numeric(arr: AnyArray) -> bool:
    kind = arr.dtype.kind
    return kind in "fiub" or kind == "M"


def select_vectors(items: Mapping[str, AnyArray], source: Path | str, what: str = "variable",
                   *, constants: bool = True
                   ) -> tuple[dict[str, AnyArray], dict[str, float], dict[str, str]]:
    """Split a file's arrays into columns, constants and ignored names.

    Every real numeric (or date-time) array that squeezes to one dimension is a
    vector; the most common vector length is the record's length (the longest
    on a tie) and vectors of another length are ignored with a
    :class:`DataWarning` naming them. A 1x1 real numeric array is a constant.
    Matrices and complex arrays are ignored with the warning; anything else
    (text, structs, cells, empty arrays) is ignored silently.

    Parameters
    ----------
    items : mapping of str to ndarray
        The file's arrays by name, in file order, shaped as the file declares
        them (MATLAB's orientation).
    source : Path or str
        The file, for messages.
    what : str
        ``"variable"`` or ``"channel"``, for messages.
    constants : bool
        Whether a 1x1 array is a constant (MATLAB) or a one-sample vector (TDMS).

    Returns
    -------
    columns : dict of str to ndarray
        The vectors of the record's length, each shape (N,).
    constants : dict of str to float
        The scalars.
    ignored : dict of str to str
        Names left out and why.

    Raises
    ------
    DataError
        When no vector is left, naming the file.

    Example
    -------
    >>> cols, consts, ignored = select_vectors(
    ...     {"t": np.zeros((5, 1)), "u": np.ones((1, 5)), "kp": np.array([[2.0]]),
    ...      "name": np.array(["rig"])}, "rig.mat")
    >>> sorted(cols), consts, ignored
    (['t', 'u'], {'kp': 2.0}, {'name': 'not numeric'})
    """
    vectors: dict[str, AnyArray] = {}
    scalars: dict[str, float] = {}
    ignored: dict[str, str] = {}
    odd: list[str] = []
    for name, arr in items.items():
        if arr.dtype.kind == "c":
            ignored[name] = f"complex {describe_shape(arr.shape)}"
            odd.append(f"{name!r} ({ignored[name]})")
        elif not _is_real_numeric(arr) or arr.dtype.names is not None:
            ignored[name] = "not numeric"
        elif arr.size == 0:
            ignored[name] = "empty"
        elif constants and arr.size == 1 and arr.dtype.kind != "M":
            scalars[name] = float(arr.reshape(-1)[0])
        elif np.squeeze(arr).ndim <= 1:
            vec = np.atleast_1d(np.squeeze(arr))
            vectors[name] = vec.astype(np.float64) if vec.dtype.kind == "b" else vec
        else:
            ignored[name] = f"{describe_shape(arr.shape)} matrix, not a vector"
            odd.append(f"{name!r} ({ignored[name]})")
    if not vectors:
        found = ", ".join(f"{n!r} ({why})" for n, why in ignored.items()) or "none"
        raise DataError(f"{source}: no numeric vector in the file to read as a column "
                        f"({what}s ignored: {found})")
    lengths = Counter(v.size for v in vectors.values())
    n = max(lengths, key=lambda size: (lengths[size], size))
    for name in [k for k, v in vectors.items() if v.size != n]:
        ignored[name] = f"{vectors.pop(name).size} samples, the record has {n}"
        odd.append(f"{name!r} ({ignored[name]})")
    if odd:
        warnings.warn(f"{source}: {what}(s) {', '.join(odd)} ignored: only vectors of the "
                      f"record's length {n} become columns", DataWarning, stacklevel=5)
    return vectors, scalars, ignored


def _parse_datetimes(values: pd.Series, source: str) -> pd.Series | None:
    """Date-time strings parsed, or None when they are not all date-times."""
    import pandas as pd

    valid = values.dropna()
    if valid.empty:
        return None
    text = values.astype(str).str.strip()
    if _FRACTION_COMMA.search(str(valid.iloc[0])):  # 10:00:00,001: ISO 8601 allows the comma
        text = text.str.replace(_FRACTION_COMMA, r"\1.\2", regex=True)
    text = text.where(values.notna())
    sample = str(text.dropna().iloc[0])
    try:
        from pandas.tseries.api import guess_datetime_format
    except ImportError:  # pandas 2.1: not public yet, only in its parser module
        from pandas._libs.tslibs.parsing import guess_datetime_format

    results: dict[bool, pd.Series] = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if _ISO_DATE.match(sample):
            try:
                return pd.to_datetime(text, format="ISO8601")
            except (ValueError, TypeError, OverflowError):
                pass
        seen: set[str] = set()
        for dayfirst in (False, True):
            fmt = guess_datetime_format(sample, dayfirst=dayfirst)
            if not fmt or fmt in seen or not any(c in fmt for c in _DATE_OR_TIME):
                continue
            seen.add(fmt)
            try:
                results[dayfirst] = pd.to_datetime(text, format=fmt)
            except (ValueError, TypeError, OverflowError):
                continue
    if len(results) == 2 and not results[False].equals(results[True]):
        increasing = [d for d, r in results.items() if r.dropna().is_monotonic_increasing]
        if len(increasing) == 1:
            return results[increasing[0]]
        seconds = [(r - r.iloc[0]).dt.total_seconds() for r in results.values()]
        if not seconds[0].equals(seconds[1]):
            raise DataError(f"{source}: column {values.name!r}: the order of day and month "
                            f"in its dates is ambiguous ({sample!r}); write ISO dates "
                            "(YYYY-MM-DD)")
        # the same intervals either way, only the start date is in doubt:
        # dotted dates are day first (23.11.2026), slashed ones month first
        return results["." in sample.split()[0]]
    return next(iter(results.values()), None)


def time_to_seconds(values: pd.Series, source: str = "record") -> tuple[pd.Series, str] | None:
    """Seconds from the first sample of a date-time column, and its start.

    Parameters
    ----------
    values : pandas.Series
        Date-times (``datetime64``), date-time strings pandas can parse
        (ISO 8601 such as ``2026-11-23 10:00:00.001``, a comma before the
        fraction accepted, ``23.11.2026 10:00:00``), or times of day
        (``10:00:00.001``).
    source : str
        The file, for messages.

    Returns
    -------
    (seconds, start) or None
        The time from the first sample [s] and the first sample as an ISO 8601
        string; None when the column is not date-times (numbers, text).

    Raises
    ------
    DataError
        When the order of day and month cannot be told.

    Example
    -------
    >>> import pandas as pd
    >>> s, start = time_to_seconds(pd.Series(["2026-11-23 10:00:00.000",
    ...                                       "2026-11-23 10:00:00.250"]))
    >>> s.tolist(), start
    ([0.0, 0.25], '2026-11-23T10:00:00')
    """
    import pandas as pd

    if pd.api.types.is_datetime64_any_dtype(values.dtype):
        stamps: pd.Series | None = values
    elif pd.api.types.is_object_dtype(values.dtype) or pd.api.types.is_string_dtype(values.dtype):
        valid = values.dropna().astype(str).str.strip()
        if (not valid.empty and _TIME_OF_DAY.fullmatch(str(valid.iloc[0]))
                and bool(valid.str.fullmatch(_TIME_OF_DAY).all())):
            try:
                spans = pd.to_timedelta(values.astype(str).str.strip()
                                        .str.replace(",", ".", regex=False)
                                        .where(values.notna()))
            except (ValueError, OverflowError):
                return None
            seconds = (spans - spans.iloc[0]).dt.total_seconds()
            return seconds, str(valid.iloc[0])
        stamps = _parse_datetimes(values, source)
    else:
        return None
    if stamps is None:
        return None
    first = stamps.iloc[0]
    seconds = (stamps - first).dt.total_seconds()
    start = first.isoformat() if not pd.isna(first) else ""
    return seconds, start
