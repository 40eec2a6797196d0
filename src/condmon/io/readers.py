"""Reading records from the files real rigs write.

:func:`read_record` chooses the reader by the file's suffix, applies the column
mapping, turns a date-time time column into seconds and returns a DataFrame
under canonical column names, every format alike:

========================  =====================================================
suffix                    read as
========================  =====================================================
``.csv``                  comma or semicolon separated, decimal point or comma
                          (told from the header and the first lines)
``.tsv``, ``.txt``        tab separated (decimal point or comma)
``.parquet``, ``.pq``     Apache Parquet
``.mat``                  MATLAB v4/v5/v7 and v7.3 (HDF5): vectors as columns,
                          1x1 variables in ``attrs["constants"]``
``.tdms``                 LabVIEW TDMS: channels as columns, ``t`` from the
                          waveform properties when no time channel exists
========================  =====================================================

Every problem is a :class:`~condmon.errors.DataError` of one line naming the
file (and the column or variable): the parsers' own exceptions never reach the
caller.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from condmon.errors import DataError, MissingColumnsError
from condmon.io.raw import RawRecord, one_line, time_to_seconds
from condmon.io.size import check_record_size

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["READABLE_SUFFIXES", "check_record_path", "read_record"]

#: File suffixes :func:`read_record` reads (case-insensitive).
READABLE_SUFFIXES = (".csv", ".parquet", ".pq", ".txt", ".tsv", ".mat", ".tdms")
_KINDS = {".csv": "CSV", ".txt": "text", ".tsv": "text", ".parquet": "Parquet",
          ".pq": "Parquet", ".mat": "MATLAB", ".tdms": "TDMS"}


def read_record(path: str | Path, columns: Mapping[str, str] | None = None) -> pd.DataFrame:
    """Read a record file and rename its columns to canonical names.

    Parameters
    ----------
    path : str or Path
        ``.csv`` (``,`` or ``;`` separated, decimal point or comma), ``.tsv`` or
        ``.txt`` (tab separated), ``.parquet``/``.pq``, ``.mat`` (MATLAB, any
        version) or ``.tdms`` (LabVIEW). Text files need a header row.
    columns : mapping, optional
        ``{canonical: column in the file}``, e.g. ``{"t": "time", "V": "vir"}``;
        for a MATLAB file the column is the variable, for TDMS the channel
        (``group/channel`` when two groups share the channel's name).

    Returns
    -------
    pandas.DataFrame
        The columns, with ``attrs["source"]`` the path. A time column ``t`` of
        date-times (or a single date-time column, when nothing is mapped to
        ``t``) is turned into seconds from its first sample [s], its absolute
        start kept in ``attrs["start_time"]`` (ISO 8601), as is a TDMS file's
        ``wf_start_time``. A MATLAB file's 1x1 variables are in
        ``attrs["constants"]`` (name -> value).

    Raises
    ------
    DataError
        The file is missing, of an unknown type or unreadable, a mapped column
        is not in it, or it holds no usable column; one line naming the file.

    Warns
    -----
    DataWarning
        MATLAB variables or TDMS channels left out (another length, a matrix).

    Example
    -------
    >>> import tempfile
    >>> d = tempfile.TemporaryDirectory()
    >>> p = Path(d.name) / "rig.csv"
    >>> _ = p.write_text("time;volts\\n2026-11-23 10:00:00.000;1,5\\n"
    ...                  "2026-11-23 10:00:00.001;2,5\\n")
    >>> df = read_record(p, {"t": "time", "V": "volts"})
    >>> df["t"].tolist(), df["V"].tolist(), df.attrs["start_time"]
    ([0.0, 0.001], [1.5, 2.5], '2026-11-23T10:00:00')
    >>> d.cleanup()
    """
    p = check_record_path(path)
    suffix = p.suffix.lower()
    mapping = dict(columns or {})
    twice = sorted({f for f in mapping.values() if list(mapping.values()).count(f) > 1})
    if twice:
        takers = [k for k, v in mapping.items() if v == twice[0]]
        raise DataError(f"{p}: the column mapping gives the file's column {twice[0]!r} to "
                        f"{' and '.join(map(repr, takers))}; a file column reads as one "
                        "model column (map the others to other columns)")
    try:
        check_record_size(p, suffix)
        return _finish(_read_raw(p, suffix, mapping.get("t")), p, mapping)
    except DataError:
        raise
    except MemoryError:
        raise DataError(f"{p}: the record does not fit in memory; shorten it or lower "
                        "[records] max_samples of condmon/data/limits.toml") from None
    except Exception as err:  # parser errors of every kind become one clear line
        raise DataError(f"{p}: cannot read as a {_KINDS[suffix]} file: {one_line(err)}") from None


def check_record_path(path: str | Path) -> Path:
    """``path`` as a :class:`~pathlib.Path` once it names a non-empty file of
    a readable type: what can be told of a record without reading it.

    Raises
    ------
    DataError
        The file is missing, not a file, empty or of an unknown type.

    Example
    -------
    >>> check_record_path("rig.xlsx")
    Traceback (most recent call last):
    ...
    condmon.errors.DataError: rig.xlsx: file not found
    """
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: file not found")
    suffix = p.suffix.lower()
    if suffix not in READABLE_SUFFIXES:
        raise DataError(f"{p}: unknown file type {suffix!r}; allowed: "
                        f"{', '.join(READABLE_SUFFIXES)}")
    if not p.is_file():
        raise DataError(f"{p}: not a file")
    if p.stat().st_size == 0:
        raise DataError(f"{p}: the file is empty")
    return p


def _read_raw(p: Path, suffix: str, time_column: str | None) -> RawRecord:
    import pandas as pd

    if suffix in (".csv", ".txt", ".tsv"):
        from condmon.io.delimited import read_delimited

        return read_delimited(p)
    if suffix == ".mat":
        from condmon.io.matlab import read_mat

        return read_mat(p)
    if suffix == ".tdms":
        from condmon.io.tdms import read_tdms

        return read_tdms(p, time_column)
    return RawRecord(_read_parquet(p))


def _read_parquet(p: Path) -> pd.DataFrame:
    """A Parquet file as a DataFrame, the Arrow table's buffers handed over
    column by column as they are converted (``self_destruct``): a long record
    peaks at about one copy of itself, not two.

    Arrow's memory pool keeps the pages of the buffers it frees (the file's
    bytes, read ahead before they are decoded): they are handed back once the
    frame is made. A 1-hour record at 1 kHz (200 MB) kept about 220 MB more
    resident for the rest of its estimate without it."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    names = pq.read_schema(p).names
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:  # Arrow's own message names its internal fields, not the file's
        raise DataError(f"{p}: the file has {names.count(twice[0])} columns named "
                        f"{twice[0]!r}; rename one (condmon would not know which to use)")
    table = pq.read_table(p)
    frame: pd.DataFrame = table.to_pandas(self_destruct=True, split_blocks=True)
    del table
    pa.default_memory_pool().release_unused()
    return frame


def _is_time_column(values: pd.Series, source: str) -> bool:
    import pandas as pd

    if pd.api.types.is_datetime64_any_dtype(values.dtype):
        return True
    if not (pd.api.types.is_object_dtype(values.dtype)
            or pd.api.types.is_string_dtype(values.dtype)):
        return False
    try:
        return time_to_seconds(values.head(20), source) is not None
    except DataError:
        return True  # date-times all the same: the full conversion says what is wrong


def _finish(raw: RawRecord, p: Path, mapping: dict[str, str]) -> pd.DataFrame:
    """Mapping, time column, attrs: the same for every format."""
    df = raw.frame
    df.columns = [str(c) for c in df.columns]
    if mapping:
        missing = [f for f in mapping.values() if f not in df.columns]
        if missing:
            why = "; ".join(f"{m!r} was left out: {raw.ignored[m]}"
                            for m in missing if m in raw.ignored)
            raise MissingColumnsError(
                f"{p}: column mapping names {missing} not in the file; columns are "
                f"{list(df.columns)}" + (f" ({why})" if why else ""), tuple(missing),
                tuple(df.columns))
        # a mapped column replaces a file column that already has the canonical name
        shadowed = [k for k in mapping if k in df.columns and k not in mapping.values()]
        df = df.drop(columns=shadowed).rename(columns={v: k for k, v in mapping.items()})
    start = raw.start_time
    if "t" not in df.columns:
        stamps = [c for c in df.columns if _is_time_column(df[c], str(p))]
        if len(stamps) == 1:
            df = df.rename(columns={stamps[0]: "t"})
    if "t" in df.columns:
        converted = time_to_seconds(df["t"], str(p))
        if converted is not None:
            df["t"] = converted[0].to_numpy()
            start = converted[1] or None
    df.attrs["source"] = str(p)
    if raw.constants is not None:
        df.attrs["constants"] = dict(raw.constants)
    if start:
        df.attrs["start_time"] = start
    return df
