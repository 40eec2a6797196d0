"""Consoles and small output helpers shared by the command modules."""

from __future__ import annotations

import json
import sys
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from condmon.io.jsonable import json_safe

__all__ = ["out", "err", "fmt", "write_json", "json_safe", "progress", "status_text"]

out = Console()
err = Console(stderr=True)


def fmt(value: float) -> str:
    """A number with 5 significant digits."""
    return f"{value:.5g}"


def id_runs(ids: Any) -> str:
    """Test ids as runs: ``#1-#5,#8`` for 1, 2, 3, 4, 5, 8 (the store's
    :func:`~condmon.store.baselines.id_runs`, imported when first used)."""
    from condmon.store.baselines import id_runs as runs

    return runs(ids)


def write_json(doc: Any) -> None:
    """Print ``doc`` as JSON. Never raises on the content: a non-finite number
    (NaN, ±inf) becomes null, numpy scalars and arrays become numbers and lists,
    anything else unknown its text."""
    sys.stdout.write(json.dumps(json_safe(doc), indent=2, allow_nan=False) + "\n")


def progress() -> Progress:
    """A progress bar on stderr that disappears when done."""
    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), console=err, transient=True)


def status_text(status: str) -> str:
    """A status in its colour, as rich markup."""
    color = {"go": "green", "advisory": "yellow", "no-go": "red", "retest": "blue"}.get(status, "white")
    return f"[bold {color}]{status}[/]"
