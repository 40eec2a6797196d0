"""Validating test records at the boundary.

Everything a record can get wrong is checked here, once, and reported with the
file and the column: missing columns, non-numeric or non-finite values, a time
base that is not increasing or not uniform (:func:`check_time_base`, the one
time-base check of every command), mismatched lengths, a record too short for
the model, an input with no excitation, a saturated drive. Files are read by
:func:`condmon.io.readers.read_record` (CSV, text, Parquet, MATLAB, TDMS),
re-exported here.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import DataError, DataWarning, MissingColumnsError
from condmon.io.columns import Columns
from condmon.io.readers import read_record

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["Record", "read_record", "validate_record", "check_time_base", "parse_column_map",
           "write_record", "check_output_path", "row_text"]

FloatArray = NDArray[np.float64]

#: Relative tolerance on sample-interval jitter before the time base is refused.
TIME_JITTER = 1e-3
#: Share of samples at the input's extreme values above which saturation is flagged.
SATURATION_SHARE = 0.05
#: Largest magnitude accepted in a column: beyond it a value is corrupt or
#: mis-scaled, and its square would overflow the estimators' sums.
MAX_MAGNITUDE = 1e15


@dataclass(frozen=True, eq=False)
class Record:
    """A validated record: uniformly sampled, finite, float64 columns.

    Attributes
    ----------
    columns : dict of str to ndarray
        Every validated column (``t`` included), each shape (N,).
    dt : float
        Sample time. [s]
    source : str
        Where the record came from (file path or a label).
    """

    columns: dict[str, FloatArray]
    dt: float
    source: str

    def __getitem__(self, name: str) -> FloatArray:
        return self.columns[name]

    def __len__(self) -> int:
        return int(self.columns["t"].size)

    def stack(self, names: Sequence[str]) -> FloatArray:
        """Columns side by side, shape (N, len(names))."""
        return np.column_stack([self.columns[n] for n in names])

    def slice(self, first: int, stop: int) -> Record:
        """Rows ``[first, stop)`` as a record of their own (a window)."""
        return Record({k: v[first:stop] for k, v in self.columns.items()}, self.dt, self.source)


def parse_column_map(text: str | None) -> dict[str, str]:
    """``"V=volts,I=amps"`` -> ``{"V": "volts", "I": "amps"}`` (canonical = file column).

    Example
    -------
    >>> parse_column_map("V=volts, I=amps")
    {'V': 'volts', 'I': 'amps'}
    """
    if not text:
        return {}
    out: dict[str, str] = {}
    for item in text.split(","):
        if "=" not in item:
            raise DataError(f"cannot read column mapping {item.strip()!r}; "
                            "write CANONICAL=FILE_COLUMN, e.g. V=volts")
        key, value = (s.strip() for s in item.split("=", 1))
        if not key or not value:
            raise DataError(f"empty name in column mapping {item.strip()!r}")
        out[key] = value
    return out


def check_time_base(t: ArrayLike, source: str = "record", tolerance: float = TIME_JITTER,
                    column: str = "t", *, resolution: float = 0.0) -> float:
    """Check that a time column increases with a uniform step; return the step.

    Parameters
    ----------
    t : array_like
        The time column. [s]
    source : str
        The file (or label) named in messages.
    tolerance : float
        Largest relative deviation of a sample interval from the median
        interval. [-]
    column : str
        The column's name, for messages.
    resolution : float
        How finely the time values were stored (a float32 column's spacing
        at its largest value): two rounded values differ from their true
        interval by up to this much, which the tolerance takes on top. [s]

    Returns
    -------
    float
        The sample interval: the median of the intervals (with a
        ``resolution``, the span over their number). [s]

    Raises
    ------
    DataError
        Fewer than two samples, a value that is not finite, an interval that is
        not positive ("not increasing at row k"), or a jitter beyond the
        tolerance ("not uniformly sampled"; the message gives the jitter, the
        largest relative deviation in %, and its row).

    Example
    -------
    >>> check_time_base([0.0, 0.25, 0.5, 0.75], "rig.csv")
    0.25
    >>> check_time_base([0.0, 0.25, 0.5, 0.80], "rig.csv")
    Traceback (most recent call last):
    ...
    condmon.errors.DataError: rig.csv: column 't' is not uniformly sampled: jitter 20 % \
(tolerance 0.1 %), interval 0.3 s at row 3 against 0.25 s elsewhere; 1 interval(s) \
beyond the tolerance, first at row 3 (resample first)
    """
    try:
        arr = np.asarray(t, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise DataError(f"{source}: column {column!r} is not numeric") from None
    if arr.size < 2:
        raise DataError(f"{source}: column {column!r} has {arr.size} sample(s); "
                        "a time base needs at least 2")
    if not np.isfinite(np.sum(arr)):   # (a sum overflows to inf for finite values only
        bad = np.flatnonzero(~np.isfinite(arr))   # beyond 1e308: no row then)
        if bad.size:
            raise DataError(f"{source}: column {column!r} has {bad.size} NaN/inf value(s), "
                            f"first at {row_text(int(bad[0]), source)}")
    with np.errstate(over="ignore", invalid="ignore"):
        dts = np.diff(arr)
    low, high = float(np.min(dts)), float(np.max(dts))
    if not low > 0:   # (also a NaN)
        k = int(np.flatnonzero(~(dts > 0))[0])
        raise DataError(f"{source}: column {column!r} is not increasing at row {k + 1} "
                        f"({float(arr[k]):.9g} then {float(arr[k + 1]):.9g})")
    dt = _median(dts)
    stated = f"tolerance {100 * tolerance:.3g} %"
    if resolution > 0.0:
        stated += f", plus the values' own resolution {resolution:.3g} s"
        tolerance += resolution / dt
    # the largest deviation is the longest or the shortest interval's (the same
    # arithmetic as each interval's below): every interval is looked at only
    # when one of them is beyond the tolerance
    if (high - dt) / dt <= tolerance and (dt - low) / dt <= tolerance:
        # rounded values: the span over the intervals is exact to resolution / n,
        # where the median interval keeps a rounding of up to the resolution
        return float(arr[-1] - arr[0]) / dts.size if resolution > 0.0 else dt
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        deviation = np.abs(dts - dt) / dt
    beyond = np.flatnonzero(~(deviation <= tolerance))
    if beyond.size:
        k = int(np.nanargmax(np.where(np.isnan(deviation), np.inf, deviation)))
        raise DataError(f"{source}: column {column!r} is not uniformly sampled: jitter "
                        f"{100 * deviation[k]:.3g} % ({stated}), "
                        f"interval {dts[k]:.6g} s at row {k + 1} against {dt:.6g} s elsewhere; "
                        f"{beyond.size} interval(s) beyond the tolerance, first at row "
                        f"{beyond[0] + 1} (resample first)")
    return float(arr[-1] - arr[0]) / dts.size if resolution > 0.0 else dt


def _time_resolution(df: pd.DataFrame | Columns, t: FloatArray) -> float:
    """How finely a frame's ``t`` was stored [s]: a float32 or float16
    column's spacing at its largest magnitude (float32 holds 16 s to 1.9 µs,
    0.19 % of a 1 ms interval); 0 for float64 and :class:`Columns`."""
    if isinstance(df, Columns) or not t.size:
        return 0.0
    dtype = df["t"].dtype
    if dtype not in (np.float32, np.float16):
        return 0.0
    return float(np.spacing(np.asarray(np.max(np.abs(t)), dtype=dtype)))


def validate_record(df: pd.DataFrame | Columns, required: Sequence[str],
                    optional: Sequence[str] = (), *, input_name: str | None = None,
                    inputs: Sequence[str] = (), min_samples: int = 20,
                    source: str | None = None) -> Record:
    """Check a record and return its columns as float64 arrays.

    Parameters
    ----------
    df : pandas.DataFrame or Columns
        The record; must hold a time column ``t`` [s].
    required : sequence of str
        Columns that must be present (besides ``t``).
    optional : sequence of str
        Columns validated and kept when present.
    input_name : str, optional
        The excitation input: refused if constant, warned if saturated.
    inputs : sequence of str
        The model's known inputs: the record is refused when every one of them
        it holds is constant (nothing excites the machine).
    min_samples : int
        Fewest samples accepted.
    source : str, optional
        Name used in messages (default ``df.attrs["source"]`` or "record").

    Returns
    -------
    Record

    Raises
    ------
    DataError
        Naming the source and the column.
    """
    src = source or str(df.attrs.get("source", "record"))
    names = ["t", *required]
    missing = [c for c in names if c not in df.columns]
    if missing:
        have = list(map(str, df.columns))
        # "t [s]", "omega (rad/s)": a name with its unit written beside it
        near = {m: c for m in missing for c in have
                if c.startswith(m) and c[len(m):].lstrip().startswith(("[", "("))}
        how = (f"their names carry units: --columns '{','.join(f'{m}={c}' for m, c in near.items())}'"
               f" (check each unit is the model's)" if near else
               f"map names with the record settings: {missing[0]}=FILE_COLUMN in --columns or "
               "[record.columns]")
        raise MissingColumnsError(
            f"{src}: missing column(s) {', '.join(repr(m) for m in missing)}; the record has "
            f"{have} ({how})", tuple(missing), tuple(have))
    names += [c for c in optional if c in df.columns and c not in names]
    if not isinstance(df, Columns) and not df.columns.is_unique:
        listed = list(map(str, df.columns))
        twice = [c for c in names if listed.count(c) > 1]
        if twice:
            raise DataError(f"{src}: the frame has {listed.count(twice[0])} columns named "
                            f"{twice[0]!r}; rename or drop all but one (condmon would not "
                            "know which to use)")
    n_rows = len(df)
    header = int(df.attrs.get("header_line", 1))
    cols: dict[str, FloatArray] = {}
    for name in names:
        arr = df[name] if isinstance(df, Columns) else _numeric_column(df, name, src)
        # the extremes first (two reductions): the positions only when they are bad
        lo, hi = (float(np.min(arr)), float(np.max(arr))) if arr.size else (0.0, 0.0)
        if -MAX_MAGNITUDE <= lo and hi <= MAX_MAGNITUDE:   # False for a NaN or an inf too
            cols[name] = arr
            continue
        bad_idx = np.flatnonzero(~np.isfinite(arr))
        if bad_idx.size:
            last_good = np.flatnonzero(np.isfinite(arr))
            if (last_good.size and np.all(bad_idx > last_good[-1])
                    and np.all(np.isnan(arr[bad_idx]))):
                tail = n_rows - int(last_good[-1]) - 1
                raise DataError(f"{src}: column {name!r} has no value in the record's last "
                                f"{tail} row(s), from {row_text(int(bad_idx[0]), src, header)}: values "
                                "missing at the end, or a column shorter than the others "
                                f"({last_good[-1] + 1} samples against {n_rows} rows); drop "
                                "those rows")
            raise DataError(f"{src}: column {name!r} has {bad_idx.size} NaN/inf value(s) "
                            "(an empty cell, NaN, inf or a spreadsheet error such as #DIV/0!), "
                            f"first at {row_text(int(bad_idx[0]), src, header)}")
        huge = np.flatnonzero(np.abs(arr) > MAX_MAGNITUDE)
        if huge.size:
            raise DataError(f"{src}: column {name!r} has {huge.size} value(s) beyond "
                            f"{MAX_MAGNITUDE:g} in magnitude ({row_text(int(huge[0]), src, header)}: {arr[huge[0]]:.6g}); "
                            "a corrupt or mis-scaled column?")
        cols[name] = arr
    if n_rows < min_samples:
        are = "samples are" if n_rows != 1 else "sample is"
        raise DataError(f"{src}: {n_rows} {are} too few; need at least {min_samples}")
    dt = check_time_base(cols["t"], src, resolution=_time_resolution(df, cols["t"]))
    excited = [c for c in dict.fromkeys((*([input_name] if input_name else []), *inputs))
               if c in cols]
    if excited and all(_constant(cols[c]) for c in excited):
        which = (f"column {excited[0]!r} is" if len(excited) == 1 else
                 f"columns {', '.join(map(repr, excited))} are")
        raise DataError(f"{src}: {which} constant: no excitation, nothing can be estimated"
                        + (f" ({excited[0]} = {cols[excited[0]][0]:g} throughout)"
                           if len(excited) == 1 else ""))
    if input_name is not None:
        u = cols[input_name]
        lo, hi = float(np.min(u)), float(np.max(u))
        span = hi - lo
        at_limit = np.mean((u >= hi - 1e-9 * span) | (u <= lo + 1e-9 * span))
        # A signal that only takes a few levels (a binary PRBS, steps) sits at its
        # extremes by design: saturation is a plateau on an otherwise varying input.
        if (SATURATION_SHARE < at_limit < 0.95
                and _distinct(u[: min(u.size, 20000)]) > 10):   # (the sort only when needed)
            warnings.warn(f"{src}: {100 * at_limit:.1f} % of column {input_name!r} sits at "
                          f"its extreme values ({lo:.4g}, {hi:.4g}): the drive saturates "
                          "and the linear model may be biased", DataWarning, stacklevel=2)
    return Record(cols, dt, src)


def _numeric_column(df: pd.DataFrame, name: str, src: str) -> FloatArray:
    """A DataFrame's column as float64, or the DataError naming its first
    value that is not a number. A ``t`` of time spans (``timedelta64``) is
    their seconds; of date-times, the seconds from the first."""
    import pandas as pd

    series = df[name]
    if name == "t" and pd.api.types.is_timedelta64_dtype(series.dtype):
        return np.asarray(series.dt.total_seconds().to_numpy(dtype=np.float64, na_value=np.nan),
                          dtype=np.float64)
    if name == "t" and pd.api.types.is_datetime64_any_dtype(series.dtype):
        from condmon.io.raw import time_to_seconds   # as the file readers take a date-time t

        seconds = time_to_seconds(series, src)
        if seconds is not None:
            return np.asarray(seconds[0].to_numpy(dtype=np.float64, na_value=np.nan),
                              dtype=np.float64)
    try:
        if pd.api.types.is_numeric_dtype(series.dtype) and not pd.api.types.is_bool_dtype(series.dtype):
            return np.asarray(series.to_numpy(dtype=np.float64, na_value=np.nan),
                              dtype=np.float64)
        return np.asarray(pd.to_numeric(series, errors="raise"), dtype=np.float64)
    except (ValueError, TypeError):
        bad = series[pd.to_numeric(series, errors="coerce").isna() & series.notna()]
        row = bad.index[0] if len(bad) else "?"
        raise DataError(f"{src}: column {name!r} is not numeric "
                        f"(row {row}: {series.loc[row]!r})") from None


def _median(x: FloatArray) -> float:
    """``np.median`` of finite values, to the bit, without the numpy.ma import
    np.median costs."""
    n = x.size
    part = np.partition(x, [(n - 1) // 2, n // 2])
    if n % 2:
        return float(part[n // 2])
    return float((part[n // 2 - 1] + part[n // 2]) / 2.0)


def _distinct(u: FloatArray) -> int:
    """How many distinct values a finite signal takes (``np.unique(u).size``
    without the numpy.ma import that np.unique costs)."""
    return int(np.count_nonzero(np.diff(np.sort(u)))) + 1 if u.size else 0


def _constant(u: FloatArray) -> bool:
    """Whether a signal does not move (relative to its size)."""
    return float(np.std(u)) <= 1e-12 * max(1.0, float(np.max(np.abs(u))))


def check_output_path(path: str | Path) -> Path:
    """``path`` once a record can be written there: a ``.csv`` or Parquet
    name in a folder that exists (told before any work is done for it).

    Example
    -------
    >>> check_output_path("no/such/folder/r.csv")
    Traceback (most recent call last):
    ...
    condmon.errors.DataError: no/such/folder/r.csv: the folder 'no/such/folder' does not exist; create it first
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in (".csv", ".parquet", ".pq"):
        raise DataError(f"{p}: unknown file type {suffix!r}; allowed: .csv, .parquet")
    if not p.parent.is_dir():
        raise DataError(f"{p}: the folder {str(p.parent)!r} does not exist; create it first")
    return p


def write_record(df: pd.DataFrame, path: str | Path) -> Path:
    """Write a record as CSV or Parquet, chosen by the file's suffix.

    Example
    -------
    >>> import tempfile
    >>> import pandas as pd
    >>> p = write_record(pd.DataFrame({"t": [0.0, 0.1]}), Path(tempfile.mkdtemp()) / "r.csv")
    >>> p.suffix
    '.csv'
    """
    import pandas as pd

    p = check_output_path(path)
    suffix = p.suffix.lower()
    try:
        if suffix == ".csv":
            df.to_csv(p, index=False)
        else:
            df.to_parquet(p, index=False)
    except OSError as err:
        raise DataError(f"{p}: cannot be written: {err.strerror or err}") from None
    return p


def row_text(i: int, src: str = "", header: int = 1) -> str:
    """A 0-based sample index said as a user looks it up: the frame's row and,
    in a text file (``src`` ends .csv, .tsv or .txt), the line it is on
    (``header``: the header's line, after comments or Excel's ``sep=``).

    Example
    -------
    >>> row_text(1500, "rig.csv"), row_text(7, "rig.mat")
    ('row 1500 (from 0; line 1502 of a file with a header line)', 'row 7 (from 0)')
    """
    if not src.lower().endswith((".csv", ".tsv", ".txt")):
        return f"row {i} (from 0)"
    if header == 1:
        return f"row {i} (from 0; line {i + 2} of a file with a header line)"
    return f"row {i} (from 0; line {i + header + 1} of the file, its header on line {header})"
