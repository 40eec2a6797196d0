"""``condmon import``: already-measured indicator values as a unit's checks
(:mod:`condmon.workflows.imports`)."""

from __future__ import annotations

from typing import Annotated, Optional

import typer

from condmon.cli._console import out, write_json

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add ``import`` to the ``condmon`` application."""

    @app.command("import")
    def import_cmd(
        table: Annotated[str, typer.Argument(help="CSV (or .parquet) table: an axis column (cycle, hours or date), each indicator of the declaration, optionally <indicator>_se.")],
        model: Annotated[str, typer.Option("--model", help="The indicator declaration (TOML with [indicators]: each indicator's unit and end of life).")],
        unit: Annotated[Optional[str], typer.Option("--unit", help="The unit the table holds (else a 'unit' column names each row's).")] = None,
        indicator: Annotated[Optional[str], typer.Option("--indicator", help="The table has a column per unit, all of this indicator.")] = None,
        no_go: Annotated[Optional[list[str]], typer.Option("--no-go", help="The unit's own end of life, e.g. 'capacity<0.88' (a level in the indicator's unit), 'capacity<70%rated', 'capacity-30%'; kept for the unit.")] = None,
        baseline: Annotated[int, typer.Option("--baseline", help="Rows that make a new unit's baseline (its first ones).")] = 5,
        db: Annotated[str, typer.Option("--db", help="History database: a SQLite file or a postgresql:// URL.")] = "condmon.db",
        as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
    ) -> None:
        """Store a table of already-measured indicator values as units' checks.

        Capacity per cycle, a resistance from an impedance test, a value from another
        system: each row is a check of its unit, trended against the unit's baseline (its
        first rows when it has none) and forecast to its end of life like an estimated
        parameter (condmon forecast). Every cell is checked first: a bad one is refused
        with its row and column, and nothing is stored. Rows already stored are skipped."""
        from pathlib import Path

        from condmon.errors import CondmonError
        from condmon.store.db import open_store
        from condmon.workflows.imports import import_table

        made = "://" not in db and not Path(db).exists()
        try:
            with open_store(db) as store:
                done = import_table(store, table, model, unit=unit, indicator=indicator,
                                    no_go=no_go or (), baseline_rows=baseline)
        except CondmonError:
            if made:   # nothing was stored: no empty history left behind either
                Path(db).unlink(missing_ok=True)
            raise
        if as_json:
            write_json({"table": table, "units": [d.to_dict() for d in done]})
            return
        for d in done:
            base = f", the first {d.baseline} the baseline" if d.baseline else ""
            skipped = f"; {d.skipped} already stored" if d.skipped else ""
            status = f"; last check {d.status}" if d.status else ""
            eol = ", ".join(f"{k} {v}" for k, v in d.end_of_life.items())
            out.print(f"{d.unit}: {d.added} rows stored by {d.axis}{base}{skipped}{status} "
                      f"(end of life: {eol})", markup=False, highlight=False, soft_wrap=True)
            for line in d.changed:
                out.print(f"{d.unit}: {line}", markup=False, highlight=False, soft_wrap=True)
