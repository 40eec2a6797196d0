"""What every part of the history store shares: the engine, transactions, units, audit."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from datetime import datetime, timezone
from typing import Any, TypeVar

import numpy as np
import pandas as pd
import sqlalchemy as sa

from condmon.errors import ConfigError
from condmon.io.dates import as_utc
from condmon.models.regimes import split_key
from condmon.store import schema as S
from condmon.store.declarations import keep_declaration, resolved_model
from condmon.store.engine import SCHEMA_LOCK, actor, redact, run_read, run_write, store_error

__all__ = ["StoreBase", "TOUCHED", "now", "num", "check_name", "as_utc", "utc_column",
           "unknown_unit_message", "model_order", "audit_row"]

T = TypeVar("T")

#: Key of a connection's ``info``: the ids of the units its transaction changed.
TOUCHED = "condmon_touched_units"


def now() -> datetime:
    """The current time, UTC."""
    return datetime.now(timezone.utc)


def utc_column(values: Any) -> pd.Series:
    """Stored times as one UTC datetime column (microseconds; missing ones NaT)."""
    return pd.to_datetime(pd.Series(values), utc=True).astype("datetime64[us, UTC]")


def num(x: Any) -> float | None:
    """A finite float, or None (stored as NULL)."""
    return float(x) if x is not None and np.isfinite(x) else None


def check_name(name: str, what: str = "unit name", limit: int = S.NAME_LENGTH) -> str:
    """``name`` if the store can keep it the same on every back-end.

    Raises
    ------
    ConfigError
        Empty, longer than :data:`~condmon.store.schema.NAME_LENGTH` characters,
        or with control characters.
    """
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(f"{what} is empty")
    if len(name) > limit:
        raise ConfigError(f"{what} {name[:40]!r}... is {len(name)} characters long; at most "
                          f"{limit} are kept")
    if any(ord(c) < 32 or ord(c) == 127 for c in name):
        raise ConfigError(f"{what} {name!r} contains control characters")
    return name


class StoreBase:
    """Engine, transactions, units and the audit trail (see :class:`HistoryStore`)."""

    def __init__(self, engine: sa.Engine, db: str, timeout: float) -> None:
        self.engine = engine
        self.url = redact(db)  # the database as messages name it, never with a password
        self.timeout = timeout
        self._batch: sa.Connection | None = None
        self._reading = False  # the batch connection is a snapshot's (reads only)

    def close(self) -> None:
        """Release every pooled connection."""
        self.engine.dispose()

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- transactions -------------------------------------------------------------------
    def _read(self, fn: Callable[[sa.Connection], T]) -> T:
        if self._batch is not None:  # a read changes nothing: no savepoint of its own
            try:
                return fn(self._batch)
            except sa.exc.SQLAlchemyError as err:
                raise store_error(err, self.url, self.timeout) from None
        return run_read(self.engine, fn, db=self.url, timeout=self.timeout)

    def _write(self, fn: Callable[[sa.Connection], T], lock: str | None) -> T:
        """One write transaction holding ``lock`` (a unit name; None: the schema);
        the units it changed have their state rows worked out again before it
        commits (:meth:`_settle`)."""
        if self._reading:
            raise RuntimeError("no writes inside a snapshot")
        if self._batch is not None:
            return self._in_batch(fn)

        def run(conn: sa.Connection) -> T:
            conn.info.pop(TOUCHED, None)   # left by an attempt that failed
            out = fn(conn)
            self._settle(conn)
            return out

        return run_write(self.engine, run, db=self.url, timeout=self.timeout, lock=lock)

    def _settle(self, conn: sa.Connection) -> None:
        """Bring what is kept per unit up to date with the transaction's changes
        (the units :meth:`_log` marked, ``conn.info[TOUCHED]``); nothing here."""

    def _in_batch(self, fn: Callable[[sa.Connection], T]) -> T:
        assert self._batch is not None
        try:
            with self._batch.begin_nested():  # a failed write undoes only itself
                return fn(self._batch)
        except sa.exc.SQLAlchemyError as err:
            raise store_error(err, self.url, self.timeout) from None

    @contextmanager
    def batch(self) -> Iterator[None]:
        """Every read and write inside the block in one transaction.

        For a client writing many results at once (a fleet run): one commit
        per batch instead of one per test. A write that fails inside the block
        (a duplicate, say) is undone alone and its error raised; leaving the
        block with an exception undoes the whole batch. The batch holds the
        database's write lock (SQLite) or the schema lock (PostgreSQL) until it
        ends, so keep it to writes.

        Example
        -------
        >>> from condmon.store import open_store
        >>> with open_store("sqlite://") as store:
        ...     with store.batch():
        ...         ids = [store.unit_id(f"U{i}", create=True) for i in range(3)]
        ...     store.units()
        ['U0', 'U1', 'U2']
        """
        if self._batch is not None:
            raise RuntimeError("batches do not nest")
        def hold(conn: sa.Connection) -> None:
            self._batch = conn
        try:
            with self.engine.connect().execution_options(condmon_write=True) as conn:
                with conn.begin():
                    if conn.dialect.name == "postgresql":
                        conn.exec_driver_sql(
                            f"SET LOCAL lock_timeout = {int(self.timeout * 1000)}")
                        conn.execute(sa.select(sa.func.pg_advisory_xact_lock(SCHEMA_LOCK)))
                    conn.info.pop(TOUCHED, None)
                    hold(conn)
                    yield
                    self._settle(conn)
        except sa.exc.SQLAlchemyError as err:
            raise store_error(err, self.url, self.timeout) from None
        finally:
            self._batch = None

    @contextmanager
    def snapshot(self) -> Iterator[None]:
        """Every read inside the block on one connection, in one transaction
        (one consistent view of the history; no writes).

        Example
        -------
        >>> from condmon.store import open_store
        >>> with open_store("sqlite://") as store, store.snapshot():
        ...     store.units(), store.unit_model("EMA-1")
        ([], None)
        """
        if self._batch is not None:
            raise RuntimeError("a snapshot is not taken inside a batch")
        try:
            with self.engine.connect() as conn, conn.begin():
                self._batch, self._reading = conn, True
                yield
        except sa.exc.SQLAlchemyError as err:
            raise store_error(err, self.url, self.timeout) from None
        finally:
            self._batch, self._reading = None, False

    def _log(self, conn: sa.Connection, action: str, *, unit_id: int | None = None,
             test_id: int | None = None, isolation_id: int | None = None,
             baseline_id: int | None = None, reason: str | None = None,
             detail: dict[str, Any] | None = None) -> None:
        """One audit row, inside the caller's transaction; the unit is marked
        changed (its kept state is worked out again before the commit)."""
        if unit_id is not None:
            conn.info.setdefault(TOUCHED, set()).add(int(unit_id))
        conn.execute(sa.insert(S.audit).values(audit_row(
            action, unit_id=unit_id, test_id=test_id, isolation_id=isolation_id,
            baseline_id=baseline_id, reason=reason, detail=detail)))

    # -- units --------------------------------------------------------------------------
    def _copy_of(self, conn: sa.Connection, table: sa.Table, uid: int, record_hash: str,
                 file_digest: str, fingerprint: str | None = None) -> Any:
        """``(id, excluded)`` of the unit's row of ``table`` (tests or isolations)
        holding the same record: the same file or content hash, else a
        fingerprint of the same content (:func:`condmon.io.digest.same_content`);
        None when there is none."""
        from condmon.io.digest import fingerprint_prefix, same_content

        t = table
        row = conn.execute(sa.select(t.c.id, t.c.excluded).where(
            t.c.unit_id == uid,
            sa.or_(t.c.record_hash == record_hash, t.c.file_hash == file_digest))
            .order_by(t.c.id).limit(1)).first()
        if row is not None or not fingerprint:
            return row
        rows = int(json.loads(fingerprint)["n"])
        for cand in conn.execute(sa.select(t.c.id, t.c.excluded, t.c.fingerprint).where(
                t.c.unit_id == uid, t.c.fingerprint.like(fingerprint_prefix(rows) + "%"))
                .order_by(t.c.id)):
            if same_content(fingerprint, cand.fingerprint):
                return cand[:2]
        return None

    def _copies_elsewhere(self, table: sa.Table, unit: str, digest: str
                          ) -> list[tuple[str, int]]:
        """``(unit, id)`` of the rows of ``table`` (tests or isolations) of
        *other* units with this content hash: one record filed under two
        machines is most likely a mistake."""
        def run(c: sa.Connection) -> list[tuple[str, int]]:
            rows = c.execute(sa.select(S.units.c.name, table.c.id)
                             .join(S.units, S.units.c.id == table.c.unit_id)
                             .where(table.c.record_hash == digest, S.units.c.name != unit)
                             .order_by(table.c.id)).all()
            return [(str(r[0]), int(r[1])) for r in rows]

        return self._read(run)

    def _unit_row(self, conn: sa.Connection, name: str) -> Any:
        return conn.execute(sa.select(S.units).where(S.units.c.name == name)).first()

    def _unknown_unit(self, conn: sa.Connection, name: str) -> ConfigError:
        known = [r[0] for r in conn.execute(sa.select(S.units.c.name).order_by(S.units.c.name))]
        return ConfigError(unknown_unit_message(name, known, self.url))

    def unit_id(self, name: str, *, create: bool = False, model: str = "dc-motor",
                conn: sa.Connection | None = None, model_source: str | None = None) -> int:
        """Id of unit ``name``; created when ``create`` (else an error naming the units).

        Example
        -------
        >>> from condmon.store import open_store
        >>> with open_store("sqlite://") as store:        # in memory
        ...     store.unit_id("EMA-1", create=True)
        1
        """
        check_name(name)

        def run(c: sa.Connection) -> int:
            row = self._unit_row(c, name)
            if row is not None:
                return int(row.id)
            if not create:
                raise self._unknown_unit(c, name)
            digest = keep_declaration(c, model_source, quiet=True) if model_source else None
            res = c.execute(sa.insert(S.units).values(name=name, model=model, created_at=now(),
                                                      model_source=model_source,
                                                      model_digest=digest))
            uid = int(res.inserted_primary_key[0])  # type: ignore[index]
            self._log(c, "unit created", unit_id=uid, detail={"unit": name, "model": model})
            return uid

        if conn is not None:
            return run(conn)
        if create:
            return self._write(run, lock=name)
        return self._read(run)

    def unit_model(self, unit: str, conn: sa.Connection | None = None) -> str | None:
        """The unit's model: its declaration file when it is not a shipped model
        (the history's kept copy, written to the cache folder, when the file
        is no longer where it was), else its name (None for an unknown unit).

        Raises
        ------
        ConfigError
            The declaration file is gone and the history keeps no copy.
        """
        def run(c: sa.Connection) -> str | None:
            row = c.execute(sa.select(S.units.c.model, S.units.c.model_source,
                                      S.units.c.model_digest)
                            .where(S.units.c.name == unit)).first()
            return None if row is None else resolved_model(c, str(row[0]), row[1], row[2])

        return run(conn) if conn is not None else self._read(run)

    def unit_model_name(self, unit: str) -> str | None:
        """The unit's model as the history names it: a shipped model's name or
        a declaration's declared ``name`` (what peers of the same model share;
        None for an unknown unit)."""
        row = self._read(lambda c: c.execute(
            sa.select(S.units.c.model).where(S.units.c.name == unit)).first())
        return None if row is None else str(row[0])

    def unit_declaration(self, unit: str) -> tuple[str | None, str | None]:
        """The unit's declaration file as it was given, and the digest of the
        copy the history keeps (None, None for a shipped model)."""
        row = self._read(lambda c: c.execute(
            sa.select(S.units.c.model_source, S.units.c.model_digest)
            .where(S.units.c.name == unit)).first())
        return (None, None) if row is None else (row[0], row[1])

    def set_unit_model(self, unit: str, source: str, *, name: str, reason: str) -> str:
        """Point ``unit`` at the declaration ``source`` (kept with the unit),
        audited as ``model re-pointed`` with the path before and whether the
        declaration means the same; returns its digest.

        Raises
        ------
        ConfigError
            The file cannot be read (naming it), or the unit is unknown.
        """
        def run(c: sa.Connection) -> str:
            row = self._unit_row(c, unit)
            if row is None:
                raise self._unknown_unit(c, unit)
            digest = keep_declaration(c, source)
            assert digest is not None
            c.execute(sa.update(S.units).where(S.units.c.id == row.id).values(
                model=name[:64], model_source=source, model_digest=digest))
            self._log(c, "model re-pointed", unit_id=int(row.id), reason=reason,
                      detail={"from": row.model_source, "to": source,
                              "same_declaration": row.model_digest == digest,
                              "digest": digest})
            return digest

        return self._write(run, lock=unit)

    def _ordered(self, unit: str, names: list[str], conn: sa.Connection | None = None
                 ) -> list[str]:
        """Parameter names in the unit's model order (unknown ones last, sorted)."""
        try:
            model = self.unit_model(unit, conn)
        except ConfigError:
            model = None   # no declaration to order by: sorted
        return model_order(model, names)

    def parameter_order(self, unit: str, names: list[str]) -> list[str]:
        """``names`` in the order the unit's model reports its parameters."""
        return self._ordered(unit, names)

    def units(self) -> list[str]:
        """Names of every unit."""
        return self._read(lambda c: [r[0] for r in c.execute(
            sa.select(S.units.c.name).order_by(S.units.c.name))])

    def audit(self, unit: str | None = None) -> pd.DataFrame:
        """The audit trail (oldest first): ``at, actor, action, unit, test_id,
        isolation_id, baseline_id, reason, detail``."""
        def run(c: sa.Connection) -> list[Any]:
            q = (sa.select(S.audit.c.id, S.audit.c.at, S.audit.c.actor, S.audit.c.action,
                           S.units.c.name, S.audit.c.test_id, S.audit.c.isolation_id,
                           S.audit.c.baseline_id, S.audit.c.reason, S.audit.c.detail)
                 .outerjoin(S.units, S.units.c.id == S.audit.c.unit_id))
            if unit is not None:
                if self._unit_row(c, unit) is None:
                    raise self._unknown_unit(c, unit)
                q = q.where(S.units.c.name == unit)
            return list(c.execute(q.order_by(S.audit.c.id)).all())

        rows = self._read(run)
        frame = pd.DataFrame(rows, columns=["id", "at", "actor", "action", "unit", "test_id",
                                            "isolation_id", "baseline_id", "reason", "detail"])
        frame["at"] = utc_column(frame["at"]).to_numpy()
        for col in ("test_id", "isolation_id", "baseline_id"):
            frame[col] = frame[col].astype("Int64")  # ids stay integers beside gaps
        return frame.set_index("id")


def audit_row(action: str, *, unit_id: Any = None, test_id: Any = None,
              isolation_id: Any = None, baseline_id: Any = None, reason: str | None = None,
              detail: Any = None) -> dict[str, Any]:
    """An ``audit`` row: what was done, by whom, when, to what (``detail``: a
    JSON-ready dict, or a function giving one once the ids are known)."""
    doc: Any = None
    if callable(detail):
        doc = lambda: json.dumps(detail(), default=str)  # noqa: E731 - written at flush
    elif detail is not None:
        doc = json.dumps(detail, default=str)
    return dict(at=now(), actor=actor(), action=action, unit_id=unit_id, test_id=test_id,
                isolation_id=isolation_id, baseline_id=baseline_id, reason=reason, detail=doc)


def model_order(model: str | None, names: Sequence[str]) -> list[str]:
    """``names`` in the order ``model`` reports its parameters (a regime's by
    parameter, then regime; names the model lacks last, sorted)."""
    from condmon.errors import ModelError
    from condmon.models.registry import get_model

    try:
        order = list(get_model(model).monitored) if model else []
    except (ModelError, ConfigError):
        order = []
    rank = {p: i for i, p in enumerate(order)}

    def key(name: str) -> tuple[int, str, str]:
        base, regime = split_key(name)  # a regime's parameters by parameter, then regime
        return (rank.get(base, len(rank)), base if base not in rank else "", regime)

    return sorted(names, key=key)


def unknown_unit_message(name: str, known: Sequence[str], where: str) -> str:
    """What to say of a unit name the history does not hold: the close names
    first (a mistyped serial number), then the units, then how a new unit starts.

    Example
    -------
    >>> unknown_unit_message("EMA-l", ["EMA-1", "EMA-2", "HST-7"], "h.db")
    "unknown unit 'EMA-l' in h.db; did you mean 'EMA-1' or 'EMA-2'? (units: EMA-1, EMA-2, HST-7; a new unit starts with its healthy tests: condmon baseline add REC... --unit EMA-l, or with values measured elsewhere: condmon import TABLE --unit EMA-l --model M)"
    """
    # the names a few keystrokes away (case aside): a mistyped serial number
    target = name.lower()
    near = sorted((_edits(target, k.lower()), k) for k in known)
    close = [k for d, k in near if d <= max(1, len(target) // 4)][:3]
    shown = ", ".join(known[:20]) + (f", ... {len(known) - 20} more" if len(known) > 20 else "")
    units = f"units: {shown or 'none yet'}; a new unit starts with its healthy tests: " \
            f"condmon baseline add REC... --unit {name}, or with values measured " \
            f"elsewhere: condmon import TABLE --unit {name} --model M"
    guess = f"did you mean {' or '.join(map(repr, close))}? ({units})" if close else units
    return f"unknown unit {name!r} in {where}; {guess}"


def _edits(a: str, b: str) -> int:
    """Edits from a to b: insertions, deletions, substitutions and swaps of two
    neighbours (the optimal string alignment distance: ``WAER`` is one edit
    from ``WEAR``).

    Example
    -------
    >>> _edits("waer", "wear"), _edits("ema-l", "ema-1"), _edits("ab", "ba")
    (1, 1, 1)
    """
    before: list[int] = []
    row = list(range(len(b) + 1))
    for i, ca in enumerate(a, 1):
        prev_row, row = row, [i] + [0] * len(b)
        for j, cb in enumerate(b, 1):
            row[j] = min(prev_row[j] + 1, row[j - 1] + 1, prev_row[j - 1] + (ca != cb))
            if i > 1 and j > 1 and ca == b[j - 2] and a[i - 2] == cb:
                row[j] = min(row[j], before[j - 2] + 1)
        before = prev_row
    return row[-1]
