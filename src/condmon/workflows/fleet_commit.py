"""Committing a fleet unit's outcomes to the history, as the monitoring workflows would.

This module holds the client side of a fleet run once a unit's records are
back from the workers: the unit's plan (:class:`_Unit`: its model, how its
records are processed, what the history already knows of it), the steps that
write each outcome in date (else file-name) order, the same steps as
:func:`condmon.workflows.monitoring.add_baseline_tests` (while the unit has no
baseline), :func:`condmon.workflows.monitoring.check_test` (afterwards) and
:func:`condmon.workflows.isolation.store_isolation` (plant models), and
:class:`RecordReport`, what became of each record.

A batch of units is committed in one transaction: what the history holds of
them is read at its start (:meth:`~condmon.store.bulk.BulkMixin.unit_states`,
:meth:`~condmon.store.bulk.BulkMixin.record_rows`), every record is decided
against that copy kept in memory (:class:`~condmon.workflows.fleet_state.UnitView`),
and the new rows are written together at its end
(:meth:`~condmon.store.bulk.BulkMixin.write_bulk`): a handful of statements
per batch instead of some twenty per record, and no savepoint per record.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from condmon.errors import CondmonError
from condmon.io.raw import one_line
from condmon.store.bulk import BulkWriter, Id, Pending
from condmon.workflows.fleet_inbox import FleetRecord, _name_key
from condmon.workflows.fleet_state import Records, UnitView, Version
from condmon.workflows.fleet_work import Kind, RecordOutcome, _named

if TYPE_CHECKING:
    from condmon.diagnose.rules import RuleBase
    from condmon.identify.estimate import EstimateResult
    from condmon.models.features import ConditionSpec
    from condmon.monitor.baseline import Baseline
    from condmon.monitor.fuzzy import MonitorConfig
    from condmon.store.db import HistoryStore
    from condmon.workflows.records import RecordKey

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
    members: list[Id] = field(default_factory=list)  # accepted healthy tests while building
    hold: dict[str, float] | None = None  # the baseline's means, for unidentified unknowns
    counts: dict[str, int] = field(default_factory=dict)  # baseline tests per regime


@dataclass
class _Checker:
    """The unit's baseline while its records are committed (one batch), with
    the breakpoints and rules checks against it use."""

    baseline: Baseline
    ids: list[Id]
    latest: Version | None
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


@dataclass
class _Draft:
    """A record's report before its batch is written (ids and warnings that
    name ids are settled once it is)."""

    unit: str
    file: str
    kind: str
    date: datetime | None
    warnings: tuple[str, ...]
    record: int  # its rows' record in the batch's writer
    outcome: str
    status: str | None = None
    reason: str | Callable[[], str] | None = None
    tid: Id | None = None
    warning: Callable[[], str | None] | None = None

    def report(self) -> RecordReport:
        reason = self.reason() if callable(self.reason) else self.reason
        extra = self.warning() if self.warning is not None else None
        return RecordReport(self.unit, self.file, self.outcome, self.status, reason,
                            None if self.tid is None else int(self.tid), self.kind, self.date,
                            (*self.warnings, *([extra] if extra else [])))


@dataclass
class _Batch:
    """A batch being committed: its writer, the records its units hold, their views."""

    writer: BulkWriter
    records: Records
    views: dict[str, UnitView]


class _Duplicate(Exception):
    """The record is already in the unit's history (as DuplicateTestError)."""

    def __init__(self, text: Callable[[], str], rid: Id) -> None:
        super().__init__()
        self.text = text
        self.rid = rid


def _sessions(model: str | None) -> tuple[ConditionSpec, ...]:
    """The conditions of ``model`` that are the time since a session started."""
    if model is None:
        return ()
    from condmon.models.registry import get_model

    return get_model(model).sessions


def _commit_unit(batch: _Batch, plan: _Unit, baseline_count: int) -> list[_Draft]:
    """Decide a unit's outcomes in the order its records were run, their rows
    added to the batch's writer."""
    items = sorted(plan.outcomes, key=_order)
    drafts = []
    seen: dict[str, str] = {}
    checker: list[_Checker | None] = [None]  # loaded at the unit's first check
    view, w = batch.views[plan.name], batch.writer
    group = next((rec.group for rec, _ in items if rec.group), None)
    if group is not None and plan.model is not None and any(o.error is None for _, o in items):
        from condmon.models.registry import get_model

        machine = get_model(plan.model)
        w.record(f"unit {plan.name!r}")
        uid = view.ensure(w, machine.name, machine.origin)
        if view.group != group:
            w.set_group(uid, plan.name, group, view.group)
            view.group = group
    if plan.kind == "estimate":
        plan.building = view.latest is None
        plan.members = view.members()
        plan.counts = view.regime_counts(plan.members)
    sessions = _sessions(plan.model)
    if sessions:
        from condmon.monitor.conditions import with_session_time
    for rec, out in items:
        where = str(rec.path)
        date = rec.test_date or (out.key.test_date if out.key is not None else None)
        if sessions and out.estimate is not None:
            out = dataclasses.replace(out, estimate=with_session_time(
                out.estimate, sessions, date, view.start_times))
            view.start_times.extend([date.timestamp()] if date is not None else [])
        kind = "isolation" if plan.kind == "isolate" else "test"
        w.record(where)

        def report(outcome: str, status: str | None = None,
                   reason: str | Callable[[], str] | None = None, tid: Id | None = None,
                   warning: Callable[[], str | None] | None = None) -> _Draft:
            return _Draft(plan.name, where, kind, date, out.warnings, len(w.records) - 1,
                          outcome, status, reason, tid, warning)

        if out.error is not None:
            drafts.append(report("refused", reason=out.error))
            continue
        assert out.key is not None
        if out.known:
            what, tid = plan.known.get(out.key.content, (kind, None))
            drafts.append(report("skipped", reason=f"already in the history of "
                                 f"{plan.name!r} ({what} #{tid})", tid=tid))
            continue
        if out.key.content in seen:
            drafts.append(report("skipped", reason=f"the same content as {seen[out.key.content]}"
                                 " in this run"))
            continue
        seen[out.key.content] = where
        try:
            if out.isolation is not None:
                drafts.append(_commit_isolation(batch, plan, out, report))
            elif _joins_baseline(plan, out, baseline_count):
                drafts.append(_commit_baseline_test(batch, plan, out, baseline_count, report))
                if not plan.building:
                    checker[0] = None  # a new baseline version: checks load it again
            else:
                drafts.append(_commit_check(batch, plan, out, checker, report))
        except _Duplicate as dup:  # written meanwhile by another process, or a copy
            text = dup.text
            drafts.append(report("skipped", reason=lambda: one_line(text(), None), tid=dup.rid))
        except CondmonError as exc:  # no baseline, a rule base that does not fit, ...
            drafts.append(report("refused", reason=_named(where, str(exc))))
    return drafts


ReportFn = Callable[..., _Draft]


def _check_copy(batch: _Batch, plan: _Unit, kind: str, source: str, key: RecordKey) -> None:
    """Raise :class:`_Duplicate` when the unit holds the record already (as
    the store's own check before it adds a test or an isolation)."""
    dup = batch.records.copy_of(kind, plan.name, key)
    if dup is None:
        return
    note = " (excluded; `condmon include` restores it)" if dup.excluded and kind == "test" else ""
    unit, rid = plan.name, dup.id
    raise _Duplicate(lambda: f"{source}: already in the history of {unit!r} ({kind} "
                     f"#{int(rid)}{note}); not added again", rid)


def _add_test(batch: _Batch, plan: _Unit, out: RecordOutcome, role: str,
              **evaluation: Any) -> tuple[Pending, Callable[[], str | None]]:
    """A test added to the batch (as :meth:`HistoryStore.add_test`) and the
    warning of its record filed under another unit too."""
    res, key = out.estimate, out.key
    assert res is not None and key is not None
    _check_copy(batch, plan, "test", res.source, key)
    view = batch.views[plan.name]
    uid = view.ensure(batch.writer, res.model, getattr(res, "model_source", None))
    tid = batch.writer.add_test(uid, res, role=role, digest=key.content,
                                file_digest=key.file or key.content, test_date=key.test_date,
                                hours=key.hours, fingerprint=key.fingerprint, **evaluation)
    view.added_test(tid, res, role)
    elsewhere = batch.records.elsewhere(plan.name, key)
    batch.records.add("test", tid, plan.name, key)
    return tid, elsewhere


def _commit_isolation(batch: _Batch, plan: _Unit, out: RecordOutcome,
                      report: ReportFn) -> _Draft:
    """As :func:`condmon.workflows.isolation.store_isolation`, from the outcome."""
    from condmon.models.registry import get_model
    from condmon.store import isolation_status

    iso, key = out.isolation, out.key
    assert iso is not None and key is not None and plan.model is not None
    machine = get_model(plan.model)
    _check_copy(batch, plan, "isolation", out.path, key)
    uid = batch.views[plan.name].ensure(batch.writer, machine.name, machine.origin)
    iid = batch.writer.add_isolation(uid, iso, model=machine.name, source=out.path,
                                     digest=key.content, file_digest=key.file or key.content,
                                     fingerprint=key.fingerprint, test_date=key.test_date)
    batch.records.add("isolation", iid, plan.name, key)
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


def _commit_baseline_test(batch: _Batch, plan: _Unit, out: RecordOutcome,
                          baseline_count: int, report: ReportFn) -> _Draft:
    """As :func:`condmon.workflows.monitoring.add_baseline_tests` for one record;
    a baseline version is saved once a regime has ``baseline_count`` accepted
    tests (the unit's first, or one with a new regime)."""
    from condmon.errors import DataError
    from condmon.monitor.baseline import MIN_BASELINE_TESTS
    from condmon.workflows.monitoring import _unit_error

    res, view = out.estimate, batch.views[plan.name]
    assert res is not None
    # while building, the unit has no saved version: its baseline so far is its
    # accepted healthy tests (plan.members, kept as they are written)
    if res.usable and len(plan.members) >= MIN_BASELINE_TESTS:
        try:
            prior = view.baseline_of(plan.members)
        except DataError:  # no regime has 3 tests yet
            prior = None
        why = None if prior is None else _unit_error(res, prior)
        if why is not None:
            return report("refused", reason=_named(out.path, f"refused, {why}; nothing was "
                                                   "stored"))
    tid, elsewhere = _add_test(batch, plan, out, "baseline")
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
        stored = view.save_baseline(batch.writer, ids, reason=f"baseline of {len(ids)} tests" + (
            f" ({label} complete)" if label else ""))
        plan.building = False
        return report("stored", "baseline", f"baseline of {plan.name!r} from {len(ids)} "
                      f"accepted healthy tests ({stored.name!r} v{stored.version})"
                      + (f"; {label} complete" if label else ""), tid,
                      _flagged(plan.name, stored, elsewhere))
    n = max(plan.counts[r] for r in regimes) if regimes else len(plan.members)
    return report("stored", "baseline", f"baseline test {n} of {baseline_count}"
                  + (f" ({label})" if label else ""), tid, elsewhere)


def _flagged(unit: str, version: Version, elsewhere: Callable[[], str | None]
             ) -> Callable[[], str | None]:
    """The warning of the record that completed a baseline: its flags (as
    `baseline add` warns of them), and a copy filed under another unit."""
    def text() -> str | None:
        from condmon.monitor.baseline_checks import is_warning

        said = [f"baseline of {unit!r} flagged: {f['message']}" for f in version.flags()
                if is_warning(f)]
        also = elsewhere()
        return "; ".join([*said, *([also] if also else [])]) or None

    return text


def _commit_check(batch: _Batch, plan: _Unit, out: RecordOutcome,
                  checker: list[_Checker | None], report: ReportFn) -> _Draft:
    """As :func:`condmon.workflows.monitoring.check_test` for one estimated record."""
    from condmon.models.registry import get_model
    from condmon.monitor.conditions import NotJudged
    from condmon.workflows.monitoring import (
        _unit_error, conditioning, evaluate, governed, level_statistics, monitoring_of,
    )

    res, view = out.estimate, batch.views[plan.name]
    assert res is not None and plan.model is not None
    state = checker[0]
    if state is None:
        baseline, ids = view.current()
        cfg, rb = monitoring_of(get_model(plan.model), baseline, None, _rules(plan.model))
        state = checker[0] = _Checker(baseline, ids, view.latest, cfg, rb)
    cfg, rb = state.monitor, state.rules
    why = _unit_error(res, state.baseline) if res.usable else None
    if why is not None:
        return report("refused", reason=_named(out.path, f"refused, {why}; nothing was stored"))
    if not res.usable:
        tid, elsewhere = _add_test(batch, plan, out, "check")
        return report("rejected", "retest", one_line(str(res.reason), None), tid, elsewhere)
    machine = get_model(plan.model)
    values, conds = view.series(state.ids)
    cond = conditioning(None, state.ids, state.baseline, res.conditions, machine,
                        series=(values, conds))
    if state.latest is None or list(state.latest.test_ids) != state.ids:
        state.latest = view.save_baseline(batch.writer, state.ids, monitor=cfg,
                                          reason="baseline of the first check")
    if cond is not None and cond.not_judged is not None:   # outside its baseline's conditions
        unjudged = NotJudged(cond.not_judged)
        tid, elsewhere = _add_test(batch, plan, out, "check", symptoms={},
                                   baseline_id=state.latest.id, diagnosis=unjudged)
        return report("stored", unjudged.status, unjudged.summary, tid, elsewhere)
    judged = state.baseline if cond is None else cond.baseline
    row, diag = evaluate(res, judged, cfg, rb, machine.monitored)
    stats = level_statistics(state.baseline, values, view.errors(state.ids),
                             res.stored_values(), cfg.statistics, cond, conds)
    if stats is not None:   # as check_test: the change test governs the status
        diag = governed(diag, stats, row, judged)
    tid, elsewhere = _add_test(batch, plan, out, "check", symptoms=row,
                               baseline_id=state.latest.id, diagnosis=diag)
    return report("stored", diag.status, diag.summary, tid, elsewhere)


def _write(store: HistoryStore, ready: list[_Unit], baseline_count: int,
           reports: dict[str, list[RecordReport]]) -> None:
    """Commit the ready units' outcomes in one transaction: what the history
    holds of them read in a few queries, their new rows written with one
    statement per table.

    Raises
    ------
    StoreError
        A record cannot be written: it is named, the records before it are kept.
    """
    from condmon.io.digest import fingerprint_prefix
    from condmon.store.bulk import BulkWriteError

    keys = [out.key for plan in ready for _, out in plan.outcomes
            if out.error is None and not out.known and out.key is not None]
    hashes = [k.content for k in keys] + [k.file for k in keys if k.file]
    prefixes = [fingerprint_prefix(int(json.loads(k.fingerprint)["n"]))
                for k in keys if k.fingerprint]
    kinds = sorted({"isolation" if p.kind == "isolate" else "test" for p in ready if p.kind})
    writer = BulkWriter()
    drafts: list[_Draft] = []
    failed: BulkWriteError | None = None
    with store.batch():
        states = store.unit_states([p.name for p in ready])
        uids = [s.id for s in states.values()]
        known = {kind: store.record_rows(kind, hashes, uids, prefixes) for kind in kinds}
        batch = _Batch(writer, Records.of(known),
                       {p.name: UnitView.of(p.name, states.get(p.name)) for p in ready})
        for plan in ready:   # a session's time needs the unit's earlier records
            if _sessions(plan.model):
                batch.views[plan.name].start_times = store.start_times(plan.name)
        for plan in ready:
            drafts.extend(_commit_unit(batch, plan, baseline_count))
            plan.outcomes.clear()
        try:
            store.write_bulk(writer)
        except BulkWriteError as err:  # the records before it are kept
            failed = err
    for d in drafts:
        if failed is None or d.record < failed.written:
            reports.setdefault(d.unit, []).append(d.report())
    if failed is not None:
        raise failed
