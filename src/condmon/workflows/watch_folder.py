"""``condmon watch FOLDER``: record files dropped in a fleet inbox, handled as they complete.

The folder is laid out as ``condmon fleet run`` expects (``FOLDER/UNIT/record
files``, an optional ``unit.toml`` per unit). A file is complete once its size
and modification time have not changed for ``settle`` seconds (a logger that
writes a file elsewhere and renames it into place gives a complete file at
once, and still waits ``settle``). Complete files are handed to
:func:`condmon.workflows.fleet.run_fleet` (``files=``), so each gets exactly the
outcome a ``fleet run`` would give it, on one local cluster kept for the whole
watch; a file already in the history is skipped as ``fleet run`` skips it. Each
stored test's status is an event (:class:`~condmon.workflows.watch.WatchEvent`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from condmon.errors import ConfigError
from condmon.workflows.fleet import FleetResult, run_fleet
from condmon.workflows.fleet_inbox import inbox_records
from condmon.workflows.watch import WatchEvent

__all__ = ["FolderSummary", "watch_folder"]


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
    """

    files: int = 0
    stored: int = 0
    runs: int = 0
    events: list[WatchEvent] = field(default_factory=list)
    seconds: float = 0.0


def watch_folder(folder: str | Path, db: str, *, settle: float = 2.0, poll: float = 0.5,
                 duration: float | None = None, stop: threading.Event | None = None,
                 publish: Callable[[WatchEvent], None] = lambda event: None,
                 log: Callable[[str], None] = print, workers: int = 1) -> FolderSummary:
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

    Returns
    -------
    FolderSummary
    """
    from condmon.workflows.fleet_engine import local_cluster

    root = Path(folder)
    if not root.is_dir():
        raise ConfigError(f"{root}: not a folder (watch a fleet inbox: FOLDER/UNIT/records)")
    halt = stop or threading.Event()
    seen: dict[Path, tuple[int, int, float]] = {}   # size, mtime, since when unchanged
    handed: dict[Path, tuple[int, int]] = {}        # size, mtime when handed over
    log(f"watching {root} (a file is complete once unchanged for {settle:g} s)")
    summary = FolderSummary()
    started = time.monotonic()
    with ExitStack() as stack:
        scheduler: str | None = None
        while not halt.is_set():
            if duration is not None and time.monotonic() - started >= duration:
                break
            ready = _complete(root, seen, handed, settle)
            if ready:
                if scheduler is None:
                    client = stack.enter_context(local_cluster(workers))
                    scheduler = str(client.scheduler.address)  # type: ignore[union-attr]
                res = run_fleet(root, db, scheduler=scheduler, files=ready)
                handed.update({p: seen[p][:2] for p in ready})
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
            halt.wait(poll)
    summary.seconds = time.monotonic() - started
    return summary


def _complete(root: Path, seen: dict[Path, tuple[int, int, float]],
              handed: dict[Path, tuple[int, int]], settle: float) -> list[Path]:
    """New record files whose size and time have been still for ``settle`` s (a
    file handed over that changes afterwards, written on after a long pause, is
    handed over again once still: the fleet run skips it if it was stored)."""
    now = time.monotonic()
    ready = []
    for rec in inbox_records(root):
        path = Path(rec.path).resolve()
        try:
            st = path.stat()
        except OSError:
            continue  # gone between the listing and now
        key = (st.st_size, st.st_mtime_ns)
        if handed.get(path) == key:
            continue
        before = seen.get(path)
        if before is None or before[:2] != key:
            seen[path] = (*key, now)
        elif now - before[2] >= settle:
            ready.append(path)
    return ready


def _events(res: FleetResult) -> list[WatchEvent]:
    now = datetime.now(timezone.utc).isoformat(timespec="milliseconds")
    out = []
    for r in res.records:
        if r.outcome not in ("stored", "rejected"):
            continue
        what = f"{Path(r.file).name}: {r.outcome}" + (f", {r.reason}" if r.reason else "")
        out.append(WatchEvent(r.unit, r.status or "retest", now, what, (), "checked"))
    return out
