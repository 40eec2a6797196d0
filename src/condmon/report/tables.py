"""HTML pieces of the report pages: badges, the baseline, the tests, the isolations.

Every value that comes from the history (names, sources, reasons, advice) is
escaped for text and attributes alike (:func:`esc`). Tests are numbered by
their id (``#12``, anchor ``t12``), isolations by theirs (``i3``).
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from condmon.monitor.fuzzy import MonitorConfig
    from condmon.report.reading import CheckFault

__all__ = ["CSS", "STATUSES", "esc", "badge", "when", "page", "flags_box", "test_note",
           "baseline_section", "faults_table", "tests_table", "isolations_table"]

#: Every status a page may show.
STATUSES = ("go", "advisory", "no-go", "retest", "building", "baseline", "rejected",
            "excluded", "unchecked")

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2em;color:#222;max-width:1150px}
h1{margin-bottom:0}.sub{color:#666;margin-top:.2em}a{color:#1f4e79}
.status{display:inline-block;padding:.15em .6em;border-radius:4px;font-weight:bold;color:#fff}
.go{background:#2e7d32}.advisory{background:#ef6c00}.no-go{background:#c62828}.retest{background:#546e7a}
.baseline,.unchecked{background:#7f8c8d}.building{background:#90a4ae}.rejected{background:#c0392b}.excluded{background:#bdbdbd}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0 1.5em}
td,th{border:1px solid #ddd;padding:.25em .6em;text-align:right}th{background:#f3f3f3}
td.l,th.l{text-align:left}img{max-width:100%;border:1px solid #eee;margin:.5em 0}
tr.excluded td{color:#999}tr.excluded td.v{text-decoration:line-through}
.warn{background:#fff3e0;border-left:4px solid #ef6c00;padding:.5em 1em;margin:1em 0}
.note{background:#eef4fb;border-left:4px solid #1f4e79;padding:.5em 1em;margin:1em 0;font-size:.9em}
"""


def esc(value: object) -> str:
    """``value`` as HTML text that is also safe inside a quoted attribute.

    Examples
    --------
    >>> esc("<b>EMA[/]7</b> 'x'")
    '&lt;b&gt;EMA[/]7&lt;/b&gt; &#x27;x&#x27;'
    """
    return html.escape(str(value), quote=True)


def badge(status: object) -> str:
    """A coloured status label (plain text for anything not a status)."""
    s = status if isinstance(status, str) and status else "—"
    return f'<span class="status {s}">{esc(s)}</span>' if s in STATUSES else esc(s)


def when(stamp: Any) -> str:
    """A UTC time as ``YYYY-MM-DD HH:MM`` (``—`` when unknown)."""
    import pandas as pd

    if stamp is None or (not isinstance(stamp, str) and pd.isna(stamp)):
        return "—"
    ts = pd.Timestamp(stamp)
    ts = ts.tz_localize("UTC") if ts.tzinfo is None else ts.tz_convert("UTC")
    return f"{ts:%Y-%m-%d %H:%M}"


def page(title: str, body: Sequence[str]) -> str:
    """A whole HTML document."""
    return ("<!doctype html><html><head><meta charset='utf-8'>"
            f"<title>condmon — {esc(title)}</title><style>{CSS}</style></head><body>"
            + "\n".join(body) + "</body></html>")


def _test_links(ids: Sequence[Any]) -> str:
    return ", ".join(f"<a href='#t{int(i)}'>#{int(i)}</a>" for i in ids)


def flags_box(stored: Any) -> str:
    """The warning box of a flagged baseline: each warning and the tests to look at."""
    if stored is None or not stored.flags:
        return ""
    items = "".join(
        f"<li><b>{esc(f.get('kind', 'warning'))}</b> of {esc(f.get('parameter', '?'))}: "
        f"{esc(f.get('message', ''))} — look at {_test_links(f.get('tests', []))}</li>"
        for f in stored.flags)
    return (f"<div class='warn' id='flags'><b>Baseline {esc(stored.name)} v{stored.version} "
            f"may not be trustworthy ({len(stored.flags)} warning"
            f"{'s' if len(stored.flags) != 1 else ''}):</b><ul>{items}</ul>"
            "A check against it can hide a fault or raise a false alarm. Exclude a wrong "
            "test with <code>condmon exclude TEST --reason ...</code>; the baseline is "
            "rebuilt and the checks re-evaluated.</div>")


def baseline_section(stored: Any, cfg: MonitorConfig,
                     units: Mapping[str, str] | None = None) -> str:
    """The active baseline: name, version, tests, reason, and per parameter
    mean ± std in its unit (``units``: by parameter, a regime's ``Tc@forward``
    under ``Tc``) with the band it draws (±k·std) and the breakpoints."""
    from condmon.models.regimes import split_key

    if stored is None:
        return ("<h2 id='baseline'>Baseline</h2><p class='sub'>No baseline yet (fewer than 3 "
                "accepted healthy tests): checks are not evaluated.</p>")
    b = stored.baseline
    rows = []
    for p, m, s in zip(b.parameters, b.mean, b.std):
        rel = 100.0 * s / abs(m) if m else float("nan")
        r1, r2 = cfg.r1.get(p), cfg.r2.get(p)
        unit = (units or {}).get(split_key(p)[0], "")
        rows.append(f"<tr><td class='l'>{esc(p)}</td><td>{m:.5g} ± {s:.3g}</td>"
                    f"<td class='l'>{esc(unit)}</td>"
                    f"<td>{rel:.2f}</td><td>±{cfg.k * rel:.2f}</td>"
                    f"<td>{'—' if r1 is None else f'{r1:g}'}</td>"
                    f"<td>{'—' if r2 is None else f'{r2:g}'}</td></tr>")
    reason = f" — {esc(stored.reason)}" if stored.reason else ""
    return (f"<h2 id='baseline'>Baseline {esc(stored.name)} v{stored.version}</h2>"
            f"<p class='sub'>N = {b.n}, made {when(stored.created_at)} UTC{reason}; tests "
            f"{_test_links(stored.test_ids)}</p>"
            "<table><tr><th class='l'>parameter</th><th>mean ± std</th><th class='l'>unit</th>"
            "<th>std [%]</th>"
            f"<th>band ±{cfg.k:g}·std [%]</th><th>r1 [%]</th><th>r2 [%]</th></tr>"
            f"{''.join(rows)}</table>")


def faults_table(faults: Sequence[CheckFault]) -> str:
    """A check's faults: name, degree, severity and advice."""
    if not faults:
        return ""
    rows = "".join(f"<tr><td class='l'>{esc(f.name)}</td><td>{f.degree:.2f}</td>"
                   f"<td class='l'>{esc(f.severity)}</td><td class='l'>{esc(f.advice)}</td></tr>"
                   for f in faults)
    return ("<table><tr><th class='l'>fault</th><th>degree</th><th class='l'>severity</th>"
            f"<th class='l'>advice</th></tr>{rows}</table>")


def _change_cell(r: Any, p: str) -> str:
    import pandas as pd

    ch = r.get(f"{p}_change")
    if ch is None or pd.isna(ch):
        return "<td></td>"
    hi, lo = r.get(f"{p}_high"), r.get(f"{p}_low")
    hi = 0.0 if hi is None or pd.isna(hi) else float(hi)
    lo = 0.0 if lo is None or pd.isna(lo) else float(lo)
    deg = max(hi, lo)
    style = f" style='background:rgba(239,108,0,{0.12 + 0.6 * deg:.2f})'" if deg > 0 else ""
    return f"<td class='v' title='SymH {hi:.2f}, SymL {lo:.2f}'{style}>{ch:+.1f}</td>"



def test_note(row: Any) -> str:
    """What a test row of the history says beside its status: the exclusion's
    reason, a check's diagnosis summary, or why the estimate was rejected."""
    if row["status"] == "excluded":
        return f"excluded: {row['excluded_reason'] or 'no reason given'}"
    if row["accepted"] and isinstance(row["summary"], str):
        return str(row["summary"])
    return str(row["reason"] or "")

def tests_table(hist: Any, params: Sequence[str], stored: Any,
                versions: Mapping[int, str]) -> str:
    """Every test: id, date, source, role, fit, status, changes and why.

    Changes are tinted by their symptom (hover: SymH/SymL). Excluded tests
    are greyed with the reason; a check evaluated against another baseline
    than the active one says which.
    """
    import pandas as pd

    members = set(stored.test_ids) if stored is not None else set()
    active = stored.id if stored is not None else None
    head = ("<table><tr><th>#</th><th class='l'>date (UTC)</th><th class='l'>source</th>"
            "<th class='l'>role</th><th>fit [%]</th><th class='l'>status</th>"
            + "".join(f"<th>{esc(p)} Δ [%]</th>" for p in params)
            + "<th class='l'>diagnosis or reason</th></tr>")
    rows = []
    for tid, r in hist.iterrows():
        status = str(r["status"])
        excluded = status == "excluded"
        cells = ("<td></td>" * len(params) if excluded or r["role"] != "check"
                 else "".join(_change_cell(r, p) for p in params))
        fit = f"{r['fit_percent']:.1f}" if pd.notna(r["fit_percent"]) else "—"
        why = test_note(r)
        bid = r["baseline_id"]
        if (not excluded and r["role"] == "check" and pd.notna(bid) and active is not None
                and int(bid) != active):
            why += f" (against baseline {versions.get(int(bid), f'id {int(bid)}')})"
        date = when(r["date"]) + ("" if pd.notna(r["test_date"]) else " (stored)")
        role = str(r["role"])
        if int(tid) in members:
            role += " ●"
        rows.append(f"<tr id='t{int(tid)}' class='{'excluded' if excluded else ''}'>"
                    f"<td>#{int(tid)}</td><td class='l'>{esc(date)}</td>"
                    f"<td class='l v'>{esc(r['source'])}</td><td class='l'>{esc(role)}</td>"
                    f"<td>{fit}</td><td class='l'>{badge(status)}</td>{cells}"
                    f"<td class='l'>{esc(why)}</td></tr>")
    legend = ("<p class='sub'>●: member of the active baseline; tinted changes: their "
              "symptom is above 0 (hover for SymH/SymL); excluded tests are greyed and "
              "never trended.</p>")
    return head + "".join(rows) + "</table>" + legend


def isolations_table(isos: Any) -> str:
    """Every isolation: id, date, source, status, detection, isolated suspects,
    the conclusion and each suspect's estimated change (isolated ones bold)."""
    import pandas as pd

    params = sorted(c[: -len("_change")] for c in isos.columns if c.endswith("_change"))
    rows = []
    for iid, r in isos.iterrows():
        det = f"{r['detection_time']:.2f} s" if pd.notna(r["detection_time"]) else "—"
        excluded = bool(r["excluded"])
        status = "excluded" if excluded else str(r["status"])
        cells = []
        for p in params:
            v = r.get(f"{p}_change")
            if v is None or pd.isna(v):
                cells.append("<td></td>")
                continue
            flag = r.get(f"{p}_rejected")
            if flag is not None and pd.notna(flag) and bool(flag):
                cells.append(f"<td title='estimate {v:+.4g} %, left out of the comparison'>"
                             "rejected</td>")
                continue
            text = f"{v:+.1f}"
            cells.append(f"<td><b>{text}</b></td>" if p in list(r["isolated"])
                         else f"<td>{text}</td>")
        rows.append(f"<tr id='i{int(iid)}' class='{'excluded' if excluded else ''}'>"
                    f"<td>i{int(iid)}</td><td class='l'>{when(r['date'])}"
                    f"{'' if pd.notna(r['test_date']) else ' (stored)'}</td>"
                    f"<td class='l v'>{esc(r['source'])}</td><td class='l'>{badge(status)}</td>"
                    f"<td>{det}</td><td class='l'>{esc(', '.join(r['isolated']) or '—')}</td>"
                    f"<td class='l'>{esc(r['statement'])}</td>{''.join(cells)}</tr>")
    return ("<table><tr><th>#</th><th class='l'>date (UTC)</th><th class='l'>source</th>"
            "<th class='l'>status</th><th>detected</th><th class='l'>isolated</th>"
            "<th class='l'>conclusion</th>"
            + "".join(f"<th>{esc(p)} Δ [%]</th>" for p in params)
            + f"</tr>{''.join(rows)}</table>")
