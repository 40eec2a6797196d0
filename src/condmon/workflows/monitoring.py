"""The flow of one test (SPEC A8), as library functions the CLI calls.

run test -> estimate -> fit >= threshold? (else store as rejected and report)
-> physical parameters -> store in history -> symptoms against the baseline
-> diagnose -> go / advisory / no-go for the operator, faults for maintenance.

A unit's baseline is a named, versioned set of tests in the store; a check is
evaluated against its latest version (see :mod:`condmon.workflows.manage` for
excluding tests and rebuilding baselines).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from condmon.diagnose.diagnoser import Diagnosis, diagnose
from condmon.diagnose.rules import RuleBase, machine_rules
from condmon.errors import CondmonError, DataError, EstimationError, MissingColumnsError
from condmon.identify.estimate import EstimateResult
from condmon.io.dates import parse_date
from condmon.io.readers import check_record_path
from condmon.models.machine import Machine
from condmon.models.regimes import split_key
from condmon.models.registry import get_model
from condmon.monitor.baseline import (
    MIN_BASELINE_TESTS, Baseline, assess_baseline, baseline_scatter, missing_regimes,
)
from condmon.monitor.conditions import Conditioned, NotJudged, conditioned_baseline, explained
from condmon.monitor.fuzzy import MonitorConfig, compute_symptoms
from condmon.monitor.statistics import (
    CheckStatistics, StatisticsConfig, check_statistics, governed_status,
)
from condmon.monitor.generic import (
    describe_generic, judged_config, machine_monitor, typical_systematic,
)
from condmon.store.baselines import (  # read from the store only; kept here for callers
    StoredBaseline, _baseline_of, baseline_members, current_baseline,
)
from condmon.store.db import DuplicateTestError, HistoryStore
from condmon.workflows.baseline_results import AddedTest, BaselineAddResult, say_what_was_stored
from condmon.workflows.cycles import cycles_of
from condmon.workflows.records import Cycle, EstimateOptions, RecordKey, RecordLike, record_key
from condmon.workflows.unit_model import session_timed, unit_options

__all__ = ["EstimateOptions", "AddedTest", "BaselineAddResult", "RecordKey",
           "add_baseline_tests", "current_baseline", "RecordLike",
           "unit_monitor", "save_current_baseline", "reevaluate", "parse_date", "record_key",
           "evaluate", "baseline_members", "filed_elsewhere", "elsewhere_warning", "monitoring_of", "restricted",
           "no_baseline_yet", "baseline_notes", "in_time_order"]

Progress = Callable[[int, int, str], None]


def unit_monitor(store: HistoryStore, unit: str, baseline: Baseline | None = None
                 ) -> MonitorConfig:
    """The monitor configuration of the unit's model: its ``[monitor]``
    breakpoints, or generic ones from ``baseline``'s spread."""
    return machine_monitor(get_model(store.unit_model(unit) or "dc-motor"), baseline)


def monitoring_of(machine: Machine, baseline: Baseline, monitor: MonitorConfig | None = None,
                  rules: RuleBase | None = None) -> tuple[MonitorConfig, RuleBase]:
    """Breakpoints and rules a check against ``baseline`` uses: the ones given,
    else the machine's own (:func:`~condmon.monitor.generic.machine_monitor`,
    :func:`~condmon.diagnose.rules.machine_rules`); the rules must name only
    the machine's parameters."""
    cfg = monitor or machine_monitor(machine, baseline)
    cfg.check_parameters(machine.monitored, machine.name)
    rb = rules or machine_rules(machine)
    rb.check_parameters(machine.monitored)
    return cfg, rb


def save_current_baseline(store: HistoryStore, unit: str, ids: Sequence[int], *,
                          name: str | None = None, reason: str | None = None,
                          monitor: MonitorConfig | None = None
                          ) -> tuple[StoredBaseline, bool]:
    """Store the baseline of tests ``ids`` as the next version of ``name`` (the
    unit's active baseline by default), with its plausibility flags (outliers,
    and a trend of the tests taken in time order: :func:`in_time_order`);
    returns it and whether it is a new version. Checks are not re-evaluated
    here (see :func:`reevaluate`).

    Raises
    ------
    DataError
        Fewer than 3 tests.
    """
    base = _baseline_of(store, unit, ids)
    order = in_time_order(store, unit, ids)
    values, ses = store.estimates_of(order)
    cfg = monitor or unit_monitor(store, unit, base)
    table = values[list(base.parameters)].to_numpy()
    conds = store.conditions_of(order)[0]
    if len(conds.columns):   # a trend its operating conditions explain is no trend
        table = explained(table, base.parameters,
                          {str(c): conds[c].to_numpy(dtype=np.float64) for c in conds.columns})
    flags = assess_baseline(table, ses[list(base.parameters)].to_numpy(), order,
                            base.parameters, cfg.baseline)
    before = store.latest_baseline(unit, name)
    bid = store.save_baseline(unit, base, ids, name=name, reason=reason, flags=flags)
    # read back by id: another writer may have saved a later version meanwhile
    saved = store.baseline_by_id(unit, bid)
    return saved, before is None or before.id != bid


def in_time_order(store: HistoryStore, unit: str, ids: Sequence[int]) -> list[int]:
    """The unit's tests ``ids`` in the order they were run: by test date (when
    only the storing time is known, by that), then by id."""
    dates = store.history(unit)["date"]
    return sorted((int(i) for i in ids), key=lambda i: (dates.get(i, pd.NaT), i))


def baseline_notes(store: HistoryStore, unit: str, baseline: StoredBaseline,
                   monitor: MonitorConfig | None = None) -> tuple[dict[str, Any], ...]:
    """What is known of a stored baseline and is no warning: the parameters
    whose tests scatter more than their standard errors say (see
    :func:`condmon.monitor.baseline.baseline_scatter`)."""
    params = list(baseline.baseline.parameters)
    values, ses = store.estimates_of(list(baseline.test_ids))
    cfg = monitor or unit_monitor(store, unit, baseline.baseline)
    return baseline_scatter(values[params].to_numpy(), ses[params].to_numpy(), params,
                            cfg.baseline)


def reevaluate(store: HistoryStore, unit: str, baseline: StoredBaseline,
               monitor: MonitorConfig | None = None, rules: RuleBase | None = None
               ) -> dict[int, tuple[str | None, str]]:
    """Evaluate every accepted, not excluded check of the unit against
    ``baseline`` (the evaluations against earlier baselines are kept), as a
    check is: at its conditions, its status governed by the change test.

    Returns
    -------
    dict
        ``{test_id: (status before, status now)}`` of the checks evaluated anew.
    """
    machine = get_model(store.unit_model(unit) or "dc-motor")
    cfg, rb = monitoring_of(machine, baseline.baseline, monitor, rules)
    hist = store.history(unit)
    todo = hist[(hist["role"] == "check") & hist["accepted"] & ~hist["excluded"]
                & (hist["baseline_id"] != baseline.id)]
    if todo.empty:
        return {}
    params = list(baseline.baseline.parameters)
    values, ses = store.estimates_of(list(todo.index))
    values, ses = values.reindex(columns=params), ses.reindex(columns=params)
    sys_ = store.systematic_of(list(todo.index)).reindex(columns=params)
    conds, conds_se = (store.conditions_of(list(todo.index)) if machine.conditions
                       else (pd.DataFrame(), pd.DataFrame()))
    members = list(baseline.test_ids)
    member_values, member_ses = store.estimates_of(members)
    member_conds = store.conditions_of(members)[0] if machine.conditions else pd.DataFrame()
    series = (member_values, member_conds)
    have = values.notna().to_numpy()
    changed: dict[int, tuple[str | None, str]] = {}
    for i, tid in enumerate(todo.index):
        own = {str(p): float(v) for p, v in sys_.iloc[i].items() if np.isfinite(v)}
        now = ({str(c): (float(v), float(conds_se.loc[tid, c]))
                for c, v in conds.loc[tid].items() if np.isfinite(v)}
               if len(conds.columns) else {})
        cond = conditioning(store, members, baseline.baseline, now, machine, series=series)
        base = baseline.baseline if cond is None else cond.baseline
        diag: Diagnosis | NotJudged
        if cond is not None and cond.not_judged is not None:
            row: dict[str, dict[str, float]] = {}
            diag = NotJudged(cond.not_judged)
        else:
            judged, _ = judged_config(cfg, base, own)
            sym = compute_symptoms(values.to_numpy()[i], base, judged, ses.to_numpy()[i])
            row = {p: v for j, (p, v) in enumerate(sym.row(0).items()) if have[i, j]}
            if not row:  # its regimes have no baseline in this version
                continue
            diag = diagnose({p: {"high": v["high"], "low": v["low"]} for p, v in row.items()},
                            rb, machine.monitored)
            stats = level_statistics(   # as a check: the change test governs the status
                baseline.baseline, member_values, member_ses,
                {p: (float(values.loc[tid, p]), float(ses.loc[tid, p])) for p in row},
                cfg.statistics, cond, member_conds)
            if stats is not None:
                diag = governed(diag, stats, row, base)
        if store.save_evaluation(unit, int(tid), baseline.id, row, diag):
            before = todo.loc[tid, "status"]
            changed[int(tid)] = (None if before == "unchecked" else str(before), diag.status)
    return changed


def conditioning(store: HistoryStore | None, ids: Sequence[Any], baseline: Baseline,
                 conditions: Mapping[str, tuple[float, float]], machine: Machine, *,
                 peer: str | None = None, group: bool = False,
                 series: tuple[pd.DataFrame, pd.DataFrame] | None = None
                 ) -> Conditioned | None:
    """The baseline of tests ``ids`` fitted against the operating conditions
    at a check's ``conditions``
    (:func:`~condmon.monitor.conditions.conditioned_baseline`); None when the
    machine declares none or the check has none. Against a ``group``,
    conditions are not used (its units' conditions are not one series);
    against another unit (``peer``, its label), only those whose level means
    the same on another unit (``between_units``). ``conditions``: the
    check's, each with its standard error. ``series``: the baseline tests'
    values and conditions, when already read."""
    if not machine.conditions or not conditions:
        return None
    if group:
        return Conditioned(baseline, None, {}, (
            "operating conditions are not used against a group: its units' conditions "
            "are not one series",))
    spec = {c.name: c for c in machine.conditions}
    now = {k: float(v[0]) for k, v in conditions.items()
           if split_key(k)[0] in spec and (peer is None or spec[split_key(k)[0]].between_units)}
    left = sorted({split_key(k)[0] for k in conditions} - {split_key(k)[0] for k in now})
    if series is None:
        assert store is not None, "the baseline's tests are read from the store"
        series = store.estimates_of(list(ids))[0], store.conditions_of(list(ids))[0]
    values, conds = series
    out = conditioned_baseline(
        baseline, {p: values[p].to_numpy(dtype=np.float64) for p in baseline.parameters
                   if p in values},
        {c: conds[c].to_numpy(dtype=np.float64) for c in now if c in conds}, now,
        {c.name: c.unit for c in machine.conditions},
        {k: float(conditions[k][1]) for k in now})
    if left:
        out = dataclasses.replace(out, notes=(*out.notes, (
            f"condition(s) {', '.join(left)} not used against {peer}: their level is each "
            "unit's own sensor's (between_units = false)")))
    return out


def governed(diag: Diagnosis, stats: CheckStatistics, row: Mapping[str, Mapping[str, float]],
             baseline: Baseline) -> Diagnosis:
    """The diagnosis with the status the calibrated change test governs
    (:func:`~condmon.monitor.statistics.governed_status`): a fault the test
    does not confirm is kept as a tendency to watch."""
    scatter = {k: 100.0 * s / abs(m) for k, m, s in zip(baseline.parameters, baseline.mean,
                                                         baseline.std) if m}
    status, why = governed_status(diag.status, stats,
                                  {p: v["percent_change"] for p, v in row.items()}, scatter)
    if not why:
        return diag
    if status == "go":
        return dataclasses.replace(diag, status=status, faults=(), candidates=(),
                                   watch=(*diag.faults, *diag.watch), calibrated=why)
    return dataclasses.replace(diag, status=status, calibrated=why)


def level_statistics(baseline: Baseline, values: pd.DataFrame, ses: pd.DataFrame,
                     stored: Mapping[str, tuple[float, float]], config: StatisticsConfig,
                     conditioned: Conditioned | None = None,
                     conditions: pd.DataFrame | None = None) -> CheckStatistics | None:
    """The calibrated change test of a check (``stored``: its values and
    standard errors) against the baseline's tests (``values`` and ``ses``:
    one row per test; ``conditions`` theirs, when the baseline is fitted
    against them), without the drift test: what governs the status
    (:func:`governed`). None when fewer than 3 baseline tests have every
    parameter the check has."""
    keys = [k for k in baseline.parameters if k in stored and k in values
            and np.isfinite(stored[k][0]) and np.isfinite(stored[k][1])]
    if not keys:
        return None
    mean = np.array([baseline.value(k) for k in keys], dtype=np.float64)
    scale = 100.0 / np.abs(mean)
    vals = values[keys].to_numpy(dtype=np.float64)
    err = ses.reindex(columns=keys).to_numpy(dtype=np.float64)
    ok = np.isfinite(vals).all(axis=1) & np.isfinite(err).all(axis=1)
    fitted = conditioned is not None and bool(conditioned.fitted) and conditions is not None
    if fitted:
        assert conditions is not None and conditioned is not None
        vals = explained(vals, keys, {str(c): conditions[c].to_numpy(dtype=np.float64)
                                      for c in conditions.columns})
    if int(ok.sum()) < 3:
        return None
    centre = (np.array([conditioned.baseline.value(k) for k in keys], dtype=np.float64)
              if fitted and conditioned is not None else mean)
    now = (np.array([stored[k][0] for k in keys]) - centre) * scale
    return check_statistics(tuple(keys), now, np.array([stored[k][1] for k in keys]) * scale,
                            (vals[ok] - mean) * scale, err[ok] * scale, now[None, :], config)


def restricted(baseline: Baseline, keys: Sequence[str]) -> Baseline:
    """The baseline of ``keys`` only (the parameters a test has), in their order."""
    idx = [baseline.parameters.index(k) for k in keys]
    counts = baseline.count_array[idx]
    return Baseline(tuple(keys), tuple(baseline.mean[i] for i in idx),
                    tuple(baseline.std[i] for i in idx), baseline.n,
                    None if bool(np.all(counts == baseline.n)) else tuple(map(int, counts)))


def evaluate(res: EstimateResult, baseline: Baseline, monitor: MonitorConfig,
             rules: RuleBase, parameters: Sequence[str] | None = None
             ) -> tuple[dict[str, dict[str, float]], Diagnosis]:
    """Symptoms and diagnosis of one accepted estimate against a baseline (no store).

    Each of the test's values is compared with the baseline's value of the
    same name, a regime's with its own regime's (``Tc@forward``); values the
    baseline has none of (a regime with no baseline yet) are left out. The
    change is judged against the baseline's scatter with the test's
    systematic part (:func:`~condmon.monitor.generic.judged_config`): a
    declared breakpoint inside it is raised to it.
    ``parameters``: every parameter the machine reports (the rules may name
    them; see :func:`~condmon.diagnose.diagnose`).

    Returns
    -------
    row : dict
        ``{param: {"percent_change", "high", "low"}}`` (what the store keeps).
    diagnosis : Diagnosis

    Raises
    ------
    DataError
        None of the test's values has a baseline (naming the regimes).
    """
    stored = res.stored_values()
    keys = [k for k in baseline.parameters if k in stored]
    if not keys:
        raise DataError(f"{res.source}: {no_baseline_yet(list(stored), baseline)}; it is "
                        "not compared with another regime's")
    base = restricted(baseline, keys)
    values = np.array([stored[k][0] for k in keys])
    ses = np.array([stored[k][1] for k in keys])
    sys_ = {k: res.systematic[k] for k in keys if k in res.systematic}
    cfg, _ = judged_config(monitor, base, sys_)
    sym = compute_symptoms(values, base, cfg, ses)
    return sym.row(0), diagnose(sym.to_dict(0), rules, parameters)


def no_baseline_yet(keys: Sequence[str], baseline: Baseline) -> str:
    """Which of a test's regimes have no baseline yet, in one clause."""
    regimes = sorted({split_key(k)[1] or "(none)" for k in missing_regimes(keys, baseline)})
    have = sorted({split_key(k)[1] for k in baseline.parameters if split_key(k)[1]})
    return (f"regime(s) {', '.join(repr(r) for r in regimes)} have no baseline yet "
            f"(the baseline has {', '.join(repr(r) for r in have) or 'no regime'}); add "
            "healthy tests of them with `condmon baseline add`")


def _existing_baseline(store: HistoryStore, unit: str) -> Baseline | None:
    """The unit's current baseline, or None while it has fewer than 3 healthy tests."""
    if store.unit_model(unit) is None:
        return None
    try:
        return current_baseline(store, unit)[0]
    except DataError:
        return None


def _unit_error(res: EstimateResult, baseline: Baseline) -> str | None:
    """Why a test's parameters jump beyond what is believable or flip sign
    against the baseline ("likely unit or sign error ..."), or None; each
    regime's against its own."""
    plausibility = get_model(res.model_key).spec.plausibility
    by_regime: dict[str, tuple[dict[str, float], dict[str, float]]] = {}
    for key, (value, _) in res.stored_values().items():
        mean = baseline.value(key)
        if mean is None:
            continue
        name, regime = split_key(key)
        values, means = by_regime.setdefault(regime, ({}, {}))
        values[name], means[name] = value, mean
    for regime, (values, means) in by_regime.items():
        why = plausibility.check_against_baseline(values, means, res.units)
        if why is not None:
            return why + (f" (regime {regime!r})" if regime else "")
    return None


def estimate_judged(opts: EstimateOptions, record: RecordLike | Cycle,
                    test_date: str | datetime | None, baseline: Baseline | None
                    ) -> tuple[EstimateResult, RecordKey, str | None]:
    """Estimate a record for a unit with ``baseline`` (None: none yet): the
    result, how the record is known, and why it is refused as a likely unit
    or sign error against the baseline (None when it is not).

    A refused or rejected estimate names the column whose unit would explain
    it when one does ("column 'I' (current sensor) in mA?"): the record is
    estimated again with each measured column read in the units a rig
    commonly writes instead (:mod:`condmon.identify.unit_errors`).
    """
    held = opts.with_hold(_held(baseline))
    if isinstance(record, Cycle):   # a test of several records: no column-unit hint
        res, key = held.run_cycle(record, test_date)
        return res, key, _unit_error(res, baseline) if baseline is not None and res.usable \
            else None
    df, key, source = held.parse(record, test_date)

    def believable(r: EstimateResult) -> bool:
        return r.usable and (baseline is None or _unit_error(r, baseline) is None)

    reference = None if baseline is None else dict(zip(baseline.parameters, baseline.mean))
    try:
        res = held.estimate_parsed(df, source)
    except (DataError, EstimationError) as err:   # refused by the route (a singular fit)
        if isinstance(err, MissingColumnsError):
            raise
        hint = held.unit_hint(df, source, believable, reference)
        if hint:
            raise type(err)(f"{err}{hint}") from None
        raise
    why = _unit_error(res, baseline) if baseline is not None and res.usable else None
    if why is None and (res.usable or not _scale_sensitive(res)):
        return res, key, None
    hint = held.unit_hint(df, source, believable, reference)
    if why is not None:
        return res, key, why + hint
    if hint:
        res = dataclasses.replace(res, rejection=f"{res.reason}{hint}")
    return res, key, None


def _scale_sensitive(res: EstimateResult) -> bool:
    """Whether a rejection could come from a column in the wrong unit: a value
    outside its physical bounds, or one the record does not measure; or a
    good fit whose every unknown the record is said not to identify (the
    model's fixed relations, Ke = gamma Kt, cannot hold with a voltage in mV
    against the others, and the search lands far from every nominal value).
    A fit below its threshold reads the same whatever a column's scale, so
    no re-reading is tried for it (each would cost a whole estimate)."""
    return any((p.rejection or "").startswith(("not physically possible", "not a measurement"))
               or (p.fit.accepted and p.identifiability is not None
                   and not p.identifiability.identifiable
                   and (p.rejection or "").startswith("not identifiable"))
               for p in res.regimes)


def with_unit_hint(opts: EstimateOptions, record: RecordLike,
                   res: EstimateResult) -> EstimateResult:
    """``res`` with, when it is rejected in a way a column in the wrong unit
    would explain, the column whose other unit would make it accepted
    (``condmon estimate``; checks and baselines do it in
    :func:`estimate_judged`)."""
    if res.usable or not _scale_sensitive(res):
        return res
    df, _, source = opts.parse(record)
    hint = opts.unit_hint(df, source, lambda r: r.usable)
    return dataclasses.replace(res, rejection=f"{res.reason}{hint}") if hint else res


def _held(baseline: Baseline | None) -> dict[str, float] | None:
    """Values to hold unidentified unknowns at: the baseline's means."""
    return None if baseline is None else dict(zip(baseline.parameters, baseline.mean))


def add_baseline_tests(store: HistoryStore, unit: str, records: Sequence[RecordLike],
                       options: EstimateOptions | None = None,
                       progress: Progress | None = None,
                       test_date: str | datetime | None = None,
                       group: str | None = None) -> BaselineAddResult:
    """Estimate healthy records and store them as the unit's baseline tests.

    Each record is committed on its own, so an interruption keeps every record
    finished before it. Every file is looked at before any is estimated (it
    exists, is not empty, is of a readable type); a record refused with an
    error later says which records before it were stored. A record already in the unit's history (the same
    content, whatever the file) is skipped. Once at least 3 accepted healthy
    tests exist, the new ones join the unit's active baseline (a new version,
    with its plausibility flags) and the unit's checks are evaluated against it.
    ``test_date`` applies to every record (default: each record's own date,
    if its metadata has one). ``group``: put the unit in this group of peers
    (once a test of it is stored).
    """
    opts = unit_options(store, unit, options or EstimateOptions())
    if group is not None:
        from condmon.store.base import check_name

        check_name(group, "group name")
    machine = get_model(opts.model or "dc-motor")
    for rec in records:
        if isinstance(rec, (str, Path)):
            check_record_path(rec)
    # a cycle written as several files is one test; a record that cannot join
    # one is said, never stored alone
    tests, left = cycles_of(opts, records)
    added = [AddedTest(name, -1, False, False, why, refused=True) for name, why in left]
    for i, test in enumerate(tests):
        name = test.source if isinstance(test, Cycle) else str(test) if not isinstance(
            test, pd.DataFrame) else test.attrs.get("source", f"record {i}")
        if progress is not None:
            progress(i, len(tests), str(name))
        prior = _existing_baseline(store, unit)
        try:
            res, key, why = estimate_judged(opts, test, test_date, prior)
        except CondmonError as err:
            say_what_was_stored(err, i, len(tests), added, unit)
            raise
        if why is not None:
            added.append(AddedTest(res.source, -1, False, False, why, refused=True))
            continue
        res = session_timed(store, unit, res, machine, key)
        try:
            tid = store.add_test(unit, res, role="baseline", digest=key.content,
                                 file_digest=key.file, fingerprint=key.fingerprint,
                                 test_date=key.test_date, hours=key.hours)
            added.append(AddedTest(res.source, tid, res.usable, False,
                                   None if res.usable else res.reason,
                                   warning=filed_elsewhere(store, unit, key)))
        except DuplicateTestError as dup:
            added.append(AddedTest(res.source, dup.test_id, res.usable, True,
                                   "already in the history"))
    if progress is not None:
        progress(len(tests), len(tests), "")
    new = [t.test_id for t in added if t.accepted and not (t.duplicate or t.refused)]
    if store.unit_model(unit) is None:  # nothing stored: every record refused
        return BaselineAddResult(tuple(added), None, None, str(_too_few(unit, 0)))
    if group is not None:
        store.set_group(unit, group)
    ids, latest = baseline_members(store, unit)
    ids = sorted(set(ids) | set(new))
    notes = (describe_generic(rules=machine.rules is not None,
                              breakpoints=machine.breakpoints is not None),) \
        if machine.monitored_generically else ()
    if len(ids) < MIN_BASELINE_TESTS:
        return BaselineAddResult(tuple(added), None, None, str(_too_few(unit, len(ids))),
                                 notes=notes)
    try:
        stored, fresh = save_current_baseline(
            store, unit, ids,
            reason=f"{len(new)} healthy test(s) added" if latest else "first baseline")
    except DataError as err:  # tests enough, but no regime has 3 of them yet
        return BaselineAddResult(tuple(added), None, None, f"unit {unit!r}: {err}",
                                 notes=notes)
    if fresh:
        reevaluate(store, unit, stored)
    info = baseline_notes(store, unit, stored)
    regimes = _regime_counts(stored.baseline)
    if machine.breakpoints is not None:   # declared breakpoints the healthy scatter raises
        notes = (*notes, *judged_config(
            machine_monitor(machine), stored.baseline,
            typical_systematic(store.systematic_of(list(stored.test_ids)).add_suffix("_sys"))
        )[1])
    return BaselineAddResult(tuple(added), stored.baseline, stored.id,
                             f"baseline of {unit!r} from {stored.baseline.n} accepted healthy "
                             f"tests ({stored.name!r} v{stored.version})"
                             + (f"; regimes: {regimes}" if regimes else ""), stored.flags,
                             notes, machine.monitored_units, info)


def _regime_counts(baseline: Baseline) -> str:
    """``forward 5 tests, reverse 5 tests`` ("" without regimes)."""
    return ", ".join(f"{r} {n} tests" for r, n in baseline.regime_counts().items())


def filed_elsewhere(store: HistoryStore, unit: str, key: RecordKey) -> str | None:
    """A warning when the record is also a test of another unit (one test
    record belongs to one machine: a mix-up of serial numbers or folders)."""
    return elsewhere_warning(store.copies_elsewhere(unit, key.content))


def elsewhere_warning(others: Sequence[tuple[str, int]]) -> str | None:
    """The warning of a record that is also these ``(unit, test id)`` (None: none)."""
    if not others:
        return None
    where = ", ".join(f"test #{tid} of {name!r}" for name, tid in others[:3])
    return f"the same record is also {where}; is it filed under the right unit?"


def _too_few(unit: str, n: int) -> DataError:
    return DataError(f"unit {unit!r} has {n} accepted healthy test(s); a baseline needs at "
                     f"least {MIN_BASELINE_TESTS}: add them with "
                     f"`condmon baseline add REC... --unit {unit}`")
