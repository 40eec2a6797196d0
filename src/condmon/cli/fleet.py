"""The ``fleet`` commands: every new record of many units, on a distributed engine."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer
from rich import box
from rich.markup import escape
from rich.table import Table

from condmon.cli._console import err, out, progress, write_json
from condmon.identify.defaults import DEFAULT_FIT_THRESHOLD

if TYPE_CHECKING:
    from condmon.workflows.fleet import FleetResult

__all__ = ["register"]

#: Order of the statuses in the summary table (others after, by name).
STATUS_ORDER = ("no-go", "advisory", "retest", "go", "building", "baseline")


def register(app: typer.Typer) -> None:
    """Add the ``fleet`` command group to the ``condmon`` application."""
    fleet_app = typer.Typer(no_args_is_help=True,
                            help="Process a fleet's new records: estimate or isolate, check, store.")
    app.add_typer(fleet_app, name="fleet")

    @fleet_app.command("run")
    def run_cmd(
        inbox: Annotated[Optional[Path], typer.Argument(help="Inbox folder: a folder per unit (INBOX/UNIT/record files; INBOX/UNIT/unit.toml may hold model = \"...\").", show_default=False)] = None,
        db: Annotated[str, typer.Option("--db", help="History database: a SQLite file (created if missing) or a postgresql:// URL.")] = "condmon.db",
        manifest: Annotated[Optional[Path], typer.Option("--manifest", help="CSV or TOML manifest instead of an inbox: columns unit, file, model, date (files relative to the manifest's folder).")] = None,
        workers: Annotated[Optional[int], typer.Option("--workers", help="Worker processes of the local cluster (default: the machine's cores).")] = None,
        scheduler: Annotated[Optional[str], typer.Option("--scheduler", help="An existing dask.distributed scheduler, tcp://host:port, instead of a local cluster.")] = None,
        baseline_count: Annotated[int, typer.Option("--baseline-count", help="A unit without a baseline builds it from its first N accepted records (date order, else file-name order); a new operating regime from its first N of that regime.")] = 3,
        columns: Annotated[Optional[str], typer.Option("--columns", help="Column mapping CANONICAL=FILE_COLUMN,... for every record (over unit.toml's and the manifest's).")] = None,
        fit_threshold: Annotated[float, typer.Option("--fit-threshold", help="Reject below this percentage fit [%].")] = DEFAULT_FIT_THRESHOLD,
        sample_rate: Annotated[Optional[float], typer.Option("--sample-rate", help="Samples per second when t counts samples or is absent [Hz].")] = None,
        scale: Annotated[Optional[str], typer.Option("--scale", help="Scale per column NAME=FACTOR,...: value = raw*FACTOR + OFFSET.")] = None,
        offset: Annotated[Optional[str], typer.Option("--offset", help="Offset per column NAME=VALUE,... [SI].")] = None,
        ignore: Annotated[Optional[str], typer.Option("--ignore", help="File columns to leave out, comma-separated.")] = None,
        as_json: Annotated[bool, typer.Option("--json", help="Print every record's outcome as JSON.")] = False,
    ) -> None:
        """Estimate (or isolate) and check every new record of every unit, storing the results.

        A unit's model is the manifest's, else the one its history was started
        with, else INBOX/UNIT/unit.toml's, else dc-motor; a plant model (hst)
        gets fault isolation. Records already in the history (same file or same
        content) are skipped, so running again stores nothing new. A record
        that cannot be read or estimated is refused with its reason; the others
        go on. Exits 2 when records were refused and none was stored; a run
        that only skips what is stored already exits 0, also when a unit's
        folder holds a file that is no record (notes.md: named, not read).
        """
        from condmon.errors import ConfigError
        from condmon.io.records import parse_column_map
        from condmon.io.rig import settings_from_options
        from condmon.workflows.fleet import FleetInterrupted, run_fleet
        from condmon.workflows.records import EstimateOptions

        if (inbox is None) == (manifest is None):
            raise ConfigError("give an INBOX folder or --manifest FILE (one of them)")
        if not (0.0 <= fit_threshold <= 100.0):
            raise ConfigError(f"--fit-threshold must be in 0..100 %, got {fit_threshold:g}")
        record = settings_from_options(parse_column_map(columns) or None, sample_rate, scale,
                                       offset, ignore)
        options = EstimateOptions(fit_threshold=fit_threshold,
                                  record=None if record.empty else record)
        source = manifest if manifest is not None else inbox
        assert source is not None
        try:
            with _ticker() as tick:
                res = run_fleet(source, db, manifest=manifest is not None, workers=workers,
                                scheduler=scheduler, baseline_count=baseline_count,
                                options=options, progress=tick)
        except FleetInterrupted as stop:
            err.print(str(stop), highlight=False, markup=False, soft_wrap=True)
            raise typer.Exit(130) from None
        if as_json:
            write_json(res.to_dict())
        else:
            _print_result(res, str(source))
        if res.failed:
            err.print(f"nothing new was stored: {res.count('refused')} record(s) refused and "
                      "none taken (exit 2)", highlight=False, markup=False, soft_wrap=True)
            raise typer.Exit(2)


@contextmanager
def _ticker() -> Iterator[Callable[[int, int, str], None]]:
    """A progress callback: a bar on a terminal's stderr (gone when done), else
    nothing (no blank line in a log)."""
    if not err.is_terminal:
        yield lambda done, total, label: None
        return
    with progress() as prog:
        task = prog.add_task("records", total=None)

        def tick(done: int, total: int, label: str) -> None:
            prog.update(task, completed=done, total=total, description=escape(label[:40]))

        yield tick


def _line(what: str, file: str, reason: str | None) -> str:
    text = reason or ""
    return f"{what} {text}" if text.startswith(file) else f"{what} {file}: {text}"


def _print_result(res: FleetResult, source: str) -> None:
    for r in res.records:
        for w in r.warnings:
            err.print(_line("warning:", r.file, w), highlight=False, markup=False, soft_wrap=True)
        if r.outcome == "refused":
            err.print(_line("refused", r.file, r.reason), highlight=False, markup=False,
                      soft_wrap=True)
        elif r.outcome == "rejected":
            err.print(_line("stored as rejected (retest)", r.file, r.reason), highlight=False,
                      markup=False, soft_wrap=True)
    if not res.records:
        out.print(f"no records in {escape(source)}", highlight=False)
        return
    groups: dict[str, list[str]] = {}
    for u in res.units:
        groups.setdefault(u.status or "nothing stored", []).append(u.unit)
    rank = {s: i for i, s in enumerate(STATUS_ORDER)}
    table = Table(title="Units by status", box=box.SIMPLE_HEAD, title_justify="left")
    table.add_column("status", no_wrap=True)
    table.add_column("units", justify="right")
    table.add_column("which", overflow="fold")
    for status in sorted(groups, key=lambda s: (rank.get(s, len(rank)), s)):
        names = groups[status]
        shown = ", ".join(names[:12]) + (f", ... {len(names) - 12} more" if len(names) > 12 else "")
        color = {"go": "green", "advisory": "yellow", "no-go": "red", "retest": "blue"}.get(status)
        label = f"[bold {color}]{status}[/]" if color else escape(status)
        table.add_row(label, str(len(names)), escape(shown))
    out.print(table)
    for u in res.units:
        if u.note:
            out.print(f"{u.unit}: {u.note}", highlight=False, markup=False, soft_wrap=True)
    taken = res.count("stored") + res.count("rejected")
    rate = (f" ({taken / res.seconds:.1f} records stored/s)"
            if res.workers > 0 and res.seconds > 0 and taken else "")
    from condmon.workflows.fleet import SMALL_FLEET

    if res.engine == "in-process":
        rate += (f"; in this process (fewer than {SMALL_FLEET} records: a cluster takes "
                 "longer to start; --workers N starts one)")
    elif res.workers > 0:
        how = ("local cluster started" if res.engine == "local" else
               f"connected to {res.engine}")
        rate += (f"; {how} in {res.engine_start:.1f} s, stopped in {res.engine_stop:.1f} s"
                 if res.engine == "local" else f"; {how} in {res.engine_start:.2f} s")
    stray = (f" ({res.not_records} of them no unit's record)" if res.not_records else "")
    ran = (f"{res.workers} worker{'s' if res.workers != 1 else ''}" if res.workers else
           "nothing new to estimate, no worker started")
    out.print(f"{len(res.records)} records: {res.count('stored')} stored, "
              f"{res.count('skipped')} skipped, {res.count('rejected')} rejected, "
              f"{res.count('refused')} refused{stray} — {len(res.units)} "
              f"unit{'s' if len(res.units) != 1 else ''}, {ran}, {res.seconds:.1f} s{rate}",
              highlight=False, markup=False)
