"""``condmon validate`` and ``condmon simulate record``: a model run on a recorded input."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.markup import escape
from rich.table import Table

from condmon.cli._console import err, fmt, out, write_json
from condmon.cli.estimation import (
    IgnoreOpt, ModelOpt, OffsetOpt, RateOpt, ScaleOpt, options,
)

__all__ = ["register"]

ParamsOpt = Annotated[Optional[Path], typer.Option("--params", help="Parameters: the JSON of condmon estimate --json (its parameters, constants and initial states).")]
SetOpt = Annotated[Optional[str], typer.Option("--set", help="Parameter values NAME=VALUE,... over the file's and the declaration's [SI].")]
InitialOpt = Annotated[str, typer.Option("--initial", help="Initial states: 'estimated' (the parameter file's; a state it lacks from the first sample, else declared), 'first-sample' (each state a sensor gives back from its first reading), 'fit' (the states that best simulate this record, the parameters fixed: MATLAB compare's default), or NAME=VALUE,... per state.")]
ColumnsOpt = Annotated[Optional[str], typer.Option(help="Column mapping CANONICAL=FILE_COLUMN,... e.g. u=uVal,y=yVal.")]


def register(app: typer.Typer, simulate_app: typer.Typer) -> None:
    """Add ``validate`` and ``simulate record`` to the application."""

    @app.command("validate")
    def validate_cmd(
        record: Annotated[Path, typer.Argument(help="Record with the model's inputs and sensors (not the one the parameters were estimated from).")],
        model: ModelOpt = "dc-motor",
        params: ParamsOpt = None,
        set_values: SetOpt = None,
        initial: InitialOpt = "estimated",
        columns: ColumnsOpt = None,
        sample_rate: RateOpt = None,
        scale: ScaleOpt = None,
        offset: OffsetOpt = None,
        ignore: IgnoreOpt = None,
        figure: Annotated[Optional[Path], typer.Option(help="Measured-against-model figure (PNG); default beside the parameter file, PARAMS-RECORD.validation.png (without one, beside the record: RECORD.validation.png).")] = None,
        as_json: Annotated[bool, typer.Option("--json", help="Print the figures as JSON.")] = False,
    ) -> None:
        """Simulate the model on a record's inputs and compare with its outputs: RMSE and fit % per output (MATLAB's compare)."""
        from condmon.workflows.validation import describe_initial, validate_file

        opts = options("sriv", None, "auto", columns, 0.0, model, None, None, sample_rate,
                       scale, offset, ignore)
        # beside the parameter file, named after it and the record: one parameter file
        # validated on several records keeps a figure for each
        path = figure or (params.with_name(f"{params.stem}-{record.stem}.validation.png")
                          if params is not None else
                          record.with_name(f"{record.stem}.validation.png"))
        c, written = validate_file(record, model, params=params, set_values=set_values,
                                   initial=initial, options=opts, figure=path)
        if as_json:
            write_json({**c.to_dict(), "figure": str(written) if written else None})
            return
        table = Table(title=escape(f"{record} — {c.model}, simulated on the record's inputs"))
        for col in ("output", "RMSE", "unit", "fit % (NRMSE)"):
            table.add_column(col, justify="left" if col in ("output", "unit") else "right")
        for name in c.outputs:
            table.add_row(escape(name), fmt(c.rmse[name]), escape(c.units.get(name, "")),
                          f"{c.fit_percent[name]:.1f}")
        out.print(table)
        out.print(f"initial states: {describe_initial(c.initial)}; {c.substeps} Runge-Kutta "
                  "step(s) per sample", highlight=False, markup=False, soft_wrap=True)
        for note in c.notes:
            out.print(f"note: {note}", highlight=False, markup=False, soft_wrap=True)
        err.print(f"wrote the figure to {written}", highlight=False, markup=False)

    @simulate_app.command("record")
    def simulate_record_cmd(
        record: Annotated[Path, typer.Argument(help="Record with the model's inputs; its sensor columns, when it has them, are written beside the simulated ones and compared.")],
        out_path: Annotated[Path, typer.Option("--out", help="Output file (.csv or .parquet): t, the inputs, SENSOR_sim, the measured SENSOR, and STATE_sim for each state.")],
        model: ModelOpt = "dc-motor",
        params: ParamsOpt = None,
        set_values: SetOpt = None,
        initial: InitialOpt = "estimated",
        columns: ColumnsOpt = None,
        sample_rate: RateOpt = None,
        scale: ScaleOpt = None,
        offset: OffsetOpt = None,
        ignore: IgnoreOpt = None,
    ) -> None:
        """Simulate a declared model on a recorded input, with given or estimated parameters."""
        from condmon.workflows.validation import describe_initial, simulate_file

        opts = options("sriv", None, "auto", columns, 0.0, model, None, None, sample_rate,
                       scale, offset, ignore)
        c = simulate_file(record, model, out_path, params=params, set_values=set_values,
                          initial=initial, options=opts)
        rmse = ", ".join(f"{k} {fmt(v)} {c.units.get(k, '')}".rstrip() for k, v in c.rmse.items())
        against = (f"RMSE against the record: {rmse}" if c.measured is not None else
                   "the record has no sensor columns: simulated, not compared")
        err.print(f"wrote {len(c.t)} samples to {out_path} (model {c.model}; initial states "
                  f"{describe_initial(c.initial)}; {against})",
                  highlight=False, markup=False, soft_wrap=True)
        for note in c.notes:
            err.print(f"note: {note}", highlight=False, markup=False, soft_wrap=True)
