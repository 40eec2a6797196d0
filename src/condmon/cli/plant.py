"""Commands for declared plant models: ``simulate hst`` and ``isolate``."""

from __future__ import annotations

import math

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Optional

import typer
from rich import box
from rich.markup import escape
from rich.table import Table

from condmon.cli._console import err, fmt, out, progress, write_json
from condmon.cli._options import greedy_command
from condmon.cli.estimation import IgnoreOpt, OffsetOpt, RateOpt, ScaleOpt, options
from condmon.report.tables import estimate_text, percent_text

if TYPE_CHECKING:
    from condmon.diagnose.isolation import IsolationResult

__all__ = ["register"]

ModelArg = Annotated[str, typer.Argument(help="Machine model: a registered name (hst, dc-motor, ...) or a declaration file (.toml).")]
ParamsOpt = Annotated[Optional[Path], typer.Option(help="TOML file of parameter values overriding the declaration's.")]
OutOpt = Annotated[Path, typer.Option("--out", help="Output file (.csv or .parquet).")]
FaultOpt = Annotated[Optional[list[str]], typer.Option(help="Parameter fault, e.g. Rv=+40%@10s, Dm=-25%@10s, Tld=+20@10s (repeatable).")]
SeedOpt = Annotated[int, typer.Option(help="Random seed of the sensor noise.")]
DurationOpt = Annotated[Optional[float], typer.Option(help="Record length [s] (default: the declared test's).")]


def register(app: typer.Typer, simulate_app: typer.Typer) -> None:
    """Add the plant-model commands to the ``condmon`` application."""

    @simulate_app.command("hst")
    def simulate_hst_cmd(out_path: OutOpt, fault: FaultOpt = None, params: ParamsOpt = None,
                         seed: SeedOpt = 0, duration: DurationOpt = None) -> None:
        """Simulate the hydrostatic transmission's test (columns t, Ps, omega_m, omega_p)."""
        _simulate("hst", out_path, fault, params, seed, duration)

    @simulate_app.command("plant")
    def simulate_plant_cmd(model: ModelArg, out_path: OutOpt, fault: FaultOpt = None,
                           params: ParamsOpt = None, seed: SeedOpt = 0,
                           duration: DurationOpt = None,
                           si: Annotated[bool, typer.Option("--si", help="Write the model's columns in SI units, not as the rig writes its files (the declaration's [record]).")] = False) -> None:
        """Simulate the built-in test of any declared plant model (a .toml file).

        A declaration with a [record] table gets a file as its rig writes it
        (file column names, raw units), which its own estimate reads back."""
        _simulate(model, out_path, fault, params, seed, duration, si)

    @app.command("isolate", cls=greedy_command("--healthy"))
    def isolate_cmd(
        model: ModelArg,
        record: Annotated[Path, typer.Argument(help="Record (CSV, Parquet, .mat, TDMS) with t and the sensor columns.")],
        params: ParamsOpt = None,
        columns: Annotated[Optional[str], typer.Option(help="Column mapping CANONICAL=FILE_COLUMN,... e.g. Ps=p_sys,omega_m=speed.")] = None,
        healthy: Annotated[Optional[list[Path]], typer.Option(help="Healthy records to learn the residuals' normalisation from (--healthy h1.csv h2.csv, or h*.csv; default: the sensors' declared noise).")] = None,
        residuals: Annotated[str, typer.Option(help="Residual set: simulation (one per sensor, the model from its inputs) or structured (every MSO computable by integration).")] = "simulation",
        settings: Annotated[Optional[Path], typer.Option(help="Detection/estimation/isolation settings TOML (default: the shipped isolation.toml).")] = None,
        workers: Annotated[Optional[int], typer.Option(help="Processes for the suspects' models (1: one after the other).", min=1)] = None,
        plots: Annotated[Optional[Path], typer.Option(help="Folder for the residual and model-error figures.")] = None,
        unit: Annotated[Optional[str], typer.Option("--unit", help="Store the isolation in this unit's history (with --db).")] = None,
        db: Annotated[Optional[str], typer.Option("--db", help="History database for --unit: a SQLite file or a postgresql:// URL (default condmon.db).")] = None,
        date: Annotated[Optional[str], typer.Option(help="When the test was run, ISO 8601 (UTC unless a zone is given); default: the record's own date, if any.")] = None,
        sample_rate: RateOpt = None,
        scale: ScaleOpt = None,
        offset: OffsetOpt = None,
        ignore: IgnoreOpt = None,
        as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
    ) -> None:
        """Detect a fault, estimate each suspect at steady state and isolate it by
        parallel multi-model simulation; with --unit, keep it in the unit's history.

        Records are read as `estimate` and `check` read them: the model's
        [record] table (the rig's column names and raw units), then --columns,
        --sample-rate, --scale, --offset and --ignore."""
        from condmon.diagnose.isolation import IsolationSettings, healthy_normalisation, isolate
        from condmon.diagnose.structure import RESIDUAL_KINDS
        from condmon.errors import ConfigError
        from condmon.io.columns import column_matrix
        from condmon.models.registry import load_plant_model
        from condmon.models.registry import recognised_records

        reader = options("sriv", None, "auto", columns, 0.0, model, sample_rate=sample_rate,
                         scale=scale, offset=offset, ignore=ignore)
        if residuals not in RESIDUAL_KINDS:
            raise ConfigError(f"unknown --residuals {residuals!r}; allowed: {', '.join(RESIDUAL_KINDS)}")
        plant = load_plant_model(model, params)
        cfg = IsolationSettings.load(settings)
        rec = reader.read(record)
        if unit is None and (db is not None or date is not None):
            given = "--db" if db is not None else "--date"
            raise ConfigError(f"{given} applies to an isolation stored in a unit's history: "
                              "give --unit NAME too (without it nothing is stored)")
        if unit is not None:
            from condmon.store.base import check_name
            from condmon.io.dates import parse_date

            check_name(unit)
            parse_date(date)  # a bad date is refused before the long run
        norm = None
        with progress() as prog:
            if healthy:
                task = prog.add_task("learning the normalisation", total=None)
                norm = healthy_normalisation(plant, [reader.read(h) for h in healthy],
                                             residuals, cfg.detection,  # type: ignore[arg-type]
                                             record=cfg.record, limits=cfg.simulation,
                                             sources=[str(h) for h in healthy])
                prog.update(task, visible=False)
            task = prog.add_task("isolating", total=4)

            def tick(done: int, total: int, label: str) -> None:
                prog.update(task, completed=done, total=total, description=label)

            with recognised_records(model):
                res = isolate(rec, plant, normalisation=norm, kind=residuals,  # type: ignore[arg-type]
                              settings=cfg, workers=workers, progress=tick, source=str(record))
        if plots is not None:
            from condmon.report.isolation_figures import write_isolation_figures

            measured = column_matrix(rec, plant.sensor_names)
            files = write_isolation_figures(res, plant, measured, plots)
            err.print(f"wrote {', '.join(str(f) for f in files)}", highlight=False)
        kept = None
        if unit is not None:
            from condmon.store.db import open_store
            from condmon.store.engine import redact
            from condmon.workflows.isolation import store_isolation

            with open_store(db or "condmon.db") as store:
                kept = store_isolation(store, unit, res, rec, record, model, date)
            if kept.warning:
                err.print(f"warning: {record}: {kept.warning}", highlight=False, markup=False,
                          soft_wrap=True)
        if as_json:
            doc = res.to_dict()
            if kept is not None:
                doc.update(unit=kept.unit, isolation_id=kept.isolation_id,
                           stored=not kept.duplicate, warning=kept.warning)
            write_json(doc)
            return
        _print_isolation(res)
        if kept is not None:
            what = ("already in the history of" if kept.duplicate else "stored in the history of")
            out.print(f"isolation i{kept.isolation_id} {what} {kept.unit!r} ({redact(db or 'condmon.db')})",
                      highlight=False, markup=False)


def _simulate(model: str, out_path: Path, fault: list[str] | None, params: Path | None,
              seed: int, duration: float | None, si: bool = False) -> None:
    from condmon.io.records import write_record
    from condmon.io.rig import rig_layout
    from condmon.models.registry import load_plant_model
    from condmon.models.registry import get_model
    from condmon.simulate.plant import parameter_steps, simulate_plant

    plant = load_plant_model(model, params)
    steps = parameter_steps(plant, fault or ())
    rec = simulate_plant(plant, fault or (), seed=seed, duration=duration)
    rig = None if si else get_model(model).record
    if rig is not None and not rig.empty:
        rec = rig_layout(rec, rig)
    write_record(rec, out_path)
    units = {p.name: p.unit for p in plant.parameters}
    faults = ", ".join(f"{s.name}={fmt(s.value)} {units.get(s.name, '')} at {s.at:g} s"
                       .replace("  at", " at") for s in steps) or "none"
    layout = (f"; written as the rig writes it ({', '.join(map(str, rec.columns))}, its "
              "[record] settings; --si for model columns in SI units)"
              if rig is not None and not rig.empty else "")
    err.print(f"wrote {len(rec)} samples to {out_path} (model {plant.name}, faults: {faults})"
              + layout, highlight=False, markup=False)


def _print_isolation(res: IsolationResult) -> None:
    out.print(f"[bold]{res.model}[/]: residuals normalised from {res.normalisation.source}")
    out.print(res.fsm.table(), highlight=False)
    for note in res.notes:
        out.print(f"note: {note}", highlight=False, markup=False)
    if not res.detected:
        if res.decided:
            wide = sum(n.startswith("the healthy records' residual") for n in res.notes)
            out.print("[green]no fault detected[/]" + (
                f" against a reference whose {wide} residual(s) spread well above the "
                "sensors' noise (notes above): a smaller fault would not show"
                if wide else ""), highlight=False)
        else:
            out.print(f"[bold yellow]undecided[/]: {res.reason}", highlight=False)
        return
    out.print(f"detected at {res.detection_time:.2f} s (onset {res.onset_time:.2f} s); "
              f"fired: {', '.join(res.fired_residuals)}; suspects: {', '.join(res.suspects)}",
              highlight=False)
    # 80 columns hold it whole; a narrower terminal folds a cell rather than cut it
    table = Table(title="Suspects: steady-state estimate and model output error",
                  box=box.SIMPLE_HEAD, pad_edge=False, collapse_padding=True)
    for col in ("suspect", "estimate", "nominal", "unit", "change %", "consistency",
                "error [σ]"):
        table.add_column(col, justify="left" if col in ("suspect", "unit") else "right",
                         overflow="fold")
    for p in sorted(res.suspects, key=lambda p: res.errors.get(p, float("inf"))):
        e = res.estimates[p]
        made = not math.isnan(e.value)   # NaN: not estimated (no window, a failed solve)
        change = "" if e.change_percent is None or not made else percent_text(e.change_percent)
        cons = "" if e.consistency is None else f"{e.consistency:.2f}"
        error = f"{res.errors[p]:.2f}" if p in res.errors else "—"
        name = f"[bold]{p}[/]" if p in res.isolated else p
        table.add_row(name, estimate_text(e.value if made else None, e.change_percent, fmt),
                      fmt(e.nominal),
                      escape(res.units.get(p, "")), change,
                      cons,
                      "rejected" if p in res.rejected else error)
    out.print(table)
    for p, why in res.rejected.items():
        out.print(f"rejected {p}: {why}", highlight=False, markup=False)
    color = "red" if len(res.isolated) == 1 and not res.sensor_faults else "yellow"
    out.print(f"[bold {color}]{res.statement}[/]", highlight=False)
