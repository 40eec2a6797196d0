"""The fleet page against what another tool or client may send: a retained
status that is not one, numbers and searches out of bounds, more live clients
than it serves, values no number can show."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import pytest

from condmon.report.live import LiveFeed
from condmon.report.web import EVENT_CLIENTS, create_app
from condmon.simulate import simulate_actuator
from condmon.store import open_store
from condmon.workflows.monitoring import add_baseline_tests


@pytest.fixture(scope="module")
def history(tmp_path_factory: pytest.TempPathFactory) -> Path:
    db = tmp_path_factory.mktemp("hostile") / "h.db"
    with open_store(str(db)) as store:
        add_baseline_tests(store, "EMA-1", [simulate_actuator(seed=s) for s in (1, 2, 3)])
        add_baseline_tests(store, "EMA-2", [simulate_actuator(seed=s) for s in (4, 5, 6)])
    return db


@pytest.mark.parametrize("doc", [
    {"unit": "EMA-1", "status": 7},
    {"unit": "EMA-1", "status": ["no-go"]},
    {"unit": "EMA-1", "status": "broken"},
    {"unit": "EMA-1", "status": "go", "isolated": "Rv"},
    {"unit": "EMA-1", "status": "go", "kind": {"a": 1}},
    {"unit": "EMA-2", "status": "go"},
    ["EMA-1"],
])
def test_a_retained_status_that_is_not_one_leaves_the_page_working(
        history: Path, doc: Any) -> None:
    feed = LiveFeed.offline()
    lines: list[str] = []
    feed.log = lines.append
    feed.take("condmon/EMA-1/status", json.dumps(doc).encode())
    assert feed.status("EMA-1") is None and feed.refused == 1
    assert lines and lines[0].startswith("live feed: refused condmon/EMA-1/status")
    client = create_app(history, live=feed).test_client()
    for url in ("/", "/api/units", "/?status=no-go", "/?sort=status", "/api/units?sort=forecast"):
        assert client.get(url).status_code == 200, url


def test_a_valid_status_is_kept_with_its_text_bounded(history: Path) -> None:
    feed = LiveFeed.offline()
    feed.take("condmon/EMA-1/status", json.dumps(
        {"unit": "EMA-1", "status": "no-go", "reason": "x" * 10_000, "t": 12.5, "isolated": ["Rv"], "kind": "isolated"}).encode())
    s = feed.status("EMA-1")
    assert s is not None and s["status"] == "no-go" and len(s["reason"]) == 500
    units = create_app(history, live=feed).test_client().get("/api/units").get_json()["units"]
    assert {u["unit"]: u["status"] for u in units}["EMA-1"] == "no-go"


def test_new_unit_names_past_the_limit_are_not_kept() -> None:
    feed = LiveFeed.offline()
    feed.max_units = 3
    for i in range(50):
        feed.take(f"condmon/U{i}/samples", b"")
    feed.take("condmon/U0/status", b'{"unit": "U0", "status": "go"}')
    assert len(feed._seen) == 3 and feed.refused == 47
    feed.take("condmon/..%2F/status", b'{"unit": "..%2F", "status": "go"}')
    assert feed.refused == 48


@pytest.mark.parametrize("url,message", [
    ("/api/units?per_page=99999999999999999999", "per_page=99999999999999999999: at most "
     "1000000"),
    ("/api/units?page=" + "9" * 400, "page=999999999999999999999999: at most 1000000"),
    ("/api/units?q=" + "a" * 60_000, "q: a search of up to 200 printable characters "
     "(this one has 60000)"),
    ("/api/units?q=EMA%00", "q: a search of up to 200 printable characters (this one has 4, "
     "with a control character)"),
])
def test_numbers_and_searches_out_of_bounds_are_one_line_400s(history: Path, url: str,
                                                              message: str) -> None:
    resp = create_app(history).test_client().get(url)
    assert resp.status_code == 400
    assert resp.get_json() == {"error": message}
    page = create_app(history).test_client().get(url.replace("/api/units", "/"))
    assert page.status_code == 400


def test_live_clients_past_the_bound_are_turned_away_and_pages_still_served(
        history: Path) -> None:
    feed = LiveFeed.offline()
    app = create_app(history, live=feed)
    client = app.test_client()
    open_streams = []
    for _ in range(EVENT_CLIENTS):
        resp = client.get("/api/events", buffered=False)
        assert resp.status_code == 200
        next(resp.response)  # the stream has started: it holds its slot
        open_streams.append(resp)
    extra = client.get("/api/events")
    assert extra.status_code == 503 and "live clients are connected already" in \
        extra.get_json()["error"]
    assert client.get("/").status_code == 200
    open_streams.pop().close()  # a browser gone frees its slot
    again = client.get("/api/events", buffered=False)
    assert again.status_code == 200
    again.close()
    for resp in open_streams:
        resp.close()
    assert threading.active_count() >= 1


def test_numbers_no_quantity_reaches_read_as_unknown(tmp_path: Path) -> None:
    """±inf and 1e308 written by another tool made the unit page a 500 and
    `report` a LinAlgError traceback: they are read as unknown."""
    import sqlite3

    from condmon.cli.main import app
    from condmon.workflows.checks import check_test
    from typer.testing import CliRunner

    db = tmp_path / "inf.db"
    with open_store(str(db)) as store:
        add_baseline_tests(store, "E", [simulate_actuator(seed=s) for s in (1, 2, 3)])
        for seed in (9, 10):
            check_test(store, "E", simulate_actuator(seed=seed))
    with sqlite3.connect(db) as c:
        last = "(select max(id) from tests)"
        c.execute(f"update estimates set value = 9e999 where test_id = {last} "
                  "and parameter = 'R'")
        c.execute(f"update estimates set value = -9e999 where test_id = {last} "
                  "and parameter = 'L'")
        c.execute(f"update estimates set value = 1e308, std_error = 1e308 where test_id = "
                  f"{last} - 1 and parameter = 'Kt'")
        c.execute("update symptoms set percent_change = 1e308 where parameter = 'R'")
    client = create_app(db).test_client()
    for url in ("/", "/units/E", "/api/units/E"):
        assert client.get(url).status_code == 200, url
    with open_store(str(db)) as store:
        hist = store.history("E")
    assert hist["R"].isna().sum() == 1 and hist["Kt"].isna().sum() == 1
    res = CliRunner().invoke(app, ["report", "--db", str(db), "--out", str(tmp_path / "r")])
    assert res.exit_code == 0, res.output


def test_listing_every_plant_unit_costs_the_same_queries_however_many(tmp_path: Path) -> None:
    """`?per_page=all` over 30,000 plant units ran past 400 s: each unit without
    tests cost two more queries (its baseline, its summary again)."""
    import sqlalchemy as sa

    def statements(n: int) -> int:
        db = tmp_path / f"u{n}.db"
        with open_store(str(db)) as store:
            for i in range(n):
                store.unit_id(f"HST-{i}", create=True, model="hst")
            count = [0]

            def tick(*_: Any) -> None:
                count[0] += 1

            client = create_app(db).test_client()
            sa.event.listen(sa.engine.Engine, "before_cursor_execute", tick)
            try:
                doc = client.get("/api/units?per_page=all").get_json()
            finally:
                sa.event.remove(sa.engine.Engine, "before_cursor_execute", tick)
            assert len(doc["units"]) == n
            return count[0]

    assert statements(40) == statements(10)
