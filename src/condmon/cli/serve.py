"""``condmon serve``: the live fleet page (:mod:`condmon.report.web`)."""

from __future__ import annotations

from typing import Annotated

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
    ) -> None:
        """Serve a live fleet page (every unit's status, trends, tests, isolations, JSON API)
        until Ctrl-C. Reads the history at every request; never writes it."""
        from condmon.report.web import create_app, serve
        from condmon.store.engine import redact

        web = create_app(db, refresh=refresh)  # a missing or foreign history fails here

        def ready(url: str) -> None:
            out.print(f"fleet page of {redact(db)} at {url}  (Ctrl-C stops)", markup=False,
                      highlight=False, soft_wrap=True)
            if host not in ("127.0.0.1", "localhost", "::1"):
                err.print(f"warning: listening on {host}: anyone who reaches this address "
                          "reads the history (the page has no log-in)", markup=False,
                          highlight=False, soft_wrap=True)

        serve(web, host=host, port=port, ready=ready)
        out.print("stopped", markup=False, highlight=False)
