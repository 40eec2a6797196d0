"""A fleet's new records, estimated or isolated on a distributed engine and kept in one history.

The flow of :func:`run_fleet`::

    inbox or manifest -> records per unit -> each unit's model
    -> records already in the history skipped (by file, then by content)
    -> process_record on the engine's workers (read, estimate or isolate; no database)
    -> per unit, in date order (else file-name order): baseline tests while the
       unit has no baseline, checks against it afterwards; isolations for plant models
    -> written by the client, many results per transaction (``store.batch()``)

The engine is dask.distributed: a local cluster of worker processes (one
thread each, BLAS on one thread) or an existing cluster's scheduler. The unit
of work, :func:`process_record`, is a plain function of one record's path and
options returning a small picklable :class:`RecordOutcome` (the estimate or the
isolation, how the record is known, or the error text), so one record's
failure never stops the others and a worker never touches the database.

A unit's records are committed once all of them are back from the workers, in
the order they were run, by the same steps as
:func:`condmon.workflows.monitoring.add_baseline_tests` (while the unit has no
baseline) and :func:`condmon.workflows.monitoring.check_test` (afterwards), so
the fleet gives the answers those give for the same records.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import logging
import os
import re
import time
import tomllib
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from condmon.errors import CondmonError, ConfigError, DataError
from condmon.io.dates import parse_date
from condmon.io.digest import file_hash
from condmon.io.readers import READABLE_SUFFIXES
from condmon.workflows.records import EstimateOptions, RecordKey

if TYPE_CHECKING:
    from distributed import Client

    from condmon.diagnose.isolation import IsolationResult, IsolationSettings
    from condmon.diagnose.rules import RuleBase
    from condmon.identify.estimate import EstimateResult
    from condmon.models.declared import PlantModel
    from condmon.monitor.baseline import Baseline
    from condmon.monitor.fuzzy import MonitorConfig
    from condmon.store.baselines import StoredBaseline
    from condmon.store.db import HistoryStore

__all__ = ["EngineError", "DEFAULT_MODEL", "OUTCOMES", "BLAS_ENV", "FleetRecord", "RecordTask", "RecordOutcome",
           "RecordReport", "UnitReport", "FleetResult", "inbox_records", "read_manifest",
           "process_record", "local_cluster", "run_fleet"]

#: The model of a unit named nowhere (manifest, history, ``unit.toml``).
DEFAULT_MODEL = "dc-motor"

#: What became of a record: written (``stored``; ``rejected``: its estimate
#: failed the fit and is kept as rejected), already in the history or twice in
#: this run (``skipped``), or not written with the reason (``refused``).
OUTCOMES = ("stored", "skipped", "rejected", "refused")

#: Environment of a local cluster's workers: one BLAS thread per worker process.
BLAS_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}

#: Name of a unit folder's optional declaration (``model = "..."``).
UNIT_FILE = "unit.toml"

Kind = Literal["estimate", "isolate"]


class EngineError(CondmonError, RuntimeError):
    """The distributed engine cannot be started or reached."""


Progress = Callable[[int, int, str], None]


# -- what to process ------------------------------------------------------------------


@dataclass(frozen=True)
class FleetRecord:
    """One record offered to the fleet run.

    Attributes
    ----------
    unit : str
        The unit (machine) it belongs to.
    path : Path
        The record file.
    model : str or None
        The model the manifest names for the unit (it must match the unit's
        stored model), else None.
    fallback_model : str or None
        The model of the unit folder's ``unit.toml``, used when the unit has no
        history yet and the manifest names none.
    test_date : datetime or None
        When the test was run (the manifest's ``date``, UTC); None: the
        record's own date, if its metadata has one.
    error : str or None
        Why the record is refused before it is read (a manifest row's bad date).
    """

    unit: str
    path: Path
    model: str | None = None
    fallback_model: str | None = None
    test_date: datetime | None = None
    error: str | None = None


def _natural(text: str) -> tuple[tuple[int, int | str], ...]:
    """Sort key of a name with its numbers compared as numbers (rec-2 < rec-10)."""
    return tuple((0, int(part)) if part.isdigit() else (1, part)
                 for part in re.split(r"(\d+)", text) if part)


def _name_key(path: Path) -> tuple[Any, ...]:
    """File-name order: numbers as numbers, a name before its longer variants
    (``rec-2.csv`` < ``rec-2-copy.csv`` < ``rec-10.csv``)."""
    return (_natural(str(path.with_suffix(""))), path.suffix)


def _is_record(path: Path) -> bool:
    return (path.is_file() and not path.name.startswith(".")
            and path.suffix.lower() in READABLE_SUFFIXES)


def _unit_file_model(folder: Path) -> tuple[str | None, str | None]:
    """``(model, error)`` of ``folder/unit.toml`` (both None without one)."""
    path = folder / UNIT_FILE
    if not path.is_file():
        return None, None
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        return None, f"{path}: cannot read: {_one_line(exc)}"
    model = doc.get("model")
    if not isinstance(model, str) or not model.strip():
        return None, f"{path}: needs model = \"NAME or declaration.toml\""
    model = model.strip()
    if model.lower().endswith(".toml") and not Path(model).is_absolute():
        model = str(folder / model)
    return model, None


def inbox_records(inbox: str | Path) -> list[FleetRecord]:
    """The records of an inbox folder: ``INBOX/UNIT/...`` (a folder per unit).

    Every file under a unit's folder (sub-folders too) with a record suffix
    (:data:`condmon.io.readers.READABLE_SUFFIXES`) is a record of that unit;
    other files and hidden ones are ignored. ``INBOX/UNIT/unit.toml`` may name
    the unit's model (``model = "dc-motor-coulomb"`` or a declaration file,
    relative to the folder), used while the unit has no history. A record file
    directly in the inbox (in no unit's folder) is refused.

    Raises
    ------
    ConfigError
        ``inbox`` is not a folder.

    Example
    -------
    >>> import tempfile
    >>> root = Path(tempfile.mkdtemp())
    >>> for name in ("EMA-1/rec-10.csv", "EMA-1/rec-2.csv", "EMA-1/notes.md"):
    ...     (root / name).parent.mkdir(exist_ok=True)
    ...     _ = (root / name).write_text("t\\n")
    >>> [r.path.name for r in inbox_records(root)]
    ['rec-2.csv', 'rec-10.csv']
    """
    root = Path(inbox)
    if not root.is_dir():
        raise ConfigError(f"{root}: not a folder; the inbox holds a folder per unit "
                          "(INBOX/UNIT/record files)")
    records: list[FleetRecord] = []
    for entry in sorted(root.iterdir(), key=lambda p: _natural(p.name)):
        if entry.name.startswith("."):
            continue
        if entry.is_dir():
            model, error = _unit_file_model(entry)
            files = sorted((p for p in entry.rglob("*") if _is_record(p)),
                           key=lambda p: _name_key(p.relative_to(entry)))
            records += [FleetRecord(entry.name, p, fallback_model=model, error=error)
                        for p in files]
        elif _is_record(entry):
            records.append(FleetRecord("", entry, error=f"{entry}: not in a unit's folder "
                                       "(INBOX/UNIT/record files)"))
    return records


MANIFEST_COLUMNS = ("unit", "file", "model", "date")


def read_manifest(manifest: str | Path) -> list[FleetRecord]:
    """The records listed in a manifest (CSV or TOML).

    A CSV manifest has a header with the columns ``unit`` and ``file``, and
    optionally ``model`` and ``date``; a TOML manifest lists ``[[records]]``
    tables with the same keys. A relative ``file`` (and a relative model
    declaration ``.toml``) is resolved against the manifest's folder. A unit's
    rows must name one model (or none). A row whose date cannot be read is
    refused alone.

    Raises
    ------
    ConfigError
        The manifest cannot be read, lacks a column, has an unknown column, a
        row without unit or file, or two models for one unit.

    Example
    -------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> _ = (folder / "m.csv").write_text("unit,file,date\\nEMA-1,a.csv,2026-03-01\\n")
    >>> rec = read_manifest(folder / "m.csv")[0]
    >>> rec.unit, rec.path == folder / "a.csv", rec.test_date.isoformat()
    ('EMA-1', True, '2026-03-01T00:00:00+00:00')
    """
    path = Path(manifest)
    rows = _manifest_rows(path)
    base = path.parent
    models: dict[str, tuple[str | None, int]] = {}
    records = []
    for n, row in rows:
        unit, file = (str(row.get(k) or "").strip() for k in ("unit", "file"))
        if not unit or not file:
            raise ConfigError(f"{path}: row {n}: needs a unit and a file")
        model = str(row.get("model") or "").strip() or None
        if model is not None and model.lower().endswith(".toml") and not Path(model).is_absolute():
            model = str(base / model)
        if unit in models and models[unit][0] != model:
            raise ConfigError(f"{path}: row {n}: unit {unit!r} has model {model or 'none'!r}; "
                              f"row {models[unit][1]} gave {models[unit][0] or 'none'!r} (one "
                              "model per unit)")
        models.setdefault(unit, (model, n))
        file_path = Path(file) if Path(file).is_absolute() else base / file
        when: datetime | None = None
        error = None
        raw_date = row.get("date")
        if raw_date not in (None, ""):
            try:
                when = parse_date(raw_date if isinstance(raw_date, datetime) else str(raw_date),
                                  f"{path}: row {n}: date")
            except DataError as exc:
                error = str(exc)
        records.append(FleetRecord(unit, file_path, model, None, when, error))
    return records


def _manifest_rows(path: Path) -> list[tuple[int, dict[str, Any]]]:
    """``(row number, {column: value})`` of a CSV (numbered as lines) or TOML manifest."""
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".toml"):
        raise ConfigError(f"{path}: unknown manifest type {suffix!r}; allowed: .csv, .toml")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise ConfigError(f"{path}: manifest not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read the manifest: {_one_line(exc)}") from None
    if suffix == ".toml":
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{path}: not TOML: {_one_line(exc)}") from None
        entries = doc.get("records")
        if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
            raise ConfigError(f"{path}: needs [[records]] tables with unit, file (and "
                              "optionally model, date)")
        rows = list(enumerate(entries, start=1))
    else:
        reader = csv.DictReader(text.splitlines())
        header = [h.strip() for h in reader.fieldnames or []]
        missing = [c for c in ("unit", "file") if c not in header]
        if missing:
            raise ConfigError(f"{path}: missing column {missing[0]!r}; columns: "
                              f"{', '.join(MANIFEST_COLUMNS)} (unit and file required)")
        reader.fieldnames = header
        rows = [(n, row) for n, row in enumerate(reader, start=2)
                if any((v or "").strip() for v in row.values() if isinstance(v, str))]
    for n, row in rows:
        unknown = [k for k in row if k not in MANIFEST_COLUMNS]
        if unknown:
            raise ConfigError(f"{path}: row {n}: unknown column {unknown[0]!r}; allowed: "
                              f"{', '.join(MANIFEST_COLUMNS)}")
    return rows


# -- the unit of work -----------------------------------------------------------------


@dataclass(frozen=True)
class RecordTask:
    """What a worker needs to process one record.

    Attributes
    ----------
    unit : str
    path : str
        The record file (a path the workers can read).
    kind : {"estimate", "isolate"}
        Estimate the model's parameters, or isolate a fault (a plant model).
    model : str
        Model name or declaration file.
    options : EstimateOptions
        How to read and estimate (``columns`` applies to isolations too).
    test_date : datetime or None
        When the test was run, if given (else the record's own date, if any).
    known : frozenset of str
        Content hashes already in the unit's history: such a record is
        recognised after reading and not processed.
    """

    unit: str
    path: str
    kind: Kind
    model: str
    options: EstimateOptions = field(default_factory=EstimateOptions)
    test_date: datetime | None = None
    known: frozenset[str] = frozenset()


@dataclass(frozen=True)
class RecordOutcome:
    """What a worker returns for one record (small and picklable).

    Attributes
    ----------
    unit : str
    path : str
    key : RecordKey or None
        How the record is known (None when it could not be read).
    estimate : EstimateResult or None
        For ``kind == "estimate"``.
    isolation : IsolationResult or None
        For ``kind == "isolate"``.
    error : str or None
        Why the record could not be processed (one line naming the file).
    known : bool
        Its content is already in the unit's history (nothing processed).
    warnings : tuple of str
        Warnings raised while reading or processing it.
    seconds : float
        Time on the worker. [s]
    """

    unit: str
    path: str
    key: RecordKey | None = None
    estimate: EstimateResult | None = None
    isolation: IsolationResult | None = None
    error: str | None = None
    known: bool = False
    warnings: tuple[str, ...] = ()
    seconds: float = 0.0


def _one_line(exc: BaseException | str) -> str:
    return " ".join(str(exc).split()) or (type(exc).__name__ if isinstance(exc, BaseException)
                                          else "")


def _named(path: str, message: str) -> str:
    """``message`` as one line that names the file."""
    text = _one_line(message)
    return text if path in text else f"{path}: {text}"


@functools.lru_cache(maxsize=16)
def _plant(model: str) -> PlantModel:
    from condmon.models.declared import load_plant_model

    return load_plant_model(model)


@functools.lru_cache(maxsize=1)
def _isolation_settings() -> IsolationSettings:
    from condmon.diagnose.isolation import IsolationSettings

    return IsolationSettings.load()


def process_record(task: RecordTask) -> RecordOutcome:
    """Read one record and estimate it (or isolate a fault in it); never raises
    on the record: a failure becomes the outcome's ``error``.

    This is the unit of work shipped to a worker: a pure function of the
    record's file and the options, touching no database. An isolation runs
    its suspects one after the other (a worker is one process already).

    Parameters
    ----------
    task : RecordTask

    Returns
    -------
    RecordOutcome

    Example
    -------
    >>> out = process_record(RecordTask("EMA-1", "missing.csv", "estimate", "dc-motor"))
    >>> out.error
    'missing.csv: file not found'
    """
    from condmon.io.records import read_record
    from condmon.workflows.monitoring import record_key

    started = time.perf_counter()
    key = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            df = read_record(task.path, task.options.columns)
            key = record_key(df, task.path, task.test_date)
            if key.content in task.known:
                return RecordOutcome(task.unit, task.path, key, known=True,
                                     seconds=time.perf_counter() - started)
            if task.kind == "isolate":
                from condmon.diagnose.isolation import isolate

                iso = isolate(df, _plant(task.model), settings=_isolation_settings(),
                              workers=1, source=task.path)
                return RecordOutcome(task.unit, task.path, key, isolation=iso,
                                     warnings=_texts(caught),
                                     seconds=time.perf_counter() - started)
            df.attrs["source"] = task.path
            opts = dataclasses.replace(task.options, model=task.model, columns=None)
            res, _ = opts.run(df)  # the columns were mapped when reading
            return RecordOutcome(task.unit, task.path, key, estimate=res,
                                 warnings=_texts(caught), seconds=time.perf_counter() - started)
        except CondmonError as exc:
            why = str(exc)
        except FileNotFoundError:
            why = "file not found"
        except OSError as exc:
            why = f"cannot read: {exc.strerror or exc}"
        except Exception as exc:  # noqa: BLE001 - a numerical failure is this record's alone
            why = f"{type(exc).__name__}: {exc}"
    return RecordOutcome(task.unit, task.path, key, error=_named(task.path, why),
                         warnings=_texts(caught), seconds=time.perf_counter() - started)


def _texts(caught: list[warnings.WarningMessage]) -> tuple[str, ...]:
    return tuple(dict.fromkeys(_one_line(str(w.message)) for w in caught))


# -- results --------------------------------------------------------------------------


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
        units`` shows it), ``building`` while fewer than the baseline's tests
        are accepted, None when the history has nothing of it.
    records : dict of str to int
        How many of its records had each outcome.
    """

    unit: str
    model: str | None
    kind: str | None
    status: str | None
    records: dict[str, int]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready unit."""
        return {"unit": self.unit, "model": self.model, "kind": self.kind,
                "status": self.status, "records": dict(self.records)}


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
        ``local`` or the scheduler's address (``none`` when not started).
    """

    records: tuple[RecordReport, ...]
    units: tuple[UnitReport, ...]
    workers: int
    seconds: float
    engine: str

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

    def to_dict(self) -> dict[str, Any]:
        """The ``condmon fleet run --json`` document: ``stored, skipped,
        rejected, refused`` (counts that add up to the records), ``records``,
        ``units``, ``workers``, ``seconds``, ``engine``."""
        return {**{o: self.count(o) for o in OUTCOMES},
                "records": [r.to_dict() for r in self.records],
                "units": [u.to_dict() for u in self.units],
                "workers": self.workers, "seconds": self.seconds, "engine": self.engine}


# -- the engine -----------------------------------------------------------------------


@contextmanager
def local_cluster(workers: int | None = None) -> Iterator[Client]:
    """A dask.distributed client of a local cluster: ``workers`` processes
    (default: the machine's cores), one thread each, BLAS limited to one
    thread (:data:`BLAS_ENV`); its HTTP endpoints on a free port (never the
    dashboard's 8787, which another cluster may hold); shut down when the
    block ends.

    Example
    -------
    >>> with local_cluster(1) as client:                       # doctest: +SKIP
    ...     client.submit(process_record, task).result()
    """
    from distributed import Client, LocalCluster

    n = workers if workers is not None else (os.cpu_count() or 1)
    if n < 1:
        raise ConfigError(f"workers must be >= 1, got {n}")
    try:
        cluster = LocalCluster(n_workers=n, threads_per_worker=1,  # type: ignore[no-untyped-call]
                               processes=True, dashboard_address=":0",
                               silence_logs=logging.ERROR, env=dict(BLAS_ENV))
    except (OSError, RuntimeError, TimeoutError) as exc:
        raise EngineError(f"cannot start a local cluster of {n} worker(s): "
                          f"{_one_line(exc)}") from None
    with cluster, Client(cluster, set_as_default=False) as client:  # type: ignore[no-untyped-call]
        yield client


@contextmanager
def _engine(workers: int | None, scheduler: str | None) -> Iterator[Client]:
    if scheduler is None:
        with local_cluster(workers) as client:
            yield client
        return
    from distributed import Client

    try:
        client = Client(scheduler, set_as_default=False, timeout="10s")  # type: ignore[no-untyped-call]
    except (OSError, TimeoutError, ValueError) as exc:
        raise EngineError(f"cannot reach the scheduler {scheduler!r}: {_one_line(exc)}") from None
    with client:
        yield client


def _threads(client: Client) -> int:
    """Worker threads of the cluster."""
    return sum(client.nthreads().values())  # type: ignore[no-untyped-call]


def _run_tasks(client: Client, tasks: Sequence[RecordTask]) -> Iterator[RecordOutcome]:
    """Outcomes as workers finish them, at most a few tasks per worker queued
    at a time (a unit's records finish close together)."""
    from distributed import as_completed

    window = max(16, 4 * _threads(client))
    todo = iter(tasks)
    by_future: dict[Any, RecordTask] = {}
    running = as_completed(loop=client.loop)  # type: ignore[no-untyped-call]
    for task in todo:
        fut = client.submit(process_record, task, pure=False)
        by_future[fut] = task
        running.add(fut)  # type: ignore[no-untyped-call]
        if len(by_future) >= window:
            break
    for fut in running:
        task = by_future.pop(fut)
        try:
            outcome = fut.result()
        except Exception as exc:  # noqa: BLE001 - a worker lost, a task cancelled
            outcome = RecordOutcome(task.unit, task.path, error=_named(
                task.path, f"not processed: {type(exc).__name__}: {exc}"))
        fut.release()
        yield outcome
        nxt = next(todo, None)
        if nxt is not None:
            new = client.submit(process_record, nxt, pure=False)
            by_future[new] = nxt
            running.add(new)  # type: ignore[no-untyped-call]


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


@dataclass
class _Checker:
    """The unit's baseline while its records are committed (one batch)."""

    baseline: Baseline
    ids: list[int]
    latest: StoredBaseline | None


def _stored_digests(store: HistoryStore, units: Sequence[str]) -> dict[str, dict[str, tuple[str, int]]]:
    """Content and file hashes of the units' tests and isolations, with their ids."""
    import sqlalchemy as sa

    from condmon.store import schema as S

    wanted = set(units)

    def run(c: sa.Connection) -> dict[str, dict[str, tuple[str, int]]]:
        found: dict[str, dict[str, tuple[str, int]]] = {}
        for table, kind in ((S.tests, "test"), (S.isolations, "isolation")):
            rows = c.execute(sa.select(S.units.c.name, table.c.id, table.c.record_hash,
                                       table.c.file_hash)
                             .join(S.units, S.units.c.id == table.c.unit_id)
                             .order_by(table.c.id.desc())).all()
            for name, tid, content, fdig in rows:
                if name in wanted:
                    known = found.setdefault(name, {})
                    for digest in (content, fdig):
                        if digest:
                            known[digest] = (kind, int(tid))
        return found

    return store._read(run)


def _settle_model(store: HistoryStore, plan: _Unit, rec: FleetRecord) -> None:
    """The unit's model: the manifest's, else its history's, else ``unit.toml``'s,
    else :data:`DEFAULT_MODEL`; the kind of processing; or why it is refused."""
    from condmon.models.registry import get_model
    from condmon.store.base import check_name

    try:
        check_name(plan.name)
        stored = store.unit_model(plan.name)
        model = rec.model or stored or rec.fallback_model or DEFAULT_MODEL
        machine = get_model(model)
        if stored is not None and rec.model is not None and stored not in (machine.name,
                                                                            machine.origin):
            raise DataError(f"unit {plan.name!r} is monitored with model {stored!r}; the "
                            f"manifest gives {rec.model!r}")
    except CondmonError as exc:
        plan.error = _one_line(exc)
        return
    plan.model = model
    plan.kind = "estimate" if machine.spec.unknowns else "isolate"


def _order(item: tuple[FleetRecord, RecordOutcome]) -> tuple[Any, ...]:
    """Date order when known (dated records first), else file-name order."""
    rec, out = item
    when = rec.test_date or (out.key.test_date if out.key is not None else None)
    return (when is None, when.timestamp() if when is not None else 0.0,
            _name_key(Path(rec.path.name)), _name_key(rec.path))


@functools.lru_cache(maxsize=16)
def _monitoring(model: str) -> tuple[MonitorConfig, RuleBase]:
    from condmon.diagnose.rules import load_rules
    from condmon.models.registry import get_model
    from condmon.monitor.fuzzy import load_monitor_config

    machine = get_model(model)
    return load_monitor_config(machine.breakpoints), load_rules(machine.rules)


def _commit_unit(store: HistoryStore, plan: _Unit, baseline_count: int) -> list[RecordReport]:
    """Write a unit's outcomes in the order its records were run (inside a batch)."""
    from condmon.store import DuplicateTestError, StoreError

    items = sorted(plan.outcomes, key=_order)
    reports = []
    seen: dict[str, str] = {}
    checker: list[_Checker | None] = [None]  # loaded at the unit's first check
    if plan.kind == "estimate":
        from condmon.workflows.monitoring import baseline_members

        ids, latest = baseline_members(store, plan.name)
        plan.building = latest is None and len(ids) < baseline_count
    for rec, out in items:
        where = str(rec.path)
        date = rec.test_date or (out.key.test_date if out.key is not None else None)
        kind = "isolation" if plan.kind == "isolate" else "test"

        def report(outcome: str, status: str | None = None, reason: str | None = None,
                   tid: int | None = None) -> RecordReport:
            return RecordReport(plan.name, where, outcome, status, reason, tid, kind, date,
                                out.warnings)

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
            elif plan.building:
                reports.append(_commit_baseline_test(store, plan, out, baseline_count, report))
            else:
                reports.append(_commit_check(store, plan, out, checker, report))
        except DuplicateTestError as dup:  # written meanwhile by another process
            reports.append(report("skipped", reason=_one_line(dup), tid=dup.test_id))
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
                              digest=key.content, file_digest=key.file, test_date=key.test_date,
                              model_source=machine.origin)
    return report("stored", isolation_status(iso.detected, iso.decided),
                  iso.statement if iso.decided else (iso.reason or iso.statement), iid)


def _commit_baseline_test(store: HistoryStore, plan: _Unit, out: RecordOutcome,
                          baseline_count: int, report: ReportFn) -> RecordReport:
    """As :func:`condmon.workflows.monitoring.add_baseline_tests` for one record;
    the baseline is saved once ``baseline_count`` tests are accepted."""
    from condmon.workflows.monitoring import (
        _unit_error, baseline_members, current_baseline, reevaluate, save_current_baseline,
    )

    res, key = out.estimate, out.key
    assert res is not None and key is not None
    if res.accepted:
        try:
            prior: Baseline | None = current_baseline(store, plan.name)[0]
        except DataError:
            prior = None
        why = None if prior is None else _unit_error(res, prior)
        if why is not None:
            return report("refused", reason=_named(out.path, f"refused, {why}; nothing was "
                                                   "stored"))
    tid = store.add_test(plan.name, res, role="baseline", digest=key.content,
                         file_digest=key.file, test_date=key.test_date)
    if not res.accepted:
        return report("rejected", "retest", _one_line(str(res.reason)), tid)
    ids, latest = baseline_members(store, plan.name)
    if latest is None and len(ids) >= baseline_count:
        stored, fresh = save_current_baseline(store, plan.name, ids,
                                              reason=f"first baseline ({len(ids)} tests)")
        if fresh:
            reevaluate(store, plan.name, stored)
        plan.building = False
        return report("stored", "baseline", f"baseline of {plan.name!r} from {len(ids)} "
                      f"accepted healthy tests ({stored.name!r} v{stored.version})", tid)
    return report("stored", "baseline", f"baseline test {len(ids)} of {baseline_count}", tid)


def _commit_check(store: HistoryStore, plan: _Unit, out: RecordOutcome,
                  checker: list[_Checker | None], report: ReportFn) -> RecordReport:
    """As :func:`condmon.workflows.monitoring.check_test` for one estimated record."""
    from condmon.workflows.monitoring import (
        _unit_error, current_baseline, evaluate, save_current_baseline,
    )

    res, key = out.estimate, out.key
    assert res is not None and key is not None and plan.model is not None
    cfg, rb = _monitoring(plan.model)
    state = checker[0]
    if state is None:
        baseline, ids = current_baseline(store, plan.name)
        rb.check_parameters(baseline.parameters)
        state = checker[0] = _Checker(baseline, ids, store.latest_baseline(plan.name))
    why = _unit_error(res, state.baseline) if res.accepted else None
    if why is not None:
        return report("refused", reason=_named(out.path, f"refused, {why}; nothing was stored"))
    if not res.accepted:
        tid = store.add_test(plan.name, res, role="check", digest=key.content,
                             file_digest=key.file, test_date=key.test_date)
        return report("rejected", "retest", _one_line(str(res.reason)), tid)
    row, diag = evaluate(res, state.baseline, cfg, rb)
    if state.latest is None or list(state.latest.test_ids) != state.ids:
        state.latest, _ = save_current_baseline(store, plan.name, state.ids, monitor=cfg,
                                                reason="baseline of the first check")
    tid = store.add_test(plan.name, res, role="check", digest=key.content, file_digest=key.file,
                         test_date=key.test_date, symptoms=row, baseline_id=state.latest.id,
                         diagnosis=diag)
    return report("stored", diag.status, diag.summary, tid)


# -- the run --------------------------------------------------------------------------


def run_fleet(source: str | Path, db: str | Path, *, manifest: bool | None = None,
              workers: int | None = None, scheduler: str | None = None,
              baseline_count: int = 3, options: EstimateOptions | None = None,
              progress: Progress | None = None, batch_size: int = 20,
              batch_seconds: float = 2.0) -> FleetResult:
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
        Worker processes of the local cluster (default: the machine's cores).
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
    from condmon.store.db import open_store

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
    opts = options or EstimateOptions()
    tick = progress or (lambda done, total, label: None)
    total = len(records)
    done = 0
    reports: dict[str, list[RecordReport]] = {}
    plans: dict[str, _Unit] = {}
    with open_store(db) as store:
        for rec in records:
            if rec.unit not in plans and not rec.error:
                plans[rec.unit] = _Unit(rec.unit)
                _settle_model(store, plans[rec.unit], rec)
        digests = _stored_digests(store, [u for u, p in plans.items() if p.error is None])
        for name, plan in plans.items():
            plan.known = digests.get(name, {})
            plan.digests = frozenset(plan.known)
        tasks: list[tuple[FleetRecord, RecordTask]] = []
        for rec in records:
            unit = plans.get(rec.unit)
            early = _before_work(rec, unit)
            if early is not None:
                reports.setdefault(rec.unit, []).append(early)
                done += 1
                tick(done, total, rec.path.name)
                continue
            assert unit is not None and unit.model is not None and unit.kind is not None
            unit.expected += 1
            tasks.append((rec, RecordTask(rec.unit, str(rec.path), unit.kind, unit.model, opts,
                                          rec.test_date, unit.digests)))
        n_workers, engine = 0, "none"
        if tasks:
            by_path = {(t.unit, t.path): rec for rec, t in tasks}
            with _engine(workers, scheduler) as client:
                n_workers = _threads(client)
                engine = "local" if scheduler is None else scheduler
                ready: list[_Unit] = []
                waiting_since: float | None = None
                for out in _run_tasks(client, [t for _, t in tasks]):
                    plan = plans[out.unit]
                    plan.outcomes.append((by_path[(out.unit, out.path)], out))
                    done += 1
                    tick(done, total, Path(out.path).name)
                    if len(plan.outcomes) == plan.expected:
                        ready.append(plan)
                        waiting_since = waiting_since or time.monotonic()
                    n_ready = sum(len(p.outcomes) for p in ready)
                    if ready and (n_ready >= batch_size or
                                  time.monotonic() - (waiting_since or 0.0) >= batch_seconds):
                        _write(store, ready, baseline_count, reports)
                        ready, waiting_since = [], None
                if ready:
                    _write(store, ready, baseline_count, reports)
        units = _unit_reports(store, plans, reports)
    ordered = tuple(r for u in sorted(reports, key=_natural) for r in reports[u])
    return FleetResult(ordered, units, n_workers, time.perf_counter() - started, engine)


def _before_work(rec: FleetRecord, plan: _Unit | None) -> RecordReport | None:
    """The report of a record settled without a worker: refused (its unit's
    model, a bad manifest date, an unreadable file) or skipped (this very file
    is in the unit's history); None when it is to be processed."""
    kind = "isolation" if plan is not None and plan.kind == "isolate" else "test"
    where = str(rec.path)
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


def _write(store: HistoryStore, ready: list[_Unit], baseline_count: int,
           reports: dict[str, list[RecordReport]]) -> None:
    """Commit the ready units' outcomes in one transaction."""
    with store.batch():
        for plan in ready:
            reports.setdefault(plan.name, []).extend(_commit_unit(store, plan, baseline_count))
            plan.outcomes.clear()


def _unit_reports(store: HistoryStore, plans: dict[str, _Unit],
                  reports: dict[str, list[RecordReport]]) -> tuple[UnitReport, ...]:
    """Each unit of the run with its status in the history (as ``condmon units``)."""
    summaries = {str(s["unit"]): s for s in store.unit_summaries()} if plans else {}
    out = []
    for name in sorted(reports, key=_natural):
        if not name:  # record files outside any unit's folder
            continue
        plan = plans.get(name)
        counts = {o: sum(1 for r in reports[name] if r.outcome == o) for o in OUTCOMES}
        summary = summaries.get(name)
        status = None if summary is None or summary["status"] is None else str(summary["status"])
        if (plan is not None and plan.kind == "estimate" and status in ("baseline", "rejected")
                and store.latest_baseline(name) is None):
            status = "building"
        out.append(UnitReport(name, plan.model if plan is not None else None,
                              plan.kind if plan is not None else None, status, counts))
    return tuple(out)
