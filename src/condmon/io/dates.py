"""Test dates: ISO 8601 text a user gives, and dates read back from files or a
database, as aware UTC datetimes."""

from __future__ import annotations

import re
from datetime import datetime
from typing import Any

import numpy as np
import pandas as pd

from condmon.errors import DataError

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
        Not an ISO 8601 date between the years 1900 and 2200: ``01/03/2026``
        is refused, not guessed.

    Example
    -------
    >>> parse_date("2026-03-01T14:30").isoformat()
    '2026-03-01T14:30:00+00:00'
    """
    if text is None or isinstance(text, datetime):
        return as_utc(text)
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
    return as_utc(ts)
