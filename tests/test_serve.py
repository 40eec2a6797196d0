"""The live fleet page: JSON API equal to the CLI's, names encoded and escaped,
read-only, a clean stop, and the page in a real (headless) browser."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import quote

import pandas as pd
import pytest

from condmon.cli.main import main
from condmon.report.web import create_app, readonly_url
from condmon.simulate import ActuatorRig, simulate_actuator
from condmon.store import open_store
from condmon.store.engine import StoreError
from condmon.workflows.manage import exclude_test
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import add_baseline_tests

#: A name with everything a URL or a page could trip over.
ODD = "<b>EMA/7: x</b>"
#: Names a browser would fold (a ``..`` segment) or a router drop (a leading slash).
DOTTED, LEADING = "a/../b", "/lead"


def _records(rig: ActuatorRig, faults: list[str], seeds: range, label: str) -> list[pd.DataFrame]:
    out = []
    for s in seeds:
        df = simulate_actuator(rig.with_faults(faults), seed=s)
        df.attrs["source"] = f"{label}{s}.csv"
        out.append(df)
    return out


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory, rig: ActuatorRig) -> dict[str, Any]:
    """A history: an actuator with dated go / no-go / excluded checks, an HST
    unit with one stored isolation, empty units with awkward names."""
    from condmon.diagnose.isolation import isolate
    from condmon.io.digest import content_hash
    from condmon.models.registry import load_plant_model
    from condmon.simulate.plant import simulate_plant

    db = str(tmp_path_factory.mktemp("serve") / "fleet.db")
    ids: dict[str, int] = {}
    with open_store(db) as store:
        add_baseline_tests(store, ODD, _records(rig, [], range(1, 5), "h"), test_date="2026-03-01")
        for key, faults, seed, date in (("ok", [], 21, "2026-04-01"),
                                        ("bad", ["D=*7"], 22, "2026-05-01"),
                                        ("wrong", [], 23, "2026-05-02")):
            rec = _records(rig, faults, range(seed, seed + 1), "c")[0]
            ids[key] = check_test(store, ODD, rec, test_date=date).test_id
        exclude_test(store, ids["wrong"], "sensor <unplugged>")
        hst = load_plant_model("hst")
        rec = simulate_plant(hst, ["Rv=+40%@10s"], seed=3)
        store.add_isolation("HST-1", isolate(rec, hst, workers=1), model="hst",
                            source="hst-rv.csv", digest=content_hash(rec))
        for name in (DOTTED, LEADING):
            store.unit_id(name, create=True)
    return {"db": db, "ids": ids}


@pytest.fixture(scope="module")
def client(fleet: dict[str, Any]) -> Any:
    return create_app(fleet["db"]).test_client()


def _cli_json(capsys: pytest.CaptureFixture[str], *argv: str) -> Any:
    capsys.readouterr()
    assert main(list(argv)) == 0
    return json.loads(capsys.readouterr().out)


def _api(client: Any, url: str, status: int = 200) -> Any:
    resp = client.get(url)
    assert resp.status_code == status, resp.get_data(as_text=True)
    assert resp.mimetype == "application/json"
    return resp.get_json()


# -- the JSON API ------------------------------------------------------------------------
def test_api_units_is_the_cli_units_json(fleet: dict[str, Any], client: Any,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    doc = _api(client, "/api/units")   # pages of 100 units, as `units --per-page 100`
    assert doc == _cli_json(capsys, "units", "--db", fleet["db"], "--json", "--per-page", "100")
    assert (doc["page"], doc["pages"], doc["per_page"], doc["total"]) == (1, 1, 100, 4)
    assert _api(client, "/api/units?per_page=all") == _cli_json(capsys, "units", "--db",
                                                                 fleet["db"], "--json")
    status = {u["unit"]: u["status"] for u in doc["units"]}
    assert status == {ODD: "no-go", "HST-1": "no-go", DOTTED: None, LEADING: None}


def test_api_filters(client: Any) -> None:
    names = lambda url: [u["unit"] for u in _api(client, url)["units"]]  # noqa: E731
    assert names("/api/units?status=no-go&q=ema") == [ODD]
    assert names("/api/units?status=none") == [LEADING, DOTTED]
    assert names("/api/units?status=go,none&status=advisory") == [LEADING, DOTTED]
    assert names("/api/units?q=%2F..%2F") == [DOTTED]
    err = _api(client, "/api/units?status=broken", 400)["error"]
    assert err.startswith("unknown status broken; allowed: no-go, advisory")


def test_api_unit_is_the_cli_history_json(fleet: dict[str, Any], client: Any,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    ids = fleet["ids"]
    doc = _api(client, "/api/units/" + quote(ODD, safe="/"))
    for entry in _api(client, "/api/units")["units"]:  # the overview is the fleet's entry
        assert _api(client, "/api/unit?name=" + quote(entry["unit"]))["overview"] == entry
    cli = _cli_json(capsys, "history", "--unit", ODD, "--db", fleet["db"], "--json")
    assert doc["tests"] == [{k: v for k, v in d.items() if k != "kind"} for d in cli]
    status = {d["test_id"]: d["status"] for d in doc["tests"]}
    assert (status[ids["ok"]], status[ids["bad"]], status[ids["wrong"]]) == (
        "go", "no-go", "excluded")
    assert doc["overview"]["status"] == "no-go" and doc["isolations"] == []
    assert doc["baseline"]["test_ids"] == [1, 2, 3, 4] and doc["baseline"]["n"] == 4
    # the advice is the latest check that counts (the excluded one is later)
    assert doc["advice"]["test_id"] == ids["bad"]
    assert doc["advice"]["faults"][0]["name"] == "friction increase"
    iso = _api(client, "/api/units/HST-1")
    cli = _cli_json(capsys, "history", "--unit", "HST-1", "--db", fleet["db"], "--json")
    assert iso["isolations"] == [{k: v for k, v in d.items() if k != "kind"} for d in cli]
    assert iso["isolations"][0]["isolated"] == ["Rv"] and iso["tests"] == []
    assert iso["baseline"] is None and iso["advice"] is None


# -- pages -------------------------------------------------------------------------------
def test_names_are_encoded_and_escaped(client: Any) -> None:
    page = client.get("/").get_data(as_text=True)
    assert "<b>EMA" not in page and "&lt;b&gt;EMA/7: x&lt;/b&gt;" in page
    links = dict((html_unescape(t), h) for h, t in
                 re.findall(r'<a href="([^"]*)">([^<]*)</a></td>', page))
    assert links[ODD] == "/units/%3Cb%3EEMA/7:%20x%3C/b%3E"
    assert links[LEADING] == "/units//lead"
    assert links[DOTTED] == "/unit?name=a/../b"
    for name, href in links.items():
        unit = client.get(href).get_data(as_text=True)
        assert f"<h1>{escape(name)}</h1>" in unit, href
    assert _api(client, "/api/unit?name=a/../b")["unit"] == DOTTED
    missing = client.get("/units/EMA%2F8")
    assert missing.status_code == 404 and "unknown unit &#39;EMA/8&#39;" in missing.get_data(
        as_text=True)
    assert _api(client, "/api/units/nope", 404) == {"error": "unknown unit 'nope'"}


@pytest.mark.tables
def test_index_filters_by_query(client: Any) -> None:
    page = client.get("/?status=no-go&q=HST").get_data(as_text=True)
    rows = re.findall(r'<tr data-unit="([^"]*)" data-status="([^"]*)">', page)
    assert rows == [("HST-1", "no-go")]
    assert 'value="no-go" checked' in page and 'value="HST"' in page
    bad = client.get("/?status=<x>")
    assert bad.status_code == 400 and "<x>" not in bad.get_data(as_text=True)


@pytest.mark.tables
def test_unit_page_shows_trends_advice_tests_and_isolations(fleet: dict[str, Any],
                                                            client: Any) -> None:
    ids = fleet["ids"]
    page = client.get("/units/" + quote(ODD, safe="/")).get_data(as_text=True)
    panels = re.findall(r'<svg class="trend".*?</svg>', page, re.S)
    assert len(panels) >= 5  # R, L, Kt, J, D
    d_panel = next(p for p in panels if "D change [%]" in p)
    # the 4 baseline tests and the 2 checks that count; the excluded one is not drawn
    assert len(re.findall(r"<circle ", d_panel)) == 6
    assert f'href="#t{ids["bad"]}"' in d_panel and f'href="#t{ids["wrong"]}"' not in d_panel
    assert 'class="band fault"' in d_panel and 'class="band spread"' in d_panel
    assert "2026-05-01" in d_panel  # a time axis: the tests carry dates
    assert re.search(rf'<tr id="t{ids["wrong"]}" class="excluded"', page)
    assert "excluded: sensor &lt;unplugged&gt;" in page
    assert "Friction at the motor shaft" in page  # the fault advice
    assert "Not trended: #7 excluded." in page
    hst = client.get("/units/HST-1").get_data(as_text=True)
    assert '<section id="isolations">' in hst and "fault isolated: Rv" in hst
    assert '<svg class="trend"' not in hst


def _bar(panel: str, test_id: int) -> tuple[float, float, float]:
    """The drawn error bar of test ``test_id`` in an SVG panel: its centre and
    half-length in the panel's percent, read from the y ticks' positions."""
    ticks = [(float(y), float(v)) for y, v in
             re.findall(r'<text class="ytick" x="[^"]*" y="([-0-9.]+)">([-+0-9.e]+)</text>',
                        panel)]
    (y0, v0), (y1, v1) = ticks[0], ticks[-1]
    per_px = (v1 - v0) / (y1 - y0)  # percent per pixel (negative: y grows down)
    point = re.search(rf'<a href="#t{test_id}"><g .*?</g></a>', panel, re.S)
    assert point is not None, test_id
    line = re.search(r'<line [^>]*y1="([-0-9.]+)" y2="([-0-9.]+)"', point.group(0))
    cy = re.search(r'cy="([-0-9.]+)"', point.group(0))
    assert line is not None and cy is not None, point.group(0)
    lo, hi = float(line.group(1)), float(line.group(2))
    centre = v0 + (float(cy.group(1)) + 3 - y0) * per_px  # tick labels sit 3 px low
    return centre, abs(hi - lo) / 2 * abs(per_px), (lo + hi) / 2


def test_one_error_bar_the_symptom_width(fleet: dict[str, Any], client: Any) -> None:
    """The page, its JSON and the report draw ±k·max(σ, SE) of the evaluation
    the status rests on, and say so; never a bare standard error."""
    from condmon.monitor.fuzzy import load_monitor_config

    ids, k = fleet["ids"], load_monitor_config().k
    with open_store(fleet["db"], create=False) as store:
        hist = store.history(ODD)
        used = store.baseline_by_id(ODD, int(hist.loc[ids["bad"], "baseline_id"])).baseline
    j = used.parameters.index("D")
    want = k * 100 * max(used.std[j], hist.loc[ids["bad"], "D_se"]) / abs(used.mean[j])
    one_se = 100 * hist.loc[ids["bad"], "D_se"] / used.mean[j]
    assert abs(want - one_se) > 5  # the two definitions differ visibly here
    page = client.get("/units/" + quote(ODD, safe="/")).get_data(as_text=True)
    d_panel = next(p for p in re.findall(r'<svg class="trend".*?</svg>', page, re.S)
                   if "D change [%]" in p)
    centre, half, middle = _bar(d_panel, ids["bad"])
    assert half == pytest.approx(want, rel=0.02, abs=0.6)  # pixels rounded to 0.1
    assert centre == pytest.approx(hist.loc[ids["bad"], "D_change"], abs=1.0)
    assert "±1 standard error" not in page and "(SE)" not in page
    from condmon.report.trends import error_bar

    assert error_bar(k, words=True) in html_unescape(page)
    doc = _api(client, "/api/units/" + quote(ODD, safe="/"))
    assert doc["error_bars"] == {"definition": error_bar(k, words=True), "k": k, "unit": "%"}
    d = next(t for t in doc["trends"] if t["parameter"] == "D")
    assert d["half_width"][d["test_ids"].index(ids["bad"])] == pytest.approx(want)


def _images(client: Any, url: str) -> dict[str, bytes]:
    """The figures of a unit page: name to the PNG it shows."""
    import base64

    page = client.get(url).get_data(as_text=True)
    return {name: base64.b64decode(data) for name, data in re.findall(
        r'<figure class="report" id="fig-([a-z]+)"><img src="data:image/png;base64,([^"]+)"',
        page)}


def test_unit_page_shows_the_report_s_figures(fleet: dict[str, Any], client: Any,
                                              tmp_path: Path) -> None:
    """The fit, symptom and isolation figures are the report's own, pixel for pixel."""
    from condmon.report import page_name, write_report

    with open_store(fleet["db"], create=False) as store:
        write_report(store, ODD, tmp_path)
        write_report(store, "HST-1", tmp_path)
    ema = _images(client, "/units/" + quote(ODD, safe="/"))
    assert sorted(ema) == ["fits", "symptoms"]
    for name, png in ema.items():
        assert png.startswith(b"\x89PNG") and png == (
            tmp_path / f"{page_name(ODD)}-{name}.png").read_bytes(), name
    assert _images(client, "/units/HST-1") == {
        "isolations": (tmp_path / "HST-1-isolations.png").read_bytes()}


def _suspect_cells(page: str, n: int) -> list[str]:
    """The last ``n`` cells (the suspects') of every isolation row (either page)."""
    rows = re.findall(r"<tr id=[\"']i\d+[\"'].*?</tr>", page, re.S)
    cells = [c for r in rows for c in re.findall(r"<td[^>]*>(.*?)</td>", r, re.S)[-n:]]
    return [html_unescape(re.sub(r"</?b>", "", c)) for c in cells]


def _suspects_table(page: str) -> dict[str, list[str]]:
    """The latest isolation's suspects table: suspect to its cells."""
    table = re.search(r"<table class=[\"']suspects[\"']>(.*?)</table>", page, re.S)
    assert table is not None
    rows = [[html_unescape(c) for c in re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", r, re.S)]
            for r in re.findall(r"<tr>(.*?)</tr>", table.group(1), re.S)]
    assert rows[0] == ["suspect", "estimate", "nominal", "unit", "change [%]",
                       "model error [noise σ]", ""]
    return {r[0]: r[1:] for r in rows[1:]}


@pytest.mark.tables
def test_hst_numbers_carry_their_units(fleet: dict[str, Any], client: Any,
                                       tmp_path: Path) -> None:
    """Every estimate and nominal of an HST unit, on the report's page and the
    fleet page, is written with the unit its model declares."""
    from condmon.models.registry import load_plant_model
    from condmon.report import write_report

    units = load_plant_model("hst").parameter_units()
    assert units["Rv"] == "N m s/rad"
    with open_store(fleet["db"], create=False) as store:
        iso = store.isolations("HST-1").iloc[0]
        report = write_report(store, "HST-1", tmp_path).html.read_text()
    live = client.get("/units/HST-1").get_data(as_text=True)
    for page in (report, live):
        cells = _suspect_cells(page, 6)  # Dp, Rlkgp, Dm, Rlkgm, Rv, Tld
        assert all(re.fullmatch(r"rejected|[-+][0-9.]+ %|= [-+]?[0-9.e+-]+ (.+)", c)
                   for c in cells), cells
        assert f"= {iso['Tld']:.4g} N m" in cells  # a nominal of 0: the estimate, in N m
        table = _suspects_table(page)
        assert table["Rv"] == [f"{iso['Rv']:.4g}", "11.27", "N m s/rad",
                               f"{iso['Rv_change']:+.1f}", f"{iso['Rv_error']:.2g}", "isolated"]
        assert table["Dm"][1:3] == ["4.45e-05", "m^3/rad"]
        assert all(row[2] == units[p] for p, row in table.items())
        assert f"estimate {iso['Rv']:.4g} N m s/rad, nominal 11.27 N m s/rad" in (
            html_unescape(page))  # on hover in the table of every isolation
    assert re.search(r"<td class=\"l\">D</td><td>[^<]+</td><td>[^<]+</td>"
                     r"<td class=\"l\">N m s/rad</td>",
                     client.get("/units/" + quote(ODD, safe="/")).get_data(as_text=True))


# -- read-only ---------------------------------------------------------------------------
def test_never_writes_or_creates(fleet: dict[str, Any], client: Any, tmp_path: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    db = Path(fleet["db"])
    before = (db.read_bytes(), db.stat().st_mtime_ns)
    for url in ("/", "/api/units", "/units/HST-1", "/api/units/" + quote(ODD, safe="/")):
        assert client.get(url).status_code == 200
    assert (db.read_bytes(), db.stat().st_mtime_ns) == before
    missing = tmp_path / "none.db"
    with pytest.raises(StoreError, match=r"none\.db: no history database there"):
        create_app(missing)
    capsys.readouterr()
    assert main(["serve", "--db", str(missing), "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and not missing.exists()
    foreign = tmp_path / "foreign.db"
    import sqlite3

    with sqlite3.connect(foreign) as conn:
        conn.execute("create table t (x)")
    conn.close()
    with pytest.raises(StoreError, match="not a condmon history"):
        create_app(foreign)


def test_read_only_on_each_backend(store_url: str, rig: ActuatorRig) -> None:
    import sqlalchemy as sa

    from condmon.store.engine import database_url

    if store_url.startswith("postgresql"):  # an empty database is refused, not filled
        with pytest.raises(StoreError, match="no condmon history there yet"):
            create_app(store_url)
        engine = sa.create_engine(database_url(store_url))
        assert sa.inspect(engine).get_table_names() == []
        engine.dispose()
    with open_store(store_url) as store:
        add_baseline_tests(store, "EMA 1", _records(rig, [], range(1, 4), "h"))
    client = create_app(store_url).test_client()
    assert [u["status"] for u in _api(client, "/api/units")["units"]] == ["baseline"]
    with open_store(readonly_url(store_url)) as store:  # the schema is there: only reads
        with pytest.raises(StoreError, match="read-only"):
            store.unit_id("EMA 2", create=True)


def html_unescape(text: str) -> str:
    import html

    return html.unescape(text)


def escape(text: str) -> str:
    import html

    return html.escape(text, quote=True)


# -- what a new user reads ---------------------------------------------------------------
def _copy(fleet: dict[str, Any], tmp_path: Path) -> Path:
    db = tmp_path / "copy.db"
    shutil.copy(fleet["db"], db)
    return db


def _add_tests(db: Path, unit: str, rows: list[tuple[str, bool, str | None]]) -> None:
    """Store ``(role, accepted, reason)`` tests of a new ``unit`` with plain SQL, a day apart."""
    import sqlalchemy as sa

    with open_store(db) as store:
        uid = store.unit_id(unit, create=True)
        with store.engine.begin() as conn:
            for day, (role, accepted, reason) in enumerate(rows, start=1):
                conn.execute(sa.text(
                    "insert into tests (unit_id, created_at, test_date, source, file_hash, role, "
                    "accepted, reason, fits, method, closed_loop, constants, record_hash) values "
                    "(:u, :t, :t, :s, :s, :r, :a, :why, '{}', 'ls', 0, '{}', :s)"),
                    {"u": uid, "t": f"2026-02-{day:02d} 00:00:00.000000", "s": f"{unit}-{day}.csv",
                     "r": role, "a": accepted, "why": reason})


def test_a_unit_without_a_baseline_yet_is_building(fleet: dict[str, Any], tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    db = _copy(fleet, tmp_path)
    _add_tests(db, "EMA-new", [("baseline", True, None), ("baseline", True, None)])
    _add_tests(db, "EMA-bad", [("baseline", True, None), ("baseline", False, "fit 40 %")])
    client = create_app(db).test_client()
    doc = _api(client, "/api/units")
    assert doc == _cli_json(capsys, "units", "--db", str(db), "--json", "--per-page", "100")
    units = {u["unit"]: u for u in doc["units"]}
    assert units["EMA-new"]["status"] == units["EMA-bad"]["status"] == "building"
    assert units["EMA-new"]["summary"] == "building the baseline: 2 of 3 accepted healthy tests"
    assert units["EMA-bad"]["summary"] == ("building the baseline: 1 of 3 accepted healthy "
                                           "tests; latest rejected: fit 40 %")
    assert units[ODD]["status"] == "no-go"  # a saved baseline: checks as before
    for name in ("EMA-new", "EMA-bad"):  # the unit's page says the same
        assert _api(client, "/api/units/" + name)["overview"] == units[name]
    assert [u["unit"] for u in _api(client, "/api/units?status=building")["units"]] == [
        "EMA-bad", "EMA-new"]
    page = client.get("/?status=building").get_data(as_text=True)
    assert re.findall(r'data-status="([^"]*)">', page) == ["building", "building"]
    assert 'value="building" checked' in page


def test_the_flag_legend_only_with_a_flagged_unit(fleet: dict[str, Any], client: Any,
                                                  tmp_path: Path) -> None:
    import sqlalchemy as sa

    assert all(not u["baseline_flags"] for u in _api(client, "/api/units")["units"])
    assert "⚠" not in client.get("/").get_data(as_text=True)
    db = _copy(fleet, tmp_path)
    with open_store(db) as store, store.engine.begin() as conn:
        conn.execute(sa.text("update baselines set flags = '[{\"message\": \"x\"}]'"))
    page = create_app(db).test_client().get("/").get_data(as_text=True)
    assert "⚠: the unit's baseline is flagged" in page and '<span class="flag"' in page


def test_an_empty_history_is_not_an_empty_filter(client: Any, tmp_path: Path) -> None:
    db = tmp_path / "empty.db"
    open_store(db).close()
    page = create_app(db).test_client().get("/").get_data(as_text=True)
    assert ("No units in this history yet (<code>condmon baseline add</code> or "
            "<code>condmon fleet run</code> adds some)") in page
    assert "0 of 0" not in page and "matches" not in page
    none = client.get("/?q=no-such-unit").get_data(as_text=True)
    assert "0 of 4 units shown" in none and "No unit matches the filter." in none
    assert "No units in this history yet" not in none


def test_a_file_that_is_not_a_history_and_a_history_gone(fleet: dict[str, Any],
                                                         tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    notes = tmp_path / "README.md"
    notes.write_text("# notes\n\nnot a database at all\n" * 20)
    with pytest.raises(StoreError, match=r"README\.md: not a condmon history database"):
        create_app(notes)
    capsys.readouterr()
    assert main(["serve", "--db", str(notes), "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a condmon history database" in err
    db = _copy(fleet, tmp_path)
    client = create_app(db).test_client()
    db.unlink()
    gone = f"the history database is gone or unreadable: {db}"
    resp = client.get("/")
    assert resp.status_code == 503 and gone in resp.get_data(as_text=True)
    assert _api(client, "/api/units", 503) == {"error": gone}
    assert not db.exists()  # the page never creates it


# -- fleet scale -------------------------------------------------------------------------
def _statements(store: Any) -> int:
    """How many SQL statements :meth:`unit_summaries` issues."""
    import sqlalchemy as sa

    count = [0]

    def tick(*_: Any) -> None:
        count[0] += 1

    sa.event.listen(store.engine, "before_cursor_execute", tick)
    try:
        store.unit_summaries()
    finally:
        sa.event.remove(store.engine, "before_cursor_execute", tick)
    return count[0]


def test_the_index_reads_a_fixed_number_of_queries(fleet: dict[str, Any],
                                                   tmp_path: Path) -> None:
    import sqlalchemy as sa

    db = tmp_path / "more.db"
    shutil.copy(fleet["db"], db)
    with open_store(db) as store:
        few = _statements(store)
        for n in range(20):  # 20 more units, each with a test
            store.unit_id(f"EMA-{n:02d}", create=True)
        with store.engine.begin() as conn:
            conn.execute(sa.text("insert into tests (unit_id, created_at, source, file_hash, "
                                 "role, accepted, fits, method, closed_loop, constants, "
                                 "record_hash) select id, created_at, 'r.csv', '', 'baseline', "
                                 "1, '{}', 'ls', 0, '{}', 'x' || id from units "
                                 "where name like 'EMA-%'"))
        rows = store.unit_summaries()   # rows added by hand: worked out as it reads
        assert len(rows) == 24 and {r["status"] for r in rows if r["unit"].startswith("EMA-")
                                    and r["tests"] == 1} == {"building"}
        assert store.refresh_states() == 20 and store.refresh_states() == 0
        assert _statements(store) == few


# -- the server and a real browser -------------------------------------------------------
def _start(db: str) -> tuple[subprocess.Popen[str], str]:
    """``condmon serve --port 0`` in a child process; its URL once it listens."""
    proc = subprocess.Popen([sys.executable, "-c", "from condmon.cli.main import run; run()",
                             "serve", "--db", db, "--port", "0", "--refresh", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "COLUMNS": "200"})
    assert proc.stdout is not None
    line = proc.stdout.readline()
    match = re.search(r"(http://127\.0\.0\.1:\d+/)", line)
    if match is None:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"server did not start: {line}{out}{err}")
    return proc, match.group(1)


def _stop(proc: subprocess.Popen[str]) -> tuple[int, str, str]:
    proc.send_signal(signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    return proc.returncode, out, err


def test_serve_prints_its_url_and_stops_on_ctrl_c(fleet: dict[str, Any]) -> None:
    proc, url = _start(fleet["db"])
    try:
        with urllib.request.urlopen(url + "api/units", timeout=10) as resp:
            assert {u["unit"] for u in json.load(resp)["units"]} == {ODD, "HST-1", DOTTED,
                                                                       LEADING}
    finally:
        code, out, err = _stop(proc)
    assert code == 0 and out.strip().endswith("stopped"), (out, err)
    assert "Traceback" not in err


def test_a_port_in_use_is_one_line(fleet: dict[str, Any],
                                   capsys: pytest.CaptureFixture[str]) -> None:
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        capsys.readouterr()
        assert main(["serve", "--db", fleet["db"], "--port", str(port)]) == 2
    err = capsys.readouterr().err
    assert err == (f"error: cannot listen on 127.0.0.1:{port}: Address already in use; "
                   "choose another --port or --host\n")
    assert main(["serve", "--db", fleet["db"], "--host", "999.1.1.1"]) == 2
    assert capsys.readouterr().err == ("error: cannot listen on 999.1.1.1:8050: Invalid "
                                       "host/port specified; choose another --port or --host\n")


def _chromium() -> str | None:
    """Debian's Chromium (or ``CONDMON_CHROMIUM``) when it and Playwright are installed."""
    exe = os.environ.get("CONDMON_CHROMIUM") or shutil.which("chromium") or shutil.which(
        "chromium-browser")
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return None
    return exe if exe is not None and Path(exe).is_file() else None


@pytest.fixture(scope="module")
def browser_page(fleet: dict[str, Any]) -> Iterator[tuple[Any, str]]:
    """A headless Chromium page (driven by Playwright) and the server's URL."""
    exe = _chromium()
    if exe is None:
        why = ("no browser: needs Debian's chromium (apt-get install chromium; .ci/browser.sh "
               "does it) and the playwright package (pip install condmon[test])")
        if os.environ.get("CONDMON_REQUIRE_BROWSER") == "1":
            pytest.fail(f"CONDMON_REQUIRE_BROWSER=1 but {why}")
        pytest.skip(why)
    from playwright.sync_api import sync_playwright

    proc, url = _start(fleet["db"])
    profile = tempfile.mkdtemp(prefix="condmon-chromium-")
    try:
        with sync_playwright() as pw:
            ctx = pw.chromium.launch_persistent_context(
                profile, executable_path=exe, headless=True,
                args=["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                      "--no-first-run", "--disable-background-networking",
                      "--disable-component-update", "--disable-sync"])
            try:
                page = ctx.new_page()
                page.set_default_timeout(10_000)
                yield page, url
            finally:
                ctx.close()
    finally:
        _stop(proc)
        shutil.rmtree(profile, ignore_errors=True)


def test_in_a_browser(fleet: dict[str, Any], browser_page: tuple[Any, str],
                      capsys: pytest.CaptureFixture[str]) -> None:
    from playwright.sync_api import expect

    page, url = browser_page
    started = time.monotonic()
    page.goto(url)
    rows = page.locator("#units-body tr")
    listed = {r.get_attribute("data-unit"): r.get_attribute("data-status")
              for r in rows.all()}
    assert listed == {ODD: "no-go", "HST-1": "no-go", DOTTED: "none", LEADING: "none"}
    assert page.locator(f'tr[data-unit="HST-1"] .status.no-go').inner_text() == "no-go"
    # filter as you type: the table is fetched again, the URL remembers it
    page.fill("input[name=q]", "hst")
    expect(rows).to_have_count(1)
    expect(page).to_have_url(url + "?q=hst")
    page.fill("input[name=q]", "")
    expect(rows).to_have_count(4)
    # the odd name's link leads to its page, with the trend figure drawn
    page.get_by_role("link", name=ODD).click()
    page.wait_for_selector("svg.trend circle")
    assert page.locator("h1").inner_text() == ODD
    box = page.locator("svg.trend").first.bounding_box()
    assert box is not None and box["width"] > 200 and box["height"] > 100
    assert page.locator("svg.trend circle").count() >= 5 * 6
    assert page.locator(f"#t{fleet['ids']['wrong']}.excluded").count() == 1
    # the API, asked by the page itself, agrees with `condmon history --json`
    api = page.evaluate("(u) => fetch(u).then(r => r.json())",
                        url + "api/units/" + quote(ODD, safe="/"))
    cli = _cli_json(capsys, "history", "--unit", ODD, "--db", fleet["db"], "--json")
    assert [(t["test_id"], t["status"]) for t in api["tests"]] == [
        (d["test_id"], d["status"]) for d in cli]
    page.goto(url + "units/HST-1")
    assert "fault isolated: Rv" in page.locator("#isolations").inner_text()
    assert time.monotonic() - started < 20


def test_figures_in_a_browser(fleet: dict[str, Any], browser_page: tuple[Any, str],
                              tmp_path: Path) -> None:
    """The report's figures load in the page at their size; screenshots of both
    unit pages are kept (in ``CONDMON_SCREENSHOTS`` when set) to be looked at."""
    page, url = browser_page
    shots = Path(os.environ.get("CONDMON_SCREENSHOTS") or tmp_path)
    shots.mkdir(parents=True, exist_ok=True)
    page.set_viewport_size({"width": 1200, "height": 900})
    for path, name, figures in ((quote(ODD, safe="/"), "ema", ("fits", "symptoms")),
                                ("HST-1", "hst", ("isolations",))):
        page.goto(url + "units/" + path)
        for fig in figures:
            img = page.locator(f"#fig-{fig} img")
            img.scroll_into_view_if_needed()
            size = img.evaluate("i => [i.complete, i.naturalWidth, i.naturalHeight]")
            assert size[0] and size[1] == 1100 and size[2] > 300, (fig, size)
            box = img.bounding_box()
            assert box is not None and box["width"] > 600, (fig, box)
        page.screenshot(path=str(shots / f"live-{name}.png"), full_page=True)
        assert (shots / f"live-{name}.png").stat().st_size > 10_000


@pytest.fixture(scope="module")
def wearing_page(tmp_path_factory: pytest.TempPathFactory, wearing: tuple[Path, float],
                 browser_page: tuple[Any, str]) -> Iterator[tuple[Any, str]]:
    """The browser's page and a second server, over a copy of the wearing history
    (conftest): friction rising fast (WEAR), at half that pace (SLOW) and not at
    all (STABLE)."""
    db = str(tmp_path_factory.mktemp("wear") / "wear.db")
    shutil.copy(wearing[0], db)
    proc, url = _start(db)
    try:
        yield browser_page[0], url
    finally:
        _stop(proc)


def test_forecast_band_in_a_browser(wearing_page: tuple[Any, str],
                                    tmp_path: Path) -> None:
    """The fleet ordered by urgency; a wearing unit's friction panel draws the
    forecast band and says which band it is, a stable unit's draws none."""
    page, url = wearing_page
    page.goto(url)
    page.select_option("select[name=sort]", "forecast")
    expect_url = url + "?sort=forecast"
    page.wait_for_url(expect_url)
    rows = page.locator("#units-body tr")
    assert [r.get_attribute("data-unit") for r in rows.all()] == ["WEAR", "SLOW", "STABLE"]
    assert [r.get_attribute("data-forecast") for r in rows.all()] == ["D", "D", None]
    assert "no trend" in page.locator('tr[data-unit="STABLE"] td.forecast').inner_text()
    api = page.evaluate("(u) => fetch(u).then(r => r.json())", url + "api/units?sort=forecast")
    fast = api["units"][0]["forecast"]
    cell = page.locator('tr[data-unit="WEAR"] td.forecast').inner_text()
    assert cell.startswith(f"D: {fast['median']:.2g} d (") or cell.startswith(
        f"D: {fast['median']:.0f} d (")
    page.get_by_role("link", name="WEAR", exact=True).click()
    page.wait_for_selector("svg.trend circle")
    band = page.locator('svg.trend g.forecast[data-forecast="D"] polygon.forecast-band')
    assert band.count() == 1
    box = band.bounding_box()
    assert box is not None and box["width"] > 20
    assert page.locator("svg.trend g.forecast").count() == 1  # only the friction trends
    legend = page.locator('[data-legend="forecast"]')
    assert "forecast, 90 % interval" in legend.inner_text()
    assert "Forecast: D no-go in" in page.locator("#forecast").inner_text()
    page.screenshot(path=str(tmp_path / "wear.png"), full_page=True)
    page.goto(url + "units/STABLE")
    page.wait_for_selector("svg.trend circle")
    assert page.locator("svg.trend g.forecast").count() == 0
    assert page.locator('[data-legend="forecast"]').count() == 0
    assert "none, no trend towards no-go" in page.locator("#forecast").inner_text()
