"""``condmon`` command line. Every command calls one library function and prints.

Errors a user can cause (bad file, bad column, bad option value) print one line
on stderr and exit with status 2; no traceback.
"""

from __future__ import annotations

import functools
import math
import sys
import warnings
from pathlib import Path
from typing import Annotated, Any, Optional

import typer
from typer.core import TyperGroup
from rich.markup import escape
from rich.table import Table

from condmon.cli._console import (
    err, fit_to_output, fmt, out, progress, status_text, warned, write_json,
)
from condmon.cli.check import register as register_check_command
from condmon.cli.estimation import (
    ColOpt, ConstOpt, DateOpt, DbOpt, ExcOpt, FitOpt, GammaOpt, GroupOpt, IgnoreOpt, MetaOpt,
    MethodOpt, ModelOpt, OffsetOpt, RateOpt, RouteOpt, ScaleOpt, UnitModelOpt, UnitOpt,
    WindowOpt, options,
)
from condmon.cli.fleet import register as register_fleet_commands
from condmon.cli.forecast import register as register_forecast_command
from condmon.cli.history import print_flags
from condmon.cli.imports import register as register_import_command
from condmon.cli.validate import register as register_validate_commands
from condmon.cli.history import register as register_history_commands
from condmon.cli.plant import register as register_plant_commands
from condmon.cli.rules import register as register_rules_commands
from condmon.cli.serve import register as register_serve_command
from condmon.cli.views import register as register_view_commands
from condmon.cli.watch import register as register_watch_command
from condmon.errors import CondmonError
from condmon.identify.defaults import DEFAULT_FIT_THRESHOLD, list_estimators

#: ``condmon --help`` lists the commands in the order of a user's work: try it,
#: estimate, baseline and check a unit, a fleet and live units, read the history,
#: look after it.
WORKFLOW = ("demo", "simulate", "estimate", "validate", "baseline", "check", "import", "isolate", "fleet",
            "watch", "history", "units", "forecast", "report", "serve", "exclude", "include",
            "audit", "unit", "rules")


class _InWorkflowOrder(TyperGroup):
    """Commands listed in :data:`WORKFLOW` order (any other after them, by name)."""

    def list_commands(self, ctx: Any) -> list[str]:
        rank = {name: i for i, name in enumerate(WORKFLOW)}
        return sorted(self.commands, key=lambda n: (rank.get(n, len(rank)), n))


app = typer.Typer(add_completion=False, no_args_is_help=True, rich_markup_mode="markdown",
                  cls=_InWorkflowOrder,
                  help="Model-based condition monitoring: estimate, trend, diagnose.")
simulate_app = typer.Typer(no_args_is_help=True, help="Simulate test-beds with known parameters.")
app.add_typer(simulate_app, name="simulate")
baseline_app = typer.Typer(no_args_is_help=True, help="Build a unit's healthy baseline.")
app.add_typer(baseline_app, name="baseline")
register_plant_commands(app, simulate_app)
register_history_commands(app, baseline_app)
register_serve_command(app)
register_fleet_commands(app)
register_watch_command(app)
register_forecast_command(app)
register_import_command(app)
register_validate_commands(app, simulate_app)


def _print_version(value: bool) -> None:
    if value:
        from condmon import __version__

        out.print(f"condmon {__version__}", markup=False, highlight=False)
        raise typer.Exit()


@app.callback()
def _root(version: Annotated[bool, typer.Option(
        "--version", help="Print condmon's version and exit.", callback=_print_version,
        is_eager=True)] = False) -> None:
    pass





@app.command("estimate")
def estimate_cmd(
    records: Annotated[list[Path], typer.Argument(help="Test record(s) with t and the model's input and sensor columns (DC motor: V, I, omega); several are estimated together (one set of parameters).")],
    model: ModelOpt = "dc-motor",
    method: Annotated[str, typer.Option(help=f"Estimator: {', '.join(list_estimators())}.")] = "sriv",
    gamma: Annotated[Optional[float], typer.Option(help="Ke/Kt of the motor (default from the model's configuration, 0.95).")] = None,
    excitation: Annotated[str, typer.Option(help="Excitation columns for closed-loop instruments, comma-separated; 'auto' uses yd,ud when present; 'none' forces the direct approach.")] = "auto",
    columns: Annotated[Optional[str], typer.Option(help="Column mapping CANONICAL=FILE_COLUMN,... e.g. V=volts,I=amps.")] = None,
    fit_threshold: Annotated[float, typer.Option(help="Reject below this percentage fit [%].")] = DEFAULT_FIT_THRESHOLD,
    route: RouteOpt = None,
    constants: ConstOpt = None,
    sample_rate: RateOpt = None,
    scale: ScaleOpt = None,
    offset: OffsetOpt = None,
    ignore: IgnoreOpt = None,
    meta: MetaOpt = None,
    window: WindowOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
) -> None:
    """Estimate the physical parameters of one test record (or of several together)."""
    opts = options(method, gamma, excitation, columns, fit_threshold, model, route, constants,
                    sample_rate, scale, offset, ignore, meta, window)
    if len(records) == 1:
        res, _ = opts.run(records[0])
        if not res.usable:   # a column in other units? (imported only for a rejection)
            from condmon.workflows.monitoring import with_unit_hint

            res = with_unit_hint(opts, records[0], res)
    else:
        from condmon.identify.estimate import estimate_joint

        if opts.window is not None:
            raise CondmonError("--window applies to one record; estimate the records one by one")
        res = estimate_joint([opts.read(r) for r in records],
                             opts.model or "dc-motor", fit_threshold=fit_threshold,
                             sources=[str(r) for r in records], route=route,
                             constants=opts.constants, metadata=opts.metadata)
    record = " + ".join(str(r) for r in records)
    if as_json:
        write_json(res.to_dict())
        return
    for part in res.regimes:
        _print_estimate(part, record, res.systematic)
    for title, values in (("signal features", res.features),
                          ("operating conditions", res.conditions)):
        if not values:
            continue
        table = Table(title=escape(f"{record} — {title}"))
        for col in ("name", "value", "std error", "unit"):
            table.add_column(col, justify="left" if col in ("name", "unit") else "right")
        for k, (v, se) in values.items():
            table.add_row(escape(k), fmt(v), fmt(se), escape(res.unit_of(k)))
        out.print(table)
    if res.systematic:
        out.print("systematic: how far the sensors could move a value by erring within "
                  "their stated accuracy (each reading moved by it as an offset, and as a span "
                  "error reaching it at the largest reading; the larger, root-sum-square over "
                  "the sensors; records estimated together take the same error), beside the "
                  "standard error from the records' noise",
                  highlight=False, markup=False, soft_wrap=True)


_HOW = {"inverse": "inverse model", "oe": "output error", "steady": "steady balances",
        "simulation": "simulation error"}


def _state_units(res: Any) -> dict[str, str]:
    """Units of the model's states, for the initial-state rows (empty when the
    model cannot be read again)."""
    from condmon.errors import CondmonError
    from condmon.models.registry import get_model

    try:
        plant = get_model(res.model_source or res.model).plant
    except CondmonError:
        return {}
    return {s.name: s.unit for s in plant.states}


def _print_estimate(res: Any, record: str, systematic: dict[str, float] | None = None) -> None:
    """One regime's estimate as a table, its fit, windows and notes; ``systematic``:
    the record's systematic parts, by stored name (a column when given)."""
    how = (("closed-loop instruments" if res.closed_loop_instruments else "direct approach")
           if res.route == "linear" else _HOW.get(res.route, res.route))
    regime = f", regime {res.regime}" if res.regime else ""
    method = res.method.upper()
    said = method if method.lower().replace("-", " ") == how else f"{method}, {how}"
    title = escape(f"{record} — {res.model}, {said}{regime}")
    if any(math.isfinite(v) for v in res.parameters.values()):
        table = Table(title=title)
        from condmon.models.regimes import regime_key

        sys_ = systematic or {}
        cols = ("parameter", "value", "std error", *(("systematic",) if sys_ else ()), "unit",
                "from")
        for col in cols:
            table.add_column(col, justify="right" if col not in ("parameter", "from") else "left")
        for k, v in res.parameters.items():
            source = ("record" if k in res.identified else
                      f"held ({res.held[k]})" if k in res.held else "—")
            known = sys_.get(regime_key(k, res.regime), math.nan)
            extra = ((fmt(known) if k in res.identified and math.isfinite(known) else "—",)
                     if sys_ else ())
            table.add_row(escape(k), fmt(v),
                          fmt(res.std_errors[k]) if k in res.identified else "—", *extra,
                          escape(res.units[k]), source)
        state_units = _state_units(res) if res.initial_states else {}
        for k, (v, se, how_set) in res.initial_states.items():
            table.add_row(escape(f"{k}(0)"), fmt(v), fmt(se) if how_set == "estimated" else "—",
                          *(("—",) if sys_ else ()), escape(state_units.get(k, "")),
                          f"initial, {how_set}")
        out.print(table)
    else:
        out.print(title, highlight=False)
    fits = ", ".join(f"{k} {v:.1f} %" for k, v in res.fit.fits_percent.items())
    verdict = (f"[green]accepted[/green] (threshold {res.fit.threshold:g} %)" if res.accepted
               else f"[red]rejected[/red]: {escape(str(res.reason))}")
    out.print(f"fit {res.fit_percent:.1f} % (100 R²; {fits}) — {verdict}" if fits else verdict)
    if res.windows and (len(res.windows) > 1 or res.windows[0].regime):
        several = len({w.source for w in res.windows}) > 1
        for w in res.windows:
            state = "used" if w.used else f"not used: {w.why}"
            where = f"{Path(w.source).name} " if several else ""
            out.print(f"window {where}{w.start:.3g}-{w.end:.3g} s, {w.regime or 'record'}: "
                      f"{state}", highlight=False, markup=False, soft_wrap=True)
    if res.identifiability is not None:
        for k, why in res.identifiability.reasons.items():
            out.print(f"{k} not identifiable: {why}", highlight=False, markup=False,
                      soft_wrap=True)
    for note in res.notes:
        out.print(f"note: {note}", highlight=False, markup=False)


@simulate_app.command("actuator")
def simulate_actuator_cmd(
    out_path: Annotated[Path, typer.Option("--out", help="Output file (.csv or .parquet).")],
    fault: Annotated[Optional[list[str]], typer.Option(help="Parameter fault, e.g. R=+40%, D=*7, L=+0.25mH (repeatable).")] = None,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    params: Annotated[Optional[Path], typer.Option(help="TOML file overriding the rig parameters.")] = None,
    linear: Annotated[bool, typer.Option(help="Switch every nonlinear effect off.")] = False,
) -> None:
    """Simulate one closed-loop built-in test of the actuator rig."""
    from condmon.io.records import write_record
    from condmon.models.registry import get_model
    from condmon.simulate.actuator import load_actuator_rig, simulate_actuator

    rig = load_actuator_rig(params, fault or ())
    rec = simulate_actuator(rig, seed=seed, linear=linear)
    write_record(rec, out_path)
    units = get_model("dc-motor").units
    truth = ", ".join(f"{k}={fmt(v)} {units.get(k, '')}".rstrip()
                      for k, v in rig.physical().items())
    if rig.coulomb_friction:   # a nonlinear effect the six parameters do not show
        truth += f", coulomb_friction={fmt(rig.coulomb_friction)} N m"
    err.print(f"wrote {len(rec)} samples to {out_path} ({truth})", markup=False)


@app.command("demo")
def demo_cmd(
    out_dir: Annotated[Path, typer.Option("--out", help="Folder for the demo database and report.")] = Path("condmon-demo"),
    config: Annotated[Optional[Path], typer.Option(help="Experiments file (default: the shipped demo.toml).")] = None,
) -> None:
    """Reproduce the reference experiments on the simulated test-bed and write a report."""
    from condmon.workflows.demo import run_demo

    with progress() as prog:
        task = prog.add_task("simulating and checking tests", total=None)

        def tick(done: int, total: int, label: str) -> None:
            prog.update(task, completed=done, total=total, description=label)

        res = run_demo(out_dir, config, tick)
    out.print("[bold]Reference experiments on the simulated test-bed[/] "
              "(paper-level noise, nonlinear effects on)")
    for unit in dict.fromkeys(c.unit for c in res.checks):
        rows = [c for c in res.checks if c.unit == unit]
        table = Table(title=f"{unit}: {rows[0].title}", title_justify="left")
        for col in ("test", "status", "diagnosis (degree)", "R Δ%", "L Δ%", "D Δ%"):
            table.add_column(col, justify="right" if "%" in col else "left",
                             no_wrap=col != "diagnosis (degree)")
        for c in rows:
            r = c.result
            d = r.diagnosis
            table.add_row(c.label, status_text(r.status),
                          d.summary.split(": ", 1)[1] if d is not None else str(r.estimate.reason),
                          *(f"{r.percent_change.get(p, float('nan')):+.0f}" for p in ("R", "L", "D")))
        out.print(table)
    if res.isolations:
        table = Table(title="HST: detection, steady-state estimate and multi-model isolation",
                      title_justify="left")
        from condmon.models.registry import load_plant_model

        plant = load_plant_model("hst")
        for col in ("fault", "detected", "isolated", "estimate (true)"):
            table.add_column(col)
        for iso in res.isolations:
            found, est = iso.result, iso.result.estimates.get(iso.parameter)
            unit = next((q.unit for q in plant.parameters if q.name == iso.parameter), "")
            table.add_row(iso.fault, "no" if found.detection_time is None
                          else f"{found.detection_time:.2f} s", ", ".join(found.isolated) or "—",
                          "—" if est is None else
                          f"{fmt(est.value)} ({fmt(iso.true_value)}) {unit}".rstrip())
        out.print(table)
    out.print(f"history: {res.database}")
    out.print(f"report:  {res.report}  (open it in a browser)")


def _remove_if_empty(path: Path) -> None:
    """Remove a SQLite history that holds no unit (made by a call that failed)."""
    from condmon.store.db import open_store

    try:
        with open_store(str(path), create=False) as store:
            empty = not store.units()
    except CondmonError:
        return
    if empty:
        for suffix in ("", "-wal", "-shm", "-journal"):
            Path(str(path) + suffix).unlink(missing_ok=True)



@baseline_app.command("add")
def baseline_add_cmd(
    records: Annotated[list[Path], typer.Argument(help="Healthy test records (CSV, Parquet, .mat, TDMS).")],
    unit: UnitOpt,
    db: DbOpt = "condmon.db",
    method: MethodOpt = "sriv",
    gamma: GammaOpt = None,
    excitation: ExcOpt = "auto",
    columns: ColOpt = None,
    fit_threshold: FitOpt = DEFAULT_FIT_THRESHOLD,
    model: UnitModelOpt = None,
    route: RouteOpt = None,
    constants: ConstOpt = None,
    date: DateOpt = None,
    sample_rate: RateOpt = None,
    scale: ScaleOpt = None,
    offset: OffsetOpt = None,
    ignore: IgnoreOpt = None,
    meta: MetaOpt = None,
    window: WindowOpt = None,
    group: GroupOpt = None,
) -> None:
    """Estimate healthy tests and store them as the unit's baseline."""
    from condmon.workflows.monitoring import add_baseline_tests
    from condmon.store.db import open_store

    from condmon.io.dates import parse_date
    from condmon.models.registry import get_model
    from condmon.models.regimes import split_key

    opts = options(method, gamma, excitation, columns, fit_threshold, model, route, constants,
                    sample_rate, scale, offset, ignore, meta, window)
    # what can be checked without the records, before a new history file is made
    parse_date(date)
    if model is not None:
        get_model(model)
    missing = [str(r) for r in records if not r.exists()]
    if missing:
        raise CondmonError(f"no such file: {', '.join(missing)}; nothing was stored")
    from condmon.store.engine import database_url, sqlite_path

    path = sqlite_path(database_url(db))
    fresh = path is not None and not path.exists()
    try:
        with open_store(db) as store:
            if len(records) > 1:
                with progress() as prog:
                    task = prog.add_task("estimating", total=len(records))

                    def tick(done: int, total: int, label: str) -> None:
                        prog.update(task, completed=done,
                                    description=Path(label).name or "done")

                    res = add_baseline_tests(store, unit, records, opts, tick, test_date=date,
                                             group=group)
            else:
                res = add_baseline_tests(store, unit, records, opts, test_date=date,
                                         group=group)
    except CondmonError:
        if fresh and path is not None:  # a history made for this call, still empty
            _remove_if_empty(path)
        raise
    for t in res.tests:
        if t.refused:
            err.print(f"refused {t.source}: {t.reason}", highlight=False, markup=False, soft_wrap=True)
        elif t.duplicate:
            err.print(f"skipped {t.source}: already in the history (test #{t.test_id})",
                      highlight=False, markup=False)
        elif not t.accepted:
            err.print(f"stored {t.source} as rejected: {t.reason}", highlight=False, markup=False)
        if t.warning:
            err.print(f"warning: {t.source}: {t.warning}", highlight=False, markup=False,
                      soft_wrap=True)
    n_new = sum(1 for t in res.tests if not (t.duplicate or t.refused))
    out.print(f"{n_new} test(s) added to {unit!r}; {res.message}", markup=False)
    for note in res.notes:
        out.print(f"note: {note}", highlight=False, markup=False, soft_wrap=True)
    if res.baseline is not None:
        table = Table(title=escape(f"Baseline of {unit} (N = {res.baseline.n})"))
        for col in ("parameter", "mean", "std", "unit", "std %"):
            table.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
        for p, m, sd in zip(res.baseline.parameters, res.baseline.mean, res.baseline.std):
            table.add_row(escape(p), fmt(m), fmt(sd), escape(res.units.get(split_key(p)[0], "")),
                          f"{100 * sd / abs(m):.2f}")
        out.print(table)
    print_flags((*res.info, *res.flags), unit)
    offered = [t for t in res.tests if not t.duplicate]
    if offered and not any(t.accepted and not t.refused for t in offered):
        err.print(f"no test accepted: 0 of {len(offered)} record(s) could join the baseline "
                  "(see why above)", highlight=False, markup=False, soft_wrap=True)
        raise typer.Exit(1)


register_check_command(app)
register_rules_commands(app)



register_view_commands(app)  # after the commands above: their order in --help


def _show_warning(message: Warning | str, category: type[Warning], filename: str,
                  lineno: int, file: Any = None, line: str | None = None) -> None:
    err.print(f"warning: {message}", highlight=False, markup=False)
    warned.append(str(message))


@functools.lru_cache(maxsize=1)
def _command() -> Any:
    """The click command of :data:`app`, built once per process: typer builds it
    anew at every ``app()`` call (every command's options read from its
    annotations, 65 ms), which a notebook or a test calling :func:`main` many
    times would pay each time."""
    import typer.main

    return typer.main.get_command(app)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``condmon`` console script; returns the exit status."""
    warnings.showwarning = _show_warning
    warned.clear()
    fit_to_output()
    try:
        from condmon._threads import small_blas

        with small_blas():  # small matrices: one BLAS thread (CONDMON_BLAS_THREADS)
            rc = _command().main(args=argv, prog_name="condmon", standalone_mode=False)
        return rc if isinstance(rc, int) else 0
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except CondmonError as exc:
        err.print(f"error: {exc}", highlight=False, markup=False, soft_wrap=True)
        return 2
    except OSError as exc:  # an output folder that cannot be made or written, a full disk
        where = exc.filename if exc.filename is not None else ""
        why = exc.strerror or str(exc)
        err.print(f"error: {where}{': ' if where else ''}{why}", highlight=False, markup=False,
                  soft_wrap=True)
        return 2
    except MemoryError:
        err.print("error: out of memory: the record is too large for this machine; lower "
                  "[records] max_samples of condmon/data/limits.toml (or CONDMON_MAX_SAMPLES)",
                  highlight=False, markup=False, soft_wrap=True)
        return 2
    except KeyboardInterrupt:
        err.print("interrupted")
        return 130
    except Exception as exc:  # noqa: BLE001 - the command line's own errors, else re-raised
        return _usage_error(exc)


def _usage_error(exc: Exception) -> int:
    """A usage error of the command line (a bad option value, a missing
    argument, an unknown command) in one line, exit status 2; ``condmon``
    alone prints its help. typer raises click's errors (its own copy of click
    in recent versions), so they are known by their class names; anything
    else is not a usage error and is raised again."""
    names = {c.__name__ for c in type(exc).__mro__}
    if "NoArgsIsHelpError" in names and getattr(exc, "ctx", None) is not None:
        out.print(exc.ctx.get_help(), markup=False, highlight=False)  # type: ignore[attr-defined]
        return 2
    if "Abort" in names:
        err.print("interrupted")
        return 130
    if "ClickException" not in names:
        raise exc
    ctx = getattr(exc, "ctx", None)
    if "NoSuchOption" in names and getattr(exc, "option_name", None) == "--model" and \
            ctx is not None and any(p.name == "model" and not p.param_type_name == "option"
                                    for p in ctx.command.params):
        # estimate and check take --model; isolate and simulate plant take it first
        usage = " ".join(p.name.upper() for p in ctx.command.params
                         if p.param_type_name == "argument")
        err.print(f"error: {ctx.command_path} takes the model as its first argument, not "
                  f"--model: {ctx.command_path} {usage}", highlight=False, markup=False,
                  soft_wrap=True)
        return 2
    where = f" (`{ctx.command_path} --help` lists the options)" if ctx is not None and \
        "UsageError" in names else ""
    err.print(f"error: {exc.format_message()}{where}", highlight=False,  # type: ignore[attr-defined]
              markup=False, soft_wrap=True)
    return int(getattr(exc, "exit_code", 2))


def run() -> None:
    """Console-script wrapper: exit with :func:`main`'s status."""
    sys.exit(main())


if __name__ == "__main__":  # pragma: no cover
    run()
