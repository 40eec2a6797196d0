"""``condmon forecast``: when each parameter of a unit turns no-go (:mod:`condmon.workflows.forecasting`)."""

from __future__ import annotations

import math
from typing import Annotated, Optional

import typer

from condmon.cli._console import out, write_json

__all__ = ["register", "slope_text"]


def slope_text(v: float) -> str:
    """A slope as people read it: ``+110``, ``+2.2``, ``-0.043``; ``0`` below 1e-3. [%/x]

    Example
    -------
    >>> slope_text(112.4), slope_text(2.17), slope_text(-0.0431), slope_text(-2.7e-05)
    ('+112', '+2.2', '-0.043', '0')
    """
    if not math.isfinite(v):
        return "—"
    if abs(v) < 1e-3:
        return "0"
    return f"{v:+.0f}" if abs(v) >= 100 else f"{v:+.2g}" if abs(v) >= 1 else f"{v:+.2f}" \
        if abs(v) >= 0.1 else f"{v:+.2g}"


def register(app: typer.Typer) -> None:
    """Add ``forecast`` to the ``condmon`` application."""

    @app.command("forecast")
    def forecast_cmd(
        unit: Annotated[str, typer.Option("--unit", help="The unit to forecast.")],
        db: Annotated[str, typer.Option("--db", help="History database: a SQLite file or a postgresql:// URL.")] = "condmon.db",
        horizon: Annotated[Optional[float], typer.Option(help="Also give the probability of turning no-go within this many tests (days, when the checks carry dates; operating hours, when they carry the unit's hours: --meta hours=H on check).")] = None,
        as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
    ) -> None:
        """Forecast when each parameter of a unit turns no-go, from its checks since the baseline.

        Each parameter's change series is fitted and its crossing of the no-go change
        (where a check turns no-go on it, short of r2) forecast: the tests (cycles,
        days, hours) left as a median and a 90 % interval; "no trend" when the slope's
        interval holds 0, or no-go cannot come the way it moves. Estimated parameters:
        a line or an exponential, chosen by evidence, each test weighted by its
        standard error and the baseline's spread. Imported indicators of a declaration
        with method "path": a measured degradation path (a wandering rate, recoveries),
        with three failed units of its model or more in the history their whole lives
        its prior and their lives' PITs its levels (see --json's notes)."""
        from rich.table import Table

        from condmon.store.db import open_store
        from condmon.workflows.forecasting import forecast_unit

        with open_store(db, create=False) as store:
            res = forecast_unit(store, unit, horizon)
        if as_json:
            write_json(res.to_dict())
            return
        left = {"tests": "tests left", "days": "days left", "hours": "hours left",
                "cycles": "cycles left"}[res.by]
        per = {"tests": "%/test", "days": "%/day", "hours": "%/h", "cycles": "%/cycle"}[res.by]
        span = {"tests": " tests", "days": " d", "hours": " h", "cycles": " cycles"}[res.by]
        # checks within a day or two (one session): a slope per day extrapolates
        # minutes to a day; per hour of clock time reads at the scale measured
        days = max((p.span for p in res.parameters), default=math.nan)
        scale = 24.0 if res.by == "days" and days < 2.0 else 1.0
        if scale != 1.0:
            left, per = "clock hours left", "%/h"   # (a --horizon stays in days)
        table = Table(title=f"{unit}: forecast to no-go from {res.checks} checks since the "
                      "baseline", title_justify="left")
        hours = res.by == "hours"
        cols = ["parameter", f"slope [{per}]", f"{left} (90 %)", "date",
                *(["at hours [h]"] if hours else []),
                *([f"P(≤{horizon:g}{span})"] if horizon is not None else []), "no-go at (rule)"]
        for col in cols:
            table.add_column(col, justify="left" if col in ("parameter", "no-go at (rule)")
                             else "right", no_wrap=col in ("date", "parameter"))

        def n(v: float) -> str:   # 1443, not 1.44e+03
            if not math.isfinite(v):
                return "beyond"
            v *= scale
            return f"{v:.0f}" if abs(v) >= 100 else f"{v:.3g}"

        for p in res.parameters:
            f = p.forecast
            rem = ("no trend" if f.remaining is None else
                   "at no-go now" if f.at_nogo else
                   "due now" if f.remaining[2] == 0 else
                   f"{n(f.remaining[0])} ({n(f.remaining[1])}–{n(f.remaining[2])})"
                   + (" exp." if f.model == "exponential" else
                      " path" if f.model == "path" else ""))
            # no trend: the no-go change of the way it can come (its sign follows noise
            # where both can)
            at = ("none (see --json)" if f.unreachable else
                  f"{f.threshold:+.3g} %" + (f" ({p.rule})" if p.rule and f.trend else ""))
            table.add_row(p.parameter, slope_text(f.slope / scale), rem, (p.date or "—")[:10],
                          *([n(p.hours) if p.hours is not None else "—"] if hours else []),
                          *([f"{f.p_within:.2f}" if f.p_within is not None else "—"]
                            if horizon is not None else []), at)
        out.print(table)
        if scale != 1.0:
            out.print(f"the checks span {days * 24:.2g} h: slopes and times left are per hour "
                      "of clock time (--json counts days)", markup=False, highlight=False)
        out.print(f"slope: the trend at the last check (a path's: the series' mean rate, "
                  f"the rate now drawn about it), {per} of the baseline mean; "
                  f"{left}: median and 90 % interval (exp.: an exponential trend; path: a "
                  "measured degradation path, its interval's meaning below); no trend: "
                  "the slope's 90 % interval holds 0, or no-go cannot come the way it moves "
                  "(see --json)", markup=False,
                  highlight=False, soft_wrap=True)
        e = res.earliest
        r = None if e is None else e.forecast.remaining
        out.print("no parameter trends towards no-go" if r is None or e is None else
                  f"earliest: {e.parameter}, at no-go now" if e.forecast.at_nogo else
                  f"earliest: {e.parameter}, due now (its trend is past no-go)" if r[2] == 0 else
                  f"earliest: {e.parameter} in {n(r[0])} "
                  f"{left.rsplit(' ', 1)[0].removesuffix('s' if n(r[0]) == '1' else '')} "
                  f"(90 %: {n(r[1])}–{n(r[2])})", markup=False, highlight=False)
        for note in res.notes:
            out.print(f"note: {note}", markup=False, highlight=False, soft_wrap=True)
        priors = sorted({f"{p.parameter}: {note}" if not note.startswith("no fleet") else note
                         for p in res.parameters if p.forecast.trend for note in p.forecast.notes
                         if note.startswith("fleet prior") or note.endswith("vague prior")})
        for line in priors:
            out.print(f"prior: {line}", markup=False, highlight=False, soft_wrap=True)
        # a path forecast's interval: read at its fleet's levels, or where its
        # coverage was measured (not on this unit's kind)
        fleet = sorted({f"{p.parameter}: {note}" for p in res.parameters
                        if p.forecast.model == "path" and not p.forecast.at_nogo
                        for note in p.forecast.notes
                        if note.startswith(("recalibrated on", "its 90 % interval held"))})
        for line in fleet:
            out.print(f"interval: {line}", markup=False, highlight=False, soft_wrap=True)
        # a date read at the history's mean pace, where the unit's use changed
        for p in res.parameters:
            for note in p.forecast.notes:
                if note.startswith("the date is at the history's mean pace"):
                    out.print(f"pace: {p.parameter}: {note}", markup=False, highlight=False,
                              soft_wrap=True)
