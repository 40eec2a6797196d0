"""HTML pieces of the report pages: badges, the baseline, the tests, the isolations.

Every value that comes from the history (names, sources, reasons, advice) is
escaped for text and attributes alike (:func:`esc`). Tests are numbered by
their id (``#12``, anchor ``t12``), isolations by theirs (``i3``).
"""

from __future__ import annotations

import html
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from condmon.monitor.fuzzy import MonitorConfig
    from condmon.report.reading import CheckFault

__all__ = ["CSS", "STATUSES", "esc", "badge", "when", "page", "flags_box", "test_note",
           "tests_summary",
           "baseline_section", "faults_table", "tests_table", "isolations_table", "with_unit",
           "SuspectCell", "SUSPECT_HEADS", "isolation_suspects", "suspect_cells",
           "latest_isolation", "suspects_table", "unit_of"]

#: Every status a page may show.
STATUSES = ("go", "advisory", "no-go", "retest", "not judged", "building", "baseline",
            "rejected", "excluded", "unchecked")

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2em;color:#222;max-width:1150px}
h1{margin-bottom:0}.sub{color:#666;margin-top:.2em}a{color:#1f4e79}
.status{display:inline-block;padding:.15em .6em;border-radius:4px;font-weight:bold;color:#fff}
.go{background:#2e7d32}.advisory{background:#ef6c00}.no-go{background:#c62828}.retest{background:#546e7a}.not-judged{background:#00838f}
.baseline,.unchecked{background:#7f8c8d}.building{background:#90a4ae}.rejected{background:#c0392b}.excluded{background:#bdbdbd}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0 1.5em}
td,th{border:1px solid #ddd;padding:.25em .6em;text-align:right}th{background:#f3f3f3}
td.l,th.l{text-align:left}img{max-width:100%;border:1px solid #eee;margin:.5em 0}
tr.excluded td{color:#999}tr.excluded td.v{text-decoration:line-through}
td.s.left-out{color:#999}td.s{white-space:nowrap}
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
    return (f'<span class="status {s.replace(" ", "-")}">{esc(s)}</span>' if s in STATUSES
            else esc(s))


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


def tests_summary(hist: Any, stored: Any) -> str:
    """What a unit's tests are, for a page's header: in the baseline in use
    (``stored``'s tests, which a rebuild from chosen tests makes of checks too),
    left out of it, checks, excluded; without a stored baseline, the tests
    added for one. The counts add up to the tests.

    Example
    -------
    >>> import pandas as pd
    >>> hist = pd.DataFrame({"role": ["baseline"] * 3 + ["check"] * 3,
    ...                      "excluded": [False, False, True] + [False] * 3}, index=range(1, 7))
    >>> class V2:
    ...     test_ids = (2, 4, 5)
    >>> tests_summary(hist, V2())
    '3 in the baseline in use, 1 left out of it, 1 check, 1 excluded'
    >>> tests_summary(hist, None)
    '2 for the baseline, 3 checks, 1 excluded'
    """
    if not len(hist):
        return "none"
    excluded = hist["excluded"].astype(bool).to_numpy()
    role = hist["role"].to_numpy()
    member = (hist.index.isin(stored.test_ids) if stored is not None else
              role == "baseline") & ~excluded
    left = (role == "baseline") & ~member & ~excluded
    checks = ~member & ~left & ~excluded
    parts = [f"{int(member.sum())} " + ("in the baseline in use" if stored is not None else
                                        "for the baseline")]
    if left.any():
        parts.append(f"{int(left.sum())} left out of it")
    n = int(checks.sum())
    parts += [f"{n} check{'' if n == 1 else 's'}", f"{int(excluded.sum())} excluded"]
    return ", ".join(parts)


def unit_of(units: Mapping[str, str], key: str) -> str:
    """The unit of a parameter, a regime's (``Tc@forward``) under its parameter's name.

    Example
    -------
    >>> unit_of({"Tc": "N m"}, "Tc@forward")
    'N m'
    """
    from condmon.models.regimes import split_key

    return units.get(key) or units.get(split_key(key)[0], "")


def baseline_section(stored: Any, cfg: MonitorConfig,
                     units: Mapping[str, str] | None = None, history: Any = None) -> str:
    """The baseline in use: name, version, when it was built, the tests it
    holds (per regime too, counted in ``history`` when given), reason, and per parameter
    mean ± std in its unit (``units``: by parameter, a regime's ``Tc@forward``
    under ``Tc``) with the band it draws (±k·std) and the breakpoints."""
    if stored is None:
        return ("<h2 id='baseline'>Baseline</h2><p class='sub'>No baseline yet (fewer than 3 "
                "accepted healthy tests): checks are not evaluated.</p>")
    b = stored.baseline
    rows = []
    for p, m, s in zip(b.parameters, b.mean, b.std):
        rel = 100.0 * s / abs(m) if m else float("nan")
        r1, r2 = cfg.r1.get(p), cfg.r2.get(p)
        unit = unit_of(units or {}, p)
        rows.append(f"<tr><td class='l'>{esc(p)}</td><td>{m:.5g} ± {s:.3g}</td>"
                    f"<td class='l'>{esc(unit)}</td>"
                    f"<td>{rel:.2f}</td><td>±{cfg.k * rel:.2f}</td>"
                    f"<td>{'—' if r1 is None else f'{r1:.3g}'}</td>"
                    f"<td>{'—' if r2 is None else f'{r2:.3g}'}</td></tr>")
    reason = f" — {esc(stored.reason)}" if stored.reason else ""
    return (f"<h2 id='baseline'>Baseline in use: {esc(stored.name)} v{stored.version}</h2>"
            f"<p class='sub'>{esc(stored.describe(history))}{reason}; tests "
            f"{_test_links(stored.test_ids)}</p>"
            "<table><tr><th class='l'>parameter</th><th>mean ± std</th><th class='l'>unit</th>"
            "<th>std [%]</th>"
            f"<th>band ±{cfg.k:g}·std [%]</th><th>r1 [%]</th><th>r2 [%]</th></tr>"
            f"{''.join(rows)}</table>")


def faults_table(faults: Sequence[CheckFault]) -> str:
    """A check's faults: name, degree, severity in this check and advice, with
    what the severity means (a major rule below no-go is listed minor)."""
    from condmon.diagnose.diagnoser import LEVEL_NOTE

    if not faults:
        return ""
    rows = "".join(f"<tr><td class='l'>{esc(f.name)}</td><td>{f.degree:.2f}</td>"
                   f"<td class='l'>{esc(f.severity)}</td><td class='l'>{esc(f.advice)}</td></tr>"
                   for f in faults)
    return ("<table><tr><th class='l'>fault</th><th>degree</th>"
            "<th class='l'>severity in this check</th>"
            f"<th class='l'>advice</th></tr>{rows}</table><p class='sub'>{esc(LEVEL_NOTE)}</p>")


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


def with_unit(value: Any, unit: str | None, fmt: str = ".4g") -> str:
    """A number with its unit (``""`` for a missing value; no unit text for a
    dimensionless ``-``).

    Examples
    --------
    >>> with_unit(1.7524e11, "N s/m^5"), with_unit(0.93, "-"), with_unit(float("nan"), "m")
    ('1.752e+11 N s/m^5', '0.93', '')
    """
    import math

    if value is None or not isinstance(value, (int, float)) or not math.isfinite(value):
        return ""
    return f"{value:{fmt}}" + (f" {unit}" if unit and unit != "-" else "")


#: A change beyond this is an estimate that ran away (a search beyond a factor
#: of 100 of its nominal), not a measured change. [%]
RAN_AWAY = 1e4


def percent_text(value: float) -> str:
    """A change in percent, signed, one decimal; ``ran away`` beyond
    :data:`RAN_AWAY`, ``not finite`` when it is not."""
    import math

    if not math.isfinite(value):
        return "not finite"
    return f"{value:+.1f}" if abs(value) < RAN_AWAY else "ran away"


def estimate_text(value: float | None, change: float | None,
                  number: Callable[[float], str] = lambda v: f"{v:.4g}") -> str:
    """An estimate's cell: its value (written by ``number``), ``ran away`` when its change against
    nominal is beyond :data:`RAN_AWAY` (4.6e+47 is no estimate), ``not
    finite`` when it is not, ``—`` when there is none.

    Example
    -------
    >>> estimate_text(4.6e47, 4.6e49), estimate_text(1.25, 25.0), estimate_text(float("inf"), None)
    ('ran away', '1.25', 'not finite')
    """
    import math

    if value is None:
        return "—"
    if not math.isfinite(value):
        return "not finite"
    if change is not None and math.isfinite(change) and abs(change) >= RAN_AWAY:
        return "ran away"
    return number(value)


@dataclass(frozen=True)
class SuspectCell:
    """One suspect's result in one isolation, as the report and the fleet page show it.

    Attributes
    ----------
    name : str
    estimate, nominal : float or None
        Its steady-state estimate and the value it was compared with. [unit]
    unit : str
        Of the estimate and the nominal, as the model declares it.
    change : float or None
        Estimate against nominal (None without a nominal to compare with). [%]
    error : float or None
        Its model's output error. [sensor-noise standard deviations]
    isolated, rejected : bool
        Named by the isolation; left out of the comparison.
    """

    name: str
    estimate: float | None
    nominal: float | None
    unit: str
    change: float | None
    error: float | None
    isolated: bool
    rejected: bool

    @property
    def text(self) -> str:
        """The isolations table's cell: ``+75.2 %``, ``rejected``, or the estimate
        in its unit when there is no change to give (a nominal of 0)."""
        if self.rejected:
            return "rejected"
        if self.change is not None:
            return f"{percent_text(self.change)} %"
        return f"= {with_unit(self.estimate, self.unit)}" if self.estimate is not None else ""

    @property
    def title(self) -> str:
        """Hover text: estimate and nominal in their unit, the model's output error."""
        parts = (f"estimate {with_unit(self.estimate, self.unit)}"
                 if self.estimate is not None else "",
                 f"nominal {with_unit(self.nominal, self.unit)}"
                 if self.nominal is not None else "",
                 f"model error {self.error:.2g} noise σ" if self.error is not None else "",
                 "left out of the comparison" if self.rejected else "")
        return ", ".join(p for p in parts if p)

    @property
    def row(self) -> tuple[str, ...]:
        """The suspects table's row (:data:`SUSPECT_HEADS`): name, estimate,
        nominal, unit, change [%], model error [noise σ], ``isolated`` or ``rejected``."""
        def g(v: float | None, fmt: str) -> str:
            return "—" if v is None else f"{v:{fmt}}"

        return (self.name, estimate_text(self.estimate, self.change), g(self.nominal, ".4g"),
                self.unit,
                "—" if self.change is None else percent_text(self.change), g(self.error, ".2g"),
                "rejected" if self.rejected else "isolated" if self.isolated else "")


#: Heads of the suspects table (:attr:`SuspectCell.row`).
SUSPECT_HEADS = ("suspect", "estimate", "nominal", "unit", "change [%]",
                 "model error [noise σ]", "")


def isolation_suspects(isos: Any) -> list[str]:
    """Every suspect of any of the isolations, sorted."""
    return sorted({s for v in isos["suspects"] for s in v}) if len(isos) else []


def suspect_cells(row: Any, suspects: Sequence[str],
                  units: Mapping[str, str]) -> list[SuspectCell]:
    """Each suspect's result in an isolation ``row`` (of :meth:`HistoryStore.isolations`),
    with its unit (``units``: by parameter)."""
    import pandas as pd

    def num(key: str) -> float | None:
        v = row.get(key)
        return None if v is None or pd.isna(v) else float(v)

    cells = []
    for p in suspects:
        flag = row.get(f"{p}_rejected")
        cells.append(SuspectCell(p, num(p), num(f"{p}_nominal"), units.get(p, ""),
                                 num(f"{p}_change"), num(f"{p}_error"),
                                 p in list(row["isolated"]),
                                 bool(flag is not None and pd.notna(flag) and flag)))
    return cells


def latest_isolation(isos: Any) -> Any:
    """The newest isolation that is not excluded (by date, then id), or None."""
    kept = isos[~isos["excluded"].astype(bool)] if len(isos) else isos
    if not len(kept):
        return None
    return kept.sort_index().sort_values("date", kind="stable").iloc[-1]


def suspects_table(isos: Any, units: Mapping[str, str]) -> str:
    """The latest isolation's suspects: estimate and nominal in their unit,
    change, model error, isolated or rejected ("" without an isolation)."""
    row = latest_isolation(isos)
    if row is None:
        return ""

    def cls(j: int) -> str:
        return " class='l'" if j in (0, 3, 6) else ""

    body = "".join("<tr>" + "".join(f"<td{cls(j)}>{esc(v)}</td>" for j, v in enumerate(c.row))
                   + "</tr>" for c in suspect_cells(row, isolation_suspects(isos), units))
    heads = "".join(f"<th{cls(j)}>{esc(h)}</th>" for j, h in enumerate(SUSPECT_HEADS))
    return (f"<h3>Suspects of the latest isolation, i{int(row.name)}</h3>"
            f"<table class='suspects'><tr>{heads}</tr>{body}</table>"
            "<p class='sub'>Model error: the suspect's model's output error in sensor-noise "
            "standard deviations (about 1 explains the record).</p>")


def isolations_table(isos: Any, units: Mapping[str, str] | None = None) -> str:
    """Every isolation: id, date, source, status, detection, isolated suspects,
    the conclusion and each suspect's estimate against nominal [%] (isolated
    ones bold; hover: estimate and nominal in their unit, ``units`` by
    parameter, and the model's output error), then the latest isolation's
    suspects (:func:`suspects_table`)."""
    import pandas as pd

    units = units or {}
    params = isolation_suspects(isos)
    rows = []
    for iid, r in isos.iterrows():
        det = f"{r['detection_time']:.2f} s" if pd.notna(r["detection_time"]) else "—"
        excluded = bool(r["excluded"])
        status = "excluded" if excluded else str(r["status"])
        cells = "".join(
            f"<td class='s{' named' if c.isolated else ''}{' left-out' if c.rejected else ''}' "
            f"title='{esc(c.title)}'>"
            + (f"<b>{esc(c.text)}</b>" if c.isolated and not c.rejected else esc(c.text))
            + "</td>" for c in suspect_cells(r, params, units))
        rows.append(f"<tr id='i{int(iid)}' class='{'excluded' if excluded else ''}'>"
                    f"<td>i{int(iid)}</td><td class='l'>{when(r['date'])}"
                    f"{'' if pd.notna(r['test_date']) else ' (stored)'}</td>"
                    f"<td class='l v'>{esc(r['source'])}</td><td class='l'>{badge(status)}</td>"
                    f"<td>{det}</td><td class='l'>{esc(', '.join(r['isolated']) or '—')}</td>"
                    f"<td class='l'>{esc(r['statement'])}</td>{cells}</tr>")
    return ("<table><tr><th>#</th><th class='l'>date (UTC)</th><th class='l'>source</th>"
            "<th class='l'>status</th><th>detected</th><th class='l'>isolated</th>"
            "<th class='l'>conclusion</th>"
            + "".join(f"<th>{esc(p)} Δ</th>" for p in params)
            + f"</tr>{''.join(rows)}</table>"
            "<p class='sub'>Δ: each suspect's steady-state estimate against nominal [%] (with "
            "a nominal of 0, the estimate in its unit); bold: isolated; hover for the "
            "estimate, the nominal and the model's output error.</p>"
            + suspects_table(isos, units))
