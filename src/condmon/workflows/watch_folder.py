"""``condmon watch FOLDER``: record files dropped in a fleet inbox, handled as they complete.

The folder is laid out as ``condmon fleet run`` expects (``FOLDER/UNIT/record
files``, an optional ``unit.toml`` per unit; a record file dropped beside the
unit folders is refused, as ``fleet run`` refuses it, not left unseen). When a
file is complete is said by
``complete``, best first:

- ``rename``: the logger writes each file under a hidden or temporary name
  (``.rec.csv``, ``rec.csv.part``, ``rec.csv.tmp``) and renames it into place; a
  file is complete as soon as its name appears;
- ``marker``: the logger writes ``NAME.done`` beside ``NAME`` once it is whole;
- ``settle`` (the default, for loggers that do neither): once its size and
  modification time have not changed for ``settle`` seconds. A logger that
  pauses longer than that gives a file handed over in part; when it changes
  again it is handed over again, and the test stored from the part is
  excluded as replaced (``condmon include`` restores it), so it is not kept
  twice.

The folder is not listed whole at every poll: a folder is listed again only
when its modification time changes (a file added, renamed or removed), and only
files not yet handed over, or handed over less than ``RECHECK`` seconds ago,
are looked at. Complete files are handed to
:func:`condmon.workflows.fleet.run_fleet` (``files=``), so each gets exactly the
outcome a ``fleet run`` would give it, on a local cluster kept while files
come (closed after ``IDLE`` seconds without one); a file already in the history is skipped as ``fleet run`` skips it. Each
stored test's status is an event (:class:`~condmon.workflows.watch.WatchEvent`).
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from condmon.errors import ConfigError
from condmon.workflows.fleet import FleetResult, run_fleet
from condmon.workflows.fleet_inbox import MARKER, TEMPORARY, UNIT_FILE, _readable_suffix
from condmon.workflows.watch import WatchEvent

__all__ = ["FolderSummary", "watch_folder", "COMPLETE"]

#: How a dropped file is known to be complete (see the module).
COMPLETE = ("settle", "rename", "marker")
#: A file handed over is looked at for this long after, in case it is written on
#: (settle only); then it is left alone, so idle cost does not grow with the
#: files ever seen. [s]
RECHECK = 600.0
#: The local cluster is closed after this long without a new file, and started
#: again (about 2 s) for the next. [s]
IDLE = 60.0


@dataclass
class FolderSummary:
    """What a folder watch handled.

    Attributes
    ----------
    files : int
        Files handed to the fleet run (each once).
    stored : int
        Of them, stored as tests or isolations.
    runs : int
        Fleet runs made (one per batch of files that completed together).
    events : list of WatchEvent
        One per stored record.
    seconds : float
        How long the watch ran. [s]
    replaced : int
        Tests stored from a file still being written, excluded once its
        complete version was stored.
    """

    files: int = 0
    stored: int = 0
    runs: int = 0
    replaced: int = 0
    events: list[WatchEvent] = field(default_factory=list)
    seconds: float = 0.0


def watch_folder(folder: str | Path, db: str, *, settle: float = 2.0, poll: float = 0.5,
                 duration: float | None = None, stop: threading.Event | None = None,
                 publish: Callable[[WatchEvent], None] = lambda event: None,
                 log: Callable[[str], None] = print, workers: int = 1,
                 complete: str = "settle") -> FolderSummary:
    """Watch ``folder`` and hand every complete new record file to a fleet run.

    Parameters
    ----------
    folder : str or Path
        A fleet inbox.
    db : str
        History database (SQLite file or ``postgresql://`` URL).
    settle : float
        A file is complete when unchanged this long. [s]
    poll : float
        How often the folder is listed. [s]
    duration : float, optional
        Stop after this long (default: until ``stop`` is set). [s]
    stop : threading.Event, optional
    publish : callable
        Called with each stored record's event.
    log : callable
    workers : int
        Processes of the local cluster.
    complete : {"settle", "rename", "marker"}
        How a file is known to be complete (see the module).

    Returns
    -------
    FolderSummary
    """
    from condmon.workflows.fleet_engine import local_cluster

    from condmon.workflows.fleet_inbox import check_inbox

    root = check_inbox(folder)
    if complete not in COMPLETE:
        raise ConfigError(f"--complete {complete!r}: allowed: {', '.join(COMPLETE)}")
    halt = stop or threading.Event()
    files = _Files(root, complete, settle)
    log(f"watching {root} (" + {
        "settle": f"a file is complete once unchanged for {settle:g} s",
        "rename": "a file is complete once renamed into place",
        "marker": f"a file is complete once NAME{MARKER} is beside it"}[complete] + ")")
    summary = FolderSummary()
    started = time.monotonic()
    noted: set[str] = set()
    with ExitStack() as outer:
        stack = outer.enter_context(ExitStack())   # the local cluster, while files come
        scheduler: str | None = None
        last = time.monotonic()
        while not halt.is_set():
            if duration is not None and time.monotonic() - started >= duration:
                break
            ready = files.ready()
            if not ready and scheduler is not None and time.monotonic() - last > IDLE:
                stack.close()  # an idle cluster's heartbeats cost more than the watch itself
                scheduler = None
                log(f"no new file for {IDLE:g} s: the local cluster is closed (started again "
                    "for the next file)")
            if ready:
                last = time.monotonic()
                if scheduler is None:
                    client = stack.enter_context(local_cluster(workers))
                    scheduler = str(client.scheduler.address)  # type: ignore[union-attr]
                res = run_fleet(root, db, scheduler=scheduler, files=ready)
                files.handed(ready)
                summary.replaced += _replace(db, files, res, log)
                summary.files += len(ready)
                summary.runs += 1
                summary.stored += res.stored
                for r in res.records:  # every file is accounted for, stored or not
                    if r.outcome not in ("stored", "rejected"):
                        log(f"{r.unit or Path(r.file).parent.name}: {Path(r.file).name}: "
                            f"{r.outcome}" + (f", {r.reason}" if r.reason else ""))
                for event in _events(res):
                    summary.events.append(event)
                    publish(event)
                    log(f"{event.unit}: {event.status}: {event.reason}")
                for u in res.units:   # (a unit's note once per watch: it does not change)
                    if u.note and u.unit not in noted:
                        noted.add(u.unit)
                        log(f"{u.unit}: {u.note}")
            halt.wait(poll)
    summary.seconds = time.monotonic() - started
    return summary


class _Files:
    """The inbox's files and what is known of each (see the module)."""

    def __init__(self, root: Path, complete: str, settle: float) -> None:
        self.root, self.complete, self.settle = root, complete, settle
        self.folders: dict[Path, tuple[int, list[Path], list[Path]]] = {}  # mtime, files, dirs
        self.seen: dict[Path, tuple[int, int, float]] = {}  # size, mtime, unchanged since
        self.given: dict[Path, tuple[int, int, float]] = {}  # size, mtime, handed when
        self.stored: dict[Path, tuple[str, int]] = {}  # the test or isolation it gave

    def listing(self) -> list[Path]:
        """Every file under the unit folders, each folder listed again only when
        its modification time has changed."""
        out: list[Path] = []
        todo = [(self.root, 0)]
        while todo:
            folder, depth = todo.pop()
            try:
                mtime = os.stat(folder).st_mtime_ns
            except OSError:
                self.folders.pop(folder, None)
                continue
            kept = self.folders.get(folder)
            if kept is None or kept[0] != mtime:
                names, dirs = [], []
                try:
                    with os.scandir(folder) as entries:
                        for e in entries:
                            if e.name.startswith(".") or e.name.endswith(TEMPORARY):
                                continue
                            if e.is_dir(follow_symlinks=False):
                                dirs.append(Path(e.path))
                            elif e.name.endswith(MARKER) or e.name == UNIT_FILE:
                                continue
                            elif depth > 0 or _readable_suffix(Path(e.name)):
                                # a record file at the top is handed over too, and
                                # refused as in no unit's folder (fleet run's answer),
                                # not left unseen; other files there are no records
                                names.append(Path(e.path))
                except OSError:
                    continue
                kept = self.folders[folder] = (mtime, names, dirs)
            out += kept[1]
            todo += [(d, depth + 1) for d in kept[2]]
        return out

    def ready(self) -> list[Path]:
        """Files complete and not handed over yet (or changed since, settle only)."""
        now = time.monotonic()
        ready = []
        for path in self.listing():
            given = self.given.get(path)
            if given is not None and (self.complete != "settle" or now - given[2] > RECHECK):
                continue  # handed over; written on after that only with settle
            if self.complete == "marker" and not path.with_name(path.name + MARKER).exists():
                continue
            try:
                st = path.stat()
            except OSError:
                continue  # gone between the listing and now
            key = (st.st_size, st.st_mtime_ns)
            if given is not None and given[:2] == key:
                continue
            if self.complete != "settle":
                self.seen[path] = (*key, now)
                ready.append(path)
                continue
            before = self.seen.get(path)
            if before is None or before[:2] != key:
                self.seen[path] = (*key, now)
            elif now - before[2] >= self.settle:
                ready.append(path)
        return ready

    def handed(self, paths: list[Path]) -> None:
        now = time.monotonic()
        for p in paths:
            self.given[p] = (*self.seen[p][:2], now)
            self.seen.pop(p, None)


def _replace(db: str, files: _Files, res: FleetResult, log: Callable[[str], None]) -> int:
    """Exclude the test (or isolation) a file gave while it was still being
    written, once its complete version is stored; the count excluded."""
    from condmon.store.db import open_store
    from condmon.workflows.manage import exclude_isolation, exclude_test

    done = 0
    for r in res.records:
        if r.outcome not in ("stored", "rejected") or r.test_id is None:
            continue
        path = Path(r.file).resolve()
        earlier = files.stored.get(path)
        files.stored[path] = (r.kind, r.test_id)
        if earlier is None or earlier == (r.kind, r.test_id):
            continue
        kind, ident = earlier
        why = (f"replaced: {path.name} was stored while still being written; its complete "
               f"version is {'test #' if r.kind == 'test' else 'isolation i'}{r.test_id}")
        with open_store(db) as store:
            try:
                (exclude_test if kind == "test" else exclude_isolation)(store, ident, why)
            except (ConfigError, ValueError) as exc:  # already excluded by hand
                log(f"{r.unit}: {path.name}: the earlier {kind} was not excluded: {exc}")
                continue
        log(f"{r.unit}: {path.name}: {kind} {'#' if kind == 'test' else 'i'}{ident} excluded, "
            f"{why}")
        done += 1
    return done


def _events(res: FleetResult) -> list[WatchEvent]:
    now = datetime.now(timezone.utc).isoformat(timespec="milliseconds")
    out = []
    for r in res.records:
        if r.outcome not in ("stored", "rejected"):
            continue
        what = f"{Path(r.file).name}: {r.outcome}" + (f", {r.reason}" if r.reason else "")
        out.append(WatchEvent(r.unit, r.status or "retest", now, what, (), "checked"))
    return out
