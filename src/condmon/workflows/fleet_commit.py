"""Committing a fleet unit's outcomes to the history, as the monitoring workflows would.

This module holds the client side of a fleet run once a unit's records are
back from the workers: the unit's plan (:class:`_Unit`: its model, how its
records are processed, what the history already knows of it), the steps that
write each outcome in date (else file-name) order, the same steps as
:func:`condmon.workflows.monitoring.add_baseline_tests` (while the unit has no
baseline), :func:`condmon.workflows.monitoring.check_test` (afterwards) and
:func:`condmon.workflows.isolation.store_isolation` (plant models), and
:class:`RecordReport`, what became of each record.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from condmon.errors import CondmonError
from condmon.io.raw import one_line
from condmon.workflows.fleet_inbox import FleetRecord, _name_key
from condmon.workflows.fleet_work import Kind, RecordOutcome, _named

if TYPE_CHECKING:
    from condmon.diagnose.rules import RuleBase
    from condmon.identify.estimate import EstimateResult
    from condmon.monitor.baseline import Baseline
    from condmon.monitor.fuzzy import MonitorConfig
    from condmon.store.baselines import StoredBaseline
    from condmon.store.db import HistoryStore

__all__ = ["RecordReport"]


# -- what became of a record ----------------------------------------------------------


@dataclass(frozen=True)
class RecordReport:
    """What became of one record.

    Attributes
    ----------
    unit : str
    file : str
    outcome : {"stored", "skipped", "rejected", "refused"}
    status : str or None
        A check's ``go``/``advisory``/``no-go``; ``baseline`` for a test that
        joined the unit's baseline; ``retest`` for a rejected estimate or an
        undecided isolation; an isolation's ``go``/``no-go``; None when
        nothing was written.
    reason : str or None
        The diagnosis or isolation statement, why the estimate was rejected,
        why the record was refused, or what it duplicates.
    test_id : int or None
        The test's (or isolation's) id in the history.
    kind : {"test", "isolation"}
    test_date : datetime or None
    warnings : tuple of str
    """

    unit: str
    file: str
    outcome: str
    status: str | None = None
    reason: str | None = None
    test_id: int | None = None
    kind: str = "test"
    test_date: datetime | None = None
    warnings: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready record (``unit, file, outcome, status, reason, id, kind,
        test_date, warnings``)."""
        return {"unit": self.unit, "file": self.file, "outcome": self.outcome,
                "status": self.status, "reason": self.reason, "id": self.test_id,
                "kind": self.kind,
                "test_date": None if self.test_date is None else self.test_date.isoformat(),
                "warnings": list(self.warnings)}


# -- committing a unit ----------------------------------------------------------------


@dataclass
class _Unit:
    """A unit's plan: its model, how its records are processed, what is known of it."""

    name: str
    model: str | None = None
    kind: Kind | None = None
    error: str | None = None
    known: dict[str, tuple[str, int]] = field(default_factory=dict)  # digest -> (kind, id)
    digests: frozenset[str] = frozenset()
    expected: int = 0
    outcomes: list[tuple[FleetRecord, RecordOutcome]] = field(default_factory=list)
    building: bool = False
    members: list[int] = field(default_factory=list)  # accepted healthy tests while building
    hold: dict[str, float] | None = None  # the baseline's means, for unidentified unknowns
    counts: dict[str, int] = field(default_factory=dict)  # baseline tests per regime


@dataclass
class _Checker:
    """The unit's baseline while its records are committed (one batch), with
    the breakpoints and rules checks against it use."""

    baseline: Baseline
    ids: list[int]
    latest: StoredBaseline | None
    monitor: MonitorConfig
    rules: RuleBase


def _order(item: tuple[FleetRecord, RecordOutcome]) -> tuple[Any, ...]:
    """Date order when known (dated records first), else file-name order."""
    rec, out = item
    when = rec.test_date or (out.key.test_date if out.key is not None else None)
    return (when is None, when.timestamp() if when is not None else 0.0,
            _name_key(Path(rec.path.name)), _name_key(rec.path))


@functools.lru_cache(maxsize=16)
def _rules(model: str) -> RuleBase:
    from condmon.diagnose.rules import machine_rules
    from condmon.models.registry import get_model

    return machine_rules(get_model(model))


def _regimes_of(res: EstimateResult) -> set[str]:
    """The regimes a usable estimate is trended in ("" for a machine without)."""
    from condmon.models.regimes import split_key

    return {split_key(k)[1] for k in res.stored_values()}


def _regime_counts(store: HistoryStore, ids: list[int]) -> dict[str, int]:
    """Accepted healthy tests per regime among ``ids``."""
    from condmon.models.regimes import split_key

    if not ids:
        return {}
    values, _ = store.estimates_of(ids)
    counts: dict[str, int] = {}
    for key in values.columns:
        regime = split_key(str(key))[1]
        counts[regime] = max(counts.get(regime, 0), int(values[key].notna().sum()))
    return counts


def _commit_unit(store: HistoryStore, plan: _Unit, baseline_count: int) -> list[RecordReport]:
    """Write a unit's outcomes in the order its records were run (inside a batch)."""
    from condmon.store import DuplicateTestError, StoreError

    items = sorted(plan.outcomes, key=_order)
    reports = []
    seen: dict[str, str] = {}
    checker: list[_Checker | None] = [None]  # loaded at the unit's first check
    group = next((rec.group for rec, _ in items if rec.group), None)
    if group is not None and plan.model is not None and any(o.error is None for _, o in items):
        from condmon.models.registry import get_model

        machine = get_model(plan.model)
        store.set_group(plan.name, group, model=machine.name, model_source=machine.origin)
    if plan.kind == "estimate":
        from condmon.workflows.monitoring import baseline_members

        ids, latest = baseline_members(store, plan.name)
        plan.building = latest is None
        plan.members = list(ids)
        plan.counts = _regime_counts(store, plan.members)
    for rec, out in items:
        where = str(rec.path)
        date = rec.test_date or (out.key.test_date if out.key is not None else None)
        kind = "isolation" if plan.kind == "isolate" else "test"

        def report(outcome: str, status: str | None = None, reason: str | None = None,
                   tid: int | None = None, warning: str | None = None) -> RecordReport:
            return RecordReport(plan.name, where, outcome, status, reason, tid, kind, date,
                                (*out.warnings, *([warning] if warning else [])))

        if out.error is not None:
            reports.append(report("refused", reason=out.error))
            continue
        assert out.key is not None
        if out.known:
            what, tid = plan.known.get(out.key.content, (kind, None))
            reports.append(report("skipped", reason=f"already in the history of "
                                  f"{plan.name!r} ({what} #{tid})", tid=tid))
            continue
        if out.key.content in seen:
            reports.append(report("skipped", reason=f"the same content as {seen[out.key.content]}"
                                  " in this run"))
            continue
        seen[out.key.content] = where
        try:
            if out.isolation is not None:
                reports.append(_commit_isolation(store, plan, out, report))
            elif _joins_baseline(plan, out, baseline_count):
                reports.append(_commit_baseline_test(store, plan, out, baseline_count, report))
                if not plan.building:
                    checker[0] = None  # a new baseline version: checks load it again
            else:
                reports.append(_commit_check(store, plan, out, checker, report))
        except DuplicateTestError as dup:  # written meanwhile by another process
            reports.append(report("skipped", reason=one_line(dup, None), tid=dup.test_id))
        except StoreError:
            raise
        except CondmonError as exc:  # no baseline, a rule base that does not fit, ...
            reports.append(report("refused", reason=_named(where, str(exc))))
    return reports


ReportFn = Callable[..., RecordReport]


def _commit_isolation(store: HistoryStore, plan: _Unit, out: RecordOutcome,
                      report: ReportFn) -> RecordReport:
    """As :func:`condmon.workflows.isolation.store_isolation`, from the outcome."""
    from condmon.models.registry import get_model
    from condmon.store import isolation_status

    iso, key = out.isolation, out.key
    assert iso is not None and key is not None and plan.model is not None
    machine = get_model(plan.model)
    iid = store.add_isolation(plan.name, iso, model=machine.name, source=out.path,
                              digest=key.content, file_digest=key.file,
                              fingerprint=key.fingerprint, test_date=key.test_date,
                              model_source=machine.origin)
    return report("stored", isolation_status(iso.detected, iso.decided),
                  iso.statement if iso.decided else (iso.reason or iso.statement), iid)


def _joins_baseline(plan: _Unit, out: RecordOutcome, baseline_count: int) -> bool:
    """Whether a record is one of its unit's baseline tests: while no baseline
    is saved (a rejected record too), or while one of its regimes has fewer
    than ``baseline_count`` accepted healthy tests."""
    res = out.estimate
    if res is None:
        return False
    if plan.building:
        return True
    return res.usable and any(plan.counts.get(r, 0) < baseline_count for r in _regimes_of(res))


def _commit_baseline_test(store: HistoryStore, plan: _Unit, out: RecordOutcome,
                          baseline_count: int, report: ReportFn) -> RecordReport:
    """As :func:`condmon.workflows.monitoring.add_baseline_tests` for one record;
    a baseline version is saved once a regime has ``baseline_count`` accepted
    tests (the unit's first, or one with a new regime)."""
    from condmon.errors import DataError
    from condmon.monitor.baseline import MIN_BASELINE_TESTS
    from condmon.store.baselines import _baseline_of
    from condmon.workflows.monitoring import (
        _unit_error, filed_elsewhere, save_current_baseline,
    )

    res, key = out.estimate, out.key
    assert res is not None and key is not None
    # while building, the unit has no saved version: its baseline so far is its
    # accepted healthy tests (plan.members, kept as they are written)
    if res.usable and len(plan.members) >= MIN_BASELINE_TESTS:
        try:
            prior = _baseline_of(store, plan.name, plan.members)
        except DataError:  # no regime has 3 tests yet
            prior = None
        why = None if prior is None else _unit_error(res, prior)
        if why is not None:
            return report("refused", reason=_named(out.path, f"refused, {why}; nothing was "
                                                   "stored"))
    tid = store.add_test(plan.name, res, role="baseline", digest=key.content,
                         file_digest=key.file, fingerprint=key.fingerprint,
                         test_date=key.test_date, hours=key.hours)
    elsewhere = filed_elsewhere(store, plan.name, key)
    if not res.usable:
        return report("rejected", "retest", one_line(str(res.reason), None), tid, elsewhere)
    plan.members.append(tid)
    regimes = _regimes_of(res)
    for r in regimes:
        plan.counts[r] = plan.counts.get(r, 0) + 1
    done = [r for r in regimes if plan.counts[r] == baseline_count]
    label = ", ".join(f"regime {r!r}" for r in sorted(regimes) if r)
    if done:
        ids = list(plan.members)
        # a first version (no check exists before it), or one a new regime
        # joined (the checks so far have other regimes): none to re-evaluate
        stored, _ = save_current_baseline(store, plan.name, ids,
                                          reason=f"baseline of {len(ids)} tests" + (
                                              f" ({label} complete)" if label else ""))
        plan.building = False
        return report("stored", "baseline", f"baseline of {plan.name!r} from {len(ids)} "
                      f"accepted healthy tests ({stored.name!r} v{stored.version})"
                      + (f"; {label} complete" if label else ""), tid, elsewhere)
    n = max(plan.counts[r] for r in regimes) if regimes else len(plan.members)
    return report("stored", "baseline", f"baseline test {n} of {baseline_count}"
                  + (f" ({label})" if label else ""), tid, elsewhere)


def _commit_check(store: HistoryStore, plan: _Unit, out: RecordOutcome,
                  checker: list[_Checker | None], report: ReportFn) -> RecordReport:
    """As :func:`condmon.workflows.monitoring.check_test` for one estimated record."""
    from condmon.workflows.monitoring import (
        _unit_error, current_baseline, evaluate, filed_elsewhere, monitoring_of,
        save_current_baseline,
    )

    res, key = out.estimate, out.key
    assert res is not None and key is not None and plan.model is not None
    state = checker[0]
    if state is None:
        from condmon.models.registry import get_model

        baseline, ids = current_baseline(store, plan.name)
        cfg, rb = monitoring_of(get_model(plan.model), baseline, None, _rules(plan.model))
        state = checker[0] = _Checker(baseline, ids, store.latest_baseline(plan.name), cfg, rb)
    cfg, rb = state.monitor, state.rules
    why = _unit_error(res, state.baseline) if res.usable else None
    if why is not None:
        return report("refused", reason=_named(out.path, f"refused, {why}; nothing was stored"))
    if not res.usable:
        tid = store.add_test(plan.name, res, role="check", digest=key.content,
                             file_digest=key.file, fingerprint=key.fingerprint,
                             test_date=key.test_date, hours=key.hours)
        return report("rejected", "retest", one_line(str(res.reason), None), tid,
                      filed_elsewhere(store, plan.name, key))
    from condmon.models.registry import get_model

    row, diag = evaluate(res, state.baseline, cfg, rb, get_model(plan.model).spec.report)
    if state.latest is None or list(state.latest.test_ids) != state.ids:
        state.latest, _ = save_current_baseline(store, plan.name, state.ids, monitor=cfg,
                                                reason="baseline of the first check")
    tid = store.add_test(plan.name, res, role="check", digest=key.content, file_digest=key.file,
                         fingerprint=key.fingerprint, test_date=key.test_date, hours=key.hours,
                         symptoms=row, baseline_id=state.latest.id, diagnosis=diag)
    return report("stored", diag.status, diag.summary, tid,
                  filed_elsewhere(store, plan.name, key))


def _write(store: HistoryStore, ready: list[_Unit], baseline_count: int,
           reports: dict[str, list[RecordReport]]) -> None:
    """Commit the ready units' outcomes in one transaction."""
    with store.batch():
        for plan in ready:
            reports.setdefault(plan.name, []).extend(_commit_unit(store, plan, baseline_count))
            plan.outcomes.clear()
