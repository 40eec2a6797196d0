"""Many results written at once: what a batch needs to know, read in a few
queries, and its new rows written with one statement per table.

A client committing many records at a time (a fleet run) reads what the
history holds of the batch's units with :meth:`BulkMixin.unit_states` and the
rows that may hold the same records with :meth:`BulkMixin.record_rows`, decides
every record in memory, collects the new rows in a :class:`BulkWriter` (ids
of rows not written yet are :class:`Pending`) and writes them with
:meth:`BulkMixin.write_bulk`: one ``executemany`` per table, in the order the
foreign keys need. When that fails, the records are written one at a time so
that the one at fault is named and the ones before it are kept.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import sqlalchemy as sa

from condmon.errors import ConfigError
from condmon.models.bundle import DeclarationBundle, declaration_bundle
from condmon.store import schema as S
from condmon.store.base import TOUCHED, StoreBase, as_utc, audit_row, check_name, now
from condmon.store.declarations import keep_bundles, resolved_model
from condmon.store.baselines import (
    DEFAULT_BASELINE, StoredBaseline, baseline_value_rows, members_of, stored_baseline,
)
from condmon.store.engine import StoreError, store_error
from condmon.store.history import (
    ROLES, condition_pairs, estimate_rows, evaluation_rows, stored_estimates, test_values,
)
from condmon.store.isolations import isolation_estimate_rows, isolation_values

_CHUNK = 500   # test ids per IN (...) list: well inside every back-end's limit

__all__ = ["Pending", "UnitState", "KnownRow", "BulkWriter", "BulkWriteError", "BulkMixin",
           "resolve"]

_SEQ = itertools.count()


class Pending:
    """The id of a row not written yet: ``id`` is set once its batch is
    written. Pendings sort after every written id, in the order they were
    made (a new row's id is larger than every id read before it)."""

    __slots__ = ("id", "seq")

    def __init__(self) -> None:
        self.id: int | None = None
        self.seq = next(_SEQ)

    def __int__(self) -> int:
        if self.id is None:
            raise StoreError("a row's id was needed before the row was written")
        return self.id

    def __repr__(self) -> str:
        return f"Pending({self.id})"


Id = int | Pending


def resolve(value: Any) -> Any:
    """``value`` with a :class:`Pending` replaced by its id and a function by
    what it returns (a row's values are settled only when it is written)."""
    if isinstance(value, Pending):
        return int(value)
    if callable(value):
        return value()
    return value


def id_order(value: Id) -> tuple[int, int]:
    """Sort key of written and pending ids together."""
    return (1, value.seq) if isinstance(value, Pending) else (0, int(value))


@dataclass(frozen=True)
class UnitState:
    """What the history holds of a unit that committing its records needs.

    Attributes
    ----------
    id : int
    name, model : str
    model_source : str or None
    baseline_name : str
        Its active baseline's name.
    group_name : str or None
    latest : StoredBaseline or None
        The latest version of its active baseline.
    usable : tuple of (int, str)
        Its accepted, not excluded tests as ``(id, role)``, oldest first.
    estimates : mapping of int to mapping of str to (float, float)
        The stored estimates ``{parameter: (value, standard error)}`` of its
        baseline's tests (:func:`~condmon.store.baselines.members_of`);
        missing values are NaN. [parameter units]
    conditions : mapping of int to mapping of str to float
        The operating conditions of the same tests (those that have any).
    """

    id: int
    name: str
    model: str
    model_source: str | None
    baseline_name: str
    group_name: str | None
    latest: StoredBaseline | None
    usable: tuple[tuple[int, str], ...]
    estimates: Mapping[int, Mapping[str, tuple[float, float]]]
    conditions: Mapping[int, Mapping[str, tuple[float, float]]] = field(default_factory=dict)


@dataclass(frozen=True)
class KnownRow:
    """A stored test or isolation that may hold one of a batch's records."""

    id: int
    unit_id: int
    unit: str
    excluded: bool
    record_hash: str
    file_hash: str
    fingerprint: str | None


class BulkWriteError(StoreError):
    """A batch's records could not be written; ``written`` of them were,
    one at a time, before the one named in the message."""

    def __init__(self, message: str, written: int) -> None:
        super().__init__(message)
        self.written = written


#: Tables in the order their rows are written (foreign keys first).
_ORDER = (S.units, S.tests, S.estimates, S.isolations, S.isolation_estimates, S.baselines,
          S.baseline_values, S.symptoms, S.diagnoses, S.diagnosis_faults)


@dataclass
class _Row:
    table: sa.Table
    key: Pending | None
    values: dict[str, Any]
    record: int


@dataclass
class BulkWriter:
    """New rows of many records, written together by :meth:`BulkMixin.write_bulk`.

    Every ``add_*`` validates first and adds nothing when it raises; rows
    belong to the record last named with :meth:`record` (for the message
    when one cannot be written).
    """

    rows: list[_Row] = field(default_factory=list)
    updates: list[tuple[int, Id, str | None]] = field(default_factory=list)  # group names
    audits: list[tuple[int, dict[str, Any]]] = field(default_factory=list)
    records: list[str] = field(default_factory=list)
    declarations: dict[str, DeclarationBundle] = field(default_factory=dict)

    def record(self, label: str) -> None:
        """The following rows are of the record ``label`` (its file)."""
        self.records.append(label)

    def _add(self, table: sa.Table, values: dict[str, Any], keyed: bool = False
             ) -> Pending | None:
        key = Pending() if keyed else None
        self.rows.append(_Row(table, key, values, len(self.records) - 1))
        return key

    def _log(self, action: str, **fields: Any) -> None:
        self.audits.append((len(self.records) - 1, audit_row(action, **fields)))

    def add_unit(self, name: str, model: str, model_source: str | None) -> Pending:
        """A new unit (audited as ``unit created``), with its declaration kept."""
        check_name(name)
        digest = None
        if model_source:
            try:
                bundle = declaration_bundle(model_source)
            except ConfigError:
                bundle = None   # unreadable now: kept once `unit set-model` names it
            if bundle is not None:
                digest = bundle.digest
                self.declarations[digest] = bundle
        uid = self._add(S.units, dict(name=name, model=model, created_at=now(),
                                      model_source=model_source, model_digest=digest),
                        keyed=True)
        assert uid is not None
        self._log("unit created", unit_id=uid, detail={"unit": name, "model": model})
        return uid

    def set_group(self, uid: Id, unit: str, group: str | None, before: str | None) -> None:
        """The unit's group (audited as ``group set``)."""
        if group is not None:
            check_name(group, "group name")
        self.updates.append((len(self.records) - 1, uid, group))
        self._log("group set", unit_id=uid, detail={"unit": unit, "group": group,
                                                     "before": before})

    def add_test(self, uid: Id, result: Any, *, role: str, digest: str, file_digest: str,
                 test_date: datetime | None = None, hours: float | None = None,
                 fingerprint: str | None = None,
                 symptoms: Mapping[str, Mapping[str, float]] | None = None,
                 baseline_id: Id | None = None, diagnosis: Any = None) -> Pending:
        """A test with its estimates and evaluation, as
        :meth:`~condmon.store.history.TestsMixin.add_test` writes it (no
        duplicate check: the caller has made it)."""
        stored = stored_estimates(result)
        evaluation = ((), (), ()) if baseline_id is None or (
            symptoms is None and diagnosis is None) else evaluation_rows(
            None, baseline_id, symptoms or {}, diagnosis)
        if role not in ROLES:
            raise ConfigError(f"role must be 'baseline' or 'check', got {role!r}")
        tid = self._add(S.tests, dict(unit_id=uid, **test_values(
            result, role, digest, file_digest, as_utc(test_date), fingerprint, hours)), keyed=True)
        assert tid is not None
        for row in estimate_rows(tid, stored, getattr(result, "systematic", None)):
            self._add(S.estimates, row)
        for table, rows in zip((S.symptoms, S.diagnoses, S.diagnosis_faults), evaluation):
            for row in rows:
                self._add(table, {**row, "test_id": tid})
        usable = bool(getattr(result, "usable", result.accepted))
        self._log("test added", unit_id=uid, test_id=tid, reason=None if usable else result.reason,
                  detail={"source": result.source, "role": role, "accepted": usable})
        return tid

    def add_isolation(self, uid: Id, result: Any, *, model: str, source: str, digest: str,
                      file_digest: str, test_date: datetime | None = None,
                      fingerprint: str | None = None) -> Pending:
        """An isolation, as :meth:`~condmon.store.isolations.IsolationsMixin.add_isolation`
        writes it (no duplicate check)."""
        iid = self._add(S.isolations, dict(unit_id=uid, **isolation_values(
            result, model, source, digest, file_digest, test_date, fingerprint)), keyed=True)
        assert iid is not None
        for row in isolation_estimate_rows(iid, result):
            self._add(S.isolation_estimates, row)
        self._log("isolation added", unit_id=uid, isolation_id=iid,
                  detail={"source": source, "statement": result.statement})
        return iid

    def add_baseline(self, uid: Id, baseline: Any, test_ids: Sequence[Id], *, name: str,
                     version: int, reason: str | None,
                     flags: Callable[[], Sequence[dict[str, Any]]]) -> Pending:
        """A baseline version of tests ``test_ids`` (``flags`` is called once
        the tests are written: their messages name the tests' ids)."""
        def ids() -> list[int]:
            return sorted({int(i) for i in test_ids})

        found: list[Sequence[dict[str, Any]]] = []

        def flag_list() -> Sequence[dict[str, Any]]:
            if not found:
                found.append(flags())
            return found[0]

        bid = self._add(S.baselines, dict(
            unit_id=uid, created_at=now(), n=int(baseline.n), test_ids=lambda: json.dumps(ids()),
            name=name, version=version, reason=reason,
            flags=lambda: json.dumps(list(flag_list()), default=str)), keyed=True)
        assert bid is not None
        for row in baseline_value_rows(bid, baseline):
            self._add(S.baseline_values, row)
        self._log("baseline saved", unit_id=uid, baseline_id=bid, reason=reason,
                  detail=lambda: {"name": name, "version": version, "test_ids": ids(),
                                  "flags": len(flag_list())})
        return bid

    def flush(self, conn: sa.Connection, records: Iterable[int] | None = None) -> None:
        """Write the rows (of ``records`` only, when given): one statement per table."""
        wanted = None if records is None else set(records)
        rows = [r for r in self.rows if wanted is None or r.record in wanted]
        sqlite = conn.dialect.name == "sqlite"
        keyed = [t for t in _ORDER if any(r.table is t and r.key is not None for r in rows)]
        top: dict[str, int] = {}
        if sqlite and keyed:  # the write lock is held: new ids follow the largest
            got = conn.execute(sa.select(*[sa.select(sa.func.max(t.c.id)).scalar_subquery()
                                           for t in keyed])).one()
            top = {t.name: int(v or 0) for t, v in zip(keyed, got)}
        keep_bundles(conn, self.declarations.values())
        for table in _ORDER:
            group = [r for r in rows if r.table is table]
            if not group:
                continue
            values = [{k: resolve(v) for k, v in r.values.items()} for r in group]
            if group[0].key is None:
                conn.execute(sa.insert(table), values)
                continue
            if sqlite:
                ids = list(range(top[table.name] + 1, top[table.name] + 1 + len(values)))
                conn.execute(sa.insert(table), [{**v, "id": i} for v, i in zip(values, ids)])
            else:
                ids = list(conn.execute(sa.insert(table).returning(
                    table.c.id, sort_by_parameter_order=True), values).scalars())
            for r, i in zip(group, ids):
                assert r.key is not None
                r.key.id = int(i)
        updates = [u for u in self.updates if wanted is None or u[0] in wanted]
        if updates:
            conn.execute(sa.update(S.units).where(S.units.c.id == sa.bindparam("uid"))
                         .values(group_name=sa.bindparam("g")),
                         [{"uid": int(uid), "g": g} for _, uid, g in updates])
        audits = [a for r, a in self.audits if wanted is None or r in wanted]
        if audits:
            rows_ = [{k: resolve(v) for k, v in a.items()} for a in audits]
            conn.execute(sa.insert(S.audit), rows_)
            # the units changed: their kept states are worked out again before the commit
            conn.info.setdefault(TOUCHED, set()).update(
                int(a["unit_id"]) for a in rows_ if a.get("unit_id") is not None)


def _pair(value: Any, se: Any) -> tuple[float, float]:
    """A stored estimate and its standard error (NULL as NaN)."""
    return (float("nan") if value is None else float(value),
            float("nan") if se is None else float(se))


class _Prefixed:
    """The columns of a row named ``prefix + name``, by ``name``."""

    def __init__(self, row: Any, prefix: str) -> None:
        self._row, self._prefix = row, prefix

    def __getattr__(self, name: str) -> Any:
        return getattr(self._row, self._prefix + name)


class BulkMixin(StoreBase):
    """Reading and writing a batch of records at once (part of :class:`HistoryStore`)."""

    def unit_states(self, names: Sequence[str]) -> dict[str, UnitState]:
        """What the history holds of these units (the ones it has), in two queries."""
        if not names:
            return {}

        def run(c: sa.Connection) -> dict[str, UnitState]:
            u, b, v, t, e = S.units, S.baselines, S.baseline_values, S.tests, S.estimates
            b2 = b.alias()
            label = sa.func.coalesce(sa.func.nullif(u.c.baseline_name, ""), DEFAULT_BASELINE)
            newest = sa.and_(b.c.unit_id == u.c.id, b.c.name == label,
                             b.c.version == sa.select(sa.func.max(b2.c.version))
                             .where(b2.c.unit_id == u.c.id, b2.c.name == label)
                             .scalar_subquery())
            # each unit with its active baseline's latest version and that one's values
            rows = c.execute(
                sa.select(u.c.id.label("uid"), u.c.name.label("unit"), u.c.model,
                          u.c.model_source, u.c.model_digest, u.c.baseline_name,
                          u.c.group_name,
                          *[col.label(f"b_{col.name}") for col in b.c],
                          v.c.parameter.label("p"), v.c.mean.label("m"), v.c.std.label("s"),
                          v.c.n.label("pn"))
                .select_from(u).outerjoin(b, newest).outerjoin(v, v.c.baseline_id == b.c.id)
                .where(u.c.name.in_(sorted(set(names))))).all()
            if not rows:
                return {}
            units = {int(r.uid): r for r in rows}
            values: dict[int, list[tuple[Any, ...]]] = {}
            for r in rows:
                if r.p is not None:
                    values.setdefault(int(r.uid), []).append((r.p, r.m, r.s, r.pn))
            # the usable tests, with the estimates of the healthy ones (a baseline's)
            usable: dict[int, dict[int, str]] = {}
            est: dict[int, dict[str, tuple[float, float]]] = {}
            for tid, uid, role, p, val, se in c.execute(
                    sa.select(t.c.id, t.c.unit_id, t.c.role, e.c.parameter, e.c.value,
                              e.c.std_error)
                    .outerjoin(e, sa.and_(e.c.test_id == t.c.id, t.c.role == "baseline"))
                    .where(t.c.unit_id.in_(list(units)), t.c.accepted.is_(True),
                           t.c.excluded.is_(False)).order_by(t.c.id)):
                usable.setdefault(int(uid), {})[int(tid)] = str(role)
                if p is not None:
                    est.setdefault(int(tid), {})[str(p)] = _pair(val, se)
            latest: dict[int, StoredBaseline | None] = {}
            members: dict[int, list[int]] = {}
            for uid, r in units.items():
                version = None if r.b_id is None else stored_baseline(
                    r.unit, str(r.model_source or r.model), _Prefixed(r, "b_"),
                    values.get(uid, []))
                latest[uid] = version
                members[uid] = members_of(None if version is None else version.test_ids,
                                          list(usable.get(uid, {}).items()))
            others = sorted({i for uid, ids in members.items() for i in ids
                             if usable.get(uid, {}).get(i) != "baseline"})
            if others:  # a baseline with checks among its tests
                for tid, p, val, se in c.execute(
                        sa.select(e.c.test_id, e.c.parameter, e.c.value, e.c.std_error)
                        .where(e.c.test_id.in_(others))):
                    est.setdefault(int(tid), {})[str(p)] = _pair(val, se)
            wanted = sorted({i for ids in members.values() for i in ids})
            conds: dict[int, dict[str, tuple[float, float]]] = {}
            for k in range(0, len(wanted), _CHUNK):
                for tid, doc in c.execute(sa.select(t.c.id, t.c.conditions).where(
                        t.c.id.in_(wanted[k:k + _CHUNK]), t.c.conditions.is_not(None))):
                    conds[int(tid)] = condition_pairs(doc)
            return {str(r.unit): UnitState(
                uid, str(r.unit), str(r.model), _source(c, r),
                str(r.baseline_name or DEFAULT_BASELINE), r.group_name, latest[uid],
                tuple(usable.get(uid, {}).items()),
                {i: est.get(i, {}) for i in members[uid]},
                {i: conds[i] for i in members[uid] if i in conds}) for uid, r in units.items()}

        return self._read(run)

    def record_digests(self, names: Sequence[str]) -> dict[str, dict[str, tuple[str, int]]]:
        """The content and file hashes of these units' tests and isolations:
        ``{unit: {hash: (kind, id)}}`` (``kind``: ``test`` or ``isolation``;
        of two rows with one hash, the older's id)."""
        if not names:
            return {}
        u = S.units

        def of(table: sa.Table, kind: str) -> Any:
            return (sa.select(u.c.name, table.c.id, table.c.record_hash, table.c.file_hash,
                              sa.literal(kind).label("kind"))
                    .join(u, u.c.id == table.c.unit_id).where(u.c.name.in_(sorted(set(names)))))

        both = sa.union_all(of(S.tests, "test"), of(S.isolations, "isolation")).subquery()
        rows = self._read(lambda c: c.execute(sa.select(both).order_by(
            both.c.kind.desc(), both.c.id.desc())).all())
        found: dict[str, dict[str, tuple[str, int]]] = {}
        for name, rid, content, fdig, kind in rows:
            known = found.setdefault(str(name), {})
            for digest in (content, fdig):
                if digest:
                    known[digest] = (str(kind), int(rid))
        return found

    def record_rows(self, kind: str, digests: Iterable[str], unit_ids: Iterable[int],
                    prefixes: Iterable[str]) -> list[KnownRow]:
        """Rows of ``kind`` (``test`` or ``isolation``) with one of these content or
        file hashes, and the units' rows whose fingerprint starts with one of
        ``prefixes`` (:func:`condmon.io.digest.fingerprint_prefix`); oldest first."""
        hashes, uids, starts = sorted(set(digests)), sorted(set(unit_ids)), sorted(set(prefixes))
        if not hashes:
            return []
        t = S.tests if kind == "test" else S.isolations
        cond = sa.or_(t.c.record_hash.in_(hashes), t.c.file_hash.in_(hashes))
        if uids and starts:
            cond = sa.or_(cond, sa.and_(t.c.unit_id.in_(uids),
                                        sa.or_(*[t.c.fingerprint.like(p + "%") for p in starts])))
        rows = self._read(lambda c: c.execute(
            sa.select(t.c.id, t.c.unit_id, S.units.c.name, t.c.excluded, t.c.record_hash,
                      t.c.file_hash, t.c.fingerprint)
            .join(S.units, S.units.c.id == t.c.unit_id).where(cond).order_by(t.c.id)).all())
        return [KnownRow(int(r[0]), int(r[1]), str(r[2]), bool(r[3]), str(r[4]), str(r[5]),
                         r[6]) for r in rows]

    def write_bulk(self, writer: BulkWriter) -> None:
        """Write a :class:`BulkWriter`'s rows inside :meth:`batch`.

        Raises
        ------
        BulkWriteError
            A record's rows cannot be written: the records before it are
            written (one at a time, once the whole batch failed), that one and
            the ones after it are not.
        """
        conn = self._batch
        if conn is None:
            raise RuntimeError("write_bulk runs inside store.batch()")
        try:
            with conn.begin_nested():
                writer.flush(conn)
            return
        except sa.exc.SQLAlchemyError:
            for row in writer.rows:  # ids of the undone attempt
                if row.key is not None:
                    row.key.id = None
        for k, label in enumerate(writer.records):
            try:
                with conn.begin_nested():
                    writer.flush(conn, [k])
            except sa.exc.SQLAlchemyError as err:
                raise BulkWriteError(f"{label}: {store_error(err, self.url, self.timeout)}",
                                     k) from None


def _source(conn: sa.Connection, row: Any) -> str | None:
    """A unit's declaration file, or the history's kept copy of it when the
    file is gone (as given when neither is there: the unit's record says why)."""
    if not row.model_source:
        return None
    try:
        return resolved_model(conn, str(row.model), row.model_source, row.model_digest)
    except ConfigError:
        return str(row.model_source)
