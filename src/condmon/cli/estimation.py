"""What ``estimate``, ``baseline add`` and ``check`` share: their options and how they become :class:`~condmon.workflows.records.EstimateOptions`."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any, Optional

import typer

from condmon.errors import CondmonError
from condmon.identify.defaults import list_estimators

if TYPE_CHECKING:
    from condmon.workflows.records import EstimateOptions

__all__ = ["options", "parse_metadata", "ModelOpt", "UnitModelOpt", "RouteOpt", "ConstOpt",
           "RateOpt", "ScaleOpt", "OffsetOpt", "IgnoreOpt", "GroupOpt", "MetaOpt", "WindowOpt",
           "DateOpt", "DbOpt", "UnitOpt", "MethodOpt", "GammaOpt", "ExcOpt", "ColOpt", "FitOpt"]

ModelOpt = Annotated[str, typer.Option(help="Machine model: a shipped name (dc-motor) or a declaration file (.toml).")]
UnitModelOpt = Annotated[Optional[str], typer.Option("--model", help="Machine model (name or declaration file); default: the unit's, else dc-motor.")]
RouteOpt = Annotated[Optional[str], typer.Option(help="Estimation route: auto, linear, inverse, oe, steady or simulation (default: the declaration's).")]
ConstOpt = Annotated[Optional[str], typer.Option(help="Known constants overriding the declaration's, NAME=VALUE,... e.g. gamma=0.9; naming an unknown fixes it for the run (reported, not estimated).")]
RateOpt = Annotated[Optional[float], typer.Option("--sample-rate", help="Samples per second when t counts samples or is absent [Hz] (over the model's [record] table).")]
ScaleOpt = Annotated[Optional[str], typer.Option("--scale", help="Scale per column NAME=FACTOR,...: value = raw*FACTOR + OFFSET (raw counts to SI units).")]
OffsetOpt = Annotated[Optional[str], typer.Option("--offset", help="Offset per column NAME=VALUE,... [SI], added after the scale.")]
IgnoreOpt = Annotated[Optional[str], typer.Option("--ignore", help="File columns to leave out, comma-separated (a logger's own columns).")]
GroupOpt = Annotated[Optional[str], typer.Option("--group", help="Put the unit in this group of peer units (a unit without a baseline of its own is checked against its group's).")]
MetaOpt = Annotated[Optional[str], typer.Option("--meta", help="The record's metadata KEY=VALUE,... that regimes may name, e.g. load=ball.")]
WindowOpt = Annotated[Optional[str], typer.Option("--window", help="Only this span of the record, START:END in seconds (either side may be empty).")]

def options(method: str, gamma: float | None, excitation: str, columns: str | None,
             fit_threshold: float, model: str | None = None, route: str | None = None,
             constants: str | None = None, sample_rate: float | None = None,
             scale: str | None = None, offset: str | None = None, ignore: str | None = None,
             meta: str | None = None, window: str | None = None) -> EstimateOptions:
    """The command line's estimation options as :class:`EstimateOptions`
    (every value checked here, once; a bad one is a one-line error)."""
    from condmon.identify.windows import parse_window
    from condmon.io.records import parse_column_map
    from condmon.io.rig import settings_from_options
    from condmon.workflows.records import EstimateOptions

    method = method.strip().lower()  # SRIV, as papers write it, is sriv
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
    mapped = parse_column_map(columns)
    # the columns are in the same layer as the scale and offset: a column the command
    # line maps keeps the command line's own scale (an earlier layer's is dropped)
    record = settings_from_options(columns=mapped if (scale or offset) else None,
                                   sample_rate=sample_rate, scale=scale, offset=offset,
                                   ignore=ignore)
    return EstimateOptions(model, method, gamma, exc, fit_threshold,
                           mapped or None, route, consts or None,
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

