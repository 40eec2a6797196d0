"""The watcher's journal: messages acknowledged to the broker and not yet done with.

``condmon watch --mqtt`` acknowledges a message only once it is written here
(one transaction per batch, synchronous). What a message carries is done with
when its effect is in the history (a test checked and stored, a refusal said)
or when the watcher no longer needs it (a plant unit's samples older than its
kept window). Those rows are deleted; what is left is exactly the watcher's
open state, and a restart replays it before it takes new messages. So a
SIGKILL loses nothing the broker was told was received, and the history's own
duplicate checks (a test's content hash, an isolation's stream detection
time) keep a replay from storing anything twice.

The journal is a local SQLite file through the standard library's ``sqlite3``:
it is a queue private to one watcher, not part of the shared history (which
may be PostgreSQL), and needs none of SQLAlchemy's portability.
"""

from __future__ import annotations

import sqlite3
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

from condmon.errors import CondmonError

__all__ = ["StreamJournal", "JournalError", "default_journal"]


class JournalError(CondmonError, OSError):
    """The journal file cannot be opened, read or written."""


def default_journal(history: str, client_id: str) -> Path:
    """Where a watcher keeps its journal when none is given: beside a SQLite
    history, else in the working folder; one file per MQTT client id (the
    broker's session and the journal belong together).

    Example
    -------
    >>> default_journal("plant/condmon.db", "watch-1").as_posix()
    'plant/condmon.db.watch-1.journal'
    >>> default_journal("postgresql://u@h/db", "watch-1").as_posix()
    'condmon.watch-1.journal'
    >>> default_journal("sqlite:////data/h.db", "w").as_posix(), default_journal("sqlite://", "w")
    ('/data/h.db.w.journal', PosixPath('condmon.w.journal'))
    """
    safe = "".join(ch if ch.isalnum() or ch in "._-" else "_" for ch in client_id)
    if history.startswith("sqlite:///") and len(history) > len("sqlite:///"):
        return Path(f"{history[len('sqlite:///'):]}.{safe}.journal")
    if "://" in history or history.startswith("sqlite"):  # a server, or a memory history
        return Path(f"condmon.{safe}.journal")
    return Path(f"{history}.{safe}.journal")


class StreamJournal:
    """Messages kept until their effect is durable (see the module).

    Parameters
    ----------
    path : str or Path
        The journal file (created if missing).

    Example
    -------
    >>> import tempfile, os
    >>> j = StreamJournal(os.path.join(tempfile.mkdtemp(), "w.journal"))
    >>> ids = j.add([("condmon/U1/samples", b'{"t": [0]}'), ("condmon/U2/samples", b"{}")])
    >>> j.done(ids[:1]); [(t, p) for _, t, p in j.pending()]
    [('condmon/U2/samples', b'{}')]
    >>> j.close()
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._lock = threading.Lock()  # one connection, written by two threads in turn
        try:
            self._db = sqlite3.connect(str(self.path), isolation_level=None,
                                       check_same_thread=False)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")  # an acknowledged row survives power loss
            self._db.execute("CREATE TABLE IF NOT EXISTS messages (id INTEGER PRIMARY KEY "
                             "AUTOINCREMENT, topic TEXT NOT NULL, payload BLOB NOT NULL)")
        except sqlite3.Error as exc:
            raise JournalError(f"{self.path}: cannot open the watcher's journal ({exc}); "
                               "give another with --journal") from None

    def add(self, messages: Iterable[tuple[str, bytes]]) -> list[int]:
        """Write messages in one transaction; their ids, in order."""
        try:
            with self._lock, self._tx():
                return [int(self._db.execute(
                    "INSERT INTO messages (topic, payload) VALUES (?, ?)",
                    (topic, sqlite3.Binary(payload))).lastrowid or 0)
                    for topic, payload in messages]
        except sqlite3.Error as exc:
            raise JournalError(f"{self.path}: cannot write the journal ({exc})") from None

    def done(self, ids: Iterable[int]) -> None:
        """Forget messages whose effect is durable or no longer needed."""
        rows = [(i,) for i in ids]
        if not rows:
            return
        try:
            with self._lock, self._tx():
                self._db.executemany("DELETE FROM messages WHERE id = ?", rows)
        except sqlite3.Error as exc:
            raise JournalError(f"{self.path}: cannot write the journal ({exc})") from None

    def pending(self) -> Iterator[tuple[int, str, bytes]]:
        """The messages kept, oldest first: ``(id, topic, payload)``."""
        try:
            with self._lock:
                rows = self._db.execute(
                    "SELECT id, topic, payload FROM messages ORDER BY id").fetchall()
        except sqlite3.Error as exc:
            raise JournalError(f"{self.path}: cannot read the journal ({exc})") from None
        for ident, topic, payload in rows:
            yield int(ident), str(topic), bytes(payload)

    def __len__(self) -> int:
        with self._lock:
            return int(self._db.execute("SELECT count(*) FROM messages").fetchone()[0])

    def close(self) -> None:
        """Close the file (what it holds stays for the next start)."""
        self._db.close()

    def _tx(self) -> _Transaction:
        return _Transaction(self._db)


class _Transaction:
    """BEGIN IMMEDIATE ... COMMIT, rolled back on an error."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self.db = db

    def __enter__(self) -> None:
        self.db.execute("BEGIN IMMEDIATE")

    def __exit__(self, kind: object, value: object, tb: object) -> None:
        self.db.execute("COMMIT" if kind is None else "ROLLBACK")
