"""Checking one test: against the unit's own baseline, its group's, or another unit's.

A test is compared with the unit's own baseline when it has one; a unit
without one is judged against its group of peers (:mod:`condmon.monitor.group`:
the spread a new unit's test has among them), and ``against`` compares any
unit with another unit's or a group's baseline explicitly. A comparison with
another baseline is stored against a copy of it kept under the checked unit
(``group:NAME`` or ``unit:NAME``, not its active baseline), so the history says
exactly what the test was compared with; once the unit has a baseline of its
own, its checks are evaluated against that too.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import numpy as np
import pandas as pd

from condmon.diagnose.diagnoser import Diagnosis
from condmon.diagnose.rules import RuleBase, machine_rules
from condmon.errors import ConfigError, DataError
from condmon.identify.estimate import EstimateResult
from condmon.models.machine import Machine
from condmon.models.regimes import regime_key, split_key
from condmon.models.registry import get_model
from condmon.monitor.baseline import Baseline, missing_regimes
from condmon.monitor.fuzzy import MonitorConfig
from condmon.monitor.conditions import NOT_JUDGED, Conditioned, NotJudged, departures, explained
from condmon.monitor.generic import (
    judged_config, load_generic_settings, machine_monitor, peer_monitor, peer_spread,
)
from condmon.monitor.group import GroupBaseline, group_baseline
from condmon.monitor.statistics import (
    CheckStatistics, StatisticsConfig, check_statistics, checked_alpha,
)
from condmon.forecast.unit import in_test_order
from condmon.store.db import HistoryStore
from condmon.store.kept import keep_forecast
from condmon.workflows.monitoring import (
    _existing_baseline, _held, _unit_error, conditioning, current_baseline,
    estimate_judged, evaluate, filed_elsewhere, governed, monitoring_of, no_baseline_yet,
    restricted, save_current_baseline,
)
from condmon.workflows.cycles import one_cycle
from condmon.workflows.records import Cycle, EstimateOptions, RecordLike
from condmon.workflows.unit_model import session_timed, unit_options

__all__ = ["CheckResult", "check_test", "unit_statistics", "Reference", "reference_for", "resolve_against",
           "group_reference", "judgement_notes"]


@dataclass(frozen=True)
class CheckResult:
    """Outcome of checking one test against the unit's baseline.

    Attributes
    ----------
    unit : str
    test_id : int
    estimate : EstimateResult
    status : {"go", "advisory", "no-go", "retest"}
        "retest" when the test was rejected (fit below threshold): it is stored
        as rejected and changes no symptom or trend.
    baseline : Baseline or None
    percent_change : dict of str to float
        Against the baseline mean. [%]
    symptoms : dict
        ``{param: {"high", "low"}}`` before preprocessing.
    diagnosis : Diagnosis or None
    baseline_flags : tuple of dict
        Why the baseline may not be trustworthy (empty when nothing is suspicious).
    test_date : datetime or None
        When the test was run, if known (UTC).
    warning : str or None
        Something to look at (the same record already filed under another unit).
    note : str or None
        Regimes of the record with no baseline yet (not compared with another's).
    against : str
        What the test was compared with: ``unit`` (its own baseline),
        ``group NAME`` or ``unit NAME`` (another's).
    statistics : CheckStatistics or None
        The calibrated change and drift tests beside the status
        (:mod:`condmon.monitor.statistics`); None for a rejected test, or one
        compared with another's baseline.
    forecast : dict
        The unit's earliest forecast to no-go after this check, with the
        check counted: ``{"forecast", "forecast_reason"}``
        (:func:`condmon.store.forecasts.forecast_fields`; ``forecast`` None
        with fewer than 3 checks since the baseline, no trend, a dry run).
    not_judged : str or None
        Why the check is not judged (status ``not judged``): its operating
        conditions lie outside the range its baseline's tests span
        (:mod:`condmon.monitor.conditions`). Stored and shown, never trended.
    judgement : tuple of str
        How the change was judged, where it differs from the plain baseline:
        declared breakpoints raised to the healthy scatter, parameters fitted
        against the conditions.
    """

    unit: str
    test_id: int
    estimate: EstimateResult
    status: str
    baseline: Baseline | None = None
    percent_change: dict[str, float] = field(default_factory=dict)
    symptoms: dict[str, dict[str, float]] = field(default_factory=dict)
    diagnosis: Diagnosis | None = None
    baseline_flags: tuple[dict[str, Any], ...] = ()
    test_date: datetime | None = None
    warning: str | None = None
    note: str | None = None
    against: str = "unit"
    statistics: CheckStatistics | None = None
    forecast: dict[str, Any] = field(default_factory=dict)
    not_judged: str | None = None
    judgement: tuple[str, ...] = ()

    @property
    def summary(self) -> str:
        """One line: the diagnosis, or why the test is not judged or retested."""
        return (self.diagnosis.summary if self.diagnosis is not None else
                f"not judged: {self.not_judged}" if self.not_judged else
                f"retest: {self.estimate.reason}")

    def _repr_html_(self) -> str:
        from condmon.report.notebook import check_html

        return check_html(self.unit, self.test_id, self.status, self.summary,
                          self.estimate.stored_values(), self.estimate.units,
                          self.percent_change)

    def plot(self) -> Any:
        """Each parameter's change against the baseline [%], coloured by its
        own symptom. A matplotlib Figure."""
        from condmon.report.notebook import change_figure

        return change_figure(f"{self.unit}: {self.status}", self.percent_change,
                             self.symptoms, self.status)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready result (the ``condmon check --json`` document)."""
        est = self.estimate.to_dict()
        return {
            "unit": self.unit,
            "test_id": self.test_id,
            "source": self.estimate.source,
            "test_date": None if self.test_date is None else self.test_date.isoformat(),
            "status": self.status,
            "accepted": self.estimate.accepted,
            "reason": self.estimate.reason,
            "fit_percent": est["fit_percent"],
            "fits": est["fits"],
            "parameters": est["parameters"],
            "std_errors": est["std_errors"],
            "percent_change": self.percent_change,
            "symptoms": self.symptoms,
            "faults": ([] if self.diagnosis is None else
                       [f.to_dict() for f in self.diagnosis.faults]),
            "summary": self.summary,
            "not_judged": self.not_judged,
            "judgement": list(self.judgement),
            "conditions": est.get("conditions", {}),
            "systematic": est.get("systematic", {}),
            "candidates": ([] if self.diagnosis is None else
                           [c.to_dict() for c in self.diagnosis.candidates]),
            "undetermined": ([] if self.diagnosis is None else
                             [u.to_dict() for u in self.diagnosis.undetermined]),
            "unseen": ([] if self.diagnosis is None else
                       [u.to_dict() for u in self.diagnosis.unseen]),
            "regime": self.estimate.regime_label,
            "windows": est["windows"],
            "identifiable": {**est["identifiable"],
                             **{regime_key(k, o.regime): k in o.identified
                                for o in self.estimate.others for k in o.parameters}},
            "held": est["held"],
            "against": self.against,
            "statistics": None if self.statistics is None else self.statistics.to_dict(),
            "forecast": self.forecast.get("forecast"),
            "forecast_reason": self.forecast.get("forecast_reason", "not stored: a dry run"),
            "note": self.note,
            "condition": None if self.diagnosis is None else self.diagnosis.condition,
            "preprocessing_applied": ([] if self.diagnosis is None
                                      else list(self.diagnosis.applied)),
            "baseline": None if self.baseline is None else self.baseline.to_dict(),
            "baseline_flags": list(self.baseline_flags),
            "warning": self.warning,
            "method": est["method"],
            "closed_loop_instruments": est["closed_loop_instruments"],
            "notes": est["notes"],
        }


@dataclass(frozen=True)
class Reference:
    """A baseline a test is compared with other than the unit's own.

    Attributes
    ----------
    baseline : Baseline
        For a group, its :meth:`~condmon.monitor.group.GroupBaseline.predictive`.
    label : str
        ``group NAME`` or ``unit NAME``.
    name : str
        The name its copy is kept under in the checked unit's history
        (``group:NAME``, ``unit:NAME``).
    test_ids : tuple of int
        The tests behind it (of other units).
    group : GroupBaseline or None
        The group's baseline, for a group.
    """

    baseline: Baseline
    label: str
    name: str
    test_ids: tuple[int, ...]
    group: GroupBaseline | None = None


def resolve_against(store: HistoryStore, text: str) -> tuple[str, str]:
    """``("unit" | "group", name)`` of ``--against`` (a unit's or a group's
    name, or ``unit:NAME`` / ``group:NAME``).

    Raises
    ------
    DataError
        No such unit or group (the known ones named), or a name that is both.
    """
    kind, _, name = text.partition(":")
    if name and kind in ("unit", "group"):
        wanted: str | None = kind
    else:
        wanted, name = None, text
    units = set(store.units())
    groups = store.groups()
    is_unit, is_group = name in units, name in groups
    if wanted == "unit" and is_unit or (wanted is None and is_unit and not is_group):
        return "unit", name
    if wanted == "group" and is_group or (wanted is None and is_group and not is_unit):
        return "group", name
    if is_unit and is_group:
        raise DataError(f"--against {name!r} is both a unit and a group: write unit:{name} or "
                        f"group:{name}")
    raise DataError(f"--against {text!r}: no such {wanted or 'unit or group'}; units: "
                    f"{', '.join(sorted(units)[:10]) or 'none'}; groups: "
                    f"{', '.join(sorted(groups)) or 'none'}")


def group_reference(store: HistoryStore, group: str, model: str,
                    exclude: str | None = None) -> Reference:
    """The baseline of ``group`` for a unit of ``model`` (its units of that
    model with a baseline of their own, ``exclude`` left out).

    Raises
    ------
    DataError
        The group is unknown, or has too few units with a baseline.
    """
    groups = store.groups()
    if group not in groups:
        raise DataError(f"no group {group!r} in the history; groups: "
                        f"{', '.join(sorted(groups)) or 'none yet'} (put units in one with "
                        "--group NAME)")
    machine = get_model(model)
    members = {u: b for u, b in store.group_baselines(group).items()
               if u != exclude and store.unit_model(u) in (machine.name, machine.origin)}
    settings = load_generic_settings()
    left_out = (f"; {exclude!r} itself is left out of its group's baseline"
                if exclude is not None and exclude in groups[group] else "")
    if not members:
        raise DataError(f"group {group!r} has no unit of model {machine.name!r} with a "
                        f"baseline of its own (units: {', '.join(groups[group])}){left_out}; "
                        "add healthy tests to its units with `condmon baseline add`")
    try:
        g = group_baseline(group, {u: b.baseline for u, b in members.items()},
                           settings.group_min_units)
    except DataError as err:
        raise DataError(f"{err}{left_out}") from None
    ids = tuple(sorted({i for b in members.values() for i in b.test_ids}))
    return Reference(g.predictive(), f"group {group}", f"group:{group}", ids, g)


def reference_for(store: HistoryStore, unit: str, machine: Machine, against: str | None,
                  group: str | None) -> Reference | None:
    """What a test of ``unit`` is compared with: None for its own baseline,
    else the reference ``against`` names, or its group's when it has no
    baseline of its own."""
    if against is not None:
        kind, name = resolve_against(store, against)
        if kind == "group":
            return group_reference(store, name, machine.origin or machine.name, exclude=unit)
        if name == unit:
            raise ConfigError(f"--against {against}: that is the unit itself; a check is "
                              "judged against the unit's own baseline without --against")
        other = store.unit_model(name)
        if other not in (machine.name, machine.origin):
            raise DataError(f"--against unit {name!r} is monitored with model {other!r}; "
                            f"{unit!r} with {machine.name!r}")
        baseline, ids = current_baseline(store, name)
        return Reference(baseline, f"unit {name}", f"unit:{name}", tuple(ids))
    if _existing_baseline(store, unit) is not None:
        return None
    peers = group or store.unit_group(unit)
    if peers is None:
        return None
    return group_reference(store, peers, machine.origin or machine.name, exclude=unit)


def _forecast(store: HistoryStore, unit: str, dry_run: bool) -> dict[str, Any]:
    """The unit's earliest forecast to no-go, read after the check is stored."""
    return {} if dry_run else keep_forecast(store, unit)


def check_test(store: HistoryStore, unit: str, record: RecordLike | Cycle,
               options: EstimateOptions | None = None, monitor: MonitorConfig | None = None,
               rules: RuleBase | None = None, dry_run: bool = False,
               test_date: str | datetime | None = None, against: str | None = None,
               group: str | None = None, alpha: float | None = None,
               drift_alpha: float | None = None) -> CheckResult:
    """Estimate a test, store it, compute symptoms against the baseline and diagnose.

    The baseline is the unit's own; for a unit without one, its group's
    (``group``, or the one it is in); ``against`` names another unit or a
    group to compare with explicitly (a unit in that group is left out of
    it). The monitor breakpoints and the rule base are the model's own
    (declared in its ``[monitor]`` table; generic ones without it), unless
    given; against peers, the breakpoints are capped at the peers' spread
    (:func:`~condmon.monitor.generic.peer_monitor`). ``dry_run``: estimate and
    diagnose, store nothing (``test_id`` is -1; a record already in the
    history is checked again). ``test_date``: when the test was run
    (default: from the record's metadata, if any). ``group`` also puts the
    unit in that group (not on a dry run). ``alpha``, ``drift_alpha``: the
    false-alarm probabilities of the calibrated tests, in (0, 0.5) (default:
    the monitor file's ``[statistics]``).

    Raises
    ------
    DataError
        The unit has no baseline yet (fewer than 3 accepted healthy tests) and
        no group with one, the group or unit to compare with has none, or the
        test's parameters jump beyond the model's believable change or flip
        sign against the baseline (a likely unit or sign error; nothing stored),
        an alpha outside (0, 0.5).
    DuplicateTestError
        The record is already in the unit's history.
    """
    widened: tuple[str, ...] = ()
    override = {k: checked_alpha(v, f"--{k.replace('_', '-')}")
                for k, v in (("alpha", alpha), ("drift_alpha", drift_alpha)) if v is not None}
    opts = unit_options(store, unit, options or EstimateOptions())
    machine = get_model(opts.model or "dc-motor")
    if isinstance(record, Cycle) and machine.spec.cycle and not record.frames:
        record = one_cycle(opts, record)
    ref = reference_for(store, unit, machine, against, group)
    if ref is None:
        store.unit_id(unit)  # a unit not in the history: the close names, not "no tests yet"
        baseline, ids = current_baseline(store, unit)
        cfg, rb = monitoring_of(machine, baseline, monitor, rules)
        latest = store.latest_baseline(unit) if store.unit_model(unit) else None
        flags = latest.flags if latest is not None and list(latest.test_ids) == ids else ()
    else:
        baseline, ids = ref.baseline, list(ref.test_ids)
        if ref.group is None:   # one peer: as wide as two healthy units may differ
            baseline, widened = peer_spread(baseline, monitor or machine_monitor(machine))
        cfg, rb = monitoring_of(machine, baseline, monitor or peer_monitor(machine, baseline),
                                rules or machine_rules(machine))
        latest, flags = None, ()
    res, key, why = estimate_judged(opts, record, test_date, baseline)
    if why is not None:
        raise DataError(f"{res.source}: refused, {why}; nothing was stored")
    res = session_timed(store, unit, res, machine, key)
    against_label = "unit" if ref is None else ref.label
    if group is not None and not dry_run:  # the unit joins its group with its first test
        store.set_group(unit, group, model=machine.name, model_source=machine.origin)
    if not res.usable:
        tid = -1 if dry_run else store.add_test(unit, res, role="check", digest=key.content,
                                                file_digest=key.file,
                                                fingerprint=key.fingerprint,
                                                test_date=key.test_date, hours=key.hours)
        return CheckResult(unit, tid, res, "retest", baseline, baseline_flags=flags,
                           test_date=key.test_date, warning=filed_elsewhere(store, unit, key),
                           against=against_label, forecast=_forecast(store, unit, dry_run))
    held = {part.split(",")[0].strip() for part in res.regime.split(" + ")}
    if machine.spec.cycle and not held >= set(machine.spec.cycle) and not any(
            k in baseline.parameters for k in res.stored_values()):
        raise DataError(f"{res.source}: holds {res.regime or 'no regime'} only; a test of "
                        f"{machine.name} is one cycle ({', '.join(machine.spec.cycle)}: "
                        "[estimation] cycle): give the records of one cycle together; "
                        "nothing was stored")
    cond = conditioning(store, ids, baseline, res.conditions, machine,
                        peer=None if ref is None else ref.label,
                        group=ref is not None and ref.group is not None)
    judged = baseline if cond is None else cond.baseline
    if cond is not None and cond.not_judged is not None:
        return _not_judged(store, unit, res, key, cond, baseline, ids, ref, latest, flags, cfg,
                           against_label, dry_run, machine)
    judged_res = _with_peer_systematic(store, res, ids, ref)
    row, diag = evaluate(judged_res, judged, cfg, rb, machine.monitored)
    stats = (unit_statistics(store, unit, ids, baseline, res,
                             dataclasses.replace(cfg.statistics, **override), cond)
             if ref is None else None)
    if stats is not None:
        diag = governed(diag, stats, row, judged)
    missing = missing_regimes(list(res.stored_values()), baseline)
    note = no_baseline_yet(missing, baseline) if missing else None
    how = (*widened, *judgement_notes(judged_res, judged, cfg),
           *(cond.notes if cond is not None else ()),
           *(f"{p}: judged against its prediction at {', '.join(c)}"
             for p, c in (cond.fitted.items() if cond is not None else ())))
    if dry_run:
        tid = -1
    else:
        fresh = ref is None and (latest is None or list(latest.test_ids) != ids)
        bid, latest = _bid(store, unit, baseline, ids, ref, latest, cfg, machine)
        flags = latest.flags if fresh else flags
        tid = store.add_test(unit, res, role="check", digest=key.content, file_digest=key.file,
                             fingerprint=key.fingerprint, test_date=key.test_date, hours=key.hours,
                             symptoms=row, baseline_id=bid, diagnosis=diag)
    return CheckResult(unit, tid, res, diag.status, baseline,
                       {p: v["percent_change"] for p, v in row.items()},
                       {p: {"high": v["high"], "low": v["low"]} for p, v in row.items()},
                       diag, flags, key.test_date, filed_elsewhere(store, unit, key), note,
                       against_label, stats, _forecast(store, unit, dry_run), None, how)


def _with_peer_systematic(store: HistoryStore, res: EstimateResult, ids: Sequence[int],
                          ref: Reference | None) -> EstimateResult:
    """``res`` as a check against one other unit is judged: its systematic part
    with the peer's (the median over the peer's baseline tests; the check's own
    where the peer has none stored) in root-sum-square. Two units read through
    two sets of sensors, each within its stated accuracy: their difference may
    hold both drifts. A group's measured spread between units holds its
    members' already; against the unit's own baseline the sensors are the
    same ones."""
    if ref is None or ref.group is not None or not res.systematic:
        return res
    from condmon.monitor.generic import typical_systematic

    peer = typical_systematic(store.systematic_of(list(ids)).add_suffix("_sys"))
    return dataclasses.replace(res, systematic={
        k: math.hypot(v, peer.get(k, v)) for k, v in res.systematic.items()})


def _bid(store: HistoryStore, unit: str, baseline: Baseline, ids: list[int],
         ref: Reference | None, latest: Any, cfg: MonitorConfig, machine: Machine
         ) -> tuple[int, Any]:
    """The stored baseline version a check is evaluated against (saved when new);
    a unit new to the history (checked against another) is made with
    ``machine``'s model first."""
    if ref is not None:   # a unit checked against another may be new
        store.unit_id(unit, create=True, model=machine.name, model_source=machine.origin)
        return store.save_baseline(unit, baseline, ids, name=ref.name, activate=False,
                                   reason=f"compared with {ref.label}"), latest
    if latest is None or list(latest.test_ids) != ids:
        latest, _ = save_current_baseline(store, unit, ids, monitor=cfg,
                                          reason="baseline of the first check")
    return int(latest.id), latest


def _not_judged(store: HistoryStore, unit: str, res: EstimateResult, key: Any,
                cond: Conditioned, baseline: Baseline, ids: list[int], ref: Reference | None,
                latest: Any, flags: tuple[dict[str, Any], ...], cfg: MonitorConfig,
                against: str, dry_run: bool, machine: Machine) -> CheckResult:
    """A check whose conditions its baseline does not span: stored with the
    reason (status ``not judged``), no symptom, never trended."""
    reason = str(cond.not_judged)
    tid = -1
    if not dry_run:
        bid, latest = _bid(store, unit, baseline, ids, ref, latest, cfg, machine)
        flags = flags if ref is not None or latest is None else latest.flags
        tid = store.add_test(unit, res, role="check", digest=key.content, file_digest=key.file,
                             fingerprint=key.fingerprint, test_date=key.test_date,
                             hours=key.hours, baseline_id=bid, diagnosis=NotJudged(reason))
    return CheckResult(unit, tid, res, NOT_JUDGED, baseline, baseline_flags=flags,
                       test_date=key.test_date, warning=filed_elsewhere(store, unit, key),
                       against=against, forecast=_forecast(store, unit, dry_run),
                       not_judged=reason, judgement=cond.notes)


def judgement_notes(res: EstimateResult, baseline: Baseline, monitor: MonitorConfig
                    ) -> tuple[str, ...]:
    """The declared breakpoints a check's change is not judged with: raised to
    the healthy scatter with its systematic part (see
    :func:`~condmon.monitor.generic.judged_config`)."""
    keys = [k for k in baseline.parameters if k in res.stored_values()]
    if not keys:
        return ()
    cfg, raised = judged_config(monitor, restricted(baseline, keys),
                                {k: res.systematic[k] for k in keys if k in res.systematic})
    if monitor.sigmas is None:
        return raised
    # against peers: where the breakpoints lie, and why (peer_monitor)
    return (*raised, "breakpoints against the peers: " + ", ".join(
        f"{k} {cfg.r1[k]:.3g}/{cfg.r2[k]:.3g} %" for k in keys) + f" ({monitor.sigmas[0]:.3g} "
        f"and {monitor.sigmas[1]:.3g} spreads, at α {monitor.statistics.alpha:g} over "
        f"{len(baseline.parameters)} values, plus the sensors' accuracy)")


def unit_statistics(store: HistoryStore, unit: str, ids: list[int], baseline: Baseline,
                    res: EstimateResult, config: StatisticsConfig,
                    conditioned: Conditioned | None = None) -> CheckStatistics | None:
    """The calibrated tests of a check of ``unit`` against its own baseline (tests
    ``ids``), before it is stored: its change against the baseline's scatter,
    and the drift of the accepted checks since the baseline's last test and it.

    A test's parameters of one regime are tested with that regime's; None when
    fewer than 3 baseline tests have every parameter the test has. With the
    baseline fitted against operating conditions (``conditioned``), the
    change is the check's departure from its prediction, the baseline's
    scatter is its tests' about the fit, and the drift is that of the
    checks' departures from theirs.
    """
    stored = res.stored_values()
    keys = [k for k in baseline.parameters
            if k in stored and np.isfinite(stored[k][0]) and np.isfinite(stored[k][1])]
    hist = store.history(unit)
    if not keys or not set(keys) <= set(hist.columns):
        return None
    mean = np.array([baseline.value(k) for k in keys], dtype=np.float64)
    scale = 100.0 / np.abs(mean)

    def changes(rows: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
        vals = rows[keys].to_numpy(dtype=np.float64)
        ses = rows[[f"{k}_se" for k in keys]].to_numpy(dtype=np.float64)
        ok = np.isfinite(vals).all(axis=1) & np.isfinite(ses).all(axis=1)
        return (vals[ok] - mean) * scale, ses[ok] * scale

    members = hist.loc[[i for i in ids if i in hist.index]]
    base, base_se = changes(members)
    fitted = conditioned is not None and bool(conditioned.fitted)
    conds = store.conditions_of(list(members.index))[0] if fitted else pd.DataFrame()
    if fitted:
        vals = members[keys].to_numpy(dtype=np.float64)
        ok = np.isfinite(vals).all(axis=1) & np.isfinite(
            members[[f"{k}_se" for k in keys]].to_numpy(dtype=np.float64)).all(axis=1)
        resid = explained(vals, keys, {str(c): conds[c].to_numpy(dtype=np.float64)
                                       for c in conds.columns})
        base = (resid[ok] - mean) * scale
    if len(base) < 3:
        return None
    usable = (hist["role"] == "check") & hist["accepted"].astype(bool) \
        & ~hist["excluded"].astype(bool) & (hist["status"] != "not judged")
    since = in_test_order(hist[usable & (hist.index > max(ids))])   # as they were tested
    series, _ = changes(since)
    if fitted and len(since):
        # the checks' drift with what their conditions explain taken out
        base_c = conds
        since_c = store.conditions_of(list(since.index))[0]
        rows = since[keys].to_numpy(dtype=np.float64)
        ok = np.isfinite(rows).all(axis=1) & np.isfinite(
            since[[f"{k}_se" for k in keys]].to_numpy(dtype=np.float64)).all(axis=1)
        moved = departures(members[keys].to_numpy(dtype=np.float64), keys,
                           {str(c): base_c[c].to_numpy(dtype=np.float64)
                            for c in base_c.columns},
                           rows, {str(c): since_c[c].to_numpy(dtype=np.float64)
                                  for c in since_c.columns})
        series = (moved[ok] - mean) * scale
    centre = (np.array([conditioned.baseline.value(k) for k in keys], dtype=np.float64)
              if fitted and conditioned is not None else mean)
    now = np.array([stored[k][0] for k in keys]) - centre
    now_se = np.array([stored[k][1] for k in keys]) * scale
    return check_statistics(tuple(keys), now * scale, now_se, base, base_se,
                            np.vstack([series, now * scale]), config)
