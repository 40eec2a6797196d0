"""``condmon`` command line. Every command calls one library function and prints.

Errors a user can cause (bad file, bad column, bad option value) print one line
on stderr and exit with status 2; no traceback.
"""

from __future__ import annotations

import math
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Optional

import typer
from rich.markup import escape
from rich.table import Table

from condmon.cli._console import err, fmt, out, progress, status_text, write_json
from condmon.cli.fleet import register as register_fleet_commands
from condmon.cli.forecast import register as register_forecast_command
from condmon.cli.history import print_flags
from condmon.cli.history import register as register_history_commands
from condmon.cli.plant import register as register_plant_commands
from condmon.cli.serve import register as register_serve_command
from condmon.cli.views import register as register_view_commands
from condmon.cli.watch import register as register_watch_command
from condmon.errors import CondmonError
from condmon.identify.defaults import DEFAULT_FIT_THRESHOLD, list_estimators

if TYPE_CHECKING:
    from condmon.workflows.records import EstimateOptions

app = typer.Typer(add_completion=False, no_args_is_help=True, rich_markup_mode="markdown",
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



ModelOpt = Annotated[str, typer.Option(help="Machine model: a shipped name (dc-motor) or a declaration file (.toml).")]
UnitModelOpt = Annotated[Optional[str], typer.Option("--model", help="Machine model (name or declaration file); default: the unit's, else dc-motor.")]
RouteOpt = Annotated[Optional[str], typer.Option(help="Estimation route: auto, linear, inverse or oe (default: the declaration's).")]
ConstOpt = Annotated[Optional[str], typer.Option(help="Known constants overriding the declaration's, NAME=VALUE,... e.g. gamma=0.9; naming an unknown fixes it for the run (reported, not estimated).")]
RateOpt = Annotated[Optional[float], typer.Option("--sample-rate", help="Samples per second when t counts samples or is absent [Hz] (over the model's [record] table).")]
ScaleOpt = Annotated[Optional[str], typer.Option("--scale", help="Scale per column NAME=FACTOR,...: value = raw*FACTOR + OFFSET (raw counts to SI units).")]
OffsetOpt = Annotated[Optional[str], typer.Option("--offset", help="Offset per column NAME=VALUE,... [SI], added after the scale.")]
IgnoreOpt = Annotated[Optional[str], typer.Option("--ignore", help="File columns to leave out, comma-separated (a logger's own columns).")]
GroupOpt = Annotated[Optional[str], typer.Option("--group", help="Put the unit in this group of peer units (a unit without a baseline of its own is checked against its group's).")]
MetaOpt = Annotated[Optional[str], typer.Option("--meta", help="The record's metadata KEY=VALUE,... that regimes may name, e.g. load=ball.")]
WindowOpt = Annotated[Optional[str], typer.Option("--window", help="Only this span of the record, START:END in seconds (either side may be empty).")]


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
    opts = _options(method, gamma, excitation, columns, fit_threshold, model, route, constants,
                    sample_rate, scale, offset, ignore, meta, window)
    if len(records) == 1:
        res, _ = opts.run(records[0])
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
        _print_estimate(part, record)


_HOW = {"inverse": "inverse model", "oe": "output error", "steady": "steady balances"}


def _print_estimate(res: Any, record: str) -> None:
    """One regime's estimate as a table, its fit, windows and notes."""
    how = (("closed-loop instruments" if res.closed_loop_instruments else "direct approach")
           if res.route == "linear" else _HOW.get(res.route, res.route))
    regime = f", regime {res.regime}" if res.regime else ""
    title = escape(f"{record} — {res.model}, {res.method.upper()}, {how}{regime}")
    if any(math.isfinite(v) for v in res.parameters.values()):
        table = Table(title=title)
        for col in ("parameter", "value", "std error", "unit", "from"):
            table.add_column(col, justify="right" if col not in ("parameter", "from") else "left")
        for k, v in res.parameters.items():
            source = ("record" if k in res.identified else
                      f"held ({res.held[k]})" if k in res.held else "—")
            table.add_row(escape(k), fmt(v),
                          fmt(res.std_errors[k]) if k in res.identified else "—",
                          escape(res.units[k]), source)
        out.print(table)
    else:
        out.print(title, highlight=False)
    fits = ", ".join(f"{k} {v:.1f} %" for k, v in res.fit.fits_percent.items())
    verdict = (f"[green]accepted[/green] (threshold {res.fit.threshold:g} %)" if res.accepted
               else f"[red]rejected[/red]: {escape(str(res.reason))}")
    out.print(f"fit {res.fit_percent:.1f} % ({fits}) — {verdict}" if fits else verdict)
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
        for col in ("fault", "detected", "isolated", "estimate (true)"):
            table.add_column(col)
        for iso in res.isolations:
            found, est = iso.result, iso.result.estimates.get(iso.parameter)
            table.add_row(iso.fault, "no" if found.detection_time is None
                          else f"{found.detection_time:.2f} s", ", ".join(found.isolated) or "—",
                          "—" if est is None else f"{fmt(est.value)} ({fmt(iso.true_value)})")
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


def _options(method: str, gamma: float | None, excitation: str, columns: str | None,
             fit_threshold: float, model: str | None = None, route: str | None = None,
             constants: str | None = None, sample_rate: float | None = None,
             scale: str | None = None, offset: str | None = None, ignore: str | None = None,
             meta: str | None = None, window: str | None = None) -> EstimateOptions:
    from condmon.identify.windows import parse_window
    from condmon.io.records import parse_column_map
    from condmon.io.rig import settings_from_options
    from condmon.workflows.records import EstimateOptions

    if method not in list_estimators():
        raise CondmonError(f"unknown --method {method!r}; allowed: {', '.join(list_estimators())}")
    exc: str | tuple[str, ...] | None
    if excitation == "auto":
        exc = "auto"
    elif excitation.lower() == "none":
        exc = None
    else:
        exc = tuple(c.strip() for c in excitation.split(",") if c.strip())
    consts: dict[str, float] = {}
    for key, value in parse_column_map(constants).items():
        try:
            consts[key] = float(value)
        except ValueError:
            raise CondmonError(f"--constants: {key}={value!r} is not a number") from None
    record = settings_from_options(sample_rate=sample_rate, scale=scale, offset=offset,
                                   ignore=ignore)
    return EstimateOptions(model, method, gamma, exc, fit_threshold,
                           parse_column_map(columns) or None, route, consts or None,
                           None if record.empty else record, parse_metadata(meta),
                           parse_window(window))


def parse_metadata(text: str | None) -> dict[str, Any] | None:
    """``--meta load=ball,temp=40`` -> ``{"load": "ball", "temp": 40.0}`` (numbers as numbers)."""
    from condmon.io.rig import parse_assignments

    out: dict[str, Any] = {}
    for key, value in parse_assignments(text, "--meta").items():
        try:
            out[key] = float(value)
        except ValueError:
            out[key] = value
    return out or None


DateOpt = Annotated[Optional[str], typer.Option(help="When the test was run, ISO 8601 (2026-03-01 or 2026-03-01T14:30, UTC unless a zone is given); default: the record's own date, if it has one.")]
DbOpt = Annotated[str, typer.Option("--db", help="History database: a SQLite file or a postgresql:// URL.")]
UnitOpt = Annotated[str, typer.Option("--unit", help="Unit (machine) name.")]
MethodOpt = Annotated[str, typer.Option(help=f"Estimator: {', '.join(list_estimators())}.")]
GammaOpt = Annotated[Optional[float], typer.Option(help="Ke/Kt of the motor (default 0.95).")]
ExcOpt = Annotated[str, typer.Option(help="Excitation columns ('auto', 'none' or a,b).")]
ColOpt = Annotated[Optional[str], typer.Option(help="Column mapping CANONICAL=FILE_COLUMN,...")]
FitOpt = Annotated[float, typer.Option(help="Reject below this percentage fit [%].")]


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

    opts = _options(method, gamma, excitation, columns, fit_threshold, model, route, constants,
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
    print_flags(res.flags, unit)
    offered = [t for t in res.tests if not t.duplicate]
    if offered and not any(t.accepted and not t.refused for t in offered):
        err.print(f"no test accepted: 0 of {len(offered)} record(s) could join the baseline "
                  "(see why above)", highlight=False, markup=False, soft_wrap=True)
        raise typer.Exit(1)


@app.command("check")
def check_cmd(
    record: Annotated[Path, typer.Argument(help="Test record (CSV, Parquet, .mat, TDMS).")],
    unit: UnitOpt,
    db: DbOpt = "condmon.db",
    method: MethodOpt = "sriv",
    gamma: GammaOpt = None,
    excitation: ExcOpt = "auto",
    columns: ColOpt = None,
    fit_threshold: FitOpt = DEFAULT_FIT_THRESHOLD,
    rules: Annotated[Optional[Path], typer.Option(help="Rule base TOML (default: the shipped one).")] = None,
    monitor: Annotated[Optional[Path], typer.Option(help="Monitor breakpoints TOML (default: the shipped one).")] = None,
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
    against: Annotated[Optional[str], typer.Option("--against", help="Compare with another unit's or a group's baseline (UNIT, GROUP, unit:NAME or group:NAME) instead of the unit's own.")] = None,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="Estimate and diagnose, store nothing.")] = False,
    alpha: Annotated[Optional[float], typer.Option(help="False-alarm probability of the statistical change test, in (0, 0.5) (default: the monitor file's [statistics] alpha, 0.01).")] = None,
    drift_alpha: Annotated[Optional[float], typer.Option(help="False-alarm probability of the drift test at each check, in (0, 0.5) (default: [statistics] drift_alpha, 0.01).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
) -> None:
    """Check one test against the unit's baseline: go / advisory / no-go and faults.

    Beside the fuzzy status, a calibrated test of the change against the
    baseline's scatter and of a drift over the checks since the baseline, each
    alarming with the stated false-alarm probability (--alpha, --drift-alpha);
    they never change the status."""
    from condmon.diagnose.rules import load_rules
    from condmon.models.regimes import split_key
    from condmon.monitor.fuzzy import load_monitor_config
    from condmon.workflows.checks import check_test
    from condmon.store.db import open_store

    opts = _options(method, gamma, excitation, columns, fit_threshold, model, route, constants,
                    sample_rate, scale, offset, ignore, meta, window)
    cfg = load_monitor_config(monitor) if monitor is not None else None
    rb = load_rules(rules) if rules is not None else None
    with open_store(db, create=False) as store:
        res = check_test(store, unit, record, opts, cfg, rb, dry_run=dry_run, test_date=date,
                         against=against, group=group, alpha=alpha,
                         drift_alpha=drift_alpha)
    if as_json:
        write_json(res.to_dict())
        return
    if dry_run:
        err.print("dry run: nothing was stored", highlight=False)
    if res.warning:
        err.print(f"warning: {record}: {res.warning}", highlight=False, markup=False,
                  soft_wrap=True)
    print_flags(res.baseline_flags, unit)
    fit = res.estimate.fit_percent
    out.print(f"{escape(unit)} — {escape(str(record))}: {status_text(res.status)}  "
              + (f"(fit {fit:.1f} %" if math.isfinite(fit) else "(no fit")
              + (f", regime {escape(res.estimate.regime_label)}"
                 if res.estimate.regime_label else "")
              + (f", against {escape(res.against)}" if res.against != "unit" else "")
              + (f", test #{res.test_id})" if res.test_id >= 0 else ", not stored)"))
    if res.diagnosis is None:
        out.print(f"rejected: {res.estimate.reason}; the test is stored but changes no trend. "
                  "Retest.", markup=False)
        _print_forecast(res.forecast)
        return
    table = Table()
    for col in ("parameter", "value", "unit", "change %", "SymH", "SymL"):
        table.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    stored = res.estimate.stored_values()
    units = res.estimate.units
    for p, change in res.percent_change.items():
        sym = res.symptoms.get(p, {"high": 0.0, "low": 0.0})
        table.add_row(escape(p), fmt(stored[p][0]) if p in stored else "—",
                      escape(units.get(split_key(p)[0], "")), f"{change:+.1f}",
                      f"{sym['high']:.2f}", f"{sym['low']:.2f}")
    out.print(table)
    held = {k: v for part in res.estimate.regimes for k, v in part.held.items()}
    if held:
        out.print("held (not identified by this record): " + ", ".join(
            f"{k} ({v})" for k, v in held.items()), highlight=False, markup=False,
            soft_wrap=True)
    if res.note:
        out.print(f"note: {res.note}", highlight=False, markup=False, soft_wrap=True)
    for note in res.estimate.notes:
        if note.startswith("possible structure mismatch"):
            out.print(f"note: {note}", highlight=False, markup=False)
    if res.diagnosis.no_fault:
        out.print("no fault")
    for f in res.diagnosis.faults:
        level = ("major: at no-go level" if f.severity == "major" else
                 "minor: at advisory level" + (", a major fault if it grows"
                                               if f.rule_severity == "major" else ""))
        out.print(f"[bold]{escape(f.name)}[/] — degree {f.degree:.2f} ({level}): "
                  f"{escape(f.advice)}")
    if res.diagnosis.watch:
        out.print("to watch (below advisory level, not faults): " + ", ".join(
            f"{f.name} ({f.degree:.2f})" for f in res.diagnosis.watch), highlight=False,
            markup=False, soft_wrap=True)
    if res.statistics is not None:
        out.print(res.statistics.describe(res.status), highlight=False, markup=False,
                  soft_wrap=True)
    _print_forecast(res.forecast)


def _print_forecast(ahead: dict[str, Any]) -> None:
    """The unit's earliest forecast to no-go after a check (none on a dry run)."""
    from condmon.monitor.unit_forecast import remaining_text

    f = ahead.get("forecast")
    if f:
        out.print(f"forecast: {f['parameter']} no-go in {remaining_text(f)}"
                  + (f", about {f['date'][:10]}" if f["date"] else "")
                  + (f" ({f['rule']})" if f["rule"] else "")
                  + "; median (90 % interval), `condmon forecast` for more", highlight=False,
                  markup=False, soft_wrap=True)
    elif ahead.get("forecast_reason"):
        out.print(f"forecast: none, {ahead['forecast_reason']}", highlight=False, markup=False,
                  soft_wrap=True)


register_view_commands(app)  # after the commands above: their order in --help


def _show_warning(message: Warning | str, category: type[Warning], filename: str,
                  lineno: int, file: Any = None, line: str | None = None) -> None:
    err.print(f"warning: {message}", highlight=False, markup=False)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``condmon`` console script; returns the exit status."""
    warnings.showwarning = _show_warning
    try:
        from condmon._threads import small_blas

        with small_blas():  # small matrices: one BLAS thread (CONDMON_BLAS_THREADS)
            app(args=argv, prog_name="condmon")  # usage errors exit 2 through SystemExit
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
    return 0


def run() -> None:
    """Console-script wrapper: exit with :func:`main`'s status."""
    sys.exit(main())


if __name__ == "__main__":  # pragma: no cover
    run()
