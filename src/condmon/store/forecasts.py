"""A unit's forecasts to no-go, read from the history (the store-level reader).

:func:`read_forecast` gathers what :func:`condmon.forecast.unit.
forecast_checks` needs from the store (the current baseline, the checks since
it, the model's breakpoints and fault rules) and forecasts; ``condmon
forecast``, ``condmon check``, the report and the fleet page all forecast
through it. What is kept of the forecasts, for the listings and the next
checks, is :mod:`condmon.store.kept`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from condmon.errors import CondmonError, DataError
from condmon.monitor.baseline import MIN_BASELINE_TESTS, Baseline
from condmon.forecast.calibration import MIN_PEERS, Calibration, calibrate, life_of, path_scores
from condmon.forecast.path import PATH_MIN_TESTS, Life
from condmon.forecast.prior import FleetPrior, UnitWear, prior_from_wear, unit_wear
from condmon.forecast.unit import (
    NO_TREND, NoGo, UnitForecast, forecast_axis, forecast_checks, in_test_order,
    parameter_series,
)
from condmon.store.baselines import baseline_members, current_baseline
from condmon.store.states import DEGRADED

if TYPE_CHECKING:
    from condmon.models.indicators import IndicatorModel
    from condmon.models.machine import Machine
    from condmon.store.db import HistoryStore

__all__ = ["read_forecast", "try_forecast", "forecast_fields", "machine_nogo",
           "NO_BASELINE", "FleetHistory", "DEGRADED", "prior_units", "UNFITTED"]

#: Why a unit without a baseline in use has no forecast.
NO_BASELINE = "no baseline yet"


class FleetHistory:
    """The units that have already degraded, read once for many forecasts.

    A unit has degraded when one of its accepted checks was advisory or
    no-go; its change series since its current baseline give the prior on
    the degradation of a unit of the same model (and group, when the unit is
    in one): its shape (how many peers wore exponentially) and each shape's
    rate (:func:`condmon.forecast.prior.prior_from_wear`), each unit left out
    of its own prior. What is read of them does not grow with the fleet: their
    counts by model and group (one aggregate), whether the units at hand
    have degraded, and the most recently changed peers a prior learns from
    (``[forecast] prior_units``), each one's wear fitted once, or read back
    from its kept forecast.

    ``fit_peers=False`` (a check): a peer whose wear is not kept, or kept by
    an older method or before its latest check, is left out of the prior
    (:attr:`unfitted`), not fitted from its history: a check's cost does not
    depend on what was kept. ``condmon forecast`` and the listings fit them
    and keep them.
    """

    def __init__(self, store: HistoryStore, fit_peers: bool = True) -> None:
        self.store = store
        self.fit_peers = fit_peers
        self.unfitted: set[str] = set()   # peers left out: their wear is not kept
        self._checks: dict[str, tuple[Baseline, pd.DataFrame]] = {}
        self._flags: dict[str, bool] = {}
        self._counts: dict[tuple[str, str | None], int] | None = None
        self._wear: dict[tuple[str, str, str], UnitWear | None] = {}
        self._kept: set[str] = set()
        self._current: set[str] = set()   # peers whose kept rates are up to date
        self._limit = 0
        self._recent: dict[tuple[str, str | None], list[str]] = {}
        self._pits: dict[tuple[str, str, tuple[Life, ...]],
                         list[tuple[float, float, float, float]]] = {}
        self._series: dict[str, tuple[str, dict[str, tuple[Any, Any, float]]]] = {}
        self._lives: dict[tuple[str, str], Life | None] = {}
        self._fitted: set[str] = set()   # wear fitted here from a history, not read back

    def know(self, units: Sequence[str]) -> None:
        """Read whether each of ``units`` has degraded, in one query (a page's
        units, before each is asked :meth:`degraded`)."""
        todo = [u for u in dict.fromkeys(units) if u not in self._flags]
        if todo:
            found = self.store.degraded_among(todo)
            self._flags.update({u: u in found for u in todo})

    def degraded(self, unit: str) -> bool:
        """Whether ``unit`` has degraded (its rates teach its peers)."""
        if unit not in self._flags:
            self.know([unit])
        return self._flags[unit]

    def learning_peers(self, unit: str) -> list[str]:
        """The peers the prior learns from: the most recently changed
        ``[forecast] prior_units`` of the degraded units of ``unit``'s model
        (and group), ``unit`` left out (``generic-monitor.toml``), so a
        forecast's cost does not grow with the fleet; their kept rates
        (:meth:`rates_of`, kept with their forecasts) are read in one query."""
        # peers share the model's stored name (a declaration's file may differ per unit)
        model, group = self.store.unit_model_name(unit), self.store.unit_group(unit)
        self._limit = self._limit or prior_units()
        key = (str(model), group)
        if key not in self._recent:   # one more: the unit itself may be among them
            self._recent[key] = self.store.recent_degraded(str(model), group, self._limit + 1)
        chosen = [p for p in self._recent[key] if p != unit][:self._limit]
        fresh = [p for p in chosen if p not in self._kept]
        if fresh:
            marks = self.store.history_marks(fresh)
            for p, (mark, rates) in self.store.kept_rates(fresh).items():
                # unchanged since, and kept whole (rates kept before the curves' origin
                # was are read again): its wear, whatever is asked
                if mark == marks.get(p, 0) and all(v is None or len(v) >= 8
                                                   for v in rates.values()):
                    self._current.add(p)
                    for k, v in rates.items():
                        by, name = k.split("|", 1)
                        self._wear[(p, name, by)] = _wear_from(v)
        self._kept.update(fresh)
        if not self.fit_peers:
            self.unfitted.update(p for p in chosen if p not in self._current)
            chosen = [p for p in chosen if p in self._current]
        return sorted(chosen)

    def fitted(self) -> list[str]:
        """The units whose wear this object fitted from their histories
        (their kept rates were missing or stale), in name order."""
        return sorted(self._fitted)

    def rates_of(self, unit: str) -> dict[str, list[Any] | None] | None:
        """``unit``'s own wear, ``{"<by>|<parameter>": [exponential weight,
        [slope, variance], [growth rate, variance] or None, [amplitude,
        variance] or None, [slope at the origin, variance] or None, [bend,
        variance] or None, span, direction]}``
        (:class:`UnitWear`)
        (None when it has not degraded or has no checks since its baseline):
        what is kept with its forecast for its peers' priors."""
        if not self.degraded(unit):
            return None
        try:
            baseline, checks = self.checks(unit)
        except CondmonError:
            return None
        if not len(checks):
            return None
        by = forecast_axis(checks).by
        return {f"{by}|{key}": None if (w := self._unit_wear(unit, key, by)) is None else
                [w.exponential_weight, list(w.linear),
                 None if w.exponential is None else list(w.exponential),
                 None if w.amplitude is None else list(w.amplitude),
                 None if w.start is None else list(w.start),
                 None if w.bend is None else list(w.bend), w.span, w.direction]
                for key in baseline.parameters}

    def checks(self, unit: str) -> tuple[Baseline, pd.DataFrame]:
        """The unit's current baseline and its accepted checks since it.

        Raises
        ------
        DataError
            The unit has no baseline (:func:`~condmon.store.baselines.current_baseline`).
        """
        if unit not in self._checks:
            baseline, ids = current_baseline(self.store, unit)
            hist = self.store.history(unit)
            checks = hist[(hist["role"] == "check") & hist["accepted"].astype(bool)
                          & ~hist["excluded"].astype(bool)
                          & (hist["status"] != "not judged")]   # no change measured
            self._checks[unit] = (baseline, in_test_order(
                checks[[i not in ids for i in checks.index]]))
        return self._checks[unit]

    def peer_count(self, unit: str, model: str | None = None, group: str | None = None) -> int:
        """How many units of ``unit``'s model (and group) have degraded,
        ``unit`` left out (``model`` and ``group``: the unit's, when known;
        its model's stored name, not a declaration's file)."""
        if model is None:
            model, group = self.store.unit_model_name(unit), self.store.unit_group(unit)
        if self._counts is None:
            self._counts = self.store.degraded_counts()
        n = sum(k for (m, g), k in self._counts.items()
                if m == str(model) and (group is None or g == group))
        return n - int(self.degraded(unit))

    def _unit_wear(self, unit: str, key: str, by: str) -> UnitWear | None:
        if unit in self._current:   # its kept rates are all it has: another axis, none
            return self._wear.get((unit, key, by))
        if (unit, key, by) not in self._wear:
            found = None
            try:
                baseline, checks = self.checks(unit)
            except CondmonError:   # no baseline now: nothing to learn from
                checks = pd.DataFrame()
            if len(checks):
                axis = forecast_axis(checks)
                series = parameter_series(checks, baseline, key, axis) \
                    if axis.by == by else None
                found = None if series is None else unit_wear(*series[0])
                self._fitted.add(unit)
            self._wear[(unit, key, by)] = found
        return self._wear[(unit, key, by)]

    def calibrations(self, unit: str, by: str | None = None) -> dict[str, Calibration]:
        """The recalibration of each indicator's path forecast for ``unit``
        from its failed peers (:mod:`condmon.forecast.calibration`): where
        their true lives fell in the forecasts made along their own series,
        each to its own end of life. The peers are :meth:`learning_peers`,
        at most :data:`CALIBRATION_PEERS` of them; an indicator whose peers
        give fewer than :data:`~condmon.forecast.calibration.MIN_PITS`
        forecasts gets none. The peers counted ``by`` the unit's axis also
        lend their whole lives as the prior of its forecast
        (:func:`~condmon.forecast.path.with_fleet`), and of each other's along
        theirs."""
        series = {p: self._peer_series(p) for p in self.learning_peers(unit)[:CALIBRATION_PEERS]}
        same = _repeats(series, self._peer_series(unit)[1])
        series = {p: (axis, {k: s for k, s in found.items() if p not in same.get(k, ())})
                  for p, (axis, found) in series.items()}
        lives: dict[str, dict[str, Life]] = {}   # per indicator, the lives counted ``by``
        for p, (axis, found) in series.items():
            for key in found:
                if axis == by and (life := self._life(p, key)) is not None:
                    lives.setdefault(key, {})[p] = life
        pits: dict[str, list[tuple[float, float, float, float]]] = {}
        names: dict[str, list[str]] = {}
        apart: dict[str, int] = {}
        for p, (axis, found) in series.items():
            for key, s in found.items():
                mine = lives.get(key, {})
                # the other peers' lives, as the unit's forecast takes them (or none)
                others = tuple(life for q, life in mine.items() if q != p) \
                    if p in mine and len(mine) >= MIN_PEERS else ()
                if (p, key, others) not in self._pits:
                    self._pits[(p, key, others)] = path_scores(*s, lives=others)
                if self._pits[(p, key, others)]:   # a peer short of its end teaches no life
                    pits.setdefault(key, []).extend(self._pits[(p, key, others)])
                    names.setdefault(key, []).append(p)
                    apart[key] = apart.get(key, 0) + int(axis != by)
        return {k: c for k, v in pits.items() if (c := calibrate(
            v, len(names[k]), list(lives.get(k, {}).values()), names[k], apart[k],
            sorted(same.get(k, ())))) is not None}

    def _life(self, peer: str, key: str) -> Life | None:
        """A peer's whole life in ``key`` (:func:`~condmon.forecast.calibration.life_of`),
        fitted once."""
        if (peer, key) not in self._lives:
            self._lives[(peer, key)] = life_of(*self._peer_series(peer)[1][key])
        return self._lives[(peer, key)]

    def _peer_series(self, peer: str) -> tuple[str, dict[str, tuple[Any, Any, float]]]:
        """A peer's axis and, per indicator, its change series and end of life."""
        if peer not in self._series:
            found: dict[str, tuple[Any, Any, float]] = {}
            by = ""
            try:
                model = self.store.indicator_model(peer)
                baseline, checks = self.checks(peer) if model is not None else (None, None)
            except CondmonError:
                model = None
            if model is not None and baseline is not None and checks is not None \
                    and len(checks):
                axis = forecast_axis(checks)
                by = axis.by
                nogo, _ = indicator_nogo(model, baseline)
                for key, limit in nogo.items():
                    series = parameter_series(checks, baseline, key, axis)
                    if series is None:
                        continue
                    (x, change, _, _), _ = series
                    way = -1.0 if math.isinf(limit.rise) else 1.0
                    found[key] = (x, change, way * limit.r2)
            self._series[peer] = (by, found)
        return self._series[peer]

    def priors(self, unit: str, keys: Sequence[str], by: str
               ) -> dict[str | tuple[str, float], FleetPrior]:
        """The fleet prior (shape and rates) of each parameter key for
        ``unit`` and each way it may head, ``{(key, +1.0): the peers whose
        key rose, (key, -1.0): those whose key fell}``, its x counting ``by``
        (``tests``, ``days`` or ``hours``; peers counted otherwise are left
        out); vague ("no fleet history") when no peer's key wore that way,
        and each shape's rate vague when fewer than 2 peers wore that way."""
        peers = self.learning_peers(unit)
        out: dict[str | tuple[str, float], FleetPrior] = {}
        per = by[:-1] if by != "hours" else "h"
        for key in keys:
            wears = [r for p in peers if (r := self._unit_wear(p, key, by)) is not None]
            for way in (1.0, -1.0):
                out[(key, way)] = prior_from_wear(wears, per, way) if wears or not peers else \
                    FleetPrior.vague(per, f"none of {len(peers)} degraded peer(s) has {key} "
                                          f"counted in {by}")
                if self.unfitted:   # said, whether the others teach or not
                    why = UNFITTED.format(len(self.unfitted))
                    out[(key, way)] = FleetPrior.vague(per, why) if not peers else \
                        dataclasses.replace(out[(key, way)], why=why)
        return out


#: Why a check's prior left its peers out (:class:`FleetHistory`, ``fit_peers=False``).
UNFITTED = ("the wear of {} degraded peer(s) is not kept yet (the forecast method changed, or "
            "the history was copied): left out of this check's forecast; `condmon forecast` "
            "or `condmon units` fits and keeps it")

#: Most failed peers a path forecast is recalibrated on (20 forecasts along
#: each: 100 PITs place the 5 % and 95 % points to about ±2 %).
CALIBRATION_PEERS = 5


def _repeats(series: dict[str, tuple[str, dict[str, tuple[Any, Any, float]]]],
             own: dict[str, tuple[Any, Any, float]]) -> dict[str, set[str]]:
    """Per indicator, the peers whose change series repeats an earlier
    peer's (by name), or begins with the unit's own whole series (of
    :data:`~condmon.forecast.path.PATH_MIN_TESTS` checks or more): one unit
    imported twice lends no second life, and its own future is no prior of
    itself. Two units' readings agree to the last digit at every check only
    when they are one unit's."""
    out: dict[str, set[str]] = {}
    seen: dict[str, set[tuple[bytes, bytes]]] = {}
    for p in sorted(series):
        for key, (x, y, _) in series[p][1].items():
            xa, ya = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
            mark = (xa.tobytes(), ya.tobytes())
            mine = own.get(key)
            n = 0 if mine is None else len(mine[0])
            if mark in seen.setdefault(key, set()) or (
                    mine is not None and PATH_MIN_TESTS <= n <= xa.size
                    and np.array_equal(xa[:n], mine[0]) and np.array_equal(ya[:n], mine[1])):
                out.setdefault(key, set()).add(p)
            seen[key].add(mark)
    return out


def read_forecast(store: HistoryStore, unit: str, horizon: float | None = None,
                  seed: int = 0, fleet: FleetHistory | None = None) -> UnitForecast:
    """Forecast every parameter of ``unit`` to no-go, from its checks since its
    current baseline (accepted, not excluded), against its model's ``r2``,
    each rate updating the fleet's prior (:class:`FleetHistory`; vague, and
    said, with no fleet history).

    Parameters
    ----------
    store : HistoryStore
    unit : str
    horizon : float, optional
        For the probability of crossing within it. [tests (or d)]
    seed : int
        Seed of the predictive draws.
    fleet : FleetHistory, optional
        The fleet's degraded units, when many units are forecast at once.

    Raises
    ------
    DataError
        No baseline, fewer than 3 checks since it ("not enough tests to
        forecast"), a horizon <= 0.
    ConfigError
        An unknown unit (the message names the close ones).
    """
    from condmon.models.registry import get_model

    store.unit_id(unit)  # an unknown unit: the close names
    fleet = fleet or FleetHistory(store)
    try:
        baseline, checks = fleet.checks(unit)
    except DataError:   # no baseline: say why when the unit's records are isolated instead
        if _isolated_only(store, unit):
            raise DataError(f"{unit}: {ISOLATED}") from None
        raise
    indicators = store.indicator_model(unit)
    if indicators is not None:
        nogo, rules = indicator_nogo(indicators, baseline)
        return forecast_checks(unit, checks, baseline, nogo, rules, indicators.units, horizon,
                               seed, None, method=indicators.method,
                               calibrations=fleet.calibrations(
                                   unit, forecast_axis(checks).by if len(checks) else None)
                               if indicators.method == "path" else None)
    machine = get_model(store.unit_model(unit) or "dc-motor")
    priors = (fleet.priors(unit, baseline.parameters, forecast_axis(checks).by)
              if len(checks) else {})
    from condmon.monitor.generic import typical_systematic

    nogo, rules = machine_nogo(machine, baseline, typical_systematic(checks))
    return forecast_checks(unit, checks, baseline, nogo, rules, machine.monitored_units,
                           horizon, seed, priors)


def indicator_nogo(model: IndicatorModel, baseline: Baseline
                   ) -> tuple[dict[str, NoGo], dict[str, str]]:
    """Where each imported indicator turns a check no-go: its end of life
    as a change from the baseline's mean, crisp (no symptom width, degree
    1), the other way never; and the fault each names. [%]

    Example
    -------
    >>> from condmon.models.indicators import Indicator, IndicatorModel, parse_end_of_life
    >>> m = IndicatorModel("cell", (Indicator("capacity", "Ah", parse_end_of_life(
    ...     "< 1.4", "capacity", "Ah"), fault="capacity fade"),))
    >>> nogo, rules = indicator_nogo(m, Baseline(("capacity",), (2.0,), (0.01,), 5))
    >>> round(nogo["capacity"].r2, 6), round(nogo["capacity"].towards(False, [0.0], 0.5)[0], 6)
    (30.0, -30.0)
    >>> rules
    {'low(capacity)': 'capacity fade at < 1.4 Ah'}
    """
    out, rules = {}, {}
    for ind in model.indicators:
        if ind.name not in baseline.parameters:
            continue
        mean = float(baseline.mean[baseline.parameters.index(ind.name)])
        end = ind.end_of_life.change(mean, ind.rated)
        if not math.isfinite(end) or end == 0:
            continue
        below = end < 0
        out[ind.name] = NoGo(abs(end), abs(end), 0.0, math.inf if below else 1.0,
                             1.0 if below else math.inf)
        level = ind.end_of_life.level(mean, ind.rated)
        rules[f"{'low' if below else 'high'}({ind.name})"] = (
            f"{ind.fault} at {'<' if below else '>'} {level:.4g} {ind.unit}".rstrip())
    return out, rules


def machine_nogo(machine: Machine, baseline: Baseline | None = None,
                 systematic: Mapping[str, float] | None = None
                 ) -> tuple[dict[str, NoGo], dict[str, str]]:
    """Where each of a machine's parameters turns a check no-go on its own
    (:class:`~condmon.forecast.unit.NoGo`: its breakpoints and symptom
    width from its monitor, the diagnoser's no-go degree when a major rule
    names its rise or fall, alone or with another symptom (``low(Ke) and
    low(Kt)``: the partner is kept, :func:`~condmon.diagnose.diagnoser.joint_faults`),
    its plausible values), and the rule each one-symptom condition names
    (``{"high(D)": "friction increase", "low(Ke)": "magnet weakening"}``).
    Against a baseline, the breakpoints are the ones its checks are judged
    with (:func:`~condmon.monitor.generic.with_scatter`), with the checks'
    ``systematic`` parts. [parameter units]"""
    from condmon.diagnose.diagnoser import joint_faults, nogo_degree, single_faults
    from condmon.diagnose.rules import machine_rules
    from condmon.monitor.generic import machine_monitor, with_scatter

    rb = machine_rules(machine)
    named = single_faults(rb)
    joint = joint_faults(rb)
    degree = nogo_degree(rb)
    cfg = machine_monitor(machine, baseline)
    if baseline is not None:   # the breakpoints its checks are judged with
        cfg = with_scatter(cfg, baseline, systematic)
    bounds = machine.spec.plausibility.bounds
    out = {}
    for name, r2 in cfg.r2.items():
        sides, partners = [], []
        base = name.split("@", 1)[0]   # a regime's parameter takes its parameter's rules
        for s in (f"high({base})", f"low({base})"):   # a major rule alone, or with a partner
            major = (f := named.get(s)) is not None and f.severity == "major"
            sides.append(degree if major or s in joint else math.inf)
            partners.append(joint[s][1] if s in joint else ())
        lower, upper = -math.inf, math.inf
        for op, value in (bounds[base].limits if base in bounds else ()):
            if op in ("gt", "ge"):
                lower = max(lower, value)
            else:
                upper = min(upper, value)
        out[name] = NoGo(cfg.r1[name], r2, cfg.k, sides[0], sides[1], lower, upper,
                         partners[0], partners[1])
    # a joint rule names a symptom only where no major rule names it alone
    return out, {**{k: f.name for k, f in named.items()},
                 **{k: f.name for k, (f, _) in joint.items()}}


#: Why a unit with isolations (a plant model run beside it) and no tests has no forecast.
ISOLATED = ("its records are isolated against a plant model, not estimated; forecasts "
            "follow the parameters of estimated tests")


def _isolated_only(store: HistoryStore, unit: str, summary: dict[str, Any] | None = None
                   ) -> bool:
    row = [summary] if summary is not None else store.unit_summaries([unit])
    return bool(row) and not row[0]["tests"] and bool(row[0]["isolations"])


def try_forecast(store: HistoryStore, unit: str, fleet: FleetHistory | None = None,
                 summary: dict[str, Any] | None = None
                 ) -> tuple[UnitForecast | None, str | None]:
    """:func:`read_forecast`, or why there is none: ``(forecast, None)`` or
    ``(None, reason)`` (no baseline yet, too few usable healthy tests for
    one, not enough tests to forecast, the model cannot be loaded); never raises a :class:`~condmon.errors.CondmonError`.

    ``summary``, the unit's entry of :meth:`HistoryStore.unit_summaries` when
    the caller has it, spares a unit without tests two queries (a listing of a
    fleet of plant units is then one query, not two a unit).
    """
    if summary is not None and not summary["tests"]:
        usable = 0
    else:
        usable = 0 if store.unit_model(unit) is None else len(baseline_members(store, unit)[0])
    if usable < MIN_BASELINE_TESTS:
        if not usable and _isolated_only(store, unit, summary):
            return None, ISOLATED
        return None, NO_BASELINE if not usable else (
            f"no baseline: {usable} usable healthy test(s), a baseline needs "
            f"{MIN_BASELINE_TESTS}")
    try:
        return read_forecast(store, unit, fleet=fleet), None
    except CondmonError as err:
        return None, str(err)


def forecast_fields(res: UnitForecast | None, reason: str | None) -> dict[str, Any]:
    """``{"forecast", "forecast_reason"}`` of a unit's listing (and of ``check --json``).

    ``forecast`` is the earliest forecast to no-go
    (:meth:`~condmon.forecast.unit.UnitForecast.summary`:
    ``parameter, unit, by, median, low, high, date, rule``) or None;
    ``forecast_reason`` says why it is None (``no baseline yet``, ``not
    enough tests to forecast: ...``, ``no trend towards no-go``), else None.
    """
    summary = None if res is None else res.summary()
    why = reason if res is None else (NO_TREND if summary is None else None)
    return {"forecast": summary, "forecast_reason": why}


def _wear_from(kept: Any) -> UnitWear | None:
    """A kept :class:`UnitWear` (:meth:`FleetHistory.rates_of`) back."""
    if kept is None:
        return None
    weight, linear, exponential, amplitude, start, bend, span, direction = kept

    def pair(v: Any) -> tuple[float, float] | None:
        return None if v is None else (float(v[0]), float(v[1]))

    return UnitWear(float(weight), (float(linear[0]), float(linear[1])), pair(exponential),
                    pair(amplitude), pair(start), pair(bend),
                    None if span is None else float(span), float(direction))


def prior_units() -> int:
    """How many degraded peers a fleet prior learns from at most
    (``[forecast] prior_units`` of ``condmon/data/generic-monitor.toml``)."""
    from condmon.errors import ConfigError
    from condmon.io.config import load_default

    raw = load_default("generic-monitor.toml").get("forecast", {}).get("prior_units", 20)
    if isinstance(raw, bool) or not isinstance(raw, int) or raw < 2:
        raise ConfigError(f"condmon/data/generic-monitor.toml: [forecast] prior_units = {raw!r}:"
                          " a whole number >= 2")
    return raw
