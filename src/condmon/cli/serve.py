"""``condmon serve``: the live fleet page (:mod:`condmon.report.web`)."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from condmon.cli._console import err, out

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add ``serve`` to the ``condmon`` application."""

    @app.command("serve")
    def serve_cmd(
        db: Annotated[str, typer.Option("--db", help="History database: a SQLite file or a postgresql:// URL (only read).")] = "condmon.db",
        host: Annotated[str, typer.Option(help="Address to listen on; 127.0.0.1 is this machine only (the page has no log-in).")] = "127.0.0.1",
        port: Annotated[int, typer.Option(help="TCP port (0: any free one).", min=0, max=65535)] = 8050,
        refresh: Annotated[float, typer.Option(help="The fleet table reloads itself this often [s] (0: never).", min=0)] = 30.0,
        mqtt: Annotated[Optional[str], typer.Option("--mqtt", help="MQTT broker HOST:PORT of condmon watch: units' statuses shown live, the table redrawn at each change without a reload.")] = None,
        stale_after: Annotated[Optional[float], typer.Option(help="With --mqtt, a unit silent this long is shown stale [s] (default: [stream] stale_after of limits.toml).", min=0)] = None,
    ) -> None:
        """Serve a live fleet page (every unit's status, trends, tests, isolations, JSON API)
        until Ctrl-C. Reads the history at every request; never writes it."""
        from condmon.report.web import EVENT_CLIENTS, create_app, serve
        from condmon.store.engine import redact

        live = None
        if mqtt is not None:
            from condmon.io.stream import StreamLimits
            from condmon.report.live import LiveFeed

            live = LiveFeed(mqtt, stale_after if stale_after is not None else
                            StreamLimits.shipped().stale_after,
                            log=lambda line: err.print(line, markup=False, highlight=False))
        web = create_app(db, refresh=refresh, live=live)  # a missing or foreign history fails here
        if live is not None:
            live.start()

        def ready(url: str) -> None:
            out.print(f"fleet page of {redact(db)} at {url}  (Ctrl-C stops)", markup=False,
                      highlight=False, soft_wrap=True)
            if host not in ("127.0.0.1", "localhost", "::1"):
                err.print(f"warning: listening on {host}: anyone who reaches this address "
                          "reads the history (the page has no log-in)", markup=False,
                          highlight=False, soft_wrap=True)

        try:
            # a browser's live feed holds a thread: more of them with --mqtt
            serve(web, host=host, port=port, ready=ready,
                  threads=4 if live is None else EVENT_CLIENTS + 16)
        finally:
            if live is not None:
                live.stop()
        out.print("stopped", markup=False, highlight=False)
