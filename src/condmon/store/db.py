"""The history store: units, tests, estimates, baselines, evaluations, isolations, audit.

SQLite by default (one file), PostgreSQL for shared use, through one SQLAlchemy
code path. Each test is written in a single transaction (test row, its
estimates, symptoms and diagnosis together), so an interruption leaves either
the whole test or nothing. A test is known by its content
(:func:`condmon.io.digest.content_hash`): the same data in another file is not
stored twice. Nothing is deleted: a wrong test is excluded (and can be
included again), a baseline gets a new version, and every change is in the
audit trail. Several processes may write at once (see
:mod:`condmon.store.engine`).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import sqlalchemy as sa

from condmon.io.digest import content_hash, file_hash
from condmon.store import schema as S
from condmon.store.baselines import DEFAULT_BASELINE, StoredBaseline
from condmon.store.bulk import BulkMixin
from condmon.store.groups import GroupsMixin
from condmon.store.engine import (
    StoreBusyError, StoreError, database_url, default_timeout, make_engine, redact,
    sqlite_path, store_error,
)
from condmon.store.history import DuplicateTestError, TestsMixin
from condmon.store.imports import ImportsMixin
from condmon.store.isolations import IsolationsMixin
from condmon.store.states import StatesMixin, write_states
from condmon.store.views import ForecastCacheMixin, ViewsMixin

__all__ = ["HistoryStore", "open_store", "file_hash", "frame_hash", "DuplicateTestError",
           "StoreError", "StoreBusyError", "StoredBaseline", "DEFAULT_BASELINE"]


def frame_hash(df: pd.DataFrame) -> str:
    """Content hash of a DataFrame record (:func:`condmon.io.digest.content_hash`)."""
    return content_hash(df)


class HistoryStore(TestsMixin, GroupsMixin, IsolationsMixin, StatesMixin, ViewsMixin,
                   ForecastCacheMixin, BulkMixin, ImportsMixin):
    """A history database. Open with :func:`open_store`.

    Use it as a context manager (or call :meth:`close`) so that its connections
    are released.

    Example
    -------
    >>> with open_store("sqlite://") as store:        # in memory
    ...     store.unit_id("EMA-1", create=True)
    1
    """

    def __enter__(self) -> HistoryStore:
        return self

    # -- schema -------------------------------------------------------------------------
    def _version(self, conn: sa.Connection) -> int | None:
        """The schema version, None for an empty database; refuses a foreign one."""
        names = set(sa.inspect(conn).get_table_names())
        if "condmon_meta" not in names:
            ours = {t.name for t in S.metadata.sorted_tables}
            clash = sorted(names & ours)
            foreign = sorted(names) if self.engine.dialect.name == "sqlite" else clash
            if foreign:
                shown = ", ".join(foreign[:5]) + (" ..." if len(foreign) > 5 else "")
                raise StoreError(f"{self.url}: not a condmon history (it holds other tables: "
                                 f"{shown}); give another file or database")
            return None
        raw = conn.execute(sa.select(S.meta.c.value)
                           .where(S.meta.c.key == "schema_version")).scalar()
        try:
            return int(str(raw))
        except ValueError:
            raise StoreError(f"{self.url}: unreadable schema version {raw!r} in condmon_meta; "
                             "this history was not written by condmon") from None

    def _init_schema(self, create: bool) -> None:
        version = self._read(self._version)
        if version == S.SCHEMA_VERSION:
            return
        if version is not None and version > S.SCHEMA_VERSION:
            raise StoreError(f"{self.url}: database schema v{version} is newer than this "
                             f"condmon (v{S.SCHEMA_VERSION}); upgrade condmon")
        if version is None and not create:
            raise StoreError(f"{self.url}: no condmon history there yet (empty database)")

        def run(conn: sa.Connection) -> None:
            current = self._version(conn)  # another process may have done it meanwhile
            if current == S.SCHEMA_VERSION:
                return
            if current is None:
                S.metadata.create_all(conn)
                conn.execute(sa.insert(S.meta).values(key="schema_version",
                                                      value=str(S.SCHEMA_VERSION)))
                return
            S.metadata.create_all(conn)  # tables new in this version
            while current < S.SCHEMA_VERSION:
                if current not in S.MIGRATIONS:
                    raise StoreError(f"{self.url}: no migration from schema v{current}")
                S.MIGRATIONS[current](conn)
                current += 1
                conn.execute(sa.update(S.meta).where(S.meta.c.key == "schema_version")
                             .values(value=str(current)))
            write_states(conn)   # every unit's status, as the new code keeps it

        self._write(run, lock=None)

    @property
    def schema_version(self) -> int:
        """Schema version recorded in the database."""
        v = self._read(self._version)
        return -1 if v is None else v

    def integrity_problems(self) -> list[str]:
        """What is inconsistent in the database (empty when all is well): the
        back-end's own check on SQLite, then condmon's (every accepted test has
        its estimates, every evaluation its test, no content twice in a unit)."""
        def run(c: sa.Connection) -> list[str]:
            found: list[str] = []
            if c.dialect.name == "sqlite":
                ok = [r[0] for r in c.exec_driver_sql("PRAGMA integrity_check").all()]
                if ok != ["ok"]:
                    found += [f"integrity_check: {r}" for r in ok]
                found += [f"foreign key: {tuple(r)}" for r in
                          c.exec_driver_sql("PRAGMA foreign_key_check").all()]
            t, e = S.tests, S.estimates
            lonely = c.execute(sa.select(t.c.id).where(
                t.c.accepted.is_(True), ~sa.exists().where(e.c.test_id == t.c.id))).all()
            found += [f"test #{r[0]} has no estimates" for r in lonely]
            twice = c.execute(sa.select(t.c.unit_id, t.c.record_hash, sa.func.count())
                              .group_by(t.c.unit_id, t.c.record_hash)
                              .having(sa.func.count() > 1)).all()
            found += [f"unit {r[0]} holds content {r[1][:12]} {r[2]} times" for r in twice]
            return found

        return self._read(run)


def open_store(db: str | Path, *, create: bool = True,
               timeout: float | None = None) -> HistoryStore:
    """Open (and create or migrate) a history database.

    Parameters
    ----------
    db : str or Path
        A file path (SQLite), ``sqlite://`` (in memory) or a database URL such as
        ``postgresql://user@host/dbname``.
    create : bool
        Create a missing SQLite file or an empty database's tables. False for
        commands that only read (a mistyped path is then an error, not a new
        empty history, and nothing is written to a database that is not a
        history yet).
    timeout : float, optional
        Longest wait for a database another process is writing [s] (default
        ``CONDMON_DB_TIMEOUT`` or 60).

    Returns
    -------
    HistoryStore

    Raises
    ------
    StoreError
        The database cannot be opened, is not a condmon history, is newer than
        this condmon, or (``create=False``) does not exist.

    Example
    -------
    >>> with open_store("sqlite://") as store:
    ...     store.schema_version == S.SCHEMA_VERSION
    True
    """
    url = database_url(db)
    wait = default_timeout() if timeout is None else float(timeout)
    path = sqlite_path(url)
    if path is not None:
        if not create and not path.exists():
            demo = path.parent / "condmon-demo" / path.name
            hint = (f"; `condmon demo` wrote its history to {demo} (--db {demo})"
                    if demo.is_file() else "")
            raise StoreError(f"{db}: no history database there (check the path; `baseline add` "
                             f"creates one){hint}")
        if path.is_dir():
            raise StoreError(f"{db}: is a folder, not a history database file")
        if not create and path.stat().st_size == 0:
            raise StoreError(f"{db}: the file is empty, not a history database")
    try:
        engine = make_engine(url, wait)
    except sa.exc.SQLAlchemyError as err:
        raise store_error(err, str(db), wait) from None
    except ModuleNotFoundError as err:
        raise StoreError(f"{redact(str(db))}: database driver missing ({err.name}); for PostgreSQL "
                         "install condmon[postgres]") from None
    store = HistoryStore(engine, str(db), wait)
    try:
        store._init_schema(create)
    except BaseException:
        engine.dispose()
        raise
    return store

