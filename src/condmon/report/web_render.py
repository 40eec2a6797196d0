"""What the live fleet page draws: a unit's trend figure (inline SVG), the
report's figures and the rows of its tables.

This module holds the rendering side of :mod:`condmon.report.web`, free of
the web framework: the trend panels a unit's page draws as SVG (each
parameter's change against the baseline over the test dates, or the test ids
when none is recorded, with the r1/r2 bands, the baseline spread and each
test's symptom half-width ±k·max(σ, SE) as its error bar, and for a parameter
trending towards no-go its forecast band), the report's fit,
symptom and isolation figures as ``data:`` images (drawn by
:mod:`condmon.report.figures`), the rows of its tests and isolations tables
(each suspect's numbers with their units, as the report's), and the dates as
the page writes them. The templates turn these into HTML.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any, cast

from condmon.report.figures import STATUS_COLOURS
from condmon.report.tables import (
    SUSPECT_HEADS, isolation_suspects, latest_isolation, suspect_cells, test_note,
)
from condmon.report.trends import FORECAST_LABEL, error_bar, forecast_bands

if TYPE_CHECKING:
    import pandas as pd

    from condmon.report.trends import TrendData
    from condmon.report.web_data import UnitData

__all__: list[str] = []


# -- the trend figure (inline SVG) -----------------------------------------------------
_W, _H = 460, 210
_LEFT, _RIGHT, _TOP, _BOTTOM = 54, 12, 20, 34
_TIME_STEPS = (1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600, 7200, 10800, 21600,
               43200, 86400, 2 * 86400, 7 * 86400, 14 * 86400, 30 * 86400, 61 * 86400,
               91 * 86400, 182 * 86400, 365 * 86400, 730 * 86400, 1826 * 86400)


@dataclass(frozen=True)
class _Point:
    x: float
    y: float
    y_low: float
    y_high: float
    colour: str
    test_id: int
    title: str
    member: bool


@dataclass(frozen=True)
class _Forecast:
    band: str      # the 90 % band's polygon
    trend: str     # the fitted trend continued
    no_go: float   # y of the no-go line
    title: str


@dataclass(frozen=True)
class _Panel:
    parameter: str
    bands: list[tuple[float, float, str]]
    zero: float
    yticks: list[tuple[float, str]]
    xticks: list[tuple[float, str]]
    points: list[_Point]
    line: str
    width: int = _W
    height: int = _H
    left: int = _LEFT
    right: int = _W - _RIGHT
    top: int = _TOP
    bottom: int = _H - _BOTTOM
    forecast: _Forecast | None = None


@dataclass(frozen=True)
class _Trends:
    panels: list[_Panel] = field(default_factory=list)
    xlabel: str = ""
    statuses: list[str] = field(default_factory=list)
    k: float = 2.0
    banded: bool = False
    spread: bool = False
    untrended: list[str] = field(default_factory=list)
    checks: tuple[TrendData, ...] = ()  # what the report's trend and symptom figures draw
    forecast: bool = False  # a panel draws a forecast band


def _nice(span: float, count: int = 5) -> float:
    raw = span / count
    mag = 10.0 ** math.floor(math.log10(raw))
    return float(next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw))


def _time_ticks(lo: float, hi: float) -> list[tuple[float, str]]:
    step = next((s for s in _TIME_STEPS if (hi - lo) / s <= 6), _TIME_STEPS[-1])
    fmt = ("%Y-%m-%d" if step >= 86400 else "%m-%d %H:%M" if step >= 60 else "%H:%M:%S")
    first = math.ceil(lo / step) * step
    return [(t, datetime.fromtimestamp(t, timezone.utc).strftime(fmt))
            for t in (first + i * step for i in range(int((hi - first) // step) + 1))]


def _trends(data: UnitData) -> _Trends:
    """The trend panels: accepted checks that are not excluded, at their change
    against the baseline they were evaluated with (:func:`trend_data`, as the
    report's trend figure), and the active baseline's tests at their deviation
    from its mean; every error bar is the symptom half-width ±k·max(σ, SE)
    (:func:`condmon.monitor.fuzzy.symptom_width`)."""
    from condmon.monitor.fuzzy import symptom_width
    from condmon.report.trends import trend_data

    hist, cfg, stored = data.history, data.monitor, data.baseline
    if not len(hist):
        return _Trends()
    params = ([p for p in cfg.r1 if p in hist.columns] if cfg is not None else
              [c[:-len("_change")] for c in hist.columns
               if c.endswith("_change") and c[:-len("_change")] in hist.columns])
    k = cfg.k if cfg is not None else 2.0
    stats = {} if stored is None else {
        p: (m, s) for p, m, s in zip(stored.baseline.parameters, stored.baseline.mean,
                                     stored.baseline.std) if m}
    members = [] if stored is None else [
        i for i in stored.test_ids if i in hist.index and not hist.loc[i, "excluded"]]
    checks = [int(i) for i in hist.index[(hist["role"] == "check") & hist["accepted"]
                                         & ~hist["excluded"]
                                         & (hist["status"] != "not judged")]]
    if not params or not (members or checks):
        return _Trends(untrended=_untrended(hist))
    stamps = {int(str(i)): float(d.timestamp()) for i, d in hist["date"].items()}
    dated = bool(hist["test_date"].notna().any())
    shown = sorted({*members, *checks})
    if dated:  # on the time axis
        where = {i: stamps[i] for i in shown}
    else:  # no test dates: one step per test, in id order
        where = {i: float(n) for n, i in enumerate(shown)}
    ahead = {b.parameter: (b, b.x([where[i] for i in b.test_ids], 86400.0))
             for b in forecast_bands(data.forecast)
             if all(i in where for i in b.test_ids) and (dated or b.by == "tests")}
    if dated:
        lo = min(where.values())
        hi = max([*where.values(), *(float(x[-1]) for _, x in ahead.values())])
        pad = max((hi - lo) * 0.05, 3600.0)
        lo, hi = lo - pad, hi + pad
        xticks = _time_ticks(lo, hi)
    else:
        lo = -0.6
        hi = max([len(shown) - 0.4, *(float(x[-1]) + 0.4 for _, x in ahead.values())])
        every = max(1, math.ceil(len(shown) / 12))
        xticks = [(where[i], f"#{i}") for i in shown[::every]]

    def px(t: float) -> float:
        return _LEFT + (t - lo) / (hi - lo) * (_W - _LEFT - _RIGHT)

    def value(i: int, column: str) -> float:
        v: Any = hist.loc[i, column] if column in hist.columns else None
        return float(v) if isinstance(v, (int, float)) and v == v else math.nan

    by_id = {b.id: b.baseline for b in data.baselines}
    active = None if stored is None else stored.id
    panels, seen, drawn = [], [], []
    for p in params:
        mean, std = stats.get(p, (math.nan, math.nan))
        scale = 100.0 / abs(mean)  # nan without a baseline
        pts = [(i, (value(i, p) - mean) * scale,
                float(symptom_width(mean, std, value(i, f"{p}_se"), k)), "baseline", True)
               for i in members]
        r1 = cfg.r1.get(p, math.nan) if cfg is not None else math.nan
        r2 = cfg.r2.get(p, math.nan) if cfg is not None else math.nan
        d = trend_data(hist, p, by_id, r1, r2, k, active)
        drawn.append(d)
        pts += [(i, float(c), float(w), s, False)   # coloured by this parameter's symptom
                for i, c, w, s in zip(d.test_ids, d.change, d.width, d.panel_status)]
        pts = [t for t in pts if math.isfinite(t[1])]
        spread = k * std * scale if math.isfinite(std * scale) else 0.0
        reach = [abs(c) + (e if math.isfinite(e) else 0.0) for _, c, e, _, _ in pts]
        top = max([r2 * 1.15 if math.isfinite(r2) else 0.0, spread * 1.3, *reach, 1.0]) * 1.08
        step = _nice(2 * top)

        def py(v: float, top: float = top) -> float:
            return _TOP + (top - v) / (2 * top) * (_H - _TOP - _BOTTOM)

        bands = []
        if math.isfinite(r1) and math.isfinite(r2):
            for a, b, cls in ((r1, r2, "developing"), (r2, top, "fault")):
                if a < top:
                    bands += [(py(min(b, top)), py(a), cls), (py(-a), py(-min(b, top)), cls)]
        if spread > 0:
            bands.append((py(min(spread, top)), py(-min(spread, top)), "spread"))
        ticks = [v * step for v in range(-int(top // step), int(top // step) + 1)]
        points = []
        for i, c, e, s, member in sorted(pts, key=lambda t: (where[t[0]], t[0])):
            when = datetime.fromtimestamp(stamps[i], timezone.utc).strftime("%Y-%m-%d %H:%M")
            bar = f" ± {e:.2g} % ({error_bar(k)})" if math.isfinite(e) else ""
            role = "baseline test" if member else s
            points.append(_Point(px(where[i]), py(c), py(c - e) if math.isfinite(e) else py(c),
                                 py(c + e) if math.isfinite(e) else py(c),
                                 STATUS_COLOURS.get(s, "#444"), i,
                                 f"#{i} {when} {role}: {p} {c:+.1f} %{bar}", member))
            seen.append(s)
        line = " ".join(f"{q.x:.1f},{q.y:.1f}" for q in points if not q.member)
        drawn_band = None
        if p in ahead:
            fb, fx = ahead[p]

            def at(v: float, top: float = top) -> float:
                return py(min(max(v, -top), top))

            edge = [f"{px(x):.1f},{at(y):.1f}" for x, y in zip(fx, fb.low)]
            edge += [f"{px(x):.1f},{at(y):.1f}" for x, y in zip(fx[::-1], fb.high[::-1])]
            drawn_band = _Forecast(
                " ".join(edge), " ".join(f"{px(x):.1f},{at(y):.1f}" for x, y in zip(fx, fb.median)),
                at(fb.threshold), f"{p}: {FORECAST_LABEL} of the fitted trend continued to the "
                f"no-go line ({fb.threshold:+g} %)")
        panels.append(_Panel(p, bands, py(0.0), [(py(v), f"{v:+g}") for v in ticks],
                             [(px(t), label) for t, label in xticks
                              if 28 <= px(t) <= _W - 28],  # the label fits the figure
                             points, line, forecast=drawn_band))
    xlabel = ("test date (UTC)" if dated and not hist["test_date"].isna().any() else
              "date (UTC): test date, else when stored" if dated else
              "test # (no test dates recorded)")
    order: list[str] = [s for s in ("baseline", "go", "advisory", "no-go", "unchecked")
                        if s in seen]
    return _Trends(panels, xlabel, order, k, cfg is not None, bool(stats), _untrended(hist),
                   tuple(drawn), any(q.forecast for q in panels))


# -- the report's figures, as images in the page ------------------------------------------
@dataclass(frozen=True)
class _Figure:
    name: str
    caption: str
    uri: str


def _png_uri(fig: Any) -> str:
    """A figure as a ``data:`` URI of its PNG (the page never writes a file)."""
    import base64
    import io

    from condmon.report.figures import save_figure

    png = io.BytesIO()
    save_figure(fig, png)
    return "data:image/png;base64," + base64.b64encode(png.getvalue()).decode("ascii")


#: Figures drawn, by a digest of exactly what they draw (so a unit's figures are
#: drawn once per state of its history, and a changed history can never show
#: old ones); the least recently shown are dropped beyond :data:`FIGURE_CACHE`.
_DRAWN: OrderedDict[str, _Figure] = OrderedDict()
_DRAWN_LOCK = threading.Lock()
#: How many figures the page keeps drawn (about 50-150 kB each).
FIGURE_CACHE = 96


def _digest(what: object) -> str | None:
    """A digest of ``what``'s pickle, or None when it cannot be pickled."""
    import hashlib
    import pickle

    try:
        return hashlib.blake2b(pickle.dumps(what, protocol=5), digest_size=20).hexdigest()
    except (pickle.PicklingError, TypeError, AttributeError, RecursionError):
        return None


def _drawn(name: str, caption: str, inputs: object, draw: Any) -> _Figure:
    """The figure ``draw()`` makes of ``inputs``, drawn once per content."""
    key = _digest((name, caption, inputs))
    if key is not None:
        with _DRAWN_LOCK:
            hit = _DRAWN.get(key)
            if hit is not None:
                _DRAWN.move_to_end(key)
                return hit
    fig = _Figure(name, caption, _png_uri(draw()))
    if key is not None:
        with _DRAWN_LOCK:
            _DRAWN[key] = fig
            while len(_DRAWN) > FIGURE_CACHE:
                _DRAWN.popitem(last=False)
    return fig


def _figures(data: UnitData, trends: _Trends) -> dict[str, _Figure]:
    """The report's fit, symptom and isolation figures of the unit, drawn by
    the report's own code (:mod:`condmon.report.figures`) from what the page
    read: ``fits``, ``symptoms`` (with trended checks) and ``isolations``.
    Each is drawn once for what it shows (:func:`_drawn`)."""
    from condmon.identify.defaults import DEFAULT_FIT_THRESHOLD
    from condmon.report.figures import fit_figure, isolation_figure, symptom_figure
    from condmon.report.trends import fit_data, isolation_trend

    out = {}
    if len(data.history):
        fits = fit_data(data.history)
        out["fits"] = _drawn("fits", "Model fit of every test that is not excluded, with the "
                             f"{DEFAULT_FIT_THRESHOLD:g} % threshold [%]", fits,
                             lambda: fit_figure(fits, DEFAULT_FIT_THRESHOLD))
    if trends.checks and trends.checks[0].test_ids:
        out["symptoms"] = _drawn("symptoms", "Fuzzy symptoms of each trended check, SymH up "
                                 "and SymL down, per parameter [-]", trends.checks,
                                 lambda: symptom_figure(trends.checks))
    iso = isolation_trend(data.isolations) if len(data.isolations) else None
    if iso is not None and iso.isolation_ids:
        out["isolations"] = _drawn("isolations", "Each suspect's steady-state estimate "
                                   "against nominal, per isolation [%]", iso,
                                   lambda: isolation_figure(iso))
    return out


def _untrended(hist: pd.DataFrame) -> list[str]:
    """Tests left out of the trends, with why."""
    out = []
    for i, r in hist.iterrows():
        if r["status"] in ("excluded", "rejected", "retest"):
            out.append(f"#{i} {r['status']}")
    return out


# -- rows of the tables -----------------------------------------------------------------
def _fmt_date(value: Any, stored: bool = False) -> str:
    import pandas as pd

    if value is None or (not isinstance(value, str) and pd.isna(value)):
        return "—"
    stamp = pd.Timestamp(value)
    stamp = stamp.tz_localize("UTC") if stamp.tzinfo is None else stamp.tz_convert("UTC")
    return f"{stamp:%Y-%m-%d %H:%M}" + (" (stored)" if stored else "")


def _test_rows(hist: pd.DataFrame, params: Sequence[str]) -> list[dict[str, Any]]:
    import pandas as pd

    rows = []
    for tid, r in hist.iterrows():
        status = str(r["status"])
        excluded = status == "excluded"
        changes = [f"{r[f'{p}_change']:+.1f}" if not excluded and f"{p}_change" in r
                   and pd.notna(r[f"{p}_change"]) else "" for p in params]
        note = test_note(r)
        rows.append({"id": int(cast(int, tid)),
                     "date": _fmt_date(r["date"], pd.isna(r["test_date"])),
                     "source": str(r["source"]), "role": str(r["role"]), "status": status,
                     "fit": f"{r['fit_percent']:.1f}" if pd.notna(r["fit_percent"]) else "—",
                     "regime": str(r["regime"]) if "regime" in r and pd.notna(r["regime"])
                     else "",
                     "changes": changes, "note": note, "excluded": excluded})
    return rows


def _isolation_rows(isos: pd.DataFrame, units: Mapping[str, str]
                    ) -> tuple[list[str], list[dict[str, Any]], dict[str, Any] | None]:
    """The isolations table's suspects and rows (each suspect's cell as the
    report's, :func:`~condmon.report.tables.suspect_cells`), and the latest
    isolation's suspects table (``id``, ``heads``, ``cells``: every estimate
    and nominal with its unit), as the report's."""
    import pandas as pd

    suspects = isolation_suspects(isos)
    rows = []
    for iid, r in isos.iterrows():
        cells = suspect_cells(r, suspects, units)
        det = r["detection_time"]
        rows.append({"id": int(cast(int, iid)),
                     "date": _fmt_date(r["date"], pd.isna(r["test_date"])),
                     "source": str(r["source"]),
                     "status": "excluded" if r["excluded"] else str(r["status"]),
                     "detected": f"{det:.2f} s" if pd.notna(det) else "—",
                     "isolated": ", ".join(r["isolated"]) or "—",
                     "statement": str(r["statement"] or ""),
                     "reason": str(r["reason"]) if isinstance(r["reason"], str) else "",
                     "cells": cells})
    latest = latest_isolation(isos)
    table = None if latest is None else {
        "id": int(latest.name), "heads": SUSPECT_HEADS,
        "cells": suspect_cells(latest, suspects, units)}
    return suspects, rows, table
