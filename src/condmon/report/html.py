"""An HTML page a person can open: the unit's status, faults, trends and tests."""

from __future__ import annotations

import html
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from condmon.identify.fit import DEFAULT_FIT_THRESHOLD
from condmon.monitor.fuzzy import MonitorConfig, load_monitor_config
from condmon.report.figures import plot_fits, plot_symptoms, plot_trends
from condmon.store.db import HistoryStore

__all__ = ["ReportFiles", "write_report"]

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2em;color:#222;max-width:1100px}
h1{margin-bottom:0}.sub{color:#666;margin-top:.2em}
.status{display:inline-block;padding:.3em .8em;border-radius:4px;font-weight:bold;color:#fff}
.go{background:#2e7d32}.advisory{background:#ef6c00}.no-go{background:#c62828}.retest{background:#546e7a}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0 1.5em}
td,th{border:1px solid #ddd;padding:.25em .6em;text-align:right}th{background:#f3f3f3}
td.l,th.l{text-align:left}img{max-width:100%;border:1px solid #eee;margin:.5em 0}
"""


@dataclass(frozen=True)
class ReportFiles:
    """Files written by :func:`write_report`."""

    html: Path
    figures: tuple[Path, ...]


def _status_badge(status: object) -> str:
    s = str(status) if isinstance(status, str) else "baseline"
    cls = s if s in ("go", "advisory", "no-go", "retest") else ""
    return f'<span class="status {cls}">{html.escape(s)}</span>' if cls else html.escape(s)


def write_report(store: HistoryStore, unit: str, out_dir: str | Path,
                 monitor: MonitorConfig | None = None,
                 fit_threshold: float = DEFAULT_FIT_THRESHOLD) -> ReportFiles:
    """Write ``index.html`` and PNG figures of a unit's history into ``out_dir``.

    Returns
    -------
    ReportFiles
    """
    cfg = monitor or load_monitor_config()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    hist = store.history(unit)
    params = [p for p in cfg.r1 if p in hist.columns]
    slug = "".join(c if c.isalnum() or c in "-_" else "_" for c in unit)
    figs = (
        plot_trends(hist, params, cfg, out / f"{slug}-trends.png"),
        plot_fits(hist, fit_threshold, out / f"{slug}-fits.png"),
        plot_symptoms(hist, params, out / f"{slug}-symptoms.png"),
    )
    checked = hist[hist["role"] == "check"]
    last = checked.iloc[-1] if len(checked) else None
    faults = _latest_faults(store, unit, int(checked.index[-1]) if len(checked) else None)
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>condmon — {html.escape(unit)}</title>"
             f"<style>{_CSS}</style></head><body>",
             f"<h1>{html.escape(unit)}</h1>",
             f"<p class='sub'>{len(hist)} tests: {int((hist['role'] == 'baseline').sum())} baseline, "
             f"{len(checked)} checked, {int((~hist['accepted'].astype(bool)).sum())} rejected</p>"]
    if last is not None:
        parts.append(f"<h2>Latest check: {_status_badge(last['status'] if last['accepted'] else 'retest')}</h2>")
        parts.append(f"<p>{html.escape(str(last['source']))} — "
                     f"{html.escape(str(last['summary'] if last['accepted'] else 'rejected: ' + str(last['reason'])))}</p>")
        if faults:
            parts.append("<table><tr><th class='l'>fault</th><th>degree</th><th class='l'>severity</th>"
                         "<th class='l'>advice</th></tr>")
            for name, degree, severity, advice in faults:
                parts.append(f"<tr><td class='l'>{html.escape(name)}</td><td>{degree:.2f}</td>"
                             f"<td class='l'>{html.escape(severity)}</td><td class='l'>{html.escape(advice)}</td></tr>")
            parts.append("</table>")
    parts.append("<h2>Trends</h2>")
    parts += [f"<img src='{f.name}' alt='{f.stem}'>" for f in figs]
    parts.append("<h2>Tests</h2>" + _tests_table(hist, params))
    parts.append("</body></html>")
    page = out / (f"{slug}.html")
    page.write_text("\n".join(parts), encoding="utf-8")
    return ReportFiles(page, figs)


def _latest_faults(store: HistoryStore, unit: str, test_id: int | None
                   ) -> list[tuple[str, float, str, str]]:
    if test_id is None:
        return []
    import sqlalchemy as sa

    from condmon.store import schema as S

    with store.engine.connect() as conn:
        rows = conn.execute(sa.select(S.diagnosis_faults.c.name, S.diagnosis_faults.c.degree,
                                      S.diagnosis_faults.c.severity, S.diagnosis_faults.c.advice)
                            .where(S.diagnosis_faults.c.test_id == test_id)
                            .order_by(S.diagnosis_faults.c.degree.desc())).all()
    return [(str(r[0]), float(r[1]), str(r[2]), str(r[3])) for r in rows]


def _tests_table(hist: pd.DataFrame, params: list[str]) -> str:
    head = ("<table><tr><th>#</th><th class='l'>source</th><th class='l'>role</th><th>fit %</th>"
            "<th class='l'>status</th>" + "".join(f"<th>{p} Δ%</th>" for p in params)
            + "<th class='l'>summary</th></tr>")
    rows = []
    for tid, r in hist.iterrows():
        status = r["status"] if r["accepted"] else "retest"
        if r["role"] == "baseline":
            status = "baseline" if r["accepted"] else "rejected"
        cells = "".join(
            f"<td>{r[f'{p}_change']:+.1f}</td>" if f"{p}_change" in r and pd.notna(r[f"{p}_change"])
            else "<td></td>" for p in params)
        fit = f"{r['fit_percent']:.1f}" if pd.notna(r["fit_percent"]) else "—"
        summary = r["summary"] if pd.notna(r["summary"]) else (r["reason"] or "")
        rows.append(f"<tr><td>{tid}</td><td class='l'>{html.escape(str(r['source']))}</td>"
                    f"<td class='l'>{r['role']}</td><td>{fit}</td><td class='l'>{_status_badge(status)}</td>"
                    f"{cells}<td class='l'>{html.escape(str(summary))}</td></tr>")
    return head + "".join(rows) + "</table>"
