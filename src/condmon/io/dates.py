"""Test dates: ISO 8601 text a user gives, and dates read back from files or a
database, as aware UTC datetimes."""

from __future__ import annotations

import re
from datetime import datetime, timedelta, timezone
from typing import TYPE_CHECKING, Any

import numpy as np

from condmon.errors import DataError

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["as_utc", "parse_date"]

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
