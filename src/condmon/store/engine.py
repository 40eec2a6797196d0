"""Connections to a history database: URLs, locking, waiting, and errors in one line.

Writers are serialised per database: on SQLite each write transaction starts
with ``BEGIN IMMEDIATE`` (it takes the write lock at once, so two writers never
both read "not there yet" and then collide) and waits for a busy database up
to the store's timeout; on PostgreSQL a write takes a transaction-level
advisory lock (per unit, or for the whole schema while it is created or
migrated) under ``lock_timeout``. A database still busy after the timeout is a
:class:`StoreBusyError`, and every other database failure a :class:`StoreError`
whose message is one line naming the database: never a driver traceback.
"""

from __future__ import annotations

import functools
import getpass
import os
import re
import socket
import time
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import sqlalchemy as sa

from condmon.errors import CondmonError

__all__ = ["StoreError", "StoreBusyError", "database_url", "make_engine", "store_error", "redact",
           "run_write", "run_read", "actor", "DEFAULT_TIMEOUT", "sqlite_path", "SCHEMA_LOCK"]

T = TypeVar("T")

#: Seconds a command waits for a database another process is writing before it
#: gives up (environment variable ``CONDMON_DB_TIMEOUT`` overrides it).
DEFAULT_TIMEOUT = 60.0

#: Advisory-lock key of schema creation, migration and batches on PostgreSQL.
SCHEMA_LOCK = 0x636F6E646D6F6E


class StoreError(CondmonError, RuntimeError):
    """The database cannot be used (unreachable, read-only, full, foreign, newer schema, ...)."""


class StoreBusyError(StoreError):
    """Another process held the database for longer than the timeout."""


def database_url(db: str | Path) -> str:
    """SQLAlchemy URL of a path (SQLite) or a database URL (psycopg 3 for PostgreSQL).

    Example
    -------
    >>> database_url("hist.db")
    'sqlite:///hist.db'
    >>> database_url("postgresql://u@h/db")
    'postgresql+psycopg://u@h/db'
    """
    text = str(db)
    if "://" not in text:
        return f"sqlite:///{Path(text).expanduser()}"
    if text.startswith("postgresql://") or text.startswith("postgres://"):
        return "postgresql+psycopg://" + text.split("://", 1)[1]
    return text


_PASSWORD = re.compile(r"(://[^:/@\s]*:)[^@\s]*(@)")


def redact(text: str) -> str:
    """``text`` with any password in a database URL replaced by ``***``.

    Example
    -------
    >>> redact("postgresql://me:secret@host/condmon: busy")
    'postgresql://me:***@host/condmon: busy'
    """
    return _PASSWORD.sub(r"\1***\2", str(text))


def sqlite_path(url: str) -> Path | None:
    """The file of a SQLite URL (None for memory or another back-end)."""
    if url.startswith("sqlite:///") and len(url) > len("sqlite:///"):
        return Path(url[len("sqlite:///"):])
    return None


def default_timeout() -> float:
    """:data:`DEFAULT_TIMEOUT`, or ``CONDMON_DB_TIMEOUT`` [s] when set to a positive number."""
    text = os.environ.get("CONDMON_DB_TIMEOUT")
    if text is None:
        return DEFAULT_TIMEOUT
    try:
        value = float(text)
    except ValueError:
        raise StoreError(f"CONDMON_DB_TIMEOUT={text!r} is not a number of seconds") from None
    if not (value > 0 and value < 1e6):
        raise StoreError(f"CONDMON_DB_TIMEOUT={text!r}: give a positive number of seconds")
    return value


def make_engine(url: str, timeout: float) -> sa.Engine:
    """An engine whose write transactions lock at once and wait up to ``timeout`` [s]."""
    if url.startswith("sqlite"):
        engine = sa.create_engine(url, connect_args={"timeout": timeout})

        @sa.event.listens_for(engine, "connect")
        def _connect(dbapi_conn: Any, _: Any) -> None:
            dbapi_conn.isolation_level = None  # transactions are begun below, not by the driver
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute(f"PRAGMA busy_timeout={int(timeout * 1000)}")
            cur.close()

        @sa.event.listens_for(engine, "begin")
        def _begin(conn: sa.Connection) -> None:
            write = conn.get_execution_options().get("condmon_write", False)
            conn.exec_driver_sql("BEGIN IMMEDIATE" if write else "BEGIN")

        return engine
    return sa.create_engine(url, connect_args={"connect_timeout": max(1, int(min(timeout, 30)))})


def actor() -> str:
    """Who makes a change: ``CONDMON_ACTOR``, else ``user@host``."""
    name = os.environ.get("CONDMON_ACTOR")
    if name:
        return name[:200]
    return _login()


@functools.lru_cache(maxsize=1)
def _login() -> str:
    """``user@host`` of this process (looked up once: a fleet run audits many rows)."""
    try:
        user = getpass.getuser()
    except Exception:  # noqa: BLE001 - no login name in some containers
        user = "unknown"
    return f"{user}@{socket.gethostname()}"[:200]


def _first_line(err: BaseException) -> str:
    orig = getattr(err, "orig", None)
    text = str(orig if orig is not None else err).strip()
    return text.splitlines()[0] if text else type(err).__name__


def _busy(err: BaseException) -> bool:
    text = _first_line(err).lower()
    code = getattr(getattr(err, "orig", None), "sqlstate", None)
    return ("database is locked" in text or "database table is locked" in text
            or "lock timeout" in text or code in ("55P03", "40001", "40P01"))


def store_error(err: BaseException, db: str, timeout: float | None = None) -> StoreError:
    """One-line :class:`StoreError` for a database or file-system failure (any
    password in the database's URL is not repeated)."""
    db = redact(db)
    text = redact(_first_line(err))
    low = text.lower()
    if _busy(err):
        wait = f" for more than {timeout:g} s" if timeout is not None else ""
        return StoreBusyError(f"{db}: the history database is busy{wait} (another condmon "
                              "is writing to it); try again, or wait longer with "
                              "CONDMON_DB_TIMEOUT=SECONDS")
    if "readonly" in low or "read-only" in low or "permission denied" in low:
        return StoreError(f"{db}: the history database is read-only here (check the file's "
                          "and its folder's permissions); nothing was written")
    if "disk is full" in low or "no space left" in low or "disk full" in low:
        return StoreError(f"{db}: the disk is full; nothing was written")
    if "not a database" in low:  # a text file, a spreadsheet, ...
        return StoreError(f"{db}: not a condmon history database (not a readable SQLite "
                          "database)")
    if "malformed" in low:
        return StoreError(f"{db}: not a readable SQLite database ({text})")
    if "unable to open database file" in low:
        return StoreError(f"{db}: cannot open the history database (does its folder exist "
                          "and may it be written?)")
    if "connection" in low or "could not translate host" in low or "timeout expired" in low:
        return StoreError(f"{db}: cannot open the history database ({text})")
    if isinstance(err, sa.exc.DataError) or "value too long" in low:
        return StoreError(f"{db}: a value does not fit the history database: {text}")
    return StoreError(f"{db}: history database error: {text}")


def _retryable(err: BaseException) -> bool:
    return isinstance(err, sa.exc.IntegrityError) or (
        isinstance(err, sa.exc.OperationalError) and _busy(err))


def run_write(engine: sa.Engine, fn: Callable[[sa.Connection], T], *, db: str,
              timeout: float, lock: str | None = None) -> T:
    """Run ``fn(conn)`` in one write transaction; retried on a lost race.

    ``lock`` names what the transaction must hold alone on PostgreSQL (a unit's
    name, or None for the whole schema's lock). A unit's lock is taken under
    the schema's lock held shared: writes of different units run together,
    and a schema-wide write (a fleet's batch) waits for them, and they for it,
    so no two transactions work out the same unit's kept state from
    snapshots that miss each other's rows. A unique-key race (two
    processes adding the same thing) or a busy database is retried until
    ``timeout`` [s]; ``fn`` must therefore only touch the database. Errors of
    ``fn`` that are not database errors pass through unchanged.
    """
    deadline = time.monotonic() + timeout
    delay = 0.02
    attempts = 0
    while True:
        attempts += 1
        try:
            with engine.connect().execution_options(condmon_write=True) as conn:
                with conn.begin():
                    if conn.dialect.name == "postgresql":
                        conn.exec_driver_sql(f"SET LOCAL lock_timeout = {int(timeout * 1000)}")
                        if lock is None:
                            conn.execute(sa.select(sa.func.pg_advisory_xact_lock(SCHEMA_LOCK)))
                        else:   # the schema shared first, then the unit: one order, no deadlock
                            conn.execute(sa.select(
                                sa.func.pg_advisory_xact_lock_shared(SCHEMA_LOCK)))
                            conn.execute(sa.select(sa.func.pg_advisory_xact_lock(
                                zlib.crc32(lock.encode()) + (1 << 40))))
                    return fn(conn)
        except sa.exc.SQLAlchemyError as err:
            # a unique-key race resolves on the next attempt (the re-check sees the
            # other's row); another integrity error would only repeat itself
            races = isinstance(err, sa.exc.IntegrityError)
            if (_retryable(err) and time.monotonic() < deadline
                    and attempts < (3 if races else 50)):
                time.sleep(delay)
                delay = min(delay * 2, 1.0)
                continue
            raise store_error(err, db, timeout) from None
        except OSError as err:
            raise store_error(err, db, timeout) from None


def run_read(engine: sa.Engine, fn: Callable[[sa.Connection], T], *, db: str,
             timeout: float) -> T:
    """Run ``fn(conn)`` on a read connection; database errors become one line."""
    try:
        with engine.connect() as conn:
            return fn(conn)
    except sa.exc.SQLAlchemyError as err:
        raise store_error(err, db, timeout) from None
    except OSError as err:
        raise store_error(err, db, timeout) from None
