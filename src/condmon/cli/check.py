"""``condmon check``: one test against the unit's baseline (:func:`condmon.workflows.checks.check_test`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any, Optional

import typer
from rich.markup import escape
from rich.table import Table

from condmon.cli._console import err, fmt, out, status_text, write_json
from condmon.cli.estimation import (
    ColOpt, ConstOpt, DateOpt, DbOpt, ExcOpt, FitOpt, GammaOpt, GroupOpt, IgnoreOpt, MetaOpt,
    MethodOpt, OffsetOpt, RateOpt, RouteOpt, ScaleOpt, UnitModelOpt, UnitOpt, WindowOpt, options,
)
from condmon.cli.history import print_flags
from condmon.identify.defaults import DEFAULT_FIT_THRESHOLD

__all__ = ["register", "folded_judgement"]


def folded_judgement(lines: Sequence[str]) -> list[str]:
    """``P: why`` lines that give one reason for several parameters as one
    line naming them all, in their order.

    Example
    -------
    >>> folded_judgement(["R: no spread stated", "L: no spread stated", "J: fitted"])
    ['R, L: no spread stated', 'J: fitted']
    """
    names: dict[str, list[str]] = {}
    for line in lines:
        name, sep, why = line.partition(": ")
        names.setdefault(why if sep else line, []).append(name if sep else "")
    return [f"{', '.join(n)}: {why}" if all(n) else why for why, n in names.items()]


def register(app: typer.Typer) -> None:
    """Add ``check`` to the ``condmon`` application."""

    @app.command("check")
    def check_cmd(
        records: Annotated[list[Path], typer.Argument(help="Test record (CSV, Parquet, .mat, TDMS); several: the records of one test, estimated together (a cycle written as several files, e.g. a stroke each way).")],
        unit: UnitOpt,
        db: DbOpt = "condmon.db",
        method: MethodOpt = "sriv",
        gamma: GammaOpt = None,
        excitation: ExcOpt = "auto",
        columns: ColOpt = None,
        fit_threshold: FitOpt = DEFAULT_FIT_THRESHOLD,
        rules: Annotated[Optional[Path], typer.Option(help="Rule base TOML (default: the model's own, from its declaration's [monitor]; generic rules from the baseline's spread when it has none).")] = None,
        monitor: Annotated[Optional[Path], typer.Option(help="Monitor breakpoints TOML (default: the model's own, from its declaration's [monitor]; 4 and 8 times the baseline's spread when it has none).")] = None,
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

        A calibrated test of the change against the baseline's scatter (--alpha,
        its false-alarm probability) governs the status against the unit's own
        baseline: without its alarm the check is go; with it the fuzzy
        monitor's status stands and names the fault. A drift test over the
        checks since the baseline (--drift-alpha) is shown beside it."""
        from condmon.diagnose.rules import load_rules
        from condmon.models.regimes import split_key
        from condmon.monitor.fuzzy import load_monitor_config
        from condmon.workflows.checks import check_test
        from condmon.store.db import open_store

        from condmon.workflows.records import Cycle

        opts = options(method, gamma, excitation, columns, fit_threshold, model, route, constants,
                        sample_rate, scale, offset, ignore, meta, window)
        record = records[0] if len(records) == 1 else Cycle(tuple(records))
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
            err.print(f"warning: {res.estimate.source}: {res.warning}", highlight=False, markup=False,
                      soft_wrap=True)
        print_flags(res.baseline_flags, unit)
        fit = res.estimate.fit_percent
        out.print(f"{escape(unit)} — {escape(res.estimate.source)}: {status_text(res.status)}  "
                  + (f"(fit {fit:.1f} %" if math.isfinite(fit) else "(no fit")
                  + (f", regime {escape(res.estimate.regime_label)}"
                     if res.estimate.regime_label else "")
                  + (f", against {escape(res.against)}" if res.against != "unit" else "")
                  + (f", {len(res.diagnosis.unseen)} fault(s) not judged"
                     if res.diagnosis is not None and res.diagnosis.unseen else "")
                  + (f", test #{res.test_id})" if res.test_id >= 0 else ", not stored)"))
        if res.not_judged is not None:
            out.print(f"not judged: {res.not_judged}: the baseline's tests do not span these "
                      "conditions, so nothing says how a healthy unit behaves here; it "
                      "changes no trend. Extend the baseline to these conditions, or test "
                      "again within them.", markup=False, soft_wrap=True)
            _print_forecast(res.forecast)
            return
        if res.diagnosis is None:
            out.print(f"rejected: {res.estimate.reason}; the test is stored but changes no trend. "
                      "Retest.", markup=False)
            _print_forecast(res.forecast)
            return
        for line in folded_judgement(res.judgement):
            out.print(f"judged: {line}", highlight=False, markup=False, soft_wrap=True)
        table = Table()
        for col in ("parameter", "value", "unit", "change %", "SymH", "SymL"):
            table.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
        stored = res.estimate.stored_values()
        units = {**res.estimate.units, **res.estimate.feature_units}
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
            out.print("no fault named" if res.diagnosis.undetermined else "no fault")
        for f in res.diagnosis.faults:
            level = ("major: at no-go level" if f.severity == "major" else
                     "minor: at advisory level" + (", a major fault if it grows"
                                                   if f.rule_severity == "major" else ""))
            out.print(f"[bold]{escape(f.name)}[/] — degree {f.degree:.2f} ({level}): "
                      f"{escape(f.advice)}")
        for c in res.diagnosis.candidates:
            if c.ambiguous:
                out.print(f"candidates, equally likely: {', '.join(c.faults)} (degree "
                          f"{c.degree_text}): the symptoms do not tell them apart",
                          highlight=False, markup=False, soft_wrap=True)
        for u in res.diagnosis.undetermined:
            out.print(f"{u.text}: {u.kind}({u.parameter}) is {u.degree:.2f} and no fault rule "
                      "naming it holds to advisory level", highlight=False, markup=False,
                      soft_wrap=True)
        if res.diagnosis.unseen:
            out.print("not judged by this test (its status says nothing of them): " + ", ".join(
                u.text for u in res.diagnosis.unseen), highlight=False, markup=False,
                soft_wrap=True)
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
    from condmon.forecast.unit import date_past, remaining_text

    f = ahead.get("forecast")
    if f:
        when, now = remaining_text(f, past=False), f["high"] == 0   # at no-go, or due, now
        out.print(f"forecast: {f['parameter']} " + (when if now else f"no-go in {when}")
                  + (f", about {f['date'][:10]}" if f["date"] and not now else "")
                  + (" (past: the check is old; check the unit again)" if date_past(f) else "")
                  + (f" ({f['rule']})" if f["rule"] else "")
                  + ("" if now else "; median (90 % interval)")
                  + ", `condmon forecast` for more", highlight=False,
                  markup=False, soft_wrap=True)
    elif ahead.get("forecast_reason"):
        out.print(f"forecast: none, {ahead['forecast_reason']}", highlight=False, markup=False,
                  soft_wrap=True)
