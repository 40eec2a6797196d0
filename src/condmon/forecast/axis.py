"""A unit's checks on one axis: tests counted, days, operating hours or cycles.

A forecast counts what the checks give: the unit's cycles when every check
stands at one (imported values per charge cycle), else operating hours when
every check gives them, else days when every check is dated, else the checks themselves
(:func:`forecast_axis`); :func:`parameter_series` reads one parameter's
change series on that axis from a unit's history.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from condmon.forecast.degradation import MIN_TESTS
from condmon.monitor.baseline import Baseline

__all__ = ["Axis", "Series", "forecast_axis", "in_test_order", "parameter_series"]

#: The farthest crossing given a date. [d]
_MAX_DAYS = 36525.0

#: One parameter's change series: x [test (or d)], change [%], each test's
#: standard error and the baseline's spread [% of the baseline mean].
Series = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float]


@dataclass(frozen=True)
class Axis:
    """What a unit's forecasts count, and where each check stands on it.

    Attributes
    ----------
    by : {"tests", "days", "hours", "cycles"}
        Checks counted, days since the first check, or the unit's operating
        hours (cycles) since the first check.
    dates : Series
        Each check's test date (NaT: unknown), by test id.
    hours : Series
        Each check's operating hours (NaN: not given), by test id. [h]
    note : str or None
        Why the forecast does not count hours (or days) that some checks give.
    """

    by: str
    dates: pd.Series
    hours: pd.Series
    note: str | None = None
    cycles: pd.Series | None = None

    def values(self, rows: pd.Index) -> NDArray[np.float64]:
        """``x`` of the checks ``rows`` (a subset of the checks, in order):
        their count from 1, or the days (hours) since the first check.
        [test (or d, h)]"""
        if self.by == "tests":
            return np.arange(1.0, len(rows) + 1.0)
        if self.by == "days":
            days = (self.dates[rows] - self.dates.iloc[0]).dt.total_seconds() / 86400.0
            return np.asarray(days.to_numpy(), dtype=np.float64)
        if self.by == "cycles" and self.cycles is not None:
            return np.asarray((self.cycles[rows] - self.cycles.iloc[0]).to_numpy(),
                              dtype=np.float64)
        return np.asarray((self.hours[rows] - self.hours.iloc[0]).to_numpy(), dtype=np.float64)

    @property
    def dated(self) -> bool:
        """Every check carries a date, in order, none twice."""
        return _increasing(self.dates)

    def pace_note(self, row: Any, ahead: float) -> str:
        """For hours and cycles: the date at the pace of the latest quarter of
        the dated checks, where it differs from the whole history's by more
        than a quarter of the time ahead ("" otherwise): a unit whose use
        changed is due sooner or later than its history's mean pace says.
        ``ahead`` in the axis' unit [h or cycles].

        Example
        -------
        >>> d = pd.Series(pd.to_datetime(["2026-01-01", "2026-01-31", "2026-03-02",
        ...                               "2026-03-03", "2026-03-04"]))
        >>> c = pd.Series([1.0, 2.0, 3.0, 13.0, 23.0])   # one a month, then ten a day
        >>> Axis("cycles", d, pd.Series([np.nan] * 5), None, c).pace_note(4, 20.0)[-34:]
        '(10 cycles a day) it is 2026-03-06'
        """
        whole = self.date_after(row, ahead)
        count = self.hours if self.by == "hours" else self.cycles
        if whole is None or count is None or self.by not in ("hours", "cycles"):
            return ""
        n = len(self.dates)
        k = max(n - max(n // 4, 2), 0)
        span_n = float(count.iloc[-1] - count.iloc[k])
        span_d = (self.dates.iloc[-1] - self.dates.iloc[k]).total_seconds() / 86400.0
        if not (span_n > 0 and span_d > 0):
            return ""
        recent = ahead * span_d / span_n
        days = (pd.Timestamp(whole) - self.dates[row]).total_seconds() / 86400.0
        if abs(recent - days) <= 0.25 * max(days, recent) or recent >= _MAX_DAYS:
            return ""
        per = "h" if self.by == "hours" else "cycles"
        mean = ahead / days if days > 0 else math.nan
        date = (self.dates[row] + pd.Timedelta(days=recent)).date()
        return (f"the date is at the history's mean pace ({mean:.3g} {per} a day); at its "
                f"latest {n - k} checks' pace ({span_n / span_d:.3g} {per} a day) it is {date}")

    def date_after(self, row: Any, ahead: float) -> str | None:
        """The date ``ahead`` days (hours, cycles) after check ``row``: for
        hours and cycles, at the unit's usage over its dated checks [h or
        cycles per day, several a day allowed]; None when not dated (tests),
        or beyond a century."""
        if self.by == "tests" or not ahead >= 0:
            return None
        days = ahead
        if self.by in ("hours", "cycles"):
            count = self.hours if self.by == "hours" else self.cycles
            if count is None or not (bool(self.dates.notna().all())
                                     and bool(self.dates.is_monotonic_increasing)):
                return None
            span_n = float(count.iloc[-1] - count.iloc[0])
            span_d = (self.dates.iloc[-1] - self.dates.iloc[0]).total_seconds() / 86400.0
            if not (span_n > 0 and span_d > 0):
                return None
            days = ahead * span_d / span_n
        elif not self.dated:
            return None
        if days >= _MAX_DAYS:   # a crossing beyond a century is no date (nor a timestamp)
            return None
        return str((self.dates[row] + pd.Timedelta(days=days)).round("s").isoformat())


def in_test_order(checks: pd.DataFrame) -> pd.DataFrame:
    """The checks in the order they were tested: by test date when every check
    carries one (a record checked late goes where it was tested; checks of
    one date keep the order they were stored in), else as stored.

    Example
    -------
    >>> c = pd.DataFrame({"test_date": ["2026-09-10", "2026-09-30", "2026-09-20"]},
    ...                  index=[5, 6, 7])
    >>> list(in_test_order(c).index), list(in_test_order(c.iloc[:2]).index)
    ([5, 7, 6], [5, 6])
    """
    if "test_date" not in checks or len(checks) < 2:
        return checks
    dates = pd.to_datetime(checks["test_date"], utc=True, errors="coerce")
    if bool(dates.isna().any()) or bool(dates.is_monotonic_increasing):
        return checks
    return checks.iloc[np.argsort(dates.to_numpy(), kind="stable")]


def _increasing(values: pd.Series) -> bool:
    return bool(values.notna().all()) and bool(values.is_monotonic_increasing) \
        and values.nunique() == len(values)


def forecast_axis(checks: pd.DataFrame) -> Axis:
    """What a unit's forecasts count: the one place the x axis is chosen.

    The unit's cycles when every check stands at one (the ``cycle`` column,
    increasing, none twice: imported values per charge cycle). Operating
    hours when every check carries them (the ``hours`` column),
    increasing, none twice: wear follows use. Else days when every check
    carries a test date, in order and none twice. Else tests (their count).

    Parameters
    ----------
    checks : DataFrame
        The checks, oldest first, with a ``test_date`` and optionally an
        ``hours`` column.

    Example
    -------
    >>> c = pd.DataFrame({"test_date": ["2026-01-02", "2026-01-05", None],
    ...                   "hours": [120.0, 190.5, 260.0]})
    >>> forecast_axis(c).by, forecast_axis(c.drop(columns="hours").iloc[:2]).by
    ('hours', 'days')
    >>> forecast_axis(c.drop(columns="hours")).by
    'tests'
    """
    dates = pd.to_datetime(checks["test_date"], utc=True, errors="coerce")
    hours = pd.to_numeric(checks["hours"], errors="coerce") if "hours" in checks \
        else pd.Series(np.nan, index=checks.index, dtype=np.float64)
    cycles = pd.to_numeric(checks["cycle"], errors="coerce") if "cycle" in checks \
        else pd.Series(np.nan, index=checks.index, dtype=np.float64)
    if _increasing(cycles):
        return Axis("cycles", dates, hours, None, cycles)
    by = "hours" if _increasing(hours) else "days" if _increasing(dates) else "tests"
    note = None
    if by != "hours" and hours.notna().any():
        note = f"counted in {by}, not operating hours: {_why_not(hours, 'hours', ' h')}"
    elif by == "tests" and dates.notna().any():
        note = f"counted in tests, not days: {_why_not(dates, 'a date', '')}"
    return Axis(by, dates, hours, note)


def _why_not(values: pd.Series, what: str, unit: str) -> str:
    """Why ``values`` (by test id) cannot be a forecast's axis, in a clause."""
    missing = values[values.isna()]
    if len(missing):
        return f"test #{missing.index[0]} has no {what.removeprefix('a ')}"
    prev = values.shift(1)
    back = values[values <= prev]
    i = back.index[0]

    def show(v: Any) -> str:
        return f"{v:g}{unit}" if unit else str(v)

    return (f"test #{i} has {show(values[i])}, not after the check before it "
            f"({show(prev[i])})")


def parameter_series(checks: pd.DataFrame, baseline: Baseline, key: str, axis: Axis
                     ) -> tuple[Series, pd.Index] | None:
    """The change series of parameter ``key`` (``Tc@forward`` for a regime's)
    in ``checks``, and the checks it is in; None when fewer than 3 checks have
    it or the baseline lacks it."""
    col = f"{key}_change"   # a regime's parameter has columns of its own (Tc@forward)
    if col not in checks or key not in baseline.parameters:
        return None
    i = baseline.parameters.index(key)
    mean, std = baseline.mean[i], baseline.std[i]
    rows = checks[checks[col].notna()]
    if len(rows) < MIN_TESTS:
        return None
    change = rows[col].to_numpy(dtype=np.float64)
    se = 100.0 * rows[f"{key}_se"].to_numpy(dtype=np.float64) / abs(mean) \
        if f"{key}_se" in rows and mean else np.zeros(len(rows))
    return (axis.values(rows.index), change, np.nan_to_num(se),
            100.0 * std / abs(mean) if mean else 0.0), rows.index
