"""A live fleet page: every unit's latest status, each unit's trends, tests and
isolations, and the same as JSON, read from the history at every request.

:func:`create_app` builds the web application (Flask) over a history database
and :func:`serve` runs it (waitress) until Ctrl-C; ``condmon serve`` is the two
together. The page only reads: a SQLite history is opened read-only
(``mode=ro``), a PostgreSQL one in read-only transactions, so nothing is ever
written, created or migrated.

Routes
------
``/``
    Every unit with its latest status, model, date, number of tests and
    isolations and baseline flags. ``?status=no-go&q=EMA`` filters (several
    statuses: ``status=go,advisory``; ``q``: part of the name, any case).
``/units/<unit>``
    One unit: latest status and fault advice, trend figure (inline SVG: change
    against the baseline over the test dates, or the test ids when none is
    recorded; r1/r2 bands, the baseline spread, each estimate's standard
    error), baseline, tests, isolations.
``/api/units``
    ``{"units": [...]}`` as ``condmon units --json`` (same filters as ``/``).
``/api/units/<unit>``
    The unit's overview, tests (as ``condmon history --json``), isolations,
    baseline and latest fault advice.

Unit names may hold any character: ``/`` stays a path separator in the URL
(``/units/EMA/7``), everything else is percent-encoded; a name with a ``.`` or
``..`` segment, which browsers would fold away, is addressed as
``/unit?name=...`` (and ``/api/unit?name=...``).
"""

from __future__ import annotations

import json
import math
import signal
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast
from urllib.parse import quote

from flask import Flask, Response, render_template, request, url_for
from werkzeug.exceptions import HTTPException
from werkzeug.routing import BaseConverter

from condmon.errors import CondmonError, ConfigError
from condmon.report.figures import STATUS_COLOURS

if TYPE_CHECKING:
    import pandas as pd

    from condmon.monitor.fuzzy import MonitorConfig
    from condmon.store.baselines import StoredBaseline
    from condmon.store.db import HistoryStore

__all__ = ["create_app", "serve", "readonly_url", "fleet_document", "unit_document",
           "read_unit", "UnitData", "UnknownUnitError", "STATUSES"]

#: Statuses a unit can show (``none``: nothing stored yet), in the filter's order.
STATUSES = ("no-go", "advisory", "retest", "go", "unchecked", "baseline", "rejected",
            "excluded", "none")

_FILES = Path(__file__).with_name("web_files")


class UnknownUnitError(CondmonError, LookupError):
    """No unit of that name in the history."""


class FilterError(ConfigError):
    """A filter value that is not allowed (the message lists the allowed ones)."""


# -- the history, read-only ------------------------------------------------------------
def readonly_url(db: str | Path) -> str:
    """The database URL that can only read: a SQLite file with ``mode=ro``,
    PostgreSQL with ``default_transaction_read_only`` (others as given).

    Example
    -------
    >>> readonly_url("/data/fleet 1.db")
    'sqlite:///file%3A///data/fleet%25201.db?mode=ro&uri=true'
    >>> readonly_url("postgresql://u@h/db")
    'postgresql://u@h/db?options=-c%20default_transaction_read_only%3Don'
    """
    import sqlalchemy as sa

    from condmon.store.engine import database_url, sqlite_path

    text = str(db)
    path = sqlite_path(database_url(text))
    if path is not None:
        url = sa.engine.URL.create("sqlite", database=path.expanduser().resolve().as_uri(),
                                   query={"mode": "ro", "uri": "true"})
        return url.render_as_string(hide_password=False)
    if text.startswith(("postgresql://", "postgres://")) and "options=" not in text:
        return text + ("&" if "?" in text else "?") + \
            "options=" + quote("-c default_transaction_read_only=on")
    return text


class _History:
    """Opens the history for one request, read-only; error messages name ``db``."""

    def __init__(self, db: str | Path) -> None:
        from condmon.store.engine import StoreError, database_url, sqlite_path

        self.db = str(db)
        self.file = sqlite_path(database_url(self.db))
        if self.file is not None:  # open_store's checks, before the read-only URL hides it
            if not self.file.exists():
                raise StoreError(f"{db}: no history database there (check the path)")
            if self.file.is_dir():
                raise StoreError(f"{db}: is a folder, not a history database file")
            if self.file.stat().st_size == 0:
                raise StoreError(f"{db}: the file is empty, not a history database")
        self.url = readonly_url(db)
        with self.open():
            pass

    @contextmanager
    def open(self) -> Iterator[HistoryStore]:
        from condmon.store import open_store
        from condmon.store.engine import StoreError

        try:
            # a read-only SQLite file: open_store's file checks would look for the URL
            store = open_store(self.url, create=self.file is not None)
        except StoreError as err:
            text = str(err).replace(self.url, self.db)
            if "read-only" in text:  # the store tried to create or upgrade its tables
                text = (f"{self.db}: not a condmon history of this version yet, and the page "
                        "only reads; run `condmon units --db DB` once (it upgrades an older "
                        "history), then serve it")
            raise type(err)(text) from None
        with store:
            yield store


# -- what the pages and the API show ---------------------------------------------------
def _plain(value: Any) -> Any:
    """``value`` with JSON types only; NaN and ±inf become None (recursively)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):  # numpy scalar
        return _plain(value.item())
    if isinstance(value, datetime):
        return value.isoformat()
    return value


def _records(frame: pd.DataFrame) -> list[dict[str, Any]]:
    """Rows as ``condmon history --json`` prints them (ISO dates, NaN as null)."""
    text = frame.reset_index().to_json(orient="records", date_format="iso")
    rows: list[dict[str, Any]] = json.loads(text or "[]")
    return rows


def _statuses(values: Sequence[str]) -> set[str]:
    wanted = {s.strip() for v in values for s in v.split(",") if s.strip()}
    unknown = sorted(wanted - set(STATUSES))
    if unknown:
        raise FilterError(f"unknown status {', '.join(unknown)}; allowed: {', '.join(STATUSES)}")
    return wanted


def fleet_document(store: HistoryStore, status: Sequence[str] = (),
                   q: str | None = None) -> dict[str, Any]:
    """``{"units": [...]}``: :meth:`HistoryStore.unit_summaries`, filtered.

    Parameters
    ----------
    store : HistoryStore
    status : sequence of str
        Keep the units whose latest status is one of these (each item may
        be comma-separated); ``none`` is a unit with nothing stored. Empty: all.
    q : str, optional
        Keep the units whose name contains this text (any case).

    Raises
    ------
    ConfigError
        A status not in :data:`STATUSES`.
    """
    return {"units": _filtered(store.unit_summaries(), _statuses(status), q)}


def _filtered(units: list[dict[str, Any]], wanted: set[str],
              q: str | None) -> list[dict[str, Any]]:
    text = (q or "").strip().casefold()
    return [_plain(u) for u in units if (not wanted or (u["status"] or "none") in wanted)
            and text in str(u["unit"]).casefold()]


@dataclass(frozen=True)
class UnitData:
    """Everything the unit page and ``/api/units/<unit>`` show.

    Attributes
    ----------
    unit, model : str
    overview : dict
        The unit's entry of :meth:`HistoryStore.unit_summaries`.
    history : DataFrame
        :meth:`HistoryStore.history`.
    isolations : DataFrame
        :meth:`HistoryStore.isolations`.
    baseline : StoredBaseline or None
    advice_test : int or None
        The latest check (by date) that is not excluded.
    faults : list of dict
        Its faults (``name, degree, severity, advice``), strongest first,
        against the baseline it was evaluated with.
    monitor : MonitorConfig or None
        The model's breakpoints (None when the model cannot be loaded).
    """

    unit: str
    model: str
    overview: dict[str, Any]
    history: pd.DataFrame
    isolations: pd.DataFrame
    baseline: StoredBaseline | None
    advice_test: int | None
    faults: list[dict[str, Any]]
    monitor: MonitorConfig | None


def _faults(store: HistoryStore, test_id: int, baseline_id: Any) -> list[dict[str, Any]]:
    import sqlalchemy as sa

    from condmon.store import schema as S

    f = S.diagnosis_faults
    q = sa.select(f.c.name, f.c.degree, f.c.severity, f.c.advice).where(f.c.test_id == test_id)
    if isinstance(baseline_id, (int, float)) and math.isfinite(baseline_id):
        q = q.where(f.c.baseline_id == int(baseline_id))
    with store.engine.connect() as conn:
        rows = conn.execute(q.order_by(f.c.degree.desc(), f.c.name)).all()
    return [{"name": str(r[0]), "degree": float(r[1]), "severity": str(r[2]),
             "advice": str(r[3])} for r in rows]


def read_unit(store: HistoryStore, unit: str) -> UnitData:
    """Read what :func:`unit_document` and the unit page show.

    Raises
    ------
    UnknownUnitError
        No such unit in the history.
    """
    from condmon.models.registry import get_model
    from condmon.monitor.fuzzy import load_monitor_config

    model = store.unit_model(unit)
    if model is None:
        raise UnknownUnitError(f"unknown unit {unit!r}")
    hist = store.history(unit)
    isos = store.isolations(unit)
    baseline = store.latest_baseline(unit)
    monitor = None
    if len(hist):
        try:
            monitor = load_monitor_config(get_model(model).breakpoints)
        except CondmonError:  # a declaration file moved away: trends without bands
            monitor = None
    checks = hist[(hist["role"] == "check") & ~hist["excluded"]] if len(hist) else hist
    advice_test, faults = None, []
    if len(checks):
        latest = checks.assign(_id=checks.index).sort_values(["date", "_id"]).iloc[-1]
        advice_test = int(latest["_id"])
        if latest["accepted"]:
            faults = _faults(store, advice_test, latest["baseline_id"])
    return UnitData(unit, model, _overview(unit, model, hist, isos, baseline), hist, isos,
                    baseline, advice_test, faults, monitor)


def _overview(unit: str, model: str, hist: pd.DataFrame, isos: pd.DataFrame,
              baseline: StoredBaseline | None) -> dict[str, Any]:
    """The unit's entry of :meth:`HistoryStore.unit_summaries`, from what the page
    has read anyway (that method reads every unit: seconds for a large fleet)."""
    status = source = when = summary = None
    tests = hist[~hist["excluded"]] if len(hist) else hist
    if len(tests):
        last = tests.assign(_id=tests.index).sort_values(["date", "_id"]).iloc[-1]
        status, source, when = str(last["status"]), last["source"], last["date"]
        summary = last["summary"] if last["accepted"] else last["reason"]
    done = isos[~isos["excluded"].astype(bool)] if len(isos) else isos
    if len(done):
        last = done.assign(_id=done.index).sort_values(["date", "_id"]).iloc[-1]
        if when is None or last["date"] >= when:
            status, source, when = str(last["status"]), last["source"], last["date"]
            summary = last["statement"]
    doc: dict[str, Any] = _plain({
        "unit": unit, "model": model, "tests": len(hist), "isolations": len(isos),
        "latest_source": source, "latest_date": None if when is None else when.isoformat(),
        "status": status, "summary": summary if isinstance(summary, str) else None,
        "baseline_flags": 0 if baseline is None else len(baseline.flags)})
    return doc


def unit_document(data: UnitData) -> dict[str, Any]:
    """The JSON of ``/api/units/<unit>``.

    Keys: ``unit``, ``overview`` (as in ``/api/units``), ``tests`` (as
    ``condmon history --json``), ``isolations``, ``baseline`` (the active
    baseline's latest version, or None) and ``advice`` (``test_id`` of the
    latest check and its ``faults``, or None).
    """
    advice = (None if data.advice_test is None else
              {"test_id": data.advice_test, "faults": data.faults})
    doc: dict[str, Any] = _plain({
        "unit": data.unit, "overview": data.overview,
        "tests": _records(data.history) if len(data.history) else [],
        "isolations": _records(data.isolations) if len(data.isolations) else [],
        "baseline": None if data.baseline is None else data.baseline.to_dict(),
        "advice": advice})
    return doc


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


@dataclass(frozen=True)
class _Trends:
    panels: list[_Panel] = field(default_factory=list)
    xlabel: str = ""
    statuses: list[str] = field(default_factory=list)
    k: float = 2.0
    banded: bool = False
    spread: bool = False
    untrended: list[str] = field(default_factory=list)


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
    against the baseline they were evaluated with, and the active baseline's
    tests at their deviation from its mean; error bars ±1 SE."""
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
                                         & ~hist["excluded"]]]
    if not params or not (members or checks):
        return _Trends(untrended=_untrended(hist))
    stamps = {int(str(i)): float(d.timestamp()) for i, d in hist["date"].items()}
    dated = bool(hist["test_date"].notna().any())
    shown = sorted({*members, *checks})
    if dated:  # on the time axis
        where = {i: stamps[i] for i in shown}
        lo, hi = min(where.values()), max(where.values())
        pad = max((hi - lo) * 0.05, 3600.0)
        lo, hi = lo - pad, hi + pad
        xticks = _time_ticks(lo, hi)
    else:  # no test dates: one step per test, in id order
        where = {i: float(n) for n, i in enumerate(shown)}
        lo, hi = -0.6, len(shown) - 0.4
        every = max(1, math.ceil(len(shown) / 12))
        xticks = [(where[i], f"#{i}") for i in shown[::every]]

    def px(t: float) -> float:
        return _LEFT + (t - lo) / (hi - lo) * (_W - _LEFT - _RIGHT)

    def value(i: int, column: str) -> float:
        v: Any = hist.loc[i, column] if column in hist.columns else None
        return float(v) if isinstance(v, (int, float)) and v == v else math.nan

    panels, seen = [], []
    for p in params:
        mean, std = stats.get(p, (math.nan, math.nan))
        scale = 100.0 / abs(mean)  # nan without a baseline
        pts = [(i, (value(i, p) - mean) * scale, value(i, f"{p}_se") * scale, "baseline", True)
               for i in members]
        pts += [(i, value(i, f"{p}_change"), value(i, f"{p}_se") * scale,
                 str(hist.loc[i, "status"]), False) for i in checks]
        pts = [t for t in pts if math.isfinite(t[1])]
        spread = k * std * scale if math.isfinite(std * scale) else 0.0
        r1 = cfg.r1.get(p, math.nan) if cfg is not None else math.nan
        r2 = cfg.r2.get(p, math.nan) if cfg is not None else math.nan
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
        for i, c, e, s, member in pts:
            when = datetime.fromtimestamp(stamps[i], timezone.utc).strftime("%Y-%m-%d %H:%M")
            sd = f" ± {e:.2g} % (SE)" if math.isfinite(e) else ""
            role = "baseline test" if member else s
            points.append(_Point(px(where[i]), py(c), py(c - e) if math.isfinite(e) else py(c),
                                 py(c + e) if math.isfinite(e) else py(c),
                                 STATUS_COLOURS.get(s, "#444"), i,
                                 f"#{i} {when} {role}: {p} {c:+.1f} %{sd}", member))
            seen.append(s)
        line = " ".join(f"{q.x:.1f},{q.y:.1f}" for q in points if not q.member)
        panels.append(_Panel(p, bands, py(0.0), [(py(v), f"{v:+g}") for v in ticks],
                             [(px(t), label) for t, label in xticks
                              if 28 <= px(t) <= _W - 28],  # the label fits the figure
                             points, line))
    xlabel = ("test date (UTC)" if dated and not hist["test_date"].isna().any() else
              "date (UTC): test date, else when stored" if dated else
              "test # (no test dates recorded)")
    order: list[str] = [s for s in ("baseline", "go", "advisory", "no-go", "unchecked")
                        if s in seen]
    return _Trends(panels, xlabel, order, k, cfg is not None, bool(stats), _untrended(hist))


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
        if excluded:
            note = f"excluded: {r['excluded_reason'] or ''}"
        elif r["accepted"] and isinstance(r["summary"], str):
            note = r["summary"]
        else:
            note = str(r["reason"] or "")
        rows.append({"id": int(cast(int, tid)),
                     "date": _fmt_date(r["date"], pd.isna(r["test_date"])),
                     "source": str(r["source"]), "role": str(r["role"]), "status": status,
                     "fit": f"{r['fit_percent']:.1f}" if pd.notna(r["fit_percent"]) else "—",
                     "changes": changes, "note": note, "excluded": excluded})
    return rows


def _isolation_rows(isos: pd.DataFrame) -> tuple[list[str], list[dict[str, Any]]]:
    import pandas as pd

    suspects = sorted({s for v in isos["suspects"] for s in v})
    rows = []
    for iid, r in isos.iterrows():
        cells = []
        for p in suspects:
            change, err, est = r.get(f"{p}_change"), r.get(f"{p}_error"), r.get(p)
            flag = r.get(f"{p}_rejected")
            rejected = bool(flag is not None and flag == flag and flag)  # NaN: not estimated
            text = ("" if est is None or pd.isna(est) else f"= {est:.4g}"
                    ) if change is None or pd.isna(change) else f"{change:+.1f} %"
            if err is not None and pd.notna(err):
                text += f" ({err:.2g} σ)"
            cells.append({"text": "rejected" if rejected else text,
                          "isolated": p in r["isolated"], "rejected": rejected})
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
    return suspects, rows


# -- the application ---------------------------------------------------------------------
class _UnitConverter(BaseConverter):
    """Any unit name, slashes (even leading, trailing or doubled) included."""

    regex = ".+"
    part_isolating = False
    weight = 200

    def to_url(self, value: Any) -> str:
        return quote(str(value), safe="/:@!$&'()*+,;=")


def _dotted(unit: str) -> bool:
    """A name with a ``.`` or ``..`` path segment, which a browser would fold away."""
    return any(part in (".", "..") for part in unit.split("/"))


def unit_href(unit: str, api: bool = False) -> str:
    """The URL path of a unit's page (``api``: of its JSON)."""
    if _dotted(unit):
        return url_for("api_unit_q" if api else "unit_q", name=unit)
    return url_for("api_unit" if api else "unit_page", unit=unit)


def _json(doc: Any, status: int = 200) -> Response:
    return Response(json.dumps(doc, allow_nan=False, ensure_ascii=False), status=status,
                    mimetype="application/json")


def create_app(db: str | Path, *, refresh: float = 30.0) -> Flask:
    """The fleet page's web application (a Flask app) over the history ``db``.

    Parameters
    ----------
    db : str or Path
        History database: a SQLite file or a ``postgresql://`` URL. Opened
        read-only at every request; never created, written or upgraded.
    refresh : float
        The index page reloads its table this often [s] (0: never).

    Returns
    -------
    flask.Flask
        A WSGI application: run it with :func:`serve` (or any WSGI server);
        ``app.test_client()`` for tests.

    Raises
    ------
    StoreError
        The database is missing, not a condmon history, or of another schema
        version (checked once here, before any server starts).

    Example
    -------
    >>> app = create_app("condmon.db")                    # doctest: +SKIP
    >>> app.test_client().get("/api/units").json["units"][0]["status"]  # doctest: +SKIP
    'no-go'
    """
    history = _History(db)
    app = Flask(__name__, template_folder=str(_FILES / "templates"),
                static_folder=str(_FILES / "static"), static_url_path="/static")
    app.url_map.merge_slashes = False
    app.url_map.strict_slashes = False
    app.url_map.converters["unit"] = _UnitConverter
    app.config["CONDMON_DB"] = history.db
    app.jinja_env.globals.update(unit_href=unit_href, colours=STATUS_COLOURS,
                                 db_name=Path(history.db).name if "://" not in history.db
                                 else history.db.split("@")[-1])
    app.jinja_env.filters["model_name"] = lambda m: Path(str(m)).name
    app.jinja_env.filters["when"] = _fmt_date

    def wants_json() -> bool:
        return request.path.startswith("/api/")

    @app.after_request
    def _headers(resp: Response) -> Response:
        resp.headers["Cache-Control"] = "no-store"
        resp.headers["X-Content-Type-Options"] = "nosniff"
        resp.headers["Content-Security-Policy"] = (
            "default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; "
            "frame-ancestors 'none'")
        return resp

    def problem(status: int, message: str) -> Response | tuple[str, int]:
        if wants_json():
            return _json({"error": message}, status)
        return render_template("error.html", status=status, message=message), status

    @app.errorhandler(CondmonError)
    def _condmon_error(err: CondmonError) -> Response | tuple[str, int]:
        status = (404 if isinstance(err, UnknownUnitError) else
                  400 if isinstance(err, FilterError) else 503)
        return problem(status, str(err).replace(history.url, history.db))

    @app.errorhandler(HTTPException)
    def _http_error(err: HTTPException) -> Response | tuple[str, int]:
        return problem(err.code or 500, f"{err.name}: {request.path}")

    def fleet() -> dict[str, Any]:
        with history.open() as store:
            return fleet_document(store, request.args.getlist("status"), request.args.get("q"))

    @app.get("/")
    def index() -> str:
        chosen = _statuses(request.args.getlist("status"))
        with history.open() as store:
            everyone = store.unit_summaries()
        tally: dict[str, int] = {}
        for u in everyone:
            tally[u["status"] or "none"] = tally.get(u["status"] or "none", 0) + 1
        units = _filtered(everyone, chosen, request.args.get("q"))
        return render_template("index.html", units=units, total=len(everyone),
                               tally=[(s, tally[s]) for s in STATUSES if s in tally],
                               statuses=STATUSES, chosen=chosen,
                               q=request.args.get("q", ""), refresh=refresh,
                               now=datetime.now(timezone.utc).strftime("%H:%M:%S"))

    def page(unit: str) -> str:
        with history.open() as store:
            data = read_unit(store, unit)
        trends = _trends(data)
        params = [p.parameter for p in trends.panels] or sorted(
            c[:-len("_change")] for c in data.history.columns if c.endswith("_change"))
        suspects, iso_rows = (_isolation_rows(data.isolations) if len(data.isolations)
                              else ([], []))
        advice = None
        if data.advice_test is not None:
            r = data.history.loc[data.advice_test]
            advice = {"id": data.advice_test, "status": str(r["status"]),
                      "text": str(r["summary"]) if r["accepted"] and
                      isinstance(r["summary"], str) else f"retest: {r['reason']}",
                      "date": _fmt_date(r["date"])}
        return render_template("unit.html", d=data, o=data.overview, trends=trends,
                               tests=_test_rows(data.history, params), params=params,
                               suspects=suspects, isolations=iso_rows, advice=advice,
                               api=unit_href(unit, api=True))

    @app.get("/units/<unit:unit>")
    def unit_page(unit: str) -> str:
        return page(unit)

    @app.get("/unit")
    def unit_q() -> str:
        return page(request.args.get("name", ""))

    @app.get("/api/units")
    def api_units() -> Response:
        return _json(fleet())

    def api_doc(unit: str) -> Response:
        with history.open() as store:
            return _json(unit_document(read_unit(store, unit)))

    @app.get("/api/units/<unit:unit>")
    def api_unit(unit: str) -> Response:
        return api_doc(unit)

    @app.get("/api/unit")
    def api_unit_q() -> Response:
        return api_doc(request.args.get("name", ""))

    return app


# -- the server ---------------------------------------------------------------------------
def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def serve(app: Any, host: str = "127.0.0.1", port: int = 8050, *, threads: int = 4,
          ready: Callable[[str], None] | None = None) -> None:
    """Serve ``app`` (from :func:`create_app`) with waitress until Ctrl-C or SIGTERM.

    Parameters
    ----------
    app : WSGI application
    host : str
        Address to listen on (default: this machine only).
    port : int
        TCP port; 0 picks a free one.
    threads : int
        Requests handled at once.
    ready : callable, optional
        Called with the page's URL once the server listens.

    Raises
    ------
    CondmonError
        The address cannot be listened on (in use, not this machine's, ...).
    """
    from waitress import wasyncore
    from waitress.server import create_server

    sockets: dict[int, Any] = {}
    try:
        server: Any = create_server(app, map=sockets, host=host, port=port, threads=threads,
                                    ident="condmon")
    except (OSError, ValueError) as err:  # in use, no such address; waitress's own checks
        wasyncore.close_all(sockets)
        why = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
        raise CondmonError(f"cannot listen on {host}:{port}: {why}; choose another --port "
                           "or --host") from None
    listen = getattr(server, "effective_listen", None) or [
        (server.effective_host, server.effective_port)]
    where, at = listen[0]
    if ready is not None:
        ready(f"http://{f'[{where}]' if ':' in str(where) else where}:{at}/")
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _interrupt) if main else None
    try:
        server.run()  # returns on Ctrl-C (waitress stops its worker threads)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        server.task_dispatcher.shutdown()
        wasyncore.close_all(sockets)

