"""``condmon watch``: live monitoring of streaming units (:mod:`condmon.workflows.live`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from condmon.cli._console import err, out

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add ``watch`` to the ``condmon`` application."""

    @app.command("watch")
    def watch_cmd(
        folder: Annotated[Optional[Path], typer.Argument(help="A fleet inbox (FOLDER/UNIT/record files) whose new files are handled as each completes, as by fleet run.")] = None,
        mqtt: Annotated[Optional[str], typer.Option("--mqtt", help="MQTT broker HOST:PORT; units publish chunks on condmon/UNIT/samples.")] = None,
        db: Annotated[str, typer.Option("--db", help="History database: a SQLite file or a postgresql:// URL.")] = "condmon.db",
        model: Annotated[Optional[str], typer.Option(help="Model of units new to the history (MQTT): a shipped name (hst, dc-motor) or a declaration file (.toml); known units keep their own.")] = None,
        duration: Annotated[Optional[float], typer.Option(help="Stop after this long [s] (default: until Ctrl-C or SIGTERM).", min=0)] = None,
        isolate_after: Annotated[Optional[float], typer.Option(help="Data after a detection before its isolation starts [s] (default: what the isolation's settings need).", min=0)] = None,
        settings: Annotated[Optional[Path], typer.Option(help="Detection/estimation/isolation settings TOML of the --mqtt stream, as for isolate (default: the shipped isolation.toml); a watched folder's records use the shipped ones, as fleet run does.")] = None,
        settle: Annotated[float, typer.Option(help="With --complete settle, a dropped file is complete once unchanged this long [s].", min=0)] = 2.0,
        complete: Annotated[str, typer.Option(help="How a dropped file is known to be complete: rename (written under a hidden or .part/.tmp name, then renamed into place: complete at once; best), marker (NAME.done written beside NAME), or settle (unchanged for --settle; a file written on after a longer pause is stored again and its part excluded as replaced).")] = "settle",
        client_id: Annotated[Optional[str], typer.Option(help="MQTT client id: the broker keeps this session's messages while the watcher is away; two watchers with one id push each other off (default: one per history).")] = None,
        notify: Annotated[Optional[str], typer.Option(help="Webhook URL: every event is POSTed to it as JSON, with retries, never holding the stream back.")] = None,
        journal: Annotated[Optional[Path], typer.Option(help="The journal of messages acknowledged to the broker and not yet stored, replayed at the next start (default: beside a SQLite history, DB.CLIENT-ID.journal; else in the working folder).")] = None,
        units: Annotated[Optional[str], typer.Option(help="Follow only units whose name matches this regular expression whole (others are refused); [stream] max_units of limits.toml bounds how many.")] = None,
    ) -> None:
        """Watch units live: MQTT streams and record files dropped in a folder.

        The model runs beside each plant-model unit's stream (residuals, detection,
        isolation); an estimation-model unit's test is checked when its last chunk
        arrives; a dropped file is handled as by fleet run. Every status change is
        published, retained, on condmon/UNIT/status and kept in the history. Ctrl-C
        or SIGTERM stops."""
        import queue
        import threading

        from condmon.diagnose.isolation import IsolationSettings
        from condmon.errors import ConfigError
        from condmon.models.registry import get_model
        from condmon.store.db import open_store
        from condmon.store.engine import redact
        from condmon.workflows.live import (parse_broker, restore_signals, stop_on_signals,
                                            watch_mqtt)
        from condmon.workflows.notify import Notifier, shown_url
        from condmon.io.stream import StreamLimits
        from condmon.workflows.watch import Watcher, WatchEvent
        from condmon.workflows.watch_bounds import Bounds, unit_pattern
        from condmon.workflows.watch_folder import COMPLETE, FolderSummary, watch_folder

        if folder is None and mqtt is None:
            raise ConfigError("give a FOLDER to watch, --mqtt HOST:PORT, or both")
        if mqtt is not None:
            parse_broker(mqtt)
        if model is not None:
            get_model(model)  # an unknown model is refused before connecting
        pattern = unit_pattern(units)
        if complete not in COMPLETE:
            raise ConfigError(f"--complete {complete!r}: allowed: {', '.join(COMPLETE)}")
        if folder is not None:
            from condmon.workflows.fleet_inbox import check_inbox

            check_inbox(folder)   # a unit's own folder is refused before watching
        if settings is not None:
            if mqtt is None:   # records dropped in a folder are isolated as fleet run does
                raise ConfigError(f"--settings {settings}: applies to an --mqtt stream; a "
                                  "watched folder's records are processed as `condmon fleet "
                                  "run` processes them, with the shipped isolation settings")
            IsolationSettings.load(settings)   # a bad file is refused before connecting

        def log(line: str) -> None:
            err.print(line, markup=False, highlight=False, soft_wrap=True)

        halt = threading.Event()
        folder_result: dict[str, FolderSummary] = {}
        notifier = (Notifier(notify, maxsize=StreamLimits.shipped().events, log=log)
                    if notify is not None else None)

        outbox: queue.Queue[WatchEvent] = queue.Queue(maxsize=StreamLimits.shipped().events)

        def post(event: WatchEvent) -> None:
            if mqtt is not None:  # published by the MQTT client, which posts it too
                try:
                    outbox.put_nowait(event)
                except queue.Full:
                    log(f"{event.unit}: event not published, the queue is full")
            elif notifier is not None:
                notifier.send(event.to_dict())

        def run_folder() -> None:
            assert folder is not None
            folder_result["summary"] = watch_folder(folder, db, settle=settle, complete=complete,
                                                    stop=halt,
                                                    duration=duration, log=log, publish=post)

        if mqtt is None:
            previous = stop_on_signals(halt)
            try:
                run_folder()
            finally:
                restore_signals(previous)
        else:
            thread = None
            if folder is not None:
                thread = threading.Thread(target=run_folder, name="watch-folder", daemon=True)
                thread.start()
            _reachable(mqtt)  # an unreachable broker makes no history file
            with open_store(db) as store:
                watcher = Watcher(store, model=model, isolate_after=isolate_after,
                                  settings=IsolationSettings.load(settings),
                                  bounds=Bounds(units=pattern))
                summary = watch_mqtt(store, mqtt, watcher=watcher, duration=duration, log=log,
                                     client_id=client_id, stop=halt,
                                     notify=notifier.send if notifier else None,
                                     outbox=outbox, journal=journal)
            halt.set()
            if thread is not None:
                thread.join()
            c = summary.counters
            out.print(f"watched {mqtt} for {summary.seconds:.1f} s: {c.received} messages "
                      f"({c.samples} samples), {c.refused} refused, {c.dropped} dropped "
                      f"({summary.overflow} for a full queue), {c.detections} detections, "
                      f"{c.isolations} isolations stored, {c.checks} tests checked, "
                      f"{c.events} events"
                      + (f", {summary.replayed} replayed from the journal" if summary.replayed
                         else "") + f"; history {redact(db)}", markup=False,
                      highlight=False, soft_wrap=True)
        if notifier is not None and notify is not None:
            notifier.close()
            out.print(f"webhook {shown_url(notify)}: {notifier.sent} events posted, "
                      f"{notifier.failed} given up, {notifier.dropped} dropped for a full "
                      f"queue, {notifier.left} left unposted at the stop", markup=False,
                      highlight=False, soft_wrap=True)
        fs = folder_result.get("summary")
        if fs is not None:
            out.print(f"watched {folder} for {fs.seconds:.1f} s: {fs.files} files handled, "
                      f"{fs.stored} stored, in {fs.runs} fleet runs"
                      + (f", {fs.replaced} stored in part and replaced" if fs.replaced else ""), markup=False,
                      highlight=False, soft_wrap=True)


def _reachable(broker: str, timeout: float = 10.0) -> None:
    """Refuse a broker nobody answers at, before anything is created."""
    import socket

    from condmon.errors import ConfigError
    from condmon.io.stream import parse_broker

    host, port = parse_broker(broker)
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        raise ConfigError(f"--mqtt {broker}: cannot reach the broker at {host}:{port} "
                          f"({exc})") from None
