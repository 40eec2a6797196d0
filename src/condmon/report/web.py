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
    isolations, baseline flags and earliest forecast to no-go
    ("no-go in"). ``?status=no-go&q=EMA`` filters (several statuses:
    ``status=go,advisory``; ``q``: part of the name, any case);
    ``sort=forecast`` lists the unit forecast to turn no-go soonest first.
``/units/<unit>``
    One unit: latest status and fault advice, trend figure (inline SVG: change
    against the baseline over the test dates, or the test ids when none is
    recorded; r1/r2 bands, the baseline spread, each test's symptom
    half-width ±k·max(σ, SE) as its error bar; for a parameter trending
    towards no-go, the fitted trend continued to the no-go line with its
    90 % band), the report's fit, symptom and
    isolation figures (drawn by :mod:`condmon.report.figures` at each request,
    as ``data:`` images), baseline, tests, isolations.
``/api/units``
    ``{"units": [...]}`` as ``condmon units --json`` (same filters and sort as ``/``).
``/api/units/<unit>``
    The unit's overview, tests (as ``condmon history --json``), isolations,
    baseline and latest fault advice.

Unit names may hold any character: ``/`` stays a path separator in the URL
(``/units/EMA/7``), everything else is percent-encoded; a name with a ``.`` or
``..`` segment, which browsers would fold away, is addressed as
``/unit?name=...`` (and ``/api/unit?name=...``).

This module holds the Flask application (its routes) and the server; what the
pages read from the history is :mod:`condmon.report.web_data` and how a unit's
trends and tables are drawn :mod:`condmon.report.web_render` (every public
name is importable from here too).
"""

from __future__ import annotations

import json
import signal
import threading
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import Any
from urllib.parse import quote

from flask import Flask, Response, render_template, request, url_for
from werkzeug.exceptions import HTTPException
from werkzeug.routing import BaseConverter

from condmon.errors import CondmonError
from condmon.forecast.unit import remaining_text
from condmon.report.figures import STATUS_COLOURS
from condmon.report.live import LiveFeed, with_live
from condmon.report.tables import tests_summary, unit_of
from condmon.report.trends import error_bar
from condmon.report.web_data import (
    PER_PAGE, SORTS, STATUSES, TESTS_PER_PAGE, FilterError, UnitData, UnknownUnitError, _History,
    _page_links,
    _statuses, fleet_document, read_unit, readonly_url, unit_document,
)
from condmon.report.web_render import (
    _figures, _fmt_date, _isolation_rows, _test_rows, _trends,
)

__all__ = ["create_app", "serve", "readonly_url", "fleet_document", "unit_document",
           "read_unit", "UnitData", "UnknownUnitError", "STATUSES"]

_FILES = Path(__file__).with_name("web_files")
MAX_NUMBER = 1_000_000  # a page number or a page's size at most (a fleet of a million units)
MAX_QUERY = 200  # characters of a search: a unit name is at most 64
#: Browsers streaming live changes at once. Each holds a server thread; ``serve
#: --mqtt`` runs EVENT_CLIENTS + 16 threads, so 16 always serve pages. A browser
#: past the bound keeps the page's timed reload.
EVENT_CLIENTS = 16


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


def create_app(db: str | Path, *, refresh: float = 30.0, live: LiveFeed | None = None) -> Flask:
    """The fleet page's web application (a Flask app) over the history ``db``.

    Parameters
    ----------
    db : str or Path
        History database: a SQLite file or a ``postgresql://`` URL. Opened
        read-only at every request; never created, written or upgraded.
    refresh : float
        The index page reloads its table this often [s] (0: never).
    live : LiveFeed, optional
        Units' live statuses from the broker (``condmon serve --mqtt``): they
        override the history's latest status on the index and ``/api/units``,
        and ``/api/events`` streams their changes (server-sent events) so the
        index redraws its table at once.

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
    streams = threading.BoundedSemaphore(EVENT_CLIENTS)
    app = Flask(__name__, template_folder=str(_FILES / "templates"),
                static_folder=str(_FILES / "static"), static_url_path="/static")
    app.url_map.merge_slashes = False
    app.url_map.strict_slashes = False
    app.url_map.converters["unit"] = _UnitConverter
    app.config["CONDMON_DB"] = history.db
    app.jinja_env.globals.update(unit_href=unit_href, colours=STATUS_COLOURS, error_bar=error_bar,
                                 unit_of=unit_of,
                                 db_name=Path(history.db).name if "://" not in history.db
                                 else history.db.split("@")[-1])
    app.jinja_env.filters["model_name"] = lambda m: Path(str(m)).name
    app.jinja_env.filters["when"] = _fmt_date
    app.jinja_env.filters["remaining"] = remaining_text

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
        from condmon.store.engine import redact

        return problem(status, redact(str(err).replace(redact(history.url), history.db)))

    @app.errorhandler(HTTPException)
    def _http_error(err: HTTPException) -> Response | tuple[str, int]:
        return problem(err.code or 500, f"{err.name}: {request.path}")

    def number(name: str, default: int | None) -> int | None:
        raw = request.args.get(name)
        if raw in (None, ""):
            return default
        if raw == "all" and name == "per_page":
            return None
        text = str(raw)
        try:
            value = int(text[:24])
        except ValueError:
            raise FilterError(f"{name}={text[:20]!r}: a whole number >= 1"
                              + (" or 'all'" if name == "per_page" else "")) from None
        if len(text) > 24 or value > MAX_NUMBER:  # the range below 1 is the listing's to say
            raise FilterError(f"{name}={text[:24]}: at most {MAX_NUMBER}")
        return value

    def query() -> str | None:
        q = request.args.get("q")
        if q is not None and (len(q) > MAX_QUERY or any(ord(ch) < 32 for ch in q)):
            raise FilterError(f"q: a search of up to {MAX_QUERY} printable characters "
                              f"(this one has {len(q)}"
                              + (", with a control character)" if any(ord(ch) < 32 for ch in q)
                                 else ")"))
        return q

    def _page(n: int | None) -> int:
        return 1 if n is None else n

    def fleet(clamp: bool = False) -> dict[str, Any]:
        """The page of the fleet the request asks for (its live statuses over the history's)."""
        with history.open() as store:
            return fleet_document(store, request.args.getlist("status"), query(),
                                  request.args.get("sort"), _page(number("page", 1)),
                                  number("per_page", PER_PAGE),
                                  None if live is None else with_live(store.unit_summaries(),
                                                                      live), clamp)

    @app.get("/api/events")
    def events() -> Response:
        if live is None:
            return _json({"error": "no live feed: start the page with condmon serve --mqtt "
                                   "HOST:PORT"}, 404)
        feed = live
        try:
            after = int(str(request.headers.get("Last-Event-ID") or request.args.get("after")
                            or feed.version)[:12])
        except ValueError:
            raise FilterError("after: the number of the last change seen") from None
        if not streams.acquire(blocking=False):
            # every event client holds a server thread: past the bound a browser
            # keeps its timed reload, and the page's own threads stay free
            return _json({"error": f"{EVENT_CLIENTS} live clients are connected already; the "
                                   "page reloads itself instead"}, 503)

        def stream() -> Any:
            try:
                last = after
                yield "retry: 2000\n\n"
                while True:
                    changes = feed.changes(last, 15.0)
                    if not changes:
                        yield ": still here\n\n"
                    for version, doc in changes:
                        last = version
                        yield f"id: {version}\ndata: {json.dumps(doc)}\n\n"
            finally:
                streams.release()

        return Response(stream(), mimetype="text/event-stream",
                        headers={"X-Accel-Buffering": "no"})

    @app.get("/")
    def index() -> str:
        chosen = _statuses(request.args.getlist("status"))
        doc = fleet(clamp=True)
        return render_template("index.html", units=doc["units"], total=doc["total"],
                               tally=list(doc["counts"].items()), doc=doc,
                               pages=_page_links(doc, request.args),
                               statuses=STATUSES, chosen=chosen,
                               sort=request.args.get("sort") or "name", sorts=SORTS,
                               q=request.args.get("q", ""), refresh=refresh,
                               events=url_for("events") if live is not None else "",
                               now=datetime.now(timezone.utc).strftime("%H:%M:%S"))

    def page(unit: str) -> str:
        with history.open() as store:
            data = read_unit(store, unit)
        trends = _trends(data)
        params = [p.parameter for p in trends.panels] or sorted(
            c[:-len("_change")] for c in data.history.columns if c.endswith("_change"))
        suspects, iso_rows, latest = (_isolation_rows(data.isolations, data.units)
                                      if len(data.isolations) else ([], [], None))
        advice = None
        if data.advice_test is not None:
            r = data.history.loc[data.advice_test]
            advice = {"id": data.advice_test, "status": str(r["status"]),
                      "text": str(r["summary"]) if r["accepted"] and
                      isinstance(r["summary"], str) else f"retest: {r['reason']}",
                      "date": _fmt_date(r["date"])}
        hist = data.history
        counts = tests_summary(hist, data.baseline)
        # the tests' table a page at a time (the latest page first); the figures use them all
        pages = max(1, -(-len(hist) // TESTS_PER_PAGE))
        at = number("page", pages)
        if at is None or at < 1:
            raise FilterError(f"page {at}: a whole number >= 1")
        at = min(at, pages)
        shown = hist.iloc[(at - 1) * TESTS_PER_PAGE: at * TESTS_PER_PAGE]
        return render_template("unit.html", d=data, o=data.overview, trends=trends,
                               figures=_figures(data, trends), counts=counts,
                               tests=_test_rows(shown, params), params=params,
                               test_pages=_page_links({"page": at, "pages": pages},
                                                      request.args),
                               shown=(len(shown), len(hist), at, pages),
                               suspects=suspects, isolations=iso_rows, latest=latest,
                               advice=advice,
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
        why = (err.strerror if isinstance(err, OSError) and err.strerror else str(err)).rstrip(".")
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

