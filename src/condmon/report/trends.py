"""The numbers the report's figures draw, computed from a unit's stored history.

Every figure of a unit page is drawn from one of these frozen results, so what
a figure shows can be checked without looking at pixels:

* :func:`trend_data`: per parameter, each trended check's change against the
  baseline it was evaluated with, the symptom half-width that evaluation used
  (``k·max(σ_baseline, SE)``, :func:`condmon.monitor.fuzzy.symptom_width`: the
  one error bar of every figure, page and JSON, :func:`error_bar` in words),
  the stored symptoms and status, on a common x axis (test dates when any
  test has one, else test ids);
* :func:`fit_data`: every test that is not excluded, with its fit and status;
* :func:`isolation_trend`: each suspect's estimated change in every isolation.

Which tests trend: accepted checks that are not excluded. Excluded tests are
never drawn; rejected tests (``rejected``, ``retest``) appear in the fit figure
only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from condmon.monitor.baseline import Baseline
from condmon.monitor.fuzzy import symptom_width

if TYPE_CHECKING:
    from condmon.forecast.unit import ParameterForecast, UnitForecast

__all__ = ["TrendData", "FitData", "IsolationTrend", "ForecastBand", "trend_data", "fit_data",
           "isolation_trend", "unexplained", "axis_label", "error_bar", "forecast_band",
           "forecast_bands", "FORECAST_LABEL"]

FloatArray = np.ndarray[Any, np.dtype[np.float64]]

#: What the shaded forecast band is, in every figure and page that draws it.
FORECAST_LABEL = "forecast, 90 % interval"

#: Statuses that ground a unit or call for attention.
_ALARM = ("advisory", "no-go")


def error_bar(k: float, words: bool = False) -> str:
    """What every error bar of the reports, the fleet page and their JSON is.

    One definition: the symptom half-width ``±k·max(σ, SE)`` the check's
    status was computed with (:func:`condmon.monitor.fuzzy.symptom_width`).
    Unlike the estimate's standard error alone, it is the band the detector
    decides with: a parameter's symptom is above 0 exactly when its bar
    reaches ``±r1``.

    Parameters
    ----------
    k : float
        Symptom width in standard deviations. [-]
    words : bool
        The whole sentence a caption states, not the formula alone.

    Examples
    --------
    >>> error_bar(2.0)
    '±2·max(σ, SE)'
    >>> error_bar(2.0, words=True)[:60]
    'error bars: ±2·max(σ, SE), the symptom half-width the status'
    """
    short = f"±{k:g}·max(σ, SE)"
    if not words:
        return short
    return (f"error bars: {short}, the symptom half-width the status was computed with: "
            f"{k:g} times the larger of the baseline's standard deviation σ and the "
            "estimate's standard error SE, in % of the baseline mean; a parameter's symptom "
            "is above 0 exactly when its bar reaches the r1 band")


def _dated(frame: pd.DataFrame) -> bool:
    return "test_date" in frame and bool(frame["test_date"].notna().any())


#: A unit's own usage axis, as imported tables count it, and its axis label.
_USAGE = {"cycle": "cycle", "hours": "operating hours"}
#: The x labels of a usage axis: its values are cycles or hours, not test ids.
USAGE_LABELS = tuple(_USAGE.values())


def _usage(frame: pd.DataFrame) -> str | None:
    """The usage column every test of ``frame`` counts (``cycle`` or ``hours``:
    an imported unit's axis), or None."""
    for col in _USAGE:
        if col in frame and len(frame) and bool(frame[col].notna().all()):
            return col
    return None


def axis_label(frame: pd.DataFrame) -> str:
    """What the x axis of ``frame``'s figures shows.

    Test dates when any test has one (a test without one is placed at the
    time it was stored, and the label says so); else the unit's usage when
    every test counts it (an imported table's cycles or operating hours);
    else test ids.

    Examples
    --------
    >>> axis_label(pd.DataFrame({"test_date": [pd.NaT]}))
    'test # (no test dates recorded)'
    >>> axis_label(pd.DataFrame({"test_date": [pd.NaT], "cycle": [1.0]}))
    'cycle'
    """
    if not _dated(frame):
        usage = _usage(frame)
        return _USAGE[usage] if usage else "test # (no test dates recorded)"
    if bool(frame["test_date"].isna().any()):
        return "date (UTC): test date, else when stored"
    return "test date (UTC)"


def _ordered(rows: pd.DataFrame, dated: bool, usage: str | None = None
             ) -> tuple[pd.DataFrame, np.ndarray[Any, Any]]:
    """``rows`` in the order of the x axis, and their x values (dates, the
    ``usage`` column every test of the unit counts, or ids)."""
    if not dated:
        rows = rows.sort_index()
        if usage:
            rows = rows.sort_values(usage, kind="stable")
            return rows, rows[usage].to_numpy(dtype=np.float64)
        return rows, np.asarray(rows.index, dtype=np.float64)
    rows = rows.sort_index().sort_values("date", kind="stable")
    return rows, rows["date"].dt.tz_convert("UTC").dt.tz_localize(None).to_numpy()


def _trended(history: pd.DataFrame) -> pd.DataFrame:
    """Accepted checks that are not excluded: the tests a trend draws."""
    if not len(history):
        return history
    ok = (history["role"] == "check") & history["accepted"].astype(bool)
    ok &= ~history["excluded"].astype(bool)
    ok &= history["status"] != "not judged"   # outside its baseline's conditions: no change
    return history[ok]


def _column(rows: pd.DataFrame, name: str) -> FloatArray:
    if name in rows:
        return rows[name].to_numpy(dtype=np.float64, na_value=np.nan)
    return np.full(len(rows), np.nan)


@dataclass(frozen=True)
class TrendData:
    """What the trend figure draws for one parameter (in percent of the baseline mean).

    Attributes
    ----------
    parameter : str
    test_ids : tuple of int
        The trended checks (accepted, not excluded), in the order of ``x``.
    x : ndarray
        Test dates (``datetime64``, UTC) or test ids, see ``xlabel``.
    xlabel : str
        What ``x`` is.
    change : ndarray
        Change against the baseline the check was evaluated with. [%]
    width : ndarray
        Symptom half-width of that evaluation, ``k·max(σ_baseline, SE)/|mean|·100``
        (:func:`condmon.monitor.fuzzy.symptom_width`): the error bar. [%]
    se : ndarray
        Each estimate's standard error. [%]
    high, low : ndarray
        Stored SymH and SymL. [-]
    status : tuple of str
        The status stored for each test.
    spread : float
        ``k·σ/|mean|·100`` of the active baseline (NaN without one). [%]
    r1, r2 : float
        Breakpoints of the HIGH/LOW ramps. [%]
    k : float
        Symptom width in standard deviations. [-]
    """

    parameter: str
    test_ids: tuple[int, ...]
    x: np.ndarray[Any, Any]
    xlabel: str
    change: FloatArray
    width: FloatArray
    se: FloatArray
    high: FloatArray
    low: FloatArray
    status: tuple[str, ...]
    spread: float
    r1: float
    r2: float
    k: float

    @property
    def symptom(self) -> FloatArray:
        """The larger of SymH and SymL (0 where none is stored). [-]"""
        return np.fmax(np.nan_to_num(self.high), np.nan_to_num(self.low))

    @property
    def implied(self) -> FloatArray:
        """The symptom the drawn bar implies: where ``|change| + width`` lies
        on the r1..r2 ramp, ``(|change| + width - r1)/(width + r2 - r1)`` clipped
        to [0, 1] (the monitor's triangle-and-ramp composition). [-]
        """
        ramp = (np.abs(self.change) + self.width - self.r1) / (self.width + self.r2 - self.r1)
        # a bar that reaches both +r1 and -r1 measures no direction: no symptom
        both = self.width - np.abs(self.change) > self.r1
        return np.where(both, 0.0, np.nan_to_num(np.clip(ramp, 0.0, 1.0)))

    @property
    def panel_status(self) -> tuple[str, ...]:
        """The status this parameter's panel shows for each check: the check's
        own where this parameter's symptom is above 0, ``go`` where it is not
        (another parameter made the check advisory or no-go; this one is not
        to blame)."""
        return tuple("go" if st in ("advisory", "no-go") and not sym > 0 else st
                     for st, sym in zip(self.status, self.symptom))

    @property
    def reaches_r1(self) -> np.ndarray[Any, np.dtype[np.bool_]]:
        """Whether the drawn bar ``change ± width`` passes ``±r1`` (the symptom is above 0)."""
        return np.asarray(self.implied > 1e-12, dtype=bool)


def trend_data(history: pd.DataFrame, parameter: str, baselines: Mapping[int, Baseline],
               r1: float, r2: float, k: float, active: int | None = None) -> TrendData:
    """The numbers the trend figure draws for ``parameter``.

    Parameters
    ----------
    history : DataFrame
        :meth:`HistoryStore.history` of the unit.
    parameter : str
    baselines : mapping of int to Baseline
        The unit's baselines by id; each check's width comes from the one its
        shown evaluation used (``baseline_id``).
    r1, r2 : float
        Breakpoints of ``parameter``. [%]
    k : float
        Symptom width in standard deviations (the monitor's ``k``). [-]
    active : int, optional
        Id of the active baseline, whose spread is drawn around 0 (default:
        the newest in ``baselines``).

    Returns
    -------
    TrendData

    Examples
    --------
    >>> h = pd.DataFrame({"role": ["check"], "accepted": [True], "excluded": [False],
    ...                   "status": ["go"], "baseline_id": [1], "R_change": [5.0],
    ...                   "R_se": [0.01], "test_date": [pd.NaT]}, index=[7])
    >>> d = trend_data(h, "R", {1: Baseline(("R",), (1.0,), (0.02,), 5)}, 20.0, 40.0, 2.0)
    >>> d.test_ids, float(d.width[0]), d.spread, bool(d.reaches_r1[0])
    ((7,), 4.0, 4.0, False)
    """
    rows, x = _ordered(_trended(history), _dated(history), _usage(history))

    def stats(bid: Any) -> tuple[float, float]:
        b = baselines.get(int(bid)) if pd.notna(bid) else None
        if b is None or parameter not in b.parameters:
            return np.nan, np.nan
        j = b.parameters.index(parameter)
        return abs(b.mean[j]), b.std[j]

    ms = np.array([stats(b) for b in rows["baseline_id"]], dtype=np.float64).reshape(-1, 2)
    scale = np.where(ms[:, 0] > 0, 100.0 / ms[:, 0], np.nan)
    se = _column(rows, f"{parameter}_se")
    width = symptom_width(ms[:, 0], ms[:, 1], se, k)
    se = se * scale
    spread = np.nan
    if baselines:
        m, s = stats(max(baselines) if active is None else active)
        spread = k * s * 100.0 / m if m > 0 else np.nan
    return TrendData(parameter, tuple(int(i) for i in rows.index), x, axis_label(history),
                     _column(rows, f"{parameter}_change"), width, se,
                     _column(rows, f"{parameter}_high"), _column(rows, f"{parameter}_low"),
                     tuple(str(s) for s in rows["status"]), float(spread), float(r1),
                     float(r2), float(k))


def unexplained(trends: Sequence[TrendData]) -> dict[int, str]:
    """Tests whose status or symptoms the trend figure does not explain by itself.

    * an alarm (advisory, no-go) with no parameter's bar beyond ``r1``;
    * ``go`` although a parameter's symptom is full (beyond ``r2``): the rule
      base makes no fault of it (or preprocessing cleared it);
    * a stored symptom that disagrees with the drawn bar (judged against its
      prediction at its operating conditions, ``[conditions]``, or with other
      breakpoints or another ``k`` than the figure's).

    Returns
    -------
    dict of int to str
        Test id to an explanation to print next to the figure.
    """
    if not trends:
        return {}
    out: dict[int, list[str]] = {}
    ids = trends[0].test_ids
    for i, tid in enumerate(ids):
        status = trends[0].status[i]
        drawn = [t.parameter for t in trends if t.reaches_r1[i]]
        full = [t.parameter for t in trends if t.symptom[i] >= 1.0]
        notes = []
        if status in _ALARM and not drawn:
            notes.append(f"{status} with no parameter beyond r1 in the figure")
        if status == "go" and full:
            notes.append(f"go although {', '.join(full)} beyond r2: the rule base makes "
                         "no fault of it here (see the diagnosis)")
        differ = [t.parameter for t in trends if np.isfinite(t.change[i])
                  and abs(t.implied[i] - t.symptom[i]) > 1e-6]
        if differ:
            notes.append(f"stored symptom of {', '.join(differ)} disagrees with the drawn "
                         "bar (the bar is against the baseline's whole spread; the check "
                         "was judged against its prediction at its operating conditions, "
                         "or with other breakpoints or k)")
        if notes:
            out[tid] = notes
    return {tid: "; ".join(notes) for tid, notes in out.items()}


@dataclass(frozen=True)
class FitData:
    """What the fit figure draws: every test that is not excluded.

    Attributes
    ----------
    test_ids : tuple of int
    x : ndarray
        Test dates (``datetime64``, UTC) or test ids.
    xlabel : str
    fit : ndarray
        Percentage fit (NaN where none was computed). [%]
    status : tuple of str
    """

    test_ids: tuple[int, ...]
    x: np.ndarray[Any, Any]
    xlabel: str
    fit: FloatArray
    status: tuple[str, ...]


def fit_data(history: pd.DataFrame) -> FitData:
    """Fit of every test that is not excluded (rejected ones included).

    Examples
    --------
    >>> h = pd.DataFrame({"excluded": [False, True], "fit_percent": [95.0, 97.0],
    ...                   "status": ["rejected", "excluded"], "test_date": [pd.NaT] * 2},
    ...                  index=[3, 4])
    >>> fit_data(h).test_ids
    (3,)
    """
    kept = history[~history["excluded"].astype(bool)] if len(history) else history
    rows, x = _ordered(kept, _dated(history), _usage(history))
    return FitData(tuple(int(i) for i in rows.index), x, axis_label(history),
                   _column(rows, "fit_percent"), tuple(str(s) for s in rows["status"]))


@dataclass(frozen=True)
class IsolationTrend:
    """What the isolation figure draws: each suspect's estimated change per isolation.

    Attributes
    ----------
    isolation_ids : tuple of int
        Isolations that are not excluded, in the order of ``x``.
    x : ndarray
        Test dates (``datetime64``, UTC) or isolation ids.
    xlabel : str
    status : tuple of str
    change : dict of str to ndarray
        Per suspect, its steady-state estimate against nominal (NaN when not
        estimated or rejected from the comparison). [%]
    isolated : dict of str to ndarray of bool
        Per suspect, whether that isolation named it.
    unshown : dict of str to str
        Suspects with no change to draw, and why: ``rejected from the
        comparison``, ``nominal 0: no change in %`` (the estimate is in the
        table) or ``not estimated``.
    """

    isolation_ids: tuple[int, ...]
    x: np.ndarray[Any, Any]
    xlabel: str
    status: tuple[str, ...]
    change: dict[str, FloatArray]
    isolated: dict[str, np.ndarray[Any, np.dtype[np.bool_]]]
    unshown: dict[str, str] = field(default_factory=dict)


def isolation_trend(isolations: pd.DataFrame) -> IsolationTrend:
    """Each suspect's change over a unit's isolations (excluded ones left out).

    Parameters
    ----------
    isolations : DataFrame
        :meth:`HistoryStore.isolations` of the unit.

    Returns
    -------
    IsolationTrend
    """
    kept = isolations[~isolations["excluded"].astype(bool)] if len(isolations) else isolations
    rows, x = _ordered(kept, _dated(isolations))
    label = axis_label(isolations).replace("test #", "isolation #")
    params = sorted(c[: -len("_change")] for c in rows.columns if c.endswith("_change"))
    change, isolated, unshown = {}, {}, {}
    for p in params:
        y = _column(rows, f"{p}_change")
        rejected = (rows[f"{p}_rejected"].fillna(False).astype(bool).to_numpy()
                    if f"{p}_rejected" in rows else np.zeros(len(rows), dtype=bool))
        y = np.where(rejected, np.nan, y)
        change[p] = y
        isolated[p] = np.array([p in list(v) for v in rows["isolated"]], dtype=bool)
        if not np.isfinite(y).any():
            valued = np.isfinite(_column(rows, p)) & ~rejected
            unshown[p] = ("nominal 0: no change in %" if valued.any() else
                          "rejected from the comparison" if rejected.any() else "not estimated")
    return IsolationTrend(tuple(int(i) for i in rows.index), x, label,
                          tuple(str(s) for s in rows["status"]), change, isolated, unshown)


@dataclass(frozen=True)
class ForecastBand:
    """What a trend figure draws of one parameter's forecast to no-go.

    Attributes
    ----------
    parameter : str
    by : {"tests", "days"}
        What ``ahead`` counts.
    test_ids : tuple of int
        The checks of the forecast's series, in order (the band starts at the last).
    ahead : ndarray
        Tests (or days) after the last check, from 0 to past the median
        crossing. [tests (or d)]
    median, low, high : ndarray
        The fitted trend continued and its 90 % band at ``ahead``. [%]
    threshold : float
        The no-go change (r2, signed in the trend's direction). [%]
    """

    parameter: str
    by: str
    test_ids: tuple[int, ...]
    ahead: FloatArray
    median: FloatArray
    low: FloatArray
    high: FloatArray
    threshold: float

    def x(self, at: Sequence[float] | FloatArray, day: float) -> FloatArray:
        """``ahead`` on a figure's x axis, from the x of the series' checks
        ``at`` (numbers: test positions, seconds or nanoseconds): a day is
        ``day`` of them; a test, the checks' mean spacing."""
        first, last = float(at[0]), float(at[-1])
        step = day if self.by == "days" else (last - first) / max(len(at) - 1, 1)
        return np.asarray(last + self.ahead * step, dtype=np.float64)


def forecast_band(forecast: ParameterForecast, by: str, points: int = 40) -> ForecastBand | None:
    """The band a trend figure draws for a parameter trending towards no-go.

    From the last check to past the median crossing (to the 95 % point of
    the tests (days) left, at most twice the median), the fitted trend and
    its 90 % band (:meth:`condmon.forecast.series.Forecast.band`); for a
    path forecast, straight lines from the last check's level to the no-go
    line at the median and at the ends of its 90 % interval (its life comes
    from the drawn paths, and a fleet may have recalibrated it). None
    without a trend.

    Parameters
    ----------
    forecast : ParameterForecast
    by : {"tests", "days", "hours", "cycles"}
        What the unit's forecasts count (hours and cycles drawn against the
        checks, at their mean spacing).
    points : int
        Points along the band.
    """
    f = forecast.forecast
    if f.remaining is None or not forecast.test_ids:
        return None
    med, low, high = f.remaining
    end = min(high, 2.0 * med) if np.isfinite(med) else max(f.last, 1.0)
    ahead = np.linspace(0.0, max(float(end), 1e-9), points)
    mid, lo, hi = f.band(ahead)
    if f.model == "path" and 0 < low <= med <= high and np.isfinite(high):
        # a path forecast's life comes from its drawn paths (and a fleet may have
        # read them at its own levels): lines from now to the no-go line at the
        # median and the interval's ends, so the figure says what the numbers do
        now = float(mid[0])
        mid, soon, late = (now + (f.threshold - now) * np.minimum(ahead / r, 1.0)
                           for r in (med, low, high))
        lo, hi = np.minimum(soon, late), np.maximum(soon, late)
    if by in ("hours", "cycles"):   # drawn against the checks: their mean usage a check
        per_check = forecast.span / max(len(forecast.test_ids) - 1, 1)
        if not per_check > 0:
            return None
        ahead, by = ahead / per_check, "tests"
    return ForecastBand(forecast.parameter, by, forecast.test_ids, ahead, mid, lo, hi,
                        float(f.threshold))


def forecast_bands(forecast: UnitForecast | None) -> tuple[ForecastBand, ...]:
    """The band of every parameter of a unit's forecast that trends towards no-go."""
    if forecast is None:
        return ()
    bands = (forecast_band(p, forecast.by) for p in forecast.parameters)
    return tuple(b for b in bands if b is not None)
