"""``condmon`` command line. Every command calls one library function and prints.

Errors a user can cause (bad file, bad column, bad option value) print one line
on stderr and exit with status 2; no traceback.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path
from typing import Annotated, Any, Optional

import typer
from rich.console import Console
from rich.table import Table

from condmon.errors import CondmonError
from condmon.identify.estimate import estimate, list_estimators
from condmon.identify.fit import DEFAULT_FIT_THRESHOLD
from condmon.io.records import parse_column_map, read_record

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Model-based condition monitoring: estimate, trend, diagnose.")
simulate_app = typer.Typer(no_args_is_help=True, help="Simulate test-beds with known parameters.")
app.add_typer(simulate_app, name="simulate")

out = Console()
err = Console(stderr=True)


def _fmt(value: float) -> str:
    return f"{value:.5g}"


def _write_json(doc: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(doc, indent=2, allow_nan=False) + "\n")


@app.command("estimate")
def estimate_cmd(
    record: Annotated[Path, typer.Argument(help="Test record (.csv or .parquet) with t, V, I, omega.")],
    model: Annotated[str, typer.Option(help="Physical model.")] = "dc-motor",
    method: Annotated[str, typer.Option(help=f"Estimator: {', '.join(list_estimators())}.")] = "sriv",
    gamma: Annotated[Optional[float], typer.Option(help="Ke/Kt of the motor (default from the model's configuration, 0.95).")] = None,
    excitation: Annotated[str, typer.Option(help="Excitation columns for closed-loop instruments, comma-separated; 'auto' uses yd,ud when present; 'none' forces the direct approach.")] = "auto",
    columns: Annotated[Optional[str], typer.Option(help="Column mapping CANONICAL=FILE_COLUMN,... e.g. V=volts,I=amps.")] = None,
    fit_threshold: Annotated[float, typer.Option(help="Reject below this percentage fit [%].")] = DEFAULT_FIT_THRESHOLD,
    as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
) -> None:
    """Estimate the physical parameters of one test record."""
    if method not in list_estimators():
        raise CondmonError(f"unknown --method {method!r}; allowed: {', '.join(list_estimators())}")
    df = read_record(record, parse_column_map(columns))
    exc: str | tuple[str, ...] | None
    if excitation == "auto":
        exc = "auto"
    elif excitation.lower() == "none":
        exc = None
    else:
        exc = tuple(c.strip() for c in excitation.split(",") if c.strip())
    res = estimate(df, model, method=method, gamma=gamma, excitation=exc,
                   fit_threshold=fit_threshold, source=str(record))
    if as_json:
        _write_json(res.to_dict())
        return
    table = Table(title=f"{record} — {res.method.upper()}, "
                        f"{'closed-loop instruments' if res.closed_loop_instruments else 'direct approach'}")
    for col in ("parameter", "value", "std error", "unit"):
        table.add_column(col, justify="right" if col != "parameter" else "left")
    for k, v in res.parameters.items():
        table.add_row(k, _fmt(v), _fmt(res.std_errors[k]), res.units[k])
    out.print(table)
    fits = ", ".join(f"{k} {v:.1f} %" for k, v in res.fit.fits_percent.items())
    verdict = "[green]accepted[/green]" if res.accepted else f"[red]rejected[/red]: {res.reason}"
    out.print(f"fit {res.fit_percent:.1f} % ({fits}) — {verdict} "
              f"(threshold {res.fit.threshold:g} %)")
    for note in res.discrete.notes:
        out.print(f"note: {note}")


@simulate_app.command("actuator")
def simulate_actuator_cmd(
    out_path: Annotated[Path, typer.Option("--out", help="Output file (.csv or .parquet).")],
    fault: Annotated[Optional[list[str]], typer.Option(help="Parameter fault, e.g. R=+40%, D=*7, L=+0.25mH (repeatable).")] = None,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    params: Annotated[Optional[Path], typer.Option(help="TOML file overriding the rig parameters.")] = None,
    linear: Annotated[bool, typer.Option(help="Switch every nonlinear effect off.")] = False,
) -> None:
    """Simulate one closed-loop built-in test of the actuator rig."""
    from condmon.simulate.actuator import load_actuator_rig, simulate_actuator

    rig = load_actuator_rig(params, fault or ())
    rec = simulate_actuator(rig, seed=seed, linear=linear)
    suffix = out_path.suffix.lower()
    if suffix == ".csv":
        rec.to_csv(out_path, index=False)
    elif suffix in (".parquet", ".pq"):
        rec.to_parquet(out_path, index=False)
    else:
        raise CondmonError(f"{out_path}: unknown file type {suffix!r}; allowed: .csv, .parquet")
    truth = ", ".join(f"{k}={_fmt(v)}" for k, v in rig.physical().items())
    err.print(f"wrote {len(rec)} samples to {out_path} ({truth})")


@app.command("demo")
def demo_cmd(
    fault: Annotated[Optional[list[str]], typer.Option(help="Fault of the second test (repeatable).")] = None,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """Simulate a healthy and a faulty test, estimate both, show the changes."""
    from condmon.demo import run_demo

    res = run_demo(tuple(fault) if fault else ("R=+40%",), seed)
    tab = res.table()
    table = Table(title=f"Built-in test, healthy vs faulty ({', '.join(res.faults)})")
    for col in ("", "unit", "true", "healthy", "± σ", "faulty", "Δ est%", "Δ true%"):
        table.add_column(col, justify="left" if col in ("", "unit") else "right",
                         no_wrap=True)
    for k, row in tab.iterrows():
        table.add_row(str(k), row["unit"], f"{row['true_healthy']:.4g}",
                      f"{row['estimated_healthy']:.4g}", f"{row['std_error_healthy']:.2g}",
                      f"{row['estimated_faulty']:.4g}", f"{row['change_estimated_percent']:+.1f}",
                      f"{row['change_true_percent']:+.1f}")
    out.print(table)
    for name, r in (("healthy", res.healthy), ("faulty", res.faulty)):
        out.print(f"{name} test: fit {r.fit_percent:.1f} % "
                  f"({'accepted' if r.accepted else 'rejected'}), {r.method.upper()} "
                  f"with {'closed-loop instruments' if r.closed_loop_instruments else 'direct approach'}")


def _show_warning(message: Warning | str, category: type[Warning], filename: str,
                  lineno: int, file: Any = None, line: str | None = None) -> None:
    err.print(f"warning: {message}", highlight=False)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``condmon`` console script; returns the exit status."""
    warnings.showwarning = _show_warning
    try:
        app(args=argv, prog_name="condmon")  # usage errors exit 2 through SystemExit
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except CondmonError as exc:
        err.print(f"error: {exc}", highlight=False, markup=False)
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
