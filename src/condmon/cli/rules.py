"""``condmon rules check``: what a model's fault rules can tell apart (:func:`condmon.diagnose.structure_rules.check_model_rules`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.markup import escape
from rich.table import Table

from condmon.cli._console import out, write_json

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add the ``rules`` group (``rules check``) to the ``condmon`` application."""
    rules_app = typer.Typer(no_args_is_help=True, help="Fault rule bases: what they tell apart.")
    app.add_typer(rules_app, name="rules")

    @rules_app.command("check")
    def rules_check_cmd(
        model: Annotated[str, typer.Argument(help="Machine model: a shipped name (dc-motor) or a declaration file (.toml).")],
        rules: Annotated[Optional[Path], typer.Option(help="Rule base TOML to check instead of the model's own.")] = None,
        as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
    ) -> None:
        """List the faults a model's rules cannot tell apart, the parameters no
        rule names and the parameters the rules name that the model does not report.

        Each fault is evaluated over every crisp symptom pattern (each
        parameter low, none or high): faults firing on the same patterns are
        indistinguishable; one firing only where another fires is never told
        from it. Exit status 0 when nothing is found, 1 when something is."""
        from condmon.diagnose.structure_rules import check_model_rules

        check = check_model_rules(model, rules)
        if as_json:
            write_json(check.to_dict())
        else:
            out.print(f"[bold]{escape(check.model)}[/] — rules {escape(check.source)}: "
                      f"{len(check.faults)} faults over {', '.join(check.parameters)}",
                      highlight=False)
            rows = check.findings()
            if rows:
                table = Table()
                for col in ("finding", "faults or parameter", "why"):
                    table.add_column(col)
                for row in rows:
                    table.add_row(*(escape(v) for v in row))
                out.print(table)
            else:
                out.print("fine: each fault fires on symptom patterns no other fault fires "
                          "on, and the rules name what the model reports", highlight=False)
            if check.alone_unnamed:
                out.print("symptoms that fire no fault on their own (a clear one is "
                          "'change detected, cause not determined' unless a rule names it with "
                          "another symptom): " + ", ".join(check.alone_unnamed),
                          highlight=False, markup=False, soft_wrap=True)
        if not check.ok:
            raise typer.Exit(1)
