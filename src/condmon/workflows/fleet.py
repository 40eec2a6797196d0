"""A fleet's new records, estimated or isolated on a distributed engine and kept in one history.

The flow of :func:`run_fleet`::

    inbox or manifest -> records per unit -> each unit's model
    -> records already in the history skipped (by file, then by content)
    -> process_record on the engine's workers, a few records per task (read,
       estimate or isolate; no database)
    -> per unit, in date order (else file-name order): baseline tests while the
       unit has no baseline, checks against it afterwards; isolations for plant models
    -> written by the client, many results per transaction (``store.batch()``):
       the batch's units read in a few queries, its new rows written with one
       statement per table (:mod:`condmon.store.bulk`)

The engine is dask.distributed: a local cluster of worker processes (one
thread each, BLAS on one thread) or an existing cluster's scheduler. The unit
of work, :func:`process_record`, is a plain function of one record's path and
options returning a small picklable :class:`RecordOutcome` (the estimate or the
isolation, how the record is known, or the error text), so one record's
failure never stops the others and a worker never touches the database.

A unit's records are committed once all of them are back from the workers, in
the order they were run, decided in memory (:mod:`condmon.workflows.fleet_state`)
by the same steps as
:func:`condmon.workflows.monitoring.add_baseline_tests` (while the unit has no
baseline) and :func:`condmon.workflows.monitoring.check_test` (afterwards), so
the fleet gives the answers those give for the same records.

This module holds :func:`run_fleet` and its results; finding the records is
:mod:`condmon.workflows.fleet_inbox`, the engine
:mod:`condmon.workflows.fleet_engine`, the worker's unit of work
:mod:`condmon.workflows.fleet_work`, and committing a unit's outcomes
:mod:`condmon.workflows.fleet_commit` with :mod:`condmon.workflows.fleet_state`
(every public name is importable from here too).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Collection, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from condmon.errors import CondmonError, ConfigError, DataError
from condmon.io.digest import file_hash
from condmon.io.raw import one_line
from condmon.io.rig import RecordSettings
from condmon.workflows.fleet_commit import RecordReport, _Unit, _write
from condmon.workflows.fleet_engine import BLAS_ENV as BLAS_ENV
from condmon.workflows.fleet_engine import EngineError as EngineError
from condmon.workflows.fleet_engine import (
    _engine, _run_tasks, _sigint_held, _threads, local_cluster,
)
from condmon.workflows.fleet_inbox import MANIFEST_COLUMNS as MANIFEST_COLUMNS
from condmon.workflows.fleet_state import UnitView
from condmon.workflows.fleet_inbox import UNIT_FILE as UNIT_FILE
from condmon.workflows.fleet_inbox import (
    FleetRecord, _natural, _readable_suffix, inbox_records, read_manifest,
)
from condmon.workflows.fleet_work import Kind as Kind
from condmon.workflows.fleet_work import RecordOutcome, RecordTask, _named, process_record
from condmon.workflows.cycles import record_by_record
from condmon.workflows.records import EstimateOptions

if TYPE_CHECKING:
    from distributed import Client

    from condmon.store.bulk import UnitState
    from condmon.store.db import HistoryStore

__all__ = ["EngineError", "FleetInterrupted", "DEFAULT_MODEL", "OUTCOMES", "BLAS_ENV", "FleetRecord", "RecordTask", "RecordOutcome",
           "RecordReport", "UnitReport", "FleetResult", "inbox_records", "read_manifest",
           "process_record", "local_cluster", "run_fleet"]

#: The model of a unit named nowhere (manifest, history, ``unit.toml``).
DEFAULT_MODEL = "dc-motor"

#: What became of a record: written (``stored``; ``rejected``: its estimate
#: failed the fit and is kept as rejected), already in the history or twice in
#: this run (``skipped``), or not written with the reason (``refused``).
OUTCOMES = ("stored", "skipped", "rejected", "refused")

class FleetInterrupted(KeyboardInterrupt):
    """A run stopped by Ctrl-C (SIGINT); what was written stays written.

    Its text is the one line to show: ``interrupted: 88 of 144 records
    stored; run again to finish``.

    Attributes
    ----------
    stored : int
        Records written in this run (stored or kept as rejected).
    total : int
        Records offered.
    """

    def __init__(self, stored: int, total: int) -> None:
        super().__init__(f"interrupted: {stored} of {total} records stored"
                         + ("; run again to finish" if stored < total else ""))
        self.stored = stored
        self.total = total


Progress = Callable[[int, int, str], None]


# -- results --------------------------------------------------------------------------


@dataclass(frozen=True)
class UnitReport:
    """A unit after the run.

    Attributes
    ----------
    unit : str
    model : str or None
        None when the unit's model could not be settled.
    kind : {"estimate", "isolate"} or None
    status : str or None
        Its latest test's or isolation's status in the history (as ``condmon
        units`` shows it), ``building`` while its baseline is not saved yet,
        None when the history has nothing of it.
    records : dict of str to int
        How many of its records had each outcome.
    note : str
        What the run could not do as its model declares (a cycle checked
        record by record, :func:`~condmon.workflows.cycles.record_by_record`).
    """

    unit: str
    model: str | None
    kind: str | None
    status: str | None
    records: dict[str, int]
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready unit."""
        return {"unit": self.unit, "model": self.model, "kind": self.kind,
                "status": self.status, "records": dict(self.records),
                **({"note": self.note} if self.note else {})}


@dataclass(frozen=True)
class FleetResult:
    """Outcome of a fleet run.

    Attributes
    ----------
    records : tuple of RecordReport
        Every record offered, by unit, each unit's in the order committed.
    units : tuple of UnitReport
    workers : int
        Worker threads of the engine (0 when no record needed one).
    seconds : float
        Wall time of the run. [s]
    engine : str
        ``local``, the scheduler's address, ``in-process`` (a small fleet,
        :data:`SMALL_FLEET`) or ``none`` (nothing to compute).
    engine_start : float
        Time to start the local cluster, or to connect to the scheduler (0
        without an engine). [s]
    engine_stop : float
        Time to shut the local cluster down, or to disconnect. [s]
    """

    records: tuple[RecordReport, ...]
    units: tuple[UnitReport, ...]
    workers: int
    seconds: float
    engine: str
    engine_start: float = 0.0
    engine_stop: float = 0.0

    def count(self, outcome: str) -> int:
        """Number of records with ``outcome`` (one of :data:`OUTCOMES`)."""
        if outcome not in OUTCOMES:
            raise ValueError(f"unknown outcome {outcome!r}; allowed: {', '.join(OUTCOMES)}")
        return sum(1 for r in self.records if r.outcome == outcome)

    @property
    def stored(self) -> int:
        """Records written as tests or isolations (rejected ones counted apart)."""
        return self.count("stored")

    @property
    def skipped(self) -> int:
        """Records already in the history, or offered twice in this run."""
        return self.count("skipped")

    @property
    def not_records(self) -> int:
        """Refused files that are no unit's record: no record by their suffix (a
        unit folder's ``notes.md``), or in no unit's folder (a ``README.txt``
        beside them). Named at every run, but no failure of a record."""
        return sum(1 for r in self.records if r.outcome == "refused"
                   and (not r.unit or not _readable_suffix(Path(r.file))))

    @property
    def failed(self) -> bool:
        """Whether the run failed its input (``fleet run`` exits 2): records
        were refused and none was taken (stored or rejected), and either a
        refused file was a record file or nothing was in the history already.
        So an up-to-date fleet with a stray ``notes.md`` in a unit's folder
        does not fail at every run, while an inbox of files no reader takes,
        or a record that cannot be read, does."""
        refused = self.count("refused")
        if not refused or self.count("stored") or self.count("rejected"):
            return False
        return refused > self.not_records or not self.count("skipped")

    def to_dict(self) -> dict[str, Any]:
        """The ``condmon fleet run --json`` document: ``stored, skipped,
        rejected, refused`` (counts that add up to the records), ``records``,
        ``units``, ``workers``, ``seconds``, ``engine``, ``engine_start_seconds``
        and ``engine_stop_seconds``."""
        return {**{o: self.count(o) for o in OUTCOMES},
                "records": [r.to_dict() for r in self.records],
                "units": [u.to_dict() for u in self.units],
                "workers": self.workers, "seconds": self.seconds, "engine": self.engine,
                "engine_start_seconds": self.engine_start,
                "engine_stop_seconds": self.engine_stop}


# -- a unit's plan --------------------------------------------------------------------


def _settle_model(state: UnitState | None, plan: _Unit, rec: FleetRecord) -> None:
    """The unit's model: the manifest's, else its history's (``state``), else
    ``unit.toml``'s, else :data:`DEFAULT_MODEL`; the kind of processing; or
    why it is refused (naming the ``unit.toml`` whose model it is)."""
    from condmon.models.registry import get_model
    from condmon.store.base import check_name

    try:
        check_name(plan.name)
        stored = None if state is None else str(state.model_source or state.model)
        model = rec.model or stored or rec.fallback_model or DEFAULT_MODEL
        try:
            machine = get_model(model)
        except CondmonError as exc:
            if rec.model or stored or not rec.fallback_source:
                raise
            raise DataError(f"{rec.fallback_source}: {one_line(exc, None)}") from None
        if stored is not None and rec.model is not None and stored not in (machine.name,
                                                                            machine.origin):
            raise DataError(f"unit {plan.name!r} is monitored with model {stored!r}; the "
                            f"manifest gives {rec.model!r}")
    except CondmonError as exc:
        plan.error = one_line(exc, None)
        return
    plan.model = model
    plan.kind = "estimate" if machine.spec.unknowns else "isolate"
    if plan.kind == "estimate" and state is not None:
        from condmon.workflows.monitoring import _held

        try:
            plan.hold = _held(UnitView.of(plan.name, state).current()[0])
        except DataError:  # fewer than 3 healthy tests
            plan.hold = None


# -- the run --------------------------------------------------------------------------


def run_fleet(source: str | Path, db: str | Path, *, manifest: bool | None = None,
              workers: int | None = None, scheduler: str | None = None,
              baseline_count: int = 3, options: EstimateOptions | None = None,
              progress: Progress | None = None, batch_size: int = 20,
              batch_seconds: float = 2.0,
              files: Collection[str | Path] | None = None) -> FleetResult:
    """Estimate (or isolate) every new record of a fleet and keep the results.

    Parameters
    ----------
    source : str or Path
        An inbox folder (``INBOX/UNIT/record files``, see :func:`inbox_records`)
        or a manifest file (CSV or TOML, see :func:`read_manifest`).
    db : str or Path
        History database: a SQLite file (created if missing) or a
        ``postgresql://`` URL.
    manifest : bool, optional
        Whether ``source`` is a manifest (default: when it is a file).
    workers : int, optional
        Worker processes of the local cluster (default: the machine's cores;
        a run with fewer than :data:`SMALL_FLEET` records to process then
        runs them in this process, its engine ``"in-process"``: a cluster
        would take longer to start than they take).
    scheduler : str, optional
        Address of an existing dask.distributed scheduler
        (``tcp://host:8786``) instead of a local cluster; its workers must
        read the record files at the same paths.
    baseline_count : int
        A unit without a baseline builds it from its first ``baseline_count``
        accepted records (>= 3); its later records are checked against it.
    options : EstimateOptions, optional
        How records are read and estimated (``model`` is each unit's).
    progress : callable, optional
        ``progress(done, total, label)`` as each record comes back.
    batch_size : int
        Results written per transaction (at least; a unit's records are
        written together).
    batch_seconds : float
        Longest wait before results ready to write are written. [s]
    files : collection of paths, optional
        Only these files of the inbox or manifest (``condmon watch FOLDER``
        hands over each file once it is complete); default: every one.

    Returns
    -------
    FleetResult

    Raises
    ------
    ConfigError
        A bad manifest or inbox, ``baseline_count`` below 3, ``workers`` with
        ``scheduler``.
    EngineError
        The local cluster cannot be started, the scheduler cannot be reached.
    StoreError
        The history cannot be opened or written.

    Notes
    -----
    A unit's model is the manifest's, else the one its history was started
    with, else the ``model`` of ``INBOX/UNIT/unit.toml``, else ``dc-motor``.
    A plant model without parameters to estimate (``hst``) gets fault
    isolation. Records already in the unit's history are skipped (by the
    file's SHA-256, then by content: a re-saved copy is skipped too), so
    running again stores nothing new.

    Example
    -------
    >>> res = run_fleet("inbox/", "fleet.db", workers=2)     # doctest: +SKIP
    >>> res.stored, res.skipped, res.to_dict()["records"][0]["status"]   # doctest: +SKIP
    """
    from condmon.monitor.baseline import MIN_BASELINE_TESTS

    started = time.perf_counter()
    if baseline_count < MIN_BASELINE_TESTS:
        raise ConfigError(f"baseline count must be >= {MIN_BASELINE_TESTS}, got {baseline_count}")
    if scheduler is not None and workers is not None:
        raise ConfigError("workers are for the local cluster; an existing cluster (scheduler "
                          f"{scheduler!r}) has its own")
    if workers is not None and workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    path = Path(source)
    as_manifest = path.is_file() if manifest is None else manifest
    records = read_manifest(path) if as_manifest else inbox_records(path)
    if files is not None:
        wanted = {Path(f).resolve() for f in files}
        records = [r for r in records if Path(r.path).resolve() in wanted]
    run = _Run(records, options or EstimateOptions(),
               progress or (lambda done, total, label: None), baseline_count, batch_size,
               batch_seconds)
    try:
        units, n_workers, engine = run.run(db, workers, scheduler)
    except KeyboardInterrupt:
        raise FleetInterrupted(run.written(), len(records)) from None
    ordered = tuple(r for u in sorted(run.reports, key=_natural) for r in run.reports[u])
    return FleetResult(ordered, units, n_workers, time.perf_counter() - started, engine,
                       *run.engine_seconds)


def _new_sqlite(db: str | Path) -> bool:
    """Whether ``db`` is a SQLite file that does not exist yet."""
    from condmon.store.engine import database_url, sqlite_path

    file = sqlite_path(database_url(db))
    return file is not None and not file.exists()


@dataclass
class _Run:
    """The state of a fleet run: its records, their units' plans and reports."""

    records: list[FleetRecord]
    options: EstimateOptions
    tick: Progress
    baseline_count: int
    batch_size: int
    batch_seconds: float
    reports: dict[str, list[RecordReport]] = field(default_factory=dict)
    plans: dict[str, _Unit] = field(default_factory=dict)
    done: int = 0
    engine_seconds: list[float] = field(default_factory=lambda: [0.0, 0.0])  # start, stop [s]

    def written(self) -> int:
        """Records written so far (stored, or kept as rejected)."""
        return sum(1 for rs in self.reports.values() for r in rs
                   if r.outcome in ("stored", "rejected"))

    def run(self, db: str | Path, workers: int | None, scheduler: str | None
            ) -> tuple[tuple[UnitReport, ...], int, str]:
        """Plan, process and commit; the units, worker threads and engine.

        A new SQLite file is made only once the engine is up (a run that
        cannot start, or has nothing to compute, leaves no empty history)."""
        from condmon.store.db import open_store

        n_workers, engine = 0, "none"
        with ExitStack() as stack:
            store = None if _new_sqlite(db) else stack.enter_context(open_store(db))
            tasks = self._plan(store)
            if tasks and workers is None and scheduler is None and len(tasks) < SMALL_FLEET:
                # a cluster costs as much to start as SMALL_FLEET records take here
                if store is None:
                    store = stack.enter_context(open_store(db))
                n_workers, engine = 1, "in-process"
                self._process(_in_process([t for _, t in tasks]), store, tasks)
            elif tasks:
                client = stack.enter_context(_timed_engine(workers, scheduler,
                                                           self.engine_seconds))
                if store is None:
                    store = stack.enter_context(open_store(db))
                n_workers = _threads(client)
                engine = "local" if scheduler is None else scheduler
                self._process(_run_tasks(client, [t for _, t in tasks]), store, tasks)
            units = _unit_reports(store, self.plans, self.reports)
        return units, n_workers, engine

    def _plan(self, store: HistoryStore | None) -> list[tuple[FleetRecord, RecordTask]]:
        """Each unit's model and known digests; the records settled without a
        worker reported; the tasks of the others."""
        plans = self.plans
        names = sorted({r.unit for r in self.records if not r.error and not r.skip})
        states: dict[str, UnitState] = {}
        digests: dict[str, dict[str, tuple[str, int]]] = {}
        if store is not None and names:
            with store.snapshot():
                states, digests = store.unit_states(names), store.record_digests(names)
        for rec in self.records:
            if rec.unit not in plans and not rec.error and not rec.skip:
                plans[rec.unit] = _Unit(rec.unit)
                _settle_model(states.get(rec.unit), plans[rec.unit], rec)
        for name, plan in plans.items():
            plan.known = digests.get(name, {})
            plan.digests = frozenset(plan.known)
        tasks: list[tuple[FleetRecord, RecordTask]] = []
        for rec in self.records:
            unit = plans.get(rec.unit)
            early = _before_work(rec, unit)
            if early is not None:
                self.reports.setdefault(rec.unit, []).append(early)
                self.done += 1
                self.tick(self.done, len(self.records), rec.path.name)
                continue
            assert unit is not None and unit.model is not None and unit.kind is not None
            unit.expected += 1
            tasks.append((rec, RecordTask(rec.unit, str(rec.path), unit.kind, unit.model,
                                          self._options_of(rec, unit), rec.test_date,
                                          unit.digests)))
        return tasks

    def _options_of(self, rec: FleetRecord, unit: _Unit) -> EstimateOptions:
        """The run's options for one record: its unit folder's and manifest row's
        record settings and metadata under the command line's, and the unit's
        baseline to hold unidentified unknowns at."""
        opts = self.options
        settings = (rec.settings or RecordSettings()).merged(opts.record)
        metadata = {**(rec.metadata or {}), **(opts.metadata or {})}
        return dataclasses.replace(opts, record=None if settings.empty else settings,
                                   metadata=metadata or None, hold=unit.hold)

    def _process(self, outcomes: Iterator[RecordOutcome], store: HistoryStore,
                 tasks: list[tuple[FleetRecord, RecordTask]]) -> None:
        """Take the tasks' ``outcomes`` as they come; commit each unit once all
        its records are back, many units per transaction. A Ctrl-C never
        splits a transaction: the units complete by then are committed, and
        KeyboardInterrupt goes on."""
        by_path = {(t.unit, t.path): rec for rec, t in tasks}
        ready: list[_Unit] = []
        waiting_since: float | None = None

        def commit() -> None:
            with _sigint_held():
                _write(store, ready, self.baseline_count, self.reports)
                ready.clear()

        try:
            for out in outcomes:
                plan = self.plans[out.unit]
                plan.outcomes.append((by_path[(out.unit, out.path)], out))
                self.done += 1
                self.tick(self.done, len(self.records), Path(out.path).name)
                if len(plan.outcomes) == plan.expected:
                    ready.append(plan)
                    waiting_since = waiting_since or time.monotonic()
                n_ready = sum(len(p.outcomes) for p in ready)
                if ready and (n_ready >= self.batch_size or
                              time.monotonic() - (waiting_since or 0.0) >= self.batch_seconds):
                    commit()
                    waiting_since = None
        except KeyboardInterrupt:
            commit()
            raise
        commit()


#: Fewest records a fleet run starts a local cluster for, when not told how
#: many workers: starting one took as long as estimating 50-80 records on this
#: project's 2-core test machine (``benchmarks/bench_fleet.py``).
SMALL_FLEET = 50


def _in_process(tasks: Sequence[RecordTask]) -> Iterator[RecordOutcome]:
    """The tasks' outcomes computed here, one record at a time (a small fleet);
    a record whose processing fails unexpectedly is reported as a worker's
    would be (:func:`condmon.workflows.fleet_engine._run_tasks`)."""
    for task in tasks:
        try:
            yield process_record(task)
        except Exception as exc:  # noqa: BLE001 - as a lost worker: reported, the run goes on
            yield RecordOutcome(task.unit, task.path, error=_named(
                task.path, f"not processed: {type(exc).__name__}: {exc}"))


@contextmanager
def _timed_engine(workers: int | None, scheduler: str | None, times: list[float]
                  ) -> Iterator[Client]:
    """The engine; the seconds it took to start (or connect) and to stop in ``times``."""
    t0 = time.perf_counter()
    with _engine(workers, scheduler) as client:
        times[0] = time.perf_counter() - t0
        try:
            yield client
        finally:
            t0 = time.perf_counter()
    times[1] = time.perf_counter() - t0


def _before_work(rec: FleetRecord, plan: _Unit | None) -> RecordReport | None:
    """The report of a record settled without a worker: refused (its unit's
    model, a bad manifest row, not a record file, an unreadable file) or
    skipped (listed again in the manifest, or this very file is in the unit's
    history); None when it is to be processed."""
    kind = "isolation" if plan is not None and plan.kind == "isolate" else "test"
    where = str(rec.path)
    if rec.skip is not None and rec.error is None:
        return RecordReport(rec.unit, where, "skipped", None, _named(where, rec.skip), kind=kind,
                            test_date=rec.test_date)
    why = rec.error or (plan.error if plan is not None else None)
    if why is None:
        try:
            fdig = file_hash(rec.path)
        except FileNotFoundError:
            why = "file not found"
        except OSError as exc:
            why = f"cannot read: {exc.strerror or exc}"
    if why is not None:
        return RecordReport(rec.unit, where, "refused", None, _named(where, why), kind=kind,
                            test_date=rec.test_date)
    assert plan is not None
    known = plan.known.get(fdig)
    if known is None:
        return None
    return RecordReport(rec.unit, where, "skipped", None, f"already in the history of "
                        f"{rec.unit!r} ({known[0]} #{known[1]})", known[1], known[0],
                        rec.test_date)


def _unit_reports(store: HistoryStore | None, plans: dict[str, _Unit],
                  reports: dict[str, list[RecordReport]]) -> tuple[UnitReport, ...]:
    """Each unit of the run with its status in the history (as ``condmon units``;
    none without a history)."""
    summaries = ({str(s["unit"]): s for s in store.unit_summaries()}
                 if plans and store is not None else {})
    out = []
    for name in sorted(reports, key=_natural):
        if not name:  # record files outside any unit's folder
            continue
        plan = plans.get(name)
        counts = {o: sum(1 for r in reports[name] if r.outcome == o) for o in OUTCOMES}
        summary = summaries.get(name)
        status = None if summary is None or summary["status"] is None else str(summary["status"])
        out.append(UnitReport(name, plan.model if plan is not None else None,
                              plan.kind if plan is not None else None, status, counts,
                              record_by_record(plan.model) if plan is not None
                              and plan.kind == "estimate" else ""))
    return tuple(out)
