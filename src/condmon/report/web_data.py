"""What the live fleet page reads: the history, read-only, and the fleet's and units' documents.

This module holds the data side of :mod:`condmon.report.web`, free of the web
framework: :func:`readonly_url` and the per-request read-only opening of the
history, :func:`fleet_document` (every unit's latest status, filtered),
:func:`read_unit` with :class:`UnitData` (everything a unit's page shows) and
:func:`unit_document` (the JSON of ``/api/units/<unit>``), with the errors the
page answers with (:class:`UnknownUnitError`, :class:`FilterError`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import quote

from condmon.errors import CondmonError, ConfigError
from condmon.io.jsonable import frame_records, json_safe
from condmon.store.states import STATUS_ORDER

if TYPE_CHECKING:
    import pandas as pd

    from condmon.monitor.fuzzy import MonitorConfig
    from condmon.forecast.unit import UnitForecast
    from condmon.store.baselines import StoredBaseline
    from condmon.store.db import HistoryStore

__all__ = ["readonly_url", "fleet_document", "PER_PAGE", "TESTS_PER_PAGE", "unit_document", "read_unit", "UnitData",
           "UnknownUnitError", "STATUSES", "SORTS"]

#: Statuses a unit can show (``building``: its baseline is not saved yet; ``none``:
#: nothing stored yet), in the filter's order, the most severe first.
STATUSES = STATUS_ORDER
#: Orders of the fleet: by name, by status (the most severe first), by latest
#: date (the newest first), or by urgency (earliest forecast to no-go first).
SORTS = ("name", "status", "date", "forecast")
#: Units a fleet page (and ``/api/units``) shows at once unless asked otherwise.
PER_PAGE = 100
#: Tests a unit page's table shows at once (its figures show them all).
TESTS_PER_PAGE = 200


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
    >>> from sqlalchemy import make_url
    >>> url = make_url(readonly_url("/data/fleet 1.db"))
    >>> url.database, dict(url.query)
    ('file:///data/fleet%201.db', {'mode': 'ro', 'uri': 'true'})
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
        from condmon.store.engine import StoreError, redact

        try:
            # a read-only SQLite file: open_store's file checks would look for the URL
            store = open_store(self.url, create=self.file is not None)
        except StoreError as err:
            text = str(err).replace(redact(self.url), redact(self.db))
            if self.file is not None and (not self.file.is_file() or "cannot open" in text):
                # removed or unreadable while serving (the read-only URL skips the file checks)
                text = f"the history database is gone or unreadable: {redact(self.db)}"
            elif "read-only" in text:  # the store tried to create or upgrade its tables
                text = (f"{redact(self.db)}: not a condmon history of this version yet, and the page "
                        "only reads; run `condmon units --db DB` once (it upgrades an older "
                        "history), then serve it")
            raise type(err)(text) from None
        with store:
            yield store


# -- what the pages and the API show ---------------------------------------------------
def _statuses(values: Sequence[str]) -> set[str]:
    wanted = {s.strip() for v in values for s in v.split(",") if s.strip()}
    unknown = sorted(wanted - set(STATUSES))
    if unknown:
        raise FilterError(f"unknown status {', '.join(unknown)}; allowed: {', '.join(STATUSES)}")
    return wanted


def fleet_document(store: HistoryStore, status: Sequence[str] = (),
                   q: str | None = None, sort: str | None = None, page: int = 1,
                   per_page: int | None = None,
                   rows: list[dict[str, Any]] | None = None, clamp: bool = False
                   ) -> dict[str, Any]:
    """One page of the fleet: the units (each with its latest status and
    earliest forecast to no-go) that pass the filter, in order, and the counts.

    ``{"units", "page", "per_page", "pages", "matching", "total", "counts"}``:
    the page's units, which page of how many, the units that pass the
    filter, the units of the history and the units per latest status (of
    them all). What ``condmon units --json`` and ``/api/units`` give. Only
    the page's units are forecast (all of them to order by urgency; a check
    keeps its unit's forecast, so this is mostly a read). Without ``rows``
    and by any order but urgency, the database filters, counts and pages
    (a page of 100 units costs the same in a fleet of 10,000).

    Parameters
    ----------
    store : HistoryStore
    status : sequence of str
        Keep the units whose latest status is one of these (each item may
        be comma-separated); ``none`` is a unit with nothing stored. Empty: all.
    q : str, optional
        Keep the units whose name contains this text (any case).
    sort : {"name", "status", "date", "forecast"}, optional
        Order of the units: by name (default); by status, the most severe
        first (:data:`STATUSES`' order), then by name; by latest date, the
        newest first; or by urgency, the unit forecast to turn no-go soonest
        first (:func:`condmon.store.views.by_urgency`).
    page : int
        Which page, from 1.
    per_page : int, optional
        Units a page (default: every unit on one page).
    rows : list of dict, optional
        The units' summaries (:meth:`HistoryStore.unit_summaries`; the page
        passes them with its live statuses); default: the history's.
    clamp : bool
        A page past the last shows the last (the page, whose fleet may have
        shrunk since its link was made), instead of an error.

    Raises
    ------
    ConfigError
        A status not in :data:`STATUSES`, a sort not in :data:`SORTS`, a page
        or page size < 1, a page past the last.
    """
    from condmon.store.kept import attach_forecasts
    from condmon.store.views import by_urgency

    wanted, how = _statuses(status), _sort(sort)
    text = (q or "").strip()
    if per_page is not None and per_page < 1 or page < 1:
        raise FilterError(f"page {page}, {'all' if per_page is None else per_page} a page: "
                          "both must be >= 1")
    in_sql = (rows is None and how != "forecast" and text.isascii()
              and store.states_current())
    if in_sql:  # the database filters, counts and pages: a page's cost is its own units'
        counts = store.status_counts()
        matching = store.count_units(sorted(wanted), text)
    else:
        everyone = store.unit_summaries() if rows is None else rows
        counts = {}
        for u in everyone:
            counts[u["status"] or "none"] = counts.get(u["status"] or "none", 0) + 1
        folded = text.casefold()
        kept = [u for u in everyone if (not wanted or (u["status"] or "none") in wanted)
                and folded in str(u["unit"]).casefold()]
        matching = len(kept)
    pages = max(1, -(-matching // per_page)) if per_page else 1
    if page > pages and clamp:
        page = pages
    if page > pages:
        raise FilterError(f"page {page}: the {matching} matching unit(s) fill {pages} "
                          + (f"page(s) of {per_page}" if per_page else "page (all on one)"))
    start = (page - 1) * (per_page or 0)
    if in_sql:
        shown = store.unit_page(sorted(wanted), text, how, start, per_page)
    else:
        if how == "forecast":
            kept = by_urgency(attach_forecasts(store, kept))
        elif how != "name":
            kept = _ordered(kept, how)
        shown = kept[start: start + per_page] if per_page else kept
    if how != "forecast":
        attach_forecasts(store, shown)
    return {"units": [json_safe(u) for u in shown], "page": page, "per_page": per_page,
            "pages": pages, "matching": matching, "total": sum(counts.values()),
            "counts": {s: counts[s] for s in STATUSES if s in counts}}


def _ordered(rows: list[dict[str, Any]], how: str) -> list[dict[str, Any]]:
    """``rows`` (by name) by status severity, or by latest date (newest first)."""
    if how == "status":
        return sorted(rows, key=lambda u: STATUSES.index(u["status"] or "none")
                      if (u["status"] or "none") in STATUSES else len(STATUSES))
    dated = sorted((u for u in rows if u["latest_date"]), key=lambda u: str(u["latest_date"]),
                   reverse=True)
    return dated + [u for u in rows if not u["latest_date"]]


def _sort(sort: str | None) -> str:
    if sort in (None, ""):
        return "name"
    if sort not in SORTS:
        raise FilterError(f"unknown sort {sort}; allowed: {', '.join(SORTS)}")
    return str(sort)


def _page_links(doc: dict[str, Any], args: Any) -> list[tuple[str, str | None]]:
    """The fleet page's page links: ``(label, query string or None for the current)``,
    the other arguments (filter, order, page size) kept."""
    from urllib.parse import urlencode

    if doc["pages"] <= 1:
        return []
    keep = [(k, v) for k in args for v in args.getlist(k) if k != "page"]

    def at(n: int) -> str:
        return "?" + urlencode([*keep, ("page", str(n))])

    page, pages = doc["page"], doc["pages"]
    near = sorted({1, pages, *range(max(1, page - 2), min(pages, page + 2) + 1)})
    links: list[tuple[str, str | None]] = []
    if page > 1:
        links.append(("‹ previous", at(page - 1)))
    for i, n in enumerate(near):
        if i and n - near[i - 1] > 1:
            links.append(("…", None))
        links.append((str(n), None if n == page else at(n)))
    if page < pages:
        links.append(("next ›", at(page + 1)))
    return links


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
    baselines : tuple of StoredBaseline
        Every version of the unit's baselines, oldest first (a check's error
        bar comes from the one it was evaluated with).
    units : dict of str to str
        Unit of every parameter of the model (empty when it cannot be loaded).
    forecast : UnitForecast or None
        Every parameter's forecast to no-go
        (:func:`condmon.store.forecasts.read_forecast`); None without one
        (the overview's ``forecast_reason`` says why).
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
    baselines: tuple[StoredBaseline, ...] = ()
    units: dict[str, str] = field(default_factory=dict)
    forecast: UnitForecast | None = None


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
    from condmon.report.reading import judged_monitor, model_units
    from condmon.store.forecasts import forecast_fields, try_forecast

    model = store.unit_model(unit)
    if model is None:
        raise UnknownUnitError(f"unknown unit {unit!r}")
    hist = store.history(unit)
    isos = store.isolations(unit)
    baseline = store.latest_baseline(unit)
    monitor, units = None, {}
    source, _ = store.unit_declaration(unit)
    name = Path(model).name
    try:
        machine = get_model(model)
        name = machine.name
        units = model_units(machine)
        if len(hist):   # the breakpoints its checks were judged with
            monitor = judged_monitor(machine, None if baseline is None else baseline.baseline,
                                     hist)
    except CondmonError:  # a declaration file moved away: trends without bands or units
        monitor = None
    checks = hist[(hist["role"] == "check") & ~hist["excluded"]] if len(hist) else hist
    advice_test, faults = None, []
    if len(checks):
        latest = checks.assign(_id=checks.index).sort_values(["date", "_id"]).iloc[-1]
        advice_test = int(latest["_id"])
        if latest["accepted"]:
            faults = _faults(store, advice_test, latest["baseline_id"])
    group = store.unit_group(unit)
    unlike = store.group_flags().get(unit, []) if group else []
    forecast, why = try_forecast(store, unit)
    overview = {**_overview(unit, name, source, hist, isos, baseline, group, unlike),
                **json_safe(forecast_fields(forecast, why))}
    return UnitData(unit, model, overview, hist, isos, baseline, advice_test, faults, monitor,
                    tuple(store.baselines(unit)) if len(hist) else (), units, forecast)


def _overview(unit: str, model: str, model_source: str | None, hist: pd.DataFrame,
              isos: pd.DataFrame, baseline: StoredBaseline | None, group: str | None,
              unlike: list[dict[str, Any]]) -> dict[str, Any]:
    """The unit's entry of :meth:`HistoryStore.unit_summaries`, from what the page
    has read anyway (that method reads every unit: seconds for a large fleet);
    :func:`read_unit` adds its forecast fields."""
    from condmon.store.views import building_summary

    status = source = when = summary = regime = None
    tests = hist[~hist["excluded"]] if len(hist) else hist
    if len(tests):
        # the latest check; baseline tests only without checks (as unit_summaries)
        last = tests.assign(_id=tests.index, _check=tests["role"] == "check").sort_values(
            ["_check", "date", "_id"]).iloc[-1]
        status, source, when = str(last["status"]), last["source"], last["date"]
        summary = last["summary"] if last["accepted"] else last["reason"]
        regime = last["regime"] if isinstance(last["regime"], str) and last["regime"] else None
        if status in ("baseline", "rejected") and baseline is None:
            status = "building"
            healthy = (tests["role"] == "baseline") & tests["accepted"]
            why = None if last["accepted"] or not isinstance(last["reason"], str) \
                else last["reason"]
            summary = building_summary(int(healthy.sum()), why)
    done = isos[~isos["excluded"].astype(bool)] if len(isos) else isos
    if len(done):
        last = done.assign(_id=done.index).sort_values(["date", "_id"]).iloc[-1]
        if when is None or last["date"] >= when:
            status, source, when = str(last["status"]), last["source"], last["date"]
            summary, regime = last["statement"], None
    doc: dict[str, Any] = json_safe({
        "unit": unit, "model": model, "model_source": model_source, "tests": len(hist),
        "isolations": len(isos),
        "latest_source": source, "latest_date": None if when is None else when.isoformat(),
        "status": status, "summary": summary if isinstance(summary, str) else None,
        "latest_regime": regime, "group": group,
        "baseline_flags": 0 if baseline is None else len(baseline.flags),
        "group_flags": unlike})
    return doc


def unit_document(data: UnitData) -> dict[str, Any]:
    """The JSON of ``/api/units/<unit>``.

    Keys: ``unit``, ``overview`` (as in ``/api/units``), ``tests`` (as
    ``condmon history --json``), ``isolations``, ``baseline`` (the active
    baseline's latest version, the one in use, with its ``description``:
    name, version, when built, its tests, per regime; or None), ``advice`` (``test_id`` of the
    latest check and its ``faults``, or None), ``error_bars`` (what every
    error bar is, :func:`condmon.report.trends.error_bar`: ``definition``,
    ``k``, ``unit``) and ``trends`` (per parameter, the trended checks'
    ``test_ids``, ``change`` [%] and ``half_width`` [%], the error bar, as the
    report's trend figure draws them).
    """
    from condmon.report.trends import error_bar, trend_data

    cfg = data.monitor
    trends = []
    if cfg is not None and len(data.history):
        by_id = {b.id: b.baseline for b in data.baselines}
        active = None if data.baseline is None else data.baseline.id
        for p in (p for p in cfg.r1 if p in data.history.columns):
            d = trend_data(data.history, p, by_id, cfg.r1[p], cfg.r2[p], cfg.k, active)
            trends.append({"parameter": p, "test_ids": list(d.test_ids),
                           "change": d.change.tolist(), "half_width": d.width.tolist()})
    k = 2.0 if cfg is None else cfg.k
    advice = (None if data.advice_test is None else
              {"test_id": data.advice_test, "faults": data.faults})
    doc: dict[str, Any] = json_safe({
        "unit": data.unit, "overview": data.overview,
        "tests": frame_records(data.history) if len(data.history) else [],
        "isolations": frame_records(data.isolations) if len(data.isolations) else [],
        "baseline": None if data.baseline is None else {
            **data.baseline.to_dict(), "description": data.baseline.describe(data.history)},
        "advice": advice,
        "error_bars": {"definition": error_bar(k, words=True), "k": k, "unit": "%"},
        "trends": trends})
    return doc
