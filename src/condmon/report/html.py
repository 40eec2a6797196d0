"""HTML pages a person can open: a fleet index and one page per unit.

Every name is escaped (text and attributes) and every unit gets its own file
(:func:`page_name`), tests are numbered by their id in the history everywhere,
and a unit page shows what its latest status rests on: the baseline (version,
tests, spread, warnings), the trend figure with bands and widths, the tests
(excluded and rejected ones marked) and, for plant-model units, the isolations.
"""

from __future__ import annotations

import hashlib
import html
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from condmon.identify.defaults import DEFAULT_FIT_THRESHOLD
from condmon.monitor.fuzzy import MonitorConfig, load_monitor_config
from condmon.store.db import HistoryStore

__all__ = ["ReportFiles", "FleetReport", "write_report", "write_fleet_index",
           "write_fleet_report", "page_name"]

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2em;color:#222;max-width:1100px}
h1{margin-bottom:0}.sub{color:#666;margin-top:.2em}a{color:#1f4e79}
.status{display:inline-block;padding:.15em .6em;border-radius:4px;font-weight:bold;color:#fff}
.go{background:#2e7d32}.advisory{background:#ef6c00}.no-go{background:#c62828}.retest{background:#546e7a}
.baseline,.unchecked{background:#7f8c8d}.rejected{background:#c0392b}.excluded{background:#bdbdbd}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0 1.5em}
td,th{border:1px solid #ddd;padding:.25em .6em;text-align:right}th{background:#f3f3f3}
td.l,th.l{text-align:left}img{max-width:100%;border:1px solid #eee;margin:.5em 0}
tr.excluded td{color:#999;text-decoration:line-through}tr.excluded td.why{text-decoration:none}
.warn{background:#fff3e0;border-left:4px solid #ef6c00;padding:.5em 1em;margin:1em 0}
"""

_STATUSES = ("go", "advisory", "no-go", "retest", "baseline", "rejected", "excluded", "unchecked")


def _e(value: object) -> str:
    """Text and attribute-safe HTML."""
    return html.escape(str(value), quote=True)


def page_name(unit: str) -> str:
    """A file name (without suffix) of its own for every unit name.

    Letters, digits, ``-``, ``_`` and ``.`` are kept; when anything else had to
    be replaced, or the name is long, a short hash of the exact name is added,
    so ``EMA/7`` and ``EMA:7`` get different files and every name fits a file
    system.

    Example
    -------
    >>> page_name("EMA-7")
    'EMA-7'
    >>> page_name("EMA/7") != page_name("EMA:7")
    True
    """
    slug = re.sub(r"[^A-Za-z0-9._-]", "_", unit).strip(".") or "unit"
    if slug == unit and len(unit) <= 80:
        return unit
    return f"{slug[:80]}-{hashlib.sha256(unit.encode('utf-8')).hexdigest()[:10]}"


def _badge(status: object) -> str:
    s = str(status) if isinstance(status, str) and status else "—"
    cls = s if s in _STATUSES else ""
    return f'<span class="status {cls}">{_e(s)}</span>' if cls else _e(s)


@dataclass(frozen=True)
class ReportFiles:
    """Files written for one unit: its page and its figures."""

    html: Path
    figures: tuple[Path, ...]


@dataclass(frozen=True)
class FleetReport:
    """Files written for a fleet: the index and each unit's page."""

    index: Path
    pages: tuple[ReportFiles, ...]


def _faults(store: HistoryStore, test_id: int, baseline_id: Any
            ) -> list[tuple[str, float, str, str]]:
    import sqlalchemy as sa

    from condmon.store import schema as S

    f = S.diagnosis_faults
    q = sa.select(f.c.name, f.c.degree, f.c.severity, f.c.advice).where(f.c.test_id == test_id)
    if baseline_id is not None and baseline_id == baseline_id:
        q = q.where(f.c.baseline_id == int(baseline_id))
    with store.engine.connect() as conn:
        rows = conn.execute(q.order_by(f.c.degree.desc())).all()
    return [(str(r[0]), float(r[1]), str(r[2]), str(r[3])) for r in rows]


def _baseline_box(stored: Any) -> str:
    if stored is None:
        return "<p class='sub'>No baseline yet (fewer than 3 accepted healthy tests).</p>"
    b = stored.baseline
    rows = "".join(f"<tr><td class='l'>{_e(p)}</td><td>{m:.5g}</td><td>{s:.3g}</td>"
                   f"<td>{100 * s / abs(m):.2f}</td></tr>" if m else ""
                   for p, m, s in zip(b.parameters, b.mean, b.std))
    parts = [f"<h2>Baseline {_e(stored.name)} v{stored.version}</h2>",
             f"<p class='sub'>N = {b.n}: tests {_e(', '.join(f'#{i}' for i in stored.test_ids))}"
             f"{' — ' + _e(stored.reason) if stored.reason else ''}</p>",
             "<table><tr><th class='l'>parameter</th><th>mean</th><th>std</th><th>std %</th>"
             f"</tr>{rows}</table>"]
    if stored.flags:
        items = "".join(f"<li>{_e(f['message'])} — look at "
                        f"{_e(', '.join(f'#{t}' for t in f['tests']))}</li>" for f in stored.flags)
        parts.insert(1, "<div class='warn'><b>This baseline may not be trustworthy:</b>"
                        f"<ul>{items}</ul>Exclude a wrong test with <code>condmon exclude "
                        "TEST --reason ...</code>.</div>")
    return "".join(parts)


def _tests_table(hist: Any, params: Sequence[str]) -> str:
    import pandas as pd

    head = ("<table><tr><th>#</th><th class='l'>date</th><th class='l'>source</th>"
            "<th class='l'>role</th><th>fit %</th><th class='l'>status</th>"
            + "".join(f"<th>{_e(p)} Δ%</th>" for p in params) + "<th class='l'>summary</th></tr>")
    rows = []
    for tid, r in hist.iterrows():
        status = str(r["status"])
        excluded = status == "excluded"
        cells = "".join(
            f"<td>{r[f'{p}_change']:+.1f}</td>" if not excluded and f"{p}_change" in r
            and pd.notna(r[f"{p}_change"]) else "<td></td>" for p in params)
        fit = f"{r['fit_percent']:.1f}" if pd.notna(r["fit_percent"]) else "—"
        if excluded:
            summary = f"excluded: {r['excluded_reason']}"
        elif pd.notna(r["summary"]) and r["accepted"]:
            summary = str(r["summary"])
        else:
            summary = str(r["reason"] or "")
        date = f"{r['date']:%Y-%m-%d %H:%M}" + ("" if pd.notna(r["test_date"]) else " (stored)")
        rows.append(f"<tr id='t{tid}' class='{'excluded' if excluded else ''}'><td>#{tid}</td>"
                    f"<td class='l'>{_e(date)}</td><td class='l'>{_e(r['source'])}</td>"
                    f"<td class='l'>{_e(r['role'])}</td><td>{fit}</td>"
                    f"<td class='l'>{_badge(status)}</td>{cells}"
                    f"<td class='l why'>{_e(summary)}</td></tr>")
    return head + "".join(rows) + "</table>"


def _isolations_table(isos: Any) -> str:
    import pandas as pd

    rows = []
    for iid, r in isos.iterrows():
        det = f"{r['detection_time']:.2f} s" if pd.notna(r["detection_time"]) else "—"
        status = "excluded" if r["excluded"] else str(r["status"])
        rows.append(f"<tr id='i{iid}'><td>i{iid}</td><td class='l'>{r['date']:%Y-%m-%d %H:%M}</td>"
                    f"<td class='l'>{_e(r['source'])}</td><td class='l'>{_badge(status)}</td>"
                    f"<td>{det}</td><td class='l'>{_e(', '.join(r['isolated']) or '—')}</td>"
                    f"<td class='l'>{_e(r['statement'])}</td></tr>")
    return ("<table><tr><th>#</th><th class='l'>date</th><th class='l'>source</th>"
            "<th class='l'>status</th><th>detected</th><th class='l'>isolated</th>"
            f"<th class='l'>conclusion</th></tr>{''.join(rows)}</table>")


def _page(title: str, body: Sequence[str]) -> str:
    return ("<!doctype html><html><head><meta charset='utf-8'>"
            f"<title>condmon — {_e(title)}</title><style>{_CSS}</style></head><body>"
            + "\n".join(body) + "</body></html>")


def write_report(store: HistoryStore, unit: str, out_dir: str | Path,
                 monitor: MonitorConfig | None = None,
                 fit_threshold: float = DEFAULT_FIT_THRESHOLD) -> ReportFiles:
    """Write the unit's page (``<page_name>.html``) and its PNG figures into ``out_dir``.

    The page links to the fleet index (``index.html`` in the same folder,
    written by :func:`write_fleet_index`).

    Returns
    -------
    ReportFiles
    """
    from condmon.models.registry import get_model
    from condmon.report.figures import (
        plot_fits, plot_isolation_trends, plot_symptoms, plot_trends,
    )

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    model = store.unit_model(unit) or "dc-motor"
    cfg = monitor or load_monitor_config(get_model(model).breakpoints)
    hist = store.history(unit)
    isos = store.isolations(unit)
    stored = store.latest_baseline(unit)
    summary = next((s for s in store.unit_summaries() if s["unit"] == unit), {})
    name = page_name(unit)
    figs: list[Path] = []
    body = ["<p><a href='index.html'>← all units</a></p>", f"<h1>{_e(unit)}</h1>",
            f"<p class='sub'>model {_e(Path(model).name)} — {len(hist)} tests "
            f"({int((hist['role'] == 'baseline').sum()) if len(hist) else 0} baseline, "
            f"{int((hist['role'] == 'check').sum()) if len(hist) else 0} checked, "
            f"{int((hist['status'] == 'excluded').sum()) if len(hist) else 0} excluded), "
            f"{len(isos)} isolations</p>",
            f"<h2>Latest: {_badge(summary.get('status'))}</h2>",
            f"<p>{_e(summary.get('latest_source') or '')} — "
            f"{_e(summary.get('latest_date') or '')}</p>"]
    if len(hist):
        params = [p for p in cfg.r1 if p in hist.columns]
        checked = hist[(hist["role"] == "check") & (hist["status"] != "excluded")]
        if len(checked):
            last = checked.iloc[-1]
            faults = _faults(store, int(checked.index[-1]), last["baseline_id"])
            body.append(f"<p>Latest check #{int(checked.index[-1])}: {_e(last['summary'] if last['accepted'] else 'retest: ' + str(last['reason']))}</p>")
            if faults:
                body.append("<table><tr><th class='l'>fault</th><th>degree</th>"
                            "<th class='l'>severity</th><th class='l'>advice</th></tr>"
                            + "".join(f"<tr><td class='l'>{_e(n)}</td><td>{d:.2f}</td>"
                                      f"<td class='l'>{_e(s)}</td><td class='l'>{_e(a)}</td></tr>"
                                      for n, d, s, a in faults) + "</table>")
        body.append(_baseline_box(stored))
        figs += [plot_trends(hist, params, cfg, out / f"{name}-trends.png",
                             None if stored is None else stored.baseline),
                 plot_fits(hist, fit_threshold, out / f"{name}-fits.png"),
                 plot_symptoms(hist, params, out / f"{name}-symptoms.png")]
        body.append("<h2>Trends</h2>")
        body += [f"<img src='{_e(f.name)}' alt='{_e(unit)}: {_e(f.stem[len(name) + 1:])}'>"
                 for f in figs]
        body.append("<h2>Tests</h2>" + _tests_table(hist, params))
    if len(isos):
        fig = plot_isolation_trends(isos, out / f"{name}-isolations.png")
        figs.append(fig)
        body += ["<h2>Isolations</h2>", _isolations_table(isos),
                 f"<img src='{_e(Path(str(fig)).name)}' alt='{_e(unit)}: isolations'>"]
    page = out / f"{name}.html"
    page.write_text(_page(unit, body), encoding="utf-8")
    return ReportFiles(page, tuple(figs))


def write_fleet_index(store: HistoryStore, out_dir: str | Path, title: str = "Fleet",
                      extra: str = "") -> Path:
    """Write ``index.html``: every unit with its latest status, linked to its page.

    ``extra``: HTML appended to the page (trusted; the demo's own section).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    units = store.unit_summaries()
    counts: dict[str, int] = {}
    for s in units:
        counts[str(s["status"])] = counts.get(str(s["status"]), 0) + 1
        flag = " ⚠" if s["baseline_flags"] else ""
        rows.append(f"<tr><td class='l'><a href='{_e(page_name(s['unit']))}.html'>{_e(s['unit'])}"
                    f"</a>{flag}</td><td class='l'>{_badge(s['status'])}</td>"
                    f"<td class='l'>{_e(Path(str(s['model'])).name)}</td>"
                    f"<td class='l'>{_e((s['latest_date'] or '—')[:16])}</td>"
                    f"<td>{s['tests']}</td><td>{s['isolations']}</td>"
                    f"<td class='l'>{_e(s['summary'] or '')}</td></tr>")
    tally = ", ".join(f"{n} {_e(k)}" for k, n in sorted(counts.items()))
    body = [f"<h1>{_e(title)}</h1>", f"<p class='sub'>{len(units)} units: {tally}"
            " (⚠: baseline flagged)</p>",
            "<table><tr><th class='l'>unit</th><th class='l'>status</th><th class='l'>model</th>"
            "<th class='l'>latest (UTC)</th><th>tests</th><th>isolations</th>"
            f"<th class='l'>summary</th></tr>{''.join(rows)}</table>", extra]
    index = out / "index.html"
    index.write_text(_page(title, body), encoding="utf-8")
    return index


def write_fleet_report(store: HistoryStore, out_dir: str | Path,
                       units: Sequence[str] | None = None) -> FleetReport:
    """Write the pages of ``units`` (default: every unit) and the fleet index."""
    pages = tuple(write_report(store, u, out_dir) for u in (units or store.units()))
    return FleetReport(write_fleet_index(store, out_dir), pages)
