"""A unit's forecasts to no-go: each parameter's change series since its baseline.

:func:`forecast_checks` is pure: from a unit's checks since its current
baseline (a frame of :meth:`~condmon.store.HistoryStore.history`'s rows), the
baseline, each parameter's no-go change ``r2`` and the fault rules named by
their one-symptom condition, it forecasts every parameter (and operating
regime) with :func:`condmon.forecast.series.forecast_series`: the crossing
of ``r2`` in the trend's direction. What ``x`` counts is chosen once, by
:func:`forecast_axis`: the days since the first check when every check carries
a date (increasing, none twice), else the checks' count.

The store-level reader is :func:`condmon.store.forecasts.read_forecast`
(``condmon forecast``, ``units``, ``check``, the report and the fleet page
all forecast through it).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from condmon.errors import DataError
from condmon.monitor.baseline import Baseline
from condmon.forecast.axis import Axis, Series, forecast_axis, in_test_order, parameter_series
from condmon.forecast.degradation import steady_direction
from condmon.forecast.calibration import Calibration
from condmon.forecast.measured import forecast_by, real_coverage
from condmon.forecast.path import PATH_MIN_TESTS
from condmon.forecast.series import MIN_TESTS, Forecast, Prior, checked_horizon

__all__ = ["ParameterForecast", "UnitForecast", "forecast_checks", "forecast_axis", "Axis", "NoGo",
           "in_test_order",
           "remaining_text", "date_past", "NO_TREND", "parameter_series", "Series"]

#: Why a unit with enough checks has no forecast.
NO_TREND = "no trend towards no-go"


@dataclass(frozen=True)
class NoGo:
    """Where one parameter's change turns a check no-go on its own.

    The fuzzy monitor blurs a measured change into a symptom set of
    half-width ``w = k·max(σ, SE)/|θ̄|·100`` and its HIGH degree rises from 0
    at ``r1`` to 1 at ``r2`` (:func:`~condmon.monitor.fuzzy.symptom_degree`;
    LOW mirrors it); a check turns no-go once a major fault rule on that
    symptom alone reaches the diagnoser's no-go degree, so at the change
    ``r1 + degree·(w + r2 − r1) − w``, short of ``r2``.

    Attributes
    ----------
    r1, r2 : float
        The parameter's breakpoints. [%]
    k : float
        The symptom set's half-width in standard deviations (0: a crisp
        change). [-]
    rise, fall : float
        The symptom degree at which a rise (a fall) turns a check no-go (1:
        at ``r2``; inf: never, no major rule names it alone). [-]
    lower, upper : float
        The parameter's plausible values (a friction is ≥ 0): a no-go past
        them cannot come. [the parameter's unit]
    rise_with, fall_with : tuple of str
        The symptoms a rise (a fall) names its major fault with
        (``("low(Kt)",)`` for a fall of Ke: magnet weakening): the check
        turns no-go when the later of them reaches the degree too.

    Example
    -------
    >>> NoGo(300.0, 600.0, 2.0, 0.7).change(20.0, rising=True)   # 300 + 0.7·320 − 20
    504.0
    >>> NoGo(20.0, 40.0).change(5.0, rising=False)               # degree 1: r2 itself
    40.0
    """

    r1: float
    r2: float
    k: float = 0.0
    rise: float = 1.0
    fall: float = 1.0
    lower: float = -math.inf
    upper: float = math.inf
    rise_with: tuple[str, ...] = ()
    fall_with: tuple[str, ...] = ()

    def change(self, width: float, rising: bool) -> float:
        """How far the change goes before a check turns no-go, for a
        symptom half-width (inf: never). [%]"""
        degree = self.rise if rising else self.fall
        if not math.isfinite(degree):
            return math.inf
        return max(self.r1 + degree * (width + self.r2 - self.r1) - width, 1e-9)

    def threshold(self, x: NDArray[np.float64], change: NDArray[np.float64],
                  se: NDArray[np.float64], spread: float) -> tuple[float, str | None]:
        """The signed no-go change a series heads for (the way of its steady
        move, when its slope's 90 % interval is clear of 0; else the way of
        its last 3 checks; at a typical check's half-width: ``k`` times the
        larger of the baseline spread and the checks' median standard
        error) [%], and why a check cannot turn no-go that way (None: it can).
        ``r2`` in that direction stands in when it cannot."""
        way = steady_direction(x, change, se, spread)
        rising = way > 0 if way else float(np.nanmean(change[-MIN_TESTS:])) >= 0.0
        return self.towards(rising, se, spread)

    def towards(self, rising: bool, se: NDArray[np.float64], spread: float
                ) -> tuple[float, str | None]:
        """:meth:`threshold` for a rise (``rising``) or a fall."""
        sign = 1.0 if rising else -1.0
        width = self.k * max(spread, float(np.median(se)) if len(se) else 0.0)
        at = self.change(width, rising)
        if not math.isfinite(at):
            return sign * self.r2, (f"no major fault rule names a {'rise' if rising else 'fall'}"
                                    " of this parameter, alone or with one other symptom: "
                                    "it cannot make a check no-go")
        return sign * at, None

    def beyond(self, threshold: float, mean: float) -> str | None:
        """Why ``threshold`` [%] cannot come for a baseline ``mean`` (past
        the plausible values), or None."""
        bound = self.upper if threshold > 0 else self.lower
        if not (mean and math.isfinite(bound)):
            return None
        reach = 100.0 * (bound - mean) / abs(mean)
        if (threshold > reach) if threshold > 0 else (threshold < reach):
            return (f"no-go at {threshold:+.3g} % cannot come: the parameter's plausible "
                    f"values end at {reach:+.3g} %")
        return None


@dataclass(frozen=True)
class ParameterForecast:
    """One parameter's forecast.

    Attributes
    ----------
    parameter : str
        With its regime (``Tc@forward``) when the baseline has regimes.
    unit : str
        The parameter's unit of measure.
    rule : str
        The fault rule the threshold comes from ("" when none names it alone).
    forecast : Forecast
    date : str or None
        The median crossing date, ISO 8601 (when the checks carry dates).
    test_ids : tuple of int
        The checks of the series, in the order of ``x``.
    span : float
        ``x`` of the last of them less that of the first. [tests (or d, h)]
    hours : float or None
        The unit's operating hours at the median crossing (a forecast in
        hours). [h]
    waits_for : str
        The parameter whose no-go change this one's fault also needs and
        that comes later ("": none): magnet weakening needs Ke and Kt both
        low, so the earlier of the two is not when the unit turns no-go.
    """

    parameter: str
    unit: str
    rule: str
    forecast: Forecast
    date: str | None = None
    test_ids: tuple[int, ...] = ()
    span: float = 0.0
    hours: float | None = None
    waits_for: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"parameter": self.parameter, "unit": self.unit, "rule": self.rule or None,
                "date": self.date, "at_hours": self.hours,
                "waits_for": self.waits_for or None, **self.forecast.to_dict()}


@dataclass(frozen=True)
class UnitForecast:
    """Every parameter's forecast for one unit.

    Attributes
    ----------
    unit : str
    by : {"tests", "days", "hours", "cycles"}
        What ``remaining`` counts (cycles, or operating hours, when every check gives them).
    checks : int
        Checks since the baseline.
    parameters : tuple of ParameterForecast
        Earliest median crossing first; "no trend" last.
    notes : tuple of str
        What to know of the whole forecast (why it counts days, not hours).
    horizon : float or None
        The horizon of each ``p_within_horizon`` (None: none asked).
        [tests (or d, h)]
    """

    unit: str
    by: str
    checks: int
    parameters: tuple[ParameterForecast, ...]
    notes: tuple[str, ...] = ()
    horizon: float | None = None

    @property
    def earliest(self) -> ParameterForecast | None:
        """The parameter forecast to turn no-go first (None: no trend anywhere)."""
        trends = [p for p in self.parameters
                  if p.forecast.remaining is not None and not p.waits_for]
        return trends[0] if trends else None

    def to_dict(self) -> dict[str, Any]:
        e = self.earliest
        return {"unit": self.unit, "by": self.by, "checks": self.checks,
                "horizon": self.horizon,
                "earliest": None if e is None else e.parameter, "notes": list(self.notes),
                "parameters": [p.to_dict() for p in self.parameters]}

    def summary(self) -> dict[str, Any] | None:
        """The earliest forecast to no-go, as ``units --json`` and ``check --json`` give it.

        ``{"parameter", "unit", "by", "median", "low", "high", "date", "rule",
        "at_hours"}``: the parameter (``Tc@forward`` for a regime's), its unit
        of measure, what the numbers count (``tests``, ``days`` or operating
        ``hours``), the median and 90 % interval of the tests (days, hours)
        left [tests (or d, h)] (None: not within any horizon), the median
        crossing date (ISO 8601, dated checks only, else None), the fault rule
        the no-go change fires (None when none names it alone) and the
        operating hours at the median crossing (a forecast in hours, else
        None) [h], and whether its last check measured past the no-go
        change (``at_no_go``). None when no parameter trends towards no-go.
        """
        e = self.earliest
        if e is None or e.forecast.remaining is None:
            return None
        med, lo, hi = (v if math.isfinite(v) else None for v in e.forecast.remaining)
        return {"parameter": e.parameter, "unit": e.unit, "by": self.by, "median": med,
                "low": lo, "high": hi, "date": e.date, "rule": e.rule or None, "at_hours": e.hours,
                "at_no_go": e.forecast.at_nogo}


def forecast_checks(unit: str, checks: pd.DataFrame, baseline: Baseline,
                    r2: Mapping[str, float | NoGo], rules: Mapping[str, str],
                    units: Mapping[str, str] | None = None, horizon: float | None = None,
                    seed: int = 0,
                    priors: Mapping[str | tuple[str, float], Prior] | None = None,
                    now: pd.Timestamp | None = None, method: str = "trend",
                    calibrations: Mapping[str, Calibration] | None = None) -> UnitForecast:
    """Forecast every parameter of a unit to no-go from its checks since the baseline.

    Parameters
    ----------
    unit : str
        The unit's name (for messages and the result).
    checks : DataFrame
        The accepted checks since the baseline, not excluded, oldest first:
        rows of :meth:`~condmon.store.HistoryStore.history` with ``test_date``,
        ``<key>_change`` [%] and ``<key>_se`` [the parameter's unit] of each
        parameter key (``Tc@forward`` for a regime's).
    baseline : Baseline
        The current baseline (its mean and spread per key).
    r2 : mapping of str to float or NoGo
        Where each parameter (by name, without regime) turns a check no-go:
        its change ``r2`` [%], or how its breakpoints, symptom width and the
        diagnoser's no-go degree place it, with its plausible values
        (:class:`NoGo`: a no-go beyond them is "no trend").
    rules : mapping of str to str
        Fault rule names by their one-symptom condition (``"high(D)"``): the
        rule a single parameter's no-go change fires.
    units : mapping of str to str, optional
        Each parameter's unit of measure.
    horizon : float, optional
        For the probability of crossing within it. [tests (or d)]
    seed : int
        Seed of the predictive draws.
    priors : mapping of str (or (str, ±1.0)) to RatePrior or FleetPrior, optional
        The fleet's prior on each parameter key's degradation (its rate, or
        its shape and rates: :func:`~condmon.forecast.prior.fleet_wear_prior`),
        by key, or by key and the direction the series heads (+1.0 rising,
        -1.0 falling: peers that wore the other way teach nothing); a key
        without one is forecast from its own tests alone.
    now : Timestamp, optional
        The time a dated forecast is read at (default: the clock): a median
        no-go date already past gets a note that the unit is due a check.
    method : {"trend", "path"}
        How each series is forecast (:func:`~condmon.forecast.measured.forecast_by`).
    calibrations : mapping of str to Calibration, optional
        A path forecast's levels per parameter key, from the fleet's failed
        units (:mod:`condmon.forecast.calibration`).

    Returns
    -------
    UnitForecast

    Raises
    ------
    DataError
        Fewer than 3 checks, or 6 for the path method ("not enough tests to
        forecast"), a horizon <= 0.
    """
    checked_horizon(horizon)
    if len(checks) < MIN_TESTS:
        raise DataError(f"not enough tests to forecast: unit {unit!r} has {len(checks)} "
                        f"check(s) since its baseline, need {MIN_TESTS}")
    if method == "path" and len(checks) < PATH_MIN_TESTS:
        # (a trend in the path's place held real lives about one time in four: no
        # interval, rather than that one)
        held = real_coverage("trend")
        raise DataError(f"not enough tests to forecast: unit {unit!r} has {len(checks)} "
                        f"check(s) since its baseline, a measured degradation path needs "
                        f"{PATH_MIN_TESTS}" + (f" (a trend instead: its 90 % interval held the "
                                               f"true remaining life in only {held})"
                                               if held else ""))
    checks = in_test_order(checks)
    axis = forecast_axis(checks)
    out = []
    for key in baseline.parameters:
        name = key if key in r2 else key.split("@", 1)[0]   # a regime's own, else its parameter's
        found = parameter_series(checks, baseline, key, axis) if name in r2 else None
        if found is None:
            continue
        (x, change, se, spread), rows = found
        limit = r2[name]
        nogo = limit if isinstance(limit, NoGo) else NoGo(float(limit), float(limit))
        mean = float(baseline.mean[baseline.parameters.index(key)])
        threshold, never = nogo.threshold(x, change, se, spread)
        never = never or nogo.beyond(threshold, mean)
        rising = threshold > 0

        def heading(threshold: float, unreachable: str | None = None) -> Forecast:
            # the peers that wore this way teach it; counted in tests, the no-go is
            # a check: whole checks (days and hours have no cadence to come: the
            # crossing itself)
            prior = (priors or {}).get((key, 1.0 if threshold > 0 else -1.0),
                                       (priors or {}).get(key))
            return forecast_by(method, x, change, se, spread, threshold, horizon, seed,
                               prior=prior, step=1.0 if axis.by in ("tests", "cycles") else None,
                               unreachable=unreachable,
                               calibration=(calibrations or {}).get(key),
                               per={"hours": "h", "days": "day"}.get(axis.by, axis.by[:-1]))

        f = heading(threshold, never)
        if never and not f.trend and not f.unreachable:
            # no steady move the way its last checks pointed, where no-go cannot come:
            # the other way, if no-go can come there (a steady move that way is forecast)
            other, cannot = nogo.towards(not rising, se, spread)
            cannot = cannot or nogo.beyond(other, mean)
            if cannot:
                f = dataclasses.replace(f, unreachable=f"{never}; nor the other way: {cannot}")
            else:
                rising, f = not rising, heading(other)
        rule = rules.get(_condition(key.split("@", 1)[0], rising), "")
        said = str(checks["status"].loc[rows[-1]]) if "status" in checks else "no-go"
        if f.at_nogo and said != "no-go":   # past its no-go change, yet the check said not
            f = dataclasses.replace(f, at_nogo=False, notes=(
                *f.notes[:-1], f"the last check measured past the no-go change, yet its "
                f"status is {said}: due now"))
        when = None if f.remaining is None else axis.date_after(rows[-1], f.remaining[0])
        pace = "" if when is None or f.remaining is None else \
            axis.pace_note(rows[-1], f.remaining[0])
        if pace:
            f = dataclasses.replace(f, notes=(*f.notes, pace))
        at = (float(axis.hours[rows[-1]] + f.remaining[0])
              if axis.by == "hours" and f.remaining is not None
              and math.isfinite(f.remaining[0]) else None)
        out.append(ParameterForecast(key, (units or {}).get(key.split("@", 1)[0], ""), rule,
                                     f, when,
                                     tuple(int(i) for i in rows), float(x[-1] - x[0]), at))
    out = _with_partners(out, r2)
    order = {p.parameter: p for p in out}
    out.sort(key=lambda p: (p.forecast.remaining is None, _median(order.get(p.waits_for, p)),
                            bool(p.waits_for)))
    notes = [axis.note] if axis.note else []
    late = _overdue(out, axis, now)
    if late:
        notes.append(late)
    return UnitForecast(unit, axis.by, len(checks), tuple(out), tuple(notes), horizon)


def _median(p: ParameterForecast) -> float:
    return p.forecast.remaining[0] if p.forecast.remaining else 0.0


def _symptom(p: ParameterForecast) -> tuple[str, str]:
    """``("low(Ke)", regime)`` of a forecast, by the way it heads."""
    name, _, regime = p.parameter.partition("@")
    return _condition(name, p.forecast.threshold > 0), regime


def _condition(name: str, rising: bool) -> str:
    """A parameter's symptom as the rules name it: ``high(D)``, ``low(Ke)``."""
    return f"{'high' if rising else 'low'}({name})"


def _with_partners(out: list[ParameterForecast], r2: Mapping[str, float | NoGo]
                   ) -> list[ParameterForecast]:
    """A fault two symptoms name together (magnet weakening: ``low(Ke) and
    low(Kt)``, the minimum of the two) turns a check no-go when the later of
    them reaches its no-go change: each one's rule names its partner; the
    earlier waits for the later (``waits_for``); one whose partner does not
    trend that way (of the same regime) is "no trend", with the reason."""
    trending = {_symptom(p): p for p in out if p.forecast.trend}
    done = []
    for p in out:
        limit = r2.get(p.parameter.partition("@")[0])
        partners = (() if not isinstance(limit, NoGo) or not p.forecast.trend else
                    limit.rise_with if p.forecast.threshold > 0 else limit.fall_with)
        if not partners:
            done.append(p)
            continue
        regime = _symptom(p)[1]
        mates = [trending.get((s, regime)) for s in partners]
        missing = [s for s, m in zip(partners, mates) if m is None]
        if missing:
            why = (f"{p.rule} needs {' and '.join(missing)} too, which does not trend "
                   "towards its no-go")
            f = dataclasses.replace(p.forecast, model="no trend", remaining=None,
                                    p_within=None if p.forecast.p_within is None else 0.0,
                                    notes=(*p.forecast.notes, why), unreachable=why)
            done.append(dataclasses.replace(p, forecast=f, date=None, hours=None))
            continue
        later = max((m for m in mates if m is not None), key=_median)
        names = ", ".join(m.parameter for m in mates if m is not None)
        done.append(dataclasses.replace(
            p, rule=f"{p.rule}, with {names}",
            waits_for=later.parameter if _median(later) > _median(p) else ""))
    return done


def _overdue(out: list[ParameterForecast], axis: Axis, now: pd.Timestamp | None) -> str | None:
    """A note when the earliest median no-go date is already past: the
    forecast is of the checks stored, and the unit is due one."""
    dated = [(p.parameter, p.date) for p in out if p.date is not None]
    if not dated or not axis.dated or (out[0].forecast.remaining or (1.0,))[0] == 0:
        return None   # (due at its last check: that check's status says it)
    now = _utc(now)
    parameter, date = dated[0]
    if not _past(date, now):
        return None
    age = (now - axis.dates.max()).total_seconds() / 86400.0
    return (f"{parameter}'s median no-go date {date[:10]} is past: the last "
            f"check is {age:.0f} d old; check the unit again")


def remaining_text(f: dict[str, Any] | None, reason: str | None = None,
                   now: pd.Timestamp | None = None, past: bool = True) -> str:
    """A unit's earliest forecast (:meth:`UnitForecast.summary`) in a few
    words, as tables print it: ``12 d (11–13)`` (days), ``8.5 tests (6.1–∞)``;
    ``—`` without one (``no trend`` when ``reason`` says so); a median no-go
    date already past at ``now`` (default: the clock) says so (unless not
    ``past``: :func:`date_past` tells it): the unit is due a check.

    Example
    -------
    >>> remaining_text({"median": 12.1, "low": 11.1, "high": None, "by": "days"})
    '12 d (11–∞)'
    >>> remaining_text({"median": 12.1, "low": 11.1, "high": 13.0, "by": "days",
    ...                 "date": "2026-01-15T00:00:00+00:00"}, now=pd.Timestamp("2026-02-01"))
    '12 d (11–13), date past'
    """
    if not f:
        return "no trend" if reason == NO_TREND else "—"
    if f.get("at_no_go"):
        return "at no-go now"
    if f["high"] == 0:   # the trend is past no-go, its last check was not
        return "due now (its trend is past no-go)"

    def n(v: float | None) -> str:
        if v is None or not math.isfinite(v):
            return "∞"
        return f"{v:.0f}" if abs(v) >= 10 else f"{v:.2g}"

    per = {"days": "d", "hours": "h"}.get(f["by"], ("cycle" if f["median"] == 1 else "cycles")
                                          if f["by"] == "cycles" else
                                          "test" if f["median"] == 1 else "tests")
    flag = ", date past" if past and date_past(f, now) else ""
    return f"{n(f['median'])} {per} ({n(f['low'])}–{n(f['high'])}){flag}"


def date_past(f: dict[str, Any] | None, now: pd.Timestamp | None = None) -> bool:
    """Whether a forecast's (:meth:`UnitForecast.summary`) median no-go date
    is before ``now`` (default: the clock); False without a date."""
    if not f or not f.get("date"):
        return False
    return _past(str(f["date"]), now)


def _utc(when: Any) -> pd.Timestamp:
    """A time in UTC (a naive one taken as UTC; None: the clock)."""
    t = pd.Timestamp.now(tz="UTC") if when is None else pd.Timestamp(when)
    return t.tz_localize("UTC") if t.tzinfo is None else t


def _past(date: str, now: pd.Timestamp | None) -> bool:
    """Whether an ISO 8601 date is before ``now`` (default: the clock)."""
    return bool(_utc(date) < _utc(now))
