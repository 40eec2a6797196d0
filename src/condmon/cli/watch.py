"""``condmon watch``: live monitoring of streaming units (:mod:`condmon.workflows.live`)."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from condmon.cli._console import err, out

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add ``watch`` to the ``condmon`` application."""

    @app.command("watch")
    def watch_cmd(
        mqtt: Annotated[str, typer.Option("--mqtt", help="MQTT broker HOST:PORT; units publish chunks on condmon/UNIT/samples.")],
        db: Annotated[str, typer.Option("--db", help="History database: a SQLite file or a postgresql:// URL.")] = "condmon.db",
        model: Annotated[Optional[str], typer.Option(help="Model of units new to the history: a shipped name (hst, dc-motor) or a declaration file (.toml); known units keep their own.")] = None,
        duration: Annotated[Optional[float], typer.Option(help="Stop after this long [s] (default: until Ctrl-C or SIGTERM).", min=0)] = None,
        isolate_after: Annotated[float, typer.Option(help="Data after a detection before its isolation starts [s].", min=0)] = 6.0,
        client_id: Annotated[str, typer.Option(help="MQTT client id: the broker keeps this session's messages while the watcher is away.")] = "condmon-watch",
    ) -> None:
        """Watch units streaming over MQTT: the model beside each plant-model unit's
        stream (residuals, detection, isolation), each estimation-model unit's test
        checked when its last chunk arrives; every status change published, retained,
        on condmon/UNIT/status and kept in the history. Ctrl-C or SIGTERM stops."""
        from condmon.models.registry import get_model
        from condmon.store.db import open_store
        from condmon.store.engine import redact
        from condmon.workflows.live import parse_broker, watch_mqtt
        from condmon.workflows.watch import Watcher

        parse_broker(mqtt)
        if model is not None:
            get_model(model)  # an unknown model is refused before connecting

        def log(line: str) -> None:
            err.print(line, markup=False, highlight=False, soft_wrap=True)

        with open_store(db) as store:
            watcher = Watcher(store, model=model, isolate_after=isolate_after)
            summary = watch_mqtt(store, mqtt, watcher=watcher, duration=duration, log=log,
                                 client_id=client_id)
        c = summary.counters
        out.print(f"watched {redact(db)} for {summary.seconds:.1f} s: {c.received} messages "
                  f"({c.samples} samples), {c.refused} refused, {c.dropped} dropped "
                  f"({summary.overflow} for a full queue), {c.detections} detections, "
                  f"{c.isolations} isolations stored, {c.checks} tests checked, "
                  f"{c.events} events", markup=False, highlight=False, soft_wrap=True)
