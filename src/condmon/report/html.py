"""HTML pages a person can open: a fleet index and one page per unit.

Every name is escaped (text and attributes) and every unit gets its own file
(:func:`~condmon.report.names.page_name`); tests are numbered by their id in
the history everywhere. A unit page shows what its latest status rests on: the
baseline in use (name, version, when built, its tests and how many per
regime, in the header too; mean ± std with units, warnings), the trend figure
with the bands and symptom widths the status was computed with (the one error
bar, :func:`condmon.report.trends.error_bar`), the fit and symptom figures,
the tests (excluded ones greyed with their reason, never trended; rejected
ones in the fit figure and the table only) and, for plant-model units, the
isolations with each suspect's estimate over time, in its unit. The index lists every unit with its
latest status and links to each page; each page links back.

Nothing here writes to the history.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from condmon.identify.defaults import DEFAULT_FIT_THRESHOLD
from condmon.report.names import INDEX, page_name
from condmon.report.tables import (
    badge, baseline_section, esc, faults_table, flags_box, isolations_table, page, tests_summary,
    tests_table, when,
)

if TYPE_CHECKING:
    from condmon.monitor.fuzzy import MonitorConfig
    from condmon.report.trends import FitData, IsolationTrend, TrendData
    from condmon.store.db import HistoryStore

__all__ = ["ReportFiles", "FleetReport", "write_report", "write_fleet_index",
           "write_fleet_report", "page_name"]

#: ``progress(done, total, unit)`` after each page.
Progress = Callable[[int, int, str], None]


@dataclass(frozen=True)
class ReportFiles:
    """What was written for one unit, and the data its figures drew.

    Attributes
    ----------
    unit : str
    html : Path
        The unit's page.
    figures : tuple of Path
        Its PNG figures.
    trends : tuple of TrendData
        Per trended parameter, what the trend and symptom figures drew.
    fits : FitData or None
        What the fit figure drew (None without tests).
    isolations : IsolationTrend or None
        What the isolation figure drew (None without isolations).
    notes : dict of int to str
        Tests whose status the trend figure does not explain by itself, with
        the explanation printed under it.
    """

    unit: str
    html: Path
    figures: tuple[Path, ...]
    trends: tuple[TrendData, ...] = ()
    fits: FitData | None = None
    isolations: IsolationTrend | None = None
    notes: dict[int, str] = field(default_factory=dict)


@dataclass(frozen=True)
class FleetReport:
    """Files written for a fleet: the index and each unit's page.

    Attributes
    ----------
    index : Path
    pages : tuple of ReportFiles
    """

    index: Path
    pages: tuple[ReportFiles, ...]


def _summary(store: HistoryStore, unit: str) -> dict[str, Any]:
    return next((s for s in store.unit_summaries() if s["unit"] == unit), {})


def _latest_check(hist: Any) -> Any:
    """The newest check that is not excluded (by date, then id), or None."""
    checks = hist[(hist["role"] == "check") & ~hist["excluded"].astype(bool)]
    if not len(checks):
        return None
    return checks.sort_index().sort_values("date", kind="stable").iloc[-1]


def _head(unit: str, model: str, hist: Any, isos: Any, summary: Mapping[str, Any],
          stored: Any) -> list[str]:
    n = len(hist)
    counts = f"{n} tests ({tests_summary(hist, stored)})" if n else "no tests"
    latest = summary.get("latest_source")
    in_use = ("" if not n else "<p class='sub' id='in-use'>No baseline in use yet.</p>"
              if stored is None else
              f"<p class='sub' id='in-use'>In use: <a href='#baseline'>"
              f"{esc(stored.describe(hist))}</a>.</p>")
    return ["<p><a href='index.html'>← all units</a></p>", f"<h1>{esc(unit)}</h1>",
            f"<p class='sub'>model {esc(Path(model).name)} — {counts}, {len(isos)} "
            f"isolation{'s' if len(isos) != 1 else ''}; page written "
            f"{when(datetime.now(timezone.utc))} UTC</p>", in_use,
            f"<h2>Latest: {badge(summary.get('status'))}</h2>",
            "" if latest is None else
            f"<p>{esc(latest)} — {when(summary.get('latest_date'))} UTC"
            f"{': ' + esc(summary['summary']) if summary.get('summary') else ''}</p>"]


def _tests_part(store: HistoryStore, unit: str, hist: Any, cfg: MonitorConfig, stored: Any,
                out: Path, name: str, fit_threshold: float, units: Mapping[str, str]
                ) -> tuple[list[str], list[Path], tuple[TrendData, ...], FitData, dict[int, str]]:
    """The checks, baseline, figures and tests table of an actuator unit."""
    from condmon.report import figures as F
    from condmon.report.reading import check_faults
    from condmon.report.trends import (
        FORECAST_LABEL, error_bar, fit_data, forecast_bands, trend_data, unexplained,
    )
    from condmon.store.forecasts import try_forecast

    every = store.baselines(unit)
    by_id = {b.id: b.baseline for b in every}
    versions = {b.id: f"{b.name} v{b.version}" for b in every}
    active = stored.id if stored is not None else None
    params = [p for p in cfg.r1 if p in hist.columns]
    body: list[str] = []
    last = _latest_check(hist)
    if last is not None:
        tid = int(last.name)
        what = str(last["summary"] if last["accepted"] else last["reason"] or "")
        what = what.split(": ", 1)[1] if what.startswith(f"{last['status']}: ") else what
        body.append(f"<p>Latest check <a href='#t{tid}'>#{tid}</a> ({when(last['date'])} UTC): "
                    f"{badge(last['status'])} {esc(what)}</p>")
        body.append(faults_table(check_faults(store, tid, last["baseline_id"])))
    body.append(baseline_section(stored, cfg, units, hist))
    trends = tuple(trend_data(hist, p, by_id, cfg.r1[p], cfg.r2[p], cfg.k, active)
                   for p in params)
    fits = fit_data(hist)
    notes = unexplained(trends)
    # (an imported unit's checks have no model fit: no figure of nothing)
    figs = ([F.plot_fits(fits, fit_threshold, out / f"{name}-fits.png")]
            if any(v == v for v in fits.fit.tolist()) else [])   # (v == v: not NaN)
    body.append("<h2>Trends</h2>")
    if trends and trends[0].test_ids:
        bands = forecast_bands(try_forecast(store, unit)[0])
        figs = [F.plot_trends(trends, out / f"{name}-trends.png", bands), *figs,
                F.plot_symptoms(trends, out / f"{name}-symptoms.png")]
        body.append(
            "<p class='sub'>Each check's change against its baseline, coloured by its "
            "status where this parameter's symptom is above 0, green where it is not; "
            f"{esc(error_bar(cfg.k, words=True))} (filled marker: above 0). Blue: "
            f"the active baseline's ±{cfg.k:g}·σ. Excluded and rejected tests are not "
            "drawn." + (f" Purple ({FORECAST_LABEL}): the fitted trend of "
                        f"{esc(', '.join(b.parameter for b in bands))} continued from the last "
                        "check to the no-go change (dotted: where a check turns no-go, short of "
                        "r2), as <code>condmon forecast</code> "
                        "gives it." if bands else "") + "</p>")
    else:
        body.append("<p class='sub'>No accepted check to trend yet.</p>")
    body += [f"<img src='{esc(f.name)}' alt='{esc(unit)}: {esc(f.stem[len(name) + 1:])}'>"
             for f in figs]
    if notes:
        items = "".join(f"<li><a href='#t{t}'>#{t}</a>: {esc(text)}</li>"
                        for t, text in notes.items())
        body.append(f"<div class='note'><b>Read with the table:</b><ul>{items}</ul></div>")
    body.append("<h2>Tests</h2>" + tests_table(hist, params, stored, versions))
    return body, figs, trends, fits, notes


def write_report(store: HistoryStore, unit: str, out_dir: str | Path,
                 monitor: MonitorConfig | None = None,
                 fit_threshold: float = DEFAULT_FIT_THRESHOLD,
                 summary: Mapping[str, Any] | None = None) -> ReportFiles:
    """Write the unit's page (``<page_name>.html``) and its PNG figures into ``out_dir``.

    The page links to the fleet index (``index.html`` in the same folder,
    written by :func:`write_fleet_index`).

    Parameters
    ----------
    store : HistoryStore
        Read only.
    unit : str
    out_dir : str or Path
        Created if missing.
    monitor : MonitorConfig, optional
        Breakpoints and k of the figures (default: the unit's model's).
    fit_threshold : float
        Fit line drawn in the fit figure. [%]
    summary : mapping, optional
        The unit's entry of :meth:`HistoryStore.unit_summaries` (read when omitted).

    Returns
    -------
    ReportFiles

    Raises
    ------
    ConfigError
        ``unit`` is not in the history (the message names the known units).
    """
    from condmon.report.figures import plot_isolation_trends
    from condmon.report.trends import isolation_trend

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    hist = store.history(unit)  # an unknown unit raises here
    isos = store.isolations(unit)
    model = store.unit_model(unit) or "dc-motor"
    info = _summary(store, unit) if summary is None else summary
    stored = store.latest_baseline(unit)
    name = page_name(unit)
    body = _head(unit, str(info.get("model") or model), hist, isos, info, stored)
    body.append(flags_box(stored))
    figs: list[Path] = []
    trends: tuple[TrendData, ...] = ()
    fits: FitData | None = None
    notes: dict[int, str] = {}
    units: dict[str, str] = {}
    if len(hist) or len(isos):
        from condmon.models.registry import get_model
        from condmon.report.reading import model_units

        machine = get_model(model)
        units = model_units(machine)
    if len(hist):
        from condmon.report.reading import judged_monitor

        cfg = judged_monitor(machine, stored.baseline if stored is not None else None, hist,
                             monitor)
        part, figs, trends, fits, notes = _tests_part(store, unit, hist, cfg, stored, out, name,
                                                      fit_threshold, units)
        body += part
    iso_data = None
    if len(isos):
        iso_data = isolation_trend(isos)
        body += ["<h2>Isolations</h2>", isolations_table(isos, units)]
        if iso_data.isolation_ids:
            fig = plot_isolation_trends(iso_data, out / f"{name}-isolations.png")
            figs.append(fig)
            body.append(f"<img src='{esc(fig.name)}' alt='{esc(unit)}: isolations'>")
    target = out / f"{name}.html"
    target.write_text(page(unit, body), encoding="utf-8")
    return ReportFiles(unit, target, tuple(figs), trends, fits, iso_data, notes)


def write_fleet_index(store: HistoryStore, out_dir: str | Path, title: str = "Fleet",
                      extra: str = "", summaries: Sequence[Mapping[str, Any]] | None = None
                      ) -> Path:
    """Write ``index.html``: every unit with its latest status and its earliest
    forecast to no-go, by urgency (the soonest first), linked to its page.

    Parameters
    ----------
    store : HistoryStore
        Read only.
    out_dir : str or Path
    title : str
        Page title (escaped).
    extra : str
        HTML appended to the page (trusted: the demo's own section).
    summaries : sequence of mapping, optional
        :meth:`HistoryStore.unit_summaries` (read when omitted).

    Returns
    -------
    Path
        The index file. A unit whose page is not in ``out_dir`` is listed
        without a link.
    """
    from condmon.forecast.unit import remaining_text
    from condmon.store.kept import attach_forecasts
    from condmon.store.views import by_urgency

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    units = by_urgency(attach_forecasts(store, [dict(s) for s in (
        store.unit_summaries() if summaries is None else summaries)]))
    rows: list[str] = []
    counts: dict[str, int] = {}
    flagged = 0
    for s in units:
        status = str(s["status"] or "none")
        counts[status] = counts.get(status, 0) + 1
        file = f"{page_name(s['unit'])}.html"
        has_page = (out / file).exists()
        unit = (f"<a href='{esc(file)}'>{esc(s['unit'])}</a>" if has_page
                else f"{esc(s['unit'])} <span class='sub'>(no page written)</span>")
        flags = int(s["baseline_flags"] or 0)
        flagged += flags > 0
        flag = ("—" if not flags else f"<a href='{esc(file)}#flags'>⚠ {flags}</a>" if has_page
                else f"⚠ {flags}")
        rows.append(f"<tr><td class='l'>{unit}</td><td class='l'>{badge(s['status'])}</td>"
                    f"<td class='l'>{when(s['latest_date'])}</td>"
                    f"<td class='l'>{esc(Path(str(s['model'])).name)}</td>"
                    f"<td>{int(s['tests'])}</td><td>{int(s['isolations'])}</td>"
                    f"<td>{flag}</td>"
                    f"<td class='l'>{esc(remaining_text(s['forecast'], s['forecast_reason']))}"
                    f"</td><td class='l'>{esc(s['summary'] or '')}</td></tr>")
    tally = ", ".join(f"{n} {esc(k)}" for k, n in sorted(counts.items()))
    body = [f"<h1>{esc(title)}</h1>",
            f"<p class='sub'>{len(units)} unit{'s' if len(units) != 1 else ''}"
            f"{': ' + tally if tally else ''}; {flagged} with a flagged baseline (⚠: "
            f"warnings to look at). By urgency: the earliest forecast to no-go first (no-go "
            f"in: tests, days or hours left, median and 90 % interval). Written "
            f"{when(datetime.now(timezone.utc))} UTC.</p>",
            "<table><tr><th class='l'>unit</th><th class='l'>latest status</th>"
            "<th class='l'>latest (UTC)</th><th class='l'>model</th><th>tests</th>"
            "<th>isolations</th><th>baseline flags</th><th class='l'>no-go in</th>"
            "<th class='l'>latest summary</th></tr>"
            f"{''.join(rows)}</table>", extra]
    index = out / f"{INDEX}.html"
    index.write_text(page(title, body), encoding="utf-8")
    return index


def write_fleet_report(store: HistoryStore, out_dir: str | Path,
                       units: Sequence[str] | None = None, *,
                       monitor: MonitorConfig | None = None,
                       fit_threshold: float = DEFAULT_FIT_THRESHOLD, title: str = "Fleet",
                       extra: str = "", progress: Progress | None = None) -> FleetReport:
    """Write the pages of ``units`` (default: every unit), then the fleet index.

    Parameters
    ----------
    store : HistoryStore
        Read only.
    out_dir : str or Path
    units : sequence of str, optional
        Only these units' pages (the index lists every unit either way).
    monitor : MonitorConfig, optional
        Breakpoints of every page's figures (default: each unit's model's).
    fit_threshold : float
        Fit line of the fit figures. [%]
    title, extra : str
        Of the index (see :func:`write_fleet_index`).
    progress : callable, optional
        ``progress(done, total, unit)`` after each page.

    Returns
    -------
    FleetReport
    """
    summaries = store.unit_summaries()
    by_unit = {s["unit"]: s for s in summaries}
    todo = list(by_unit) if units is None else list(units)
    pages = []
    for i, unit in enumerate(todo):
        pages.append(write_report(store, unit, out_dir, monitor, fit_threshold,
                                  by_unit.get(unit)))
        if progress is not None:
            progress(i + 1, len(todo), unit)
    index = write_fleet_index(store, out_dir, title, extra, summaries)
    return FleetReport(index, tuple(pages))
