"""Consoles and small output helpers shared by the command modules."""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from condmon.io.jsonable import json_safe

__all__ = ["out", "err", "fmt", "warned", "write_json", "write_json_list", "json_safe", "progress",
           "status_text", "fit_to_output", "PIPED_WIDTH", "fitted_widths"]

out = Console()
err = Console(stderr=True)

#: The warnings shown on stderr during the running command (``main`` clears it):
#: :func:`write_json` carries them into the document, so a ``--json`` reader
#: that keeps only stdout loses none of them.
warned: list[str] = []

#: Columns of a table printed into a pipe or a file: wide enough that a
#: plant's or a fleet's table is not folded (80, rich's default there, folded
#: them, and wrapped a line in the middle of a unit).
PIPED_WIDTH = 200


def fit_to_output() -> None:
    """Size the consoles for where they print: a terminal's own width; a pipe
    or a file (and no ``COLUMNS`` set) gets lines that are not wrapped and
    tables up to :data:`PIPED_WIDTH` columns."""
    for console, stream in ((out, sys.stdout), (err, sys.stderr)):
        try:
            terminal = stream.isatty()
        except (AttributeError, ValueError):   # a closed or replaced stream
            terminal = False
        columns = os.environ.get("COLUMNS", "")
        piped = not terminal and not columns
        console.soft_wrap = piped
        console.width = PIPED_WIDTH if piped else (  # type: ignore[assignment]
            int(columns) if columns.isdigit() else None)


def fitted_widths(columns: Sequence[str], rows: Sequence[Sequence[str]], width: int,
                  give: Sequence[tuple[str, int]], least: Mapping[str, int] | None = None,
                  drop: Sequence[str] = (), gap: int = 2, edges: int = 2
                  ) -> tuple[dict[str, int], list[str]]:
    """How a table of ``rows`` (rich markup) fits ``width`` terminal columns:
    the widths columns may take, and the columns left out.

    Each ``(column, floor)`` of ``give`` in turn gives up what it has beyond
    ``floor`` until the table fits (a column may come twice, with a lower
    floor the second time); the others keep their own width (their widest
    cell or heading, at least ``least``; ``gap`` between two columns and
    ``edges`` in all, as a table with ``pad_edge=False,
    collapse_padding=True`` takes them). When it still does not fit, the
    columns of ``drop`` are left out, in that order, until it does: the
    caller says so (a terminal too narrow must not lose a column silently).

    Example
    -------
    >>> rows = [("EMA-1", "a-long-record-file-name.csv", "[green]go[/]")]
    >>> fitted_widths(("unit", "latest", "status"), rows, 30, [("latest", 6)])
    ({'latest': 13}, [])
    >>> fitted_widths(("unit", "latest", "status"), rows, 14, [("latest", 6)], drop=["latest"])
    ({}, ['latest'])
    """
    from rich.text import Text

    now = {c: max([len(c), (least or {}).get(c, 0),
                   *(Text.from_markup(r[k]).cell_len for r in rows)])
           for k, c in enumerate(columns)}
    excess = sum(now.values()) + gap * (len(columns) - 1) + edges - width
    out: dict[str, int] = {}
    for c, floor in give:
        if excess <= 0:
            break
        if c in now and now[c] > floor:
            cut = min(excess, now[c] - floor)
            now[c] = out[c] = now[c] - cut
            excess -= cut
    hidden = []
    for c in drop:
        if excess <= 0:
            break
        if c in now:
            hidden.append(c)
            excess -= now[c] + gap
    if hidden:   # the others again, with the room the left-out ones had
        keep = [k for k, c in enumerate(columns) if c not in hidden]
        out, _ = fitted_widths([columns[k] for k in keep], [[r[k] for k in keep] for r in rows],
                               width, give, least, (), gap, edges)
    return out, hidden


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
    anything else unknown its text. A document (a mapping) gets the command's
    warnings (:data:`warned`) as ``warnings`` when there were any."""
    if warned and isinstance(doc, Mapping):
        doc = {**doc, "warnings": [*doc.get("warnings", ()), *warned]}
    sys.stdout.write(json.dumps(json_safe(doc), indent=2, allow_nan=False) + "\n")


def _dumped(value: Any, indent: str) -> str:
    """``value`` as :func:`write_json` prints it, its lines after the first indented."""
    text = json.dumps(json_safe(value), indent=2, allow_nan=False)
    return text.replace("\n", "\n" + indent)


def write_json_list(items: Iterable[Any], key: str | None = None,
                    after: dict[str, Any] | None = None) -> None:
    """Print a list as :func:`write_json` would, one item at a time (memory
    stays flat however long the list): ``items`` alone, or ``{key: items,
    **after}`` when a key is given.

    Example
    -------
    >>> write_json_list(iter([{"a": 1}]), "units", {"page": 1})
    {
      "units": [
        {
          "a": 1
        }
      ],
      "page": 1
    }
    """
    pad = "    " if key is not None else "  "
    write = sys.stdout.write
    write("{\n  " + json.dumps(key) + ": [" if key is not None else "[")
    first = True
    for item in items:
        write(("\n" if first else ",\n") + pad + _dumped(item, pad))
        first = False
    write("]" if first else "\n" + pad[:-2] + "]")
    if key is not None:
        for k, v in (after or {}).items():
            write(",\n  " + json.dumps(k) + ": " + _dumped(v, "  "))
        write("\n}")
    write("\n")


def progress() -> Progress:
    """A progress bar on stderr that disappears when done."""
    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), console=err, transient=True)


def status_text(status: str) -> str:
    """A status in its colour, as rich markup."""
    color = {"go": "green", "advisory": "yellow", "no-go": "red", "retest": "blue",
             "not judged": "cyan"}.get(status, "white")
    return f"[bold {color}]{status}[/]"
