"""Delimited text records: CSV with ``,`` or ``;``, decimal point or comma, tab text.

The separator and the decimal mark are told from the header and the first
lines, never assumed: each interpretation (``,`` with ``.``, or with ``,``
inside quoted fields; ``;`` with ``,`` or ``.``; tab with ``.`` or ``,``) is
tried on them, and the one whose rows all have the header's number of fields
and whose columns are all numbers (or date-times) wins. Two interpretations
that fit equally well but read different numbers are
refused rather than guessed.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from condmon.errors import DataError
from condmon.io.raw import RawRecord, time_to_seconds

__all__ = ["Dialect", "sniff_dialect", "read_delimited"]

#: Bytes of the file read to tell the dialect.
SNIFF_BYTES = 65536
#: Lines (header included) on which the dialect is told.
SNIFF_LINES = 50
#: Excel's first line naming the separator of a CSV it writes or reads (``sep=;``).
#: Excel's error cells, in its English and German versions, beside pandas' own
#: missing-value marks: a missing value, not text that makes a column not numeric.
_EXCEL_NA = ["#NV", "#N/A", "#WERT!", "#VALUE!", "#DIV/0!", "#BEZUG!", "#REF!", "#ZAHL!",
             "#NUM!"]
_EXCEL_SEP = re.compile(r"\A[ \t]*sep=([,;\t])[ \t]*\r?\n", re.IGNORECASE)
_NAMES = {",": "comma", ";": "semicolon", "\t": "tab"}
#: Every digit as written: before pandas 3.1 the parser's default may be off in the
#: last bit (1e-12 relative), its round-trip one is exact; from 3.1 on every
#: parser is exact and the option is deprecated.
_EXACT: dict[str, Any] = ({} if tuple(int(v) for v in pd.__version__.split(".")[:2]) >= (3, 1)
                          else {"float_precision": "round_trip"})


@dataclass(frozen=True)
class Dialect:
    """How a delimited text file is written.

    Attributes
    ----------
    sep : str
        Field separator: ``","``, ``";"`` or ``"\\t"``.
    decimal : str
        Decimal mark: ``"."`` or ``","``.
    encoding : str
        ``"utf-8-sig"``, or ``"latin-1"`` when the bytes are not UTF-8.
    skip : int
        Lines before the header: Excel's ``sep=;`` line, and comment lines
        starting with ``#``.
    """

    sep: str
    decimal: str
    encoding: str = "utf-8-sig"
    skip: int = 0

    def describe(self) -> str:
        """``"semicolon-separated, decimal comma"``."""
        mark = "comma" if self.decimal == "," else "point"
        return f"{_NAMES[self.sep]}-separated, decimal {mark}"


def _candidates(suffix: str) -> list[tuple[str, str]]:
    """Interpretations in order of preference for a tie."""
    tab = [("\t", "."), ("\t", ",")]
    text = [(",", "."), (";", ","), (";", "."), (",", ",")]  # the last: "1,5" quoted
    return tab + text if suffix in (".tsv", ".txt") else text + tab


def _typed_columns(frame: pd.DataFrame) -> int:
    """Columns that are all numbers or all date-times."""
    n = 0
    for name in frame.columns:
        col = frame[name]
        if pd.api.types.is_numeric_dtype(col.dtype) and not pd.api.types.is_bool_dtype(col.dtype):
            n += 1
        elif _is_number(str(next(iter(col.dropna()), "x")), "."):
            continue  # text that is a number under the other decimal mark: no date-time
        else:
            try:
                n += time_to_seconds(col) is not None
            except DataError:
                n += 1  # date-times, though with an ambiguous day/month order
    return n


def _is_number(text: str, decimal: str) -> bool:
    try:
        float(text.strip().replace(decimal, ".") if decimal == "," else text.strip())
    except ValueError:
        return False
    return True


def sniff_dialect(text: str, source: Path | str, suffix: str = ".csv",
                  encoding: str = "utf-8-sig") -> Dialect:
    """Tell separator and decimal mark from the first lines of a file.

    Parameters
    ----------
    text : str
        The header line and the first data lines.
    source : Path or str
        The file, for messages.
    suffix : str
        ``.csv`` prefers comma, then semicolon, then tab on a tie; ``.tsv`` and
        ``.txt`` prefer tab.
    encoding : str
        Carried into the returned dialect.

    Returns
    -------
    Dialect

    Raises
    ------
    DataError
        No interpretation gives rows of the header's width, the first line is
        numbers rather than column names, or two interpretations read different
        numbers equally well.

    Example
    -------
    >>> sniff_dialect("t;V\\n0,000;1,25\\n0,001;3,5\\n", "rig.csv").describe()
    'semicolon-separated, decimal comma'
    >>> sniff_dialect("t,V\\n0.000,1.25\\n", "rig.csv").describe()
    'comma-separated, decimal point'
    """
    lines = [ln for ln in text.splitlines() if ln.strip()][:SNIFF_LINES]
    if not lines:
        raise DataError(f"{source}: the file is empty")
    scored: list[tuple[tuple[bool, bool, int, int], int, Dialect, pd.DataFrame]] = []
    widths: dict[str, tuple[int, int, int]] = {}
    ranked = list(enumerate(_candidates(suffix)))
    # separators the header holds first: a reading by one of them, if any works,
    # outranks every other (the score's second term), so the others need no parse
    first = [c for c in ranked if c[1][0] in lines[0]]
    for rank, (sep, decimal) in first + [c for c in ranked if c not in first]:
        if scored and sep not in lines[0]:
            break
        rows = list(csv.reader(lines, delimiter=sep))
        width = len(rows[0])
        bad = next((k for k, r in enumerate(rows[1:], start=2) if len(r) != width), None)
        if bad is not None:
            widths[sep] = (width, len(rows[bad - 1]), bad)
            continue
        try:
            sample = pd.read_csv(io.StringIO("\n".join(lines)), sep=sep, decimal=decimal,
                                 na_values=_EXCEL_NA,
                                 skipinitialspace=True, **_EXACT)
        except (ValueError, pd.errors.ParserError):
            continue
        typed = _typed_columns(sample)
        score = (typed == width, sep in lines[0], typed, width)
        scored.append((score, -rank, Dialect(sep, decimal, encoding), sample))
    scored.sort(key=lambda s: (s[0], s[1]), reverse=True)
    if not scored or (len(lines) > 1 and scored[0][0][2] == 0
                      and (widths or scored[0][0][3] == 1)):
        # no reading gives a number: rows of another width than the header, or one
        # column of text (spaces as separators?)
        if widths:
            sep, (width, got, line) = next(iter(widths.items()))
            why = f"with {_NAMES[sep]}s line {line} has {got} fields but the header has {width}"
        else:
            why = "no comma, semicolon or tab splits the lines into numeric columns"
        raise DataError(f"{source}: cannot tell the separator: {why} "
                        "(expected comma, semicolon or tab separated columns)")
    best = scored[0]
    header = next(csv.reader(lines[:1], delimiter=best[2].sep))
    if len(lines) > 1 and all(_is_number(h, best[2].decimal) for h in header):
        raise DataError(f"{source}: the first line holds numbers, not column names; "
                        f"add a header row (e.g. t{best[2].sep}V{best[2].sep}I{best[2].sep}omega)")
    for other in scored[1:]:
        if other[0] == best[0] and not other[3].equals(best[3]):
            raise DataError(f"{source}: ambiguous format: read as {best[2].describe()} "
                            f"or as {other[2].describe()} gives different numbers; "
                            "write it with a decimal point and comma separators")
    return best[2]


def _read_head(path: Path) -> tuple[str, str]:
    """The first bytes decoded, and the encoding that decodes them."""
    with path.open("rb") as fh:
        head = fh.read(SNIFF_BYTES)
        more = bool(fh.read(1))
    if more and b"\n" in head:
        head = head[: head.rindex(b"\n") + 1]
    try:
        return head.decode("utf-8-sig"), "utf-8-sig"
    except UnicodeDecodeError:
        return head.decode("latin-1"), "latin-1"


def read_delimited(path: Path) -> RawRecord:
    """Read a delimited text record, its dialect told from its first lines.

    Parameters
    ----------
    path : Path
        ``.csv``, ``.tsv`` or ``.txt`` with a header row.

    Returns
    -------
    RawRecord
        Columns under the header's names (surrounding spaces removed).

    Raises
    ------
    DataError
        See :func:`sniff_dialect`; pandas' parser errors are left to the caller.

    Example
    -------
    >>> import tempfile
    >>> d = tempfile.TemporaryDirectory()
    >>> p = Path(d.name) / "rig.txt"
    >>> _ = p.write_text("t\\tV\\n0,0\\t1,5\\n0,5\\t2,5\\n")
    >>> read_delimited(p).frame["V"].tolist()
    [1.5, 2.5]
    >>> d.cleanup()
    """
    text, encoding = _read_head(path)
    said = _EXCEL_SEP.match(text)
    if said is not None:  # Excel's "sep=;" line: the separator, said before the header
        text = text[said.end():]
    # a logger's notes above the header ("# rig 7, operator jo"): comments, as
    # numpy.loadtxt and most rigs take a leading "#"
    notes = 0
    while text.lstrip(" \t").startswith("#"):
        end = text.find("\n")
        text = text[end + 1:] if end >= 0 else ""
        notes += 1
    dialect = sniff_dialect(text, path, path.suffix.lower(), encoding)
    if said is not None:
        if said.group(1) != dialect.sep:
            raise DataError(f"{path}: line 1 says sep={said.group(1)}, but the lines after it "
                            f"read as {dialect.describe()}")
    skip = notes + (said is not None)
    if skip:
        dialect = Dialect(dialect.sep, dialect.decimal, encoding, skip=skip)
    header = next(csv.reader([text.splitlines()[0] if text else ""], delimiter=dialect.sep), [])
    names = [h.strip() for h in header]
    twice = sorted({n for n in names if n and names.count(n) > 1})
    if twice:
        raise DataError(f"{path}: the header names column {twice[0]!r} more than once; "
                        "rename one (condmon would not know which to use)")
    frame = _parse(path, dialect)
    if dialect.sep != "," and _misread(frame, dialect.decimal):
        # the first lines held no decimal mark, later ones the other: read again
        other = Dialect(dialect.sep, "." if dialect.decimal == "," else ",", encoding,
                        dialect.skip)
        alt = _parse(path, other)
        if _typed_columns(alt) > _typed_columns(frame):
            frame = alt
    # a separator at the end of every line (a spreadsheet's export) makes an
    # empty column with no name: not a column of the record
    empty = [c for c in frame.columns if not c.strip() or c.startswith("Unnamed: ")]
    empty = [c for c in empty if bool(frame[c].isna().all())]
    if empty:
        frame = frame.drop(columns=empty)
    if skip:
        frame.attrs["header_line"] = skip + 1   # for the lines messages name
    return RawRecord(frame)


def _misread(frame: pd.DataFrame, decimal: str) -> bool:
    """A text column that would be all numbers with the other decimal mark."""
    for name in frame.columns:
        col = frame[name]
        if pd.api.types.is_numeric_dtype(col.dtype):
            continue
        text = col.dropna().astype(str).str.strip()
        if decimal == ".":
            text = text.str.replace(",", ".", regex=False)
        if not text.empty and bool(pd.to_numeric(text, errors="coerce").notna().all()):
            return True
    return False


def _parse(path: Path, dialect: Dialect) -> pd.DataFrame:
    frame: pd.DataFrame = pd.read_csv(path, sep=dialect.sep, decimal=dialect.decimal,
                                      encoding=dialect.encoding, skipinitialspace=True,
                                      skiprows=dialect.skip, na_values=_EXCEL_NA,
                                      low_memory=False, **_EXACT)
    frame.columns = [str(c).strip() for c in frame.columns]
    return frame
