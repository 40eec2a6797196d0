"""What a notebook shows of condmon's results: HTML summaries and figures.

Each function takes a result's plain fields, so the rich display of a check
(:class:`condmon.workflows.checks.CheckResult`), a forecast and a unit's
trends agree with the CLI's tables and the report's figures: one status
colour (:data:`condmon.report.figures.STATUS_COLOURS`), one error bar.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from condmon.report.figures import STATUS_COLOURS, new_figure
from condmon.report.tables import CSS, badge, esc

if TYPE_CHECKING:
    from condmon.forecast.unit import UnitForecast
    from condmon.store.db import HistoryStore

#: The status badges' style alone: a notebook keeps its own page style.
STYLE = "\n".join(line for line in CSS.splitlines() if line.startswith((".status", ".go",
                                                                           ".baseline")))

__all__ = ["html_table", "check_html", "change_figure", "forecast_html", "unit_trend_figure"]


def html_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A small HTML table, every cell escaped.

    Example
    -------
    >>> html_table(["a"], [["<b>"]])
    '<table><tr><th>a</th></tr><tr><td>&lt;b&gt;</td></tr></table>'
    """
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in row) + "</tr>"
                   for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _number(v: float) -> str:
    return f"{v:.4g}" if np.isfinite(v) else ("not finite" if not np.isnan(v) else "—")


def check_html(unit: str, test_id: int, status: str, summary: str,
               values: Mapping[str, tuple[float, float]], units: Mapping[str, str],
               changes: Mapping[str, float]) -> str:
    """One check as HTML: its status badge, summary and table of changes
    (``values``: ``{name: (value, standard error)}`` as the history keeps them)."""
    rows = [(p, _number(v), _number(se), units.get(p, units.get(p.split("@")[0], "")),
             _number(changes[p]) if p in changes else "—")
            for p, (v, se) in values.items()]
    tid = f"#{test_id}" if test_id >= 0 else "(not stored)"
    return (f"<style>{STYLE}</style><p><b>{esc(unit)}</b> check {esc(tid)}: {badge(status)} "
            f"{esc(summary)}</p>"
            + html_table(["parameter", "value", "std error", "unit", "change %"], rows))


def change_figure(title: str, changes: Mapping[str, float],
                  symptoms: Mapping[str, Mapping[str, float]], status: str) -> Any:
    """A check's change per parameter [%] as horizontal bars, each coloured by
    its own symptom (the status colour where its symptom is above 0, grey
    where not); non-finite changes are named, not drawn."""
    names = list(changes)
    fig = new_figure(6.0, 0.6 + 0.35 * max(len(names), 1))
    ax = fig.add_subplot()
    values = np.array([changes[p] for p in names], dtype=np.float64)
    ok = np.isfinite(values)
    colours = [STATUS_COLOURS.get(status, "#546e7a")
               if max(symptoms.get(p, {}).get("high", 0.0), symptoms.get(p, {}).get("low", 0.0))
               > 0 else STATUS_COLOURS["unchecked"] for p in names]
    y = np.arange(len(names))
    ax.barh(y[ok], values[ok], color=[c for c, k in zip(colours, ok) if k])
    ax.set_yticks(y, [p if k else f"{p} (not finite)" for p, k in zip(names, ok)])
    ax.axvline(0.0, color="black", linewidth=0.8)
    ax.set_xlabel("change against the baseline [%]")
    ax.set_title(title)
    ax.invert_yaxis()
    return fig


def forecast_html(forecast: UnitForecast) -> str:
    """A unit's forecast as HTML: each parameter's remaining life to no-go,
    its 90 % interval, the model and the rule that makes it a fault."""
    rows = []
    for p in forecast.parameters:
        f = p.forecast
        if f.remaining is None:
            why = f.unreachable or "; ".join(f.notes[:1])
            rows.append((p.parameter, "no trend", "—", f.model, p.rule, why))
            continue
        median, lo, hi = f.remaining
        rows.append((p.parameter, _number(median), f"{_number(lo)} – {_number(hi)}",
                     f.model, p.rule, "at no-go now" if f.at_nogo else ""))
    return (f"<style>{STYLE}</style><p><b>{esc(forecast.unit)}</b>: forecast to no-go, in "
            f"{esc(forecast.by)} ({forecast.checks} checks since the baseline)</p>"
            + html_table(["parameter", f"remaining [{forecast.by}]", "90 % interval", "model",
                          "no-go at (rule)", "note"], rows))


def unit_trend_figure(store: HistoryStore, unit: str) -> Any:
    """The report's trend figure of ``unit`` (its checks' changes against the
    r1/r2 bands, with the forecast), drawn, not written.

    Raises
    ------
    DataError
        The unit has no checks to draw.
    """
    from condmon.errors import DataError
    from condmon.models.registry import get_model
    from condmon.report.figures import trend_figure
    from condmon.report.reading import judged_monitor
    from condmon.report.trends import forecast_bands, trend_data
    from condmon.store.forecasts import try_forecast

    hist = store.history(unit)
    stored = store.latest_baseline(unit)
    machine = get_model(store.unit_model(unit) or "dc-motor")
    cfg = judged_monitor(machine, stored.baseline if stored is not None else None, hist)
    by_id = {b.id: b.baseline for b in store.baselines(unit)}
    trends = tuple(trend_data(hist, p, by_id, cfg.r1[p], cfg.r2[p], cfg.k,
                              None if stored is None else stored.id)
                   for p in cfg.r1 if p in hist.columns)
    if not trends or not trends[0].test_ids:
        raise DataError(f"unit {unit!r} has no checks to draw yet")
    return trend_figure(trends, forecast_bands(try_forecast(store, unit)[0]))
