"""Test dates: ISO 8601 text a user gives, and dates read back from files or a
database, as aware UTC datetimes."""

from __future__ import annotations

import functools
import re
from datetime import datetime, timedelta, timezone
from typing import TYPE_CHECKING, Any

import numpy as np

from condmon.errors import ConfigError, DataError

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["as_utc", "parse_date", "name_time_format", "time_in_name"]

_ISO = re.compile(r"\d{4}-\d{2}-\d{2}([T ][0-9:.]+)?(Z|[+-]\d{2}:?\d{2})?")


def as_utc(value: Any) -> datetime | None:
    """A stored or given date as an aware UTC datetime (None and NaT give None).

    A naive date is taken as UTC (SQLite returns naive datetimes: they were
    written as UTC).

    Example
    -------
    >>> as_utc("2026-03-01 12:00").isoformat()
    '2026-03-01T12:00:00+00:00'
    """
    import pandas as pd

    if value is None or (isinstance(value, float) and np.isnan(value)):
        return None
    ts = pd.Timestamp(value)
    if pd.isna(ts):
        return None
    if ts.tzinfo is None:
        ts = ts.tz_localize("UTC")
    return ts.tz_convert("UTC").to_pydatetime()


def parse_date(text: str | datetime | None, what: str = "--date") -> datetime | None:
    """A test date from ISO 8601 text (``2026-03-01`` or ``2026-03-01T14:30``;
    without a zone it is UTC), as an aware UTC datetime.

    Parameters
    ----------
    text : str, datetime or None
        The date; None gives None.
    what : str
        What the date is, for the error message (an option, a file's field).

    Raises
    ------
    DataError
        Not an ISO 8601 date between the years 1900 and 2200 (``01/03/2026``
        is refused, not guessed), or more than a day in the future.

    Example
    -------
    >>> parse_date("2026-03-01T14:30").isoformat()
    '2026-03-01T14:30:00+00:00'
    """
    if text is None:
        return None
    import pandas as pd

    if isinstance(text, datetime):
        return _not_future(as_utc(text), text, what)
    raw = str(text).strip()
    ts: Any = None
    if _ISO.fullmatch(raw):
        try:
            ts = pd.Timestamp(raw)
        except (ValueError, TypeError):
            ts = None
    if ts is None or pd.isna(ts) or not 1900 <= ts.year <= 2200:
        raise DataError(f"{what}: {text!r} is not a date; give ISO 8601, e.g. 2026-03-01 or "
                        "2026-03-01T14:30 (UTC unless a zone is given)")
    return _not_future(as_utc(ts), text, what)


def _not_future(when: datetime | None, given: object, what: str) -> datetime | None:
    """``when``, unless it is more than a day ahead of this machine's clock: a
    test cannot have been run then, and it would stay every trend's latest."""
    now = datetime.now(timezone.utc)
    if when is not None and when > now + timedelta(days=1):
        raise DataError(f"{what}: {given!s} is in the future (it is {now:%Y-%m-%d %H:%M} UTC "
                        "here); give the date the test was run")
    return when


# strptime directives and the text each may match in a file name. Written by
# hand: ``time.strptime`` parses a whole string only, and a file name holds the
# time among other text ("Base_000_12_508_9-11-2019-8-55-09 AM.txt").
_DIRECTIVES = {
    "Y": r"\d{4}", "y": r"\d{2}", "m": r"\d{1,2}", "d": r"\d{1,2}", "H": r"\d{1,2}",
    "I": r"\d{1,2}", "M": r"\d{1,2}", "S": r"\d{1,2}", "f": r"\d{1,6}", "j": r"\d{1,3}",
    "p": r"(?:AM|PM|am|pm)", "b": r"[A-Za-z]{3}", "B": r"[A-Za-z]{3,9}", "%": "%",
}
#: Directives a start time in a file name needs: a date and a time of day.
_NEEDED = (("Y", "y"), ("m", "b", "B", "j"), ("H", "I"))


def name_time_format(fmt: Any, where: str) -> str:
    """Check a ``strptime`` format of a start time written in file names.

    It needs a year, a month (or day of the year), an hour and only the
    directives ``%Y %y %m %d %H %I %M %S %f %j %p %b %B %%``.

    Raises
    ------
    ConfigError
        Naming ``where``: not text, an unknown directive, or no year, month
        or hour.

    Example
    -------
    >>> name_time_format("%m-%d-%Y-%I-%M-%S %p", "rig.toml[record]")
    '%m-%d-%Y-%I-%M-%S %p'
    """
    if not isinstance(fmt, str) or not fmt.strip():
        raise ConfigError(f"{where} must be a strptime format, e.g. \"%Y%m%d-%H%M%S\"")
    used = re.findall(r"%(.)", fmt)
    bad = [d for d in used if d not in _DIRECTIVES]
    if bad or fmt.count("%") != len(used) + sum(d == "%" for d in used):
        raise ConfigError(f"{where}: %{bad[0] if bad else ''} is not a directive a file name's "
                          f"time may use; allowed: {' '.join('%' + d for d in _DIRECTIVES)}")
    missing = [" or ".join("%" + d for d in group) for group in _NEEDED
               if not set(group) & set(used)]
    if missing:
        raise ConfigError(f"{where}: {fmt!r} has no {missing[0]}: a start time needs a year, "
                          "a month and an hour")
    return fmt


@functools.lru_cache(maxsize=16)
def _name_pattern(fmt: str) -> re.Pattern[str]:
    """Where ``fmt``'s text may start in a name: each directive's digits or
    letters, the rest as written (overlapping matches, by a lookahead)."""
    parts = re.split(r"(%.)", fmt)
    pattern = "".join(_DIRECTIVES[p[1]] if len(p) == 2 and p[0] == "%" else re.escape(p)
                      for p in parts if p)
    return re.compile(f"(?=({pattern}))")


def time_in_name(name: str, fmt: str) -> datetime | None:
    """The start time written in a file's name in ``strptime`` format ``fmt``,
    as an aware UTC datetime (a time without a zone is UTC, as every date
    condmon reads); None when the name holds none.

    Example
    -------
    >>> time_in_name("Base_000_12_508_9-11-2019-8-55-09 AM.txt",
    ...              "%m-%d-%Y-%I-%M-%S %p").isoformat()
    '2019-09-11T08:55:09+00:00'
    >>> time_in_name("record.csv", "%Y%m%d-%H%M%S") is None
    True
    """
    for match in _name_pattern(fmt).finditer(name):
        try:
            when = datetime.strptime(match.group(1), fmt)
        except ValueError:
            continue
        return when.replace(tzinfo=timezone.utc) if when.tzinfo is None else as_utc(when)
    return None
