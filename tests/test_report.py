"""Reports that do not mislead: the trend agrees with the stored status, one
numbering by test id, a time axis, excluded tests shown but never trended,
baseline flags shown, a fleet index linked both ways, escaped names and a file
of its own for every unit, isolation units, a read-only command."""

from __future__ import annotations

import dataclasses
import re
import shutil
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pandas as pd
import pytest

from condmon.cli.main import main
from condmon.monitor.fuzzy import load_monitor_config, symptom_degree
from condmon.report import FleetReport, ReportFiles, page_name, write_fleet_report, write_report
from condmon.report.trends import trend_data
from condmon.simulate import ActuatorRig, simulate_actuator
from condmon.store import open_store
from condmon.workflows.manage import exclude_test
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import EstimateOptions, add_baseline_tests

pytestmark = pytest.mark.tables  # the pages' tables, on every pandas allowed

ODD = "<b>EMA[/]7</b>"
HST = "HST <1> & 'x'"
LONG = "É" * 200  # 400 bytes in UTF-8
OTHERS = ("EMA/7", "EMA:7", LONG, "index")


def _records(rig: ActuatorRig, faults: list[str], seeds: range, label: str,
             month: int | None = None) -> list[pd.DataFrame]:
    """Simulated records; with ``month``, each carries a start time on day ``seed``."""
    out = []
    for s in seeds:
        df = simulate_actuator(rig.with_faults(faults), seed=s)
        df.attrs["source"] = f"{label}{s}.csv"
        if month is not None:
            df.attrs["start_time"] = f"2026-{month:02d}-{s:02d}T08:00:00+00:00"
        out.append(df)
    return out


def _isolation(statement: str, isolated: tuple[str, ...], changes: dict[str, float],
               rejected: dict[str, str]) -> Any:
    """What the store keeps of an isolation result (stored directly, no simulation)."""
    estimates = {p: SimpleNamespace(value=1.0 + c / 100, nominal=1.0, change_percent=c)
                 for p, c in changes.items()}
    return SimpleNamespace(detected=bool(isolated), detection_time=10.5 if isolated else None,
                           decided=True, reason=None, statement=statement,
                           suspects=tuple(changes), isolated=isolated, estimates=estimates,
                           errors={p: 1.0 for p in changes}, rejected=rejected,
                           to_dict=lambda: {"statement": statement})


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory, rig: ActuatorRig) -> tuple[str, dict[str, int]]:
    """One flagged actuator unit with dated checks (one excluded, one rejected,
    one stored late with an early date), four odd names, one isolation unit."""
    db = str(tmp_path_factory.mktemp("rep") / "h.db")
    ids: dict[str, int] = {}
    with open_store(db) as store:
        healthy = _records(rig, [], range(1, 5), "h", month=1)
        worn = _records(rig, ["D=*7"], range(9, 10), "worn", month=1)
        added = add_baseline_tests(store, ODD, [*healthy, *worn])
        ids["worn"] = added.tests[-1].test_id
        checks = _records(rig, [], range(21, 22), "c") + _records(rig, ["D=*7"], range(22, 23), "c")
        ids["ok"] = check_test(store, ODD, checks[0], test_date="2026-05-02").test_id
        ids["bad"] = check_test(store, ODD, checks[1], test_date="2026-05-09").test_id
        late = _records(rig, [], range(23, 26), "c")
        ids["gone"] = check_test(store, ODD, late[0], test_date="2026-05-05").test_id
        exclude_test(store, ids["gone"], "sensor <unplugged>")
        ids["retest"] = check_test(store, ODD, late[1], test_date="2026-05-06",
                                   options=EstimateOptions(fit_threshold=99.9)).test_id
        ids["early"] = check_test(store, ODD, late[2], test_date="2026-04-20").test_id
        undated = _records(rig, [], range(1, 4), "h")
        for name in OTHERS:
            add_baseline_tests(store, name, undated)
        for k, (when, isolated, changes) in enumerate([
                ("2026-03-01", ("Rv",), {"Rv": 25.0, "Dm": -3.0, "Tld": 1e30}),
                ("2026-02-01", (), {})]):
            res = _isolation(f"fault isolated: {', '.join(isolated) or 'none'}", isolated,
                             changes, {"Tld": "implausible"} if changes else {})
            store.add_isolation(HST, res, model="hst", source=f"run <{k}>.csv",
                                digest=f"d{k}", test_date=pd.Timestamp(when, tz="UTC"))
    return db, ids


@pytest.fixture(scope="module")
def report(fleet: tuple[str, dict[str, int]], tmp_path_factory: pytest.TempPathFactory
           ) -> FleetReport:
    db, _ = fleet
    with open_store(db, create=False) as store:
        return write_fleet_report(store, tmp_path_factory.mktemp("out"))


def _page(report: FleetReport, unit: str) -> ReportFiles:
    return next(p for p in report.pages if p.unit == unit)


def _row(html: str, test_id: int) -> str:
    found = re.search(rf"<tr id='t{test_id}'.*?</tr>", html)
    assert found is not None, test_id
    return found.group(0)


def test_names_are_escaped_and_every_unit_has_its_own_file(report: FleetReport) -> None:
    files = [p.html.name for p in report.pages]
    assert len(set(files)) == len(files) == 2 + len(OTHERS)
    assert all(len(f.encode()) < 255 and re.fullmatch(r"[A-Za-z0-9._-]+", f) for f in files)
    assert page_name("EMA/7") != page_name("EMA:7") and "index.html" not in files
    index = report.index.read_text()
    assert "<h1>Fleet</h1>" in index  # the unit named "index" did not overwrite it
    assert "<b>EMA" not in index and "&lt;b&gt;EMA[/]7&lt;/b&gt;" in index
    assert "HST &lt;1&gt; &amp; &#x27;x&#x27;" in index
    odd = _page(report, ODD).html.read_text()
    assert "<title>condmon — &lt;b&gt;EMA[/]7&lt;/b&gt;</title>" in odd and "<b>EMA" not in odd
    assert "alt='&lt;b&gt;EMA[/]7&lt;/b&gt;: trends'" in odd  # attributes too
    assert "sensor &lt;unplugged&gt;" in odd and "run &lt;0&gt;.csv" in (
        _page(report, HST).html.read_text())


def test_index_and_pages_link_both_ways(report: FleetReport) -> None:
    index = report.index.read_text()
    for page in report.pages:
        assert f"<a href='{page.html.name}'>" in index
        assert "<a href='index.html'>" in page.html.read_text()
        for fig in page.figures:
            assert fig.exists() and fig.name.startswith(page.html.stem + "-")
            assert f"<img src='{fig.name}'" in page.html.read_text()
    # latest status, date, model, tests and flags per unit
    row = re.search(rf"<a href='{page_name(ODD)}.html'>.*?</tr>", index)
    assert row is not None
    assert "2026-05-09 00:00" in row.group(0) and "dc-motor" in row.group(0)
    assert f"<a href='{page_name(ODD)}.html#flags'>⚠ 1</a>" in row.group(0)  # the outlier
    hst = re.search(rf"<a href='{page_name(HST)}.html'>.*?</tr>", index)
    assert hst is not None and '<span class="status no-go">' in hst.group(0)
    assert "2026-03-01 00:00" in hst.group(0) and ">hst<" in hst.group(0)


def test_trend_agrees_with_the_stored_status(fleet: tuple[str, dict[str, int]],
                                             report: FleetReport) -> None:
    db, ids = fleet
    page = _page(report, ODD)
    with open_store(db, create=False) as store:
        hist = store.history(ODD)
    # excluded and rejected tests are not trended; by date, not by id
    trended = (ids["early"], ids["ok"], ids["bad"])
    assert all(d.test_ids == trended for d in page.trends)
    assert [d.parameter for d in page.trends] == ["R", "L", "Ke", "Kt", "J", "D"]
    for d in page.trends:
        assert d.status == tuple(hist.loc[list(trended), "status"])
        assert d.xlabel == "test date (UTC)"
        assert list(d.x) == sorted(d.x)
        # the drawn bar implies exactly the symptom the status was computed from
        np.testing.assert_allclose(d.implied, d.symptom, atol=1e-9)
        assert np.all(d.width >= d.spread - 1e-9)
    assert page.notes == {}
    # the fit figure: every test but the excluded one, the rejected one included
    assert page.fits is not None
    assert ids["gone"] not in page.fits.test_ids and ids["retest"] in page.fits.test_ids
    assert page.fits.status[page.fits.test_ids.index(ids["retest"])] == "retest"


def test_tables_number_tests_by_id_and_grey_excluded_ones(
        fleet: tuple[str, dict[str, int]], report: FleetReport) -> None:
    _, ids = fleet
    html = _page(report, ODD).html.read_text()
    assert re.search(r"checked test \d|test 1\b", html) is None
    gone = _row(html, ids["gone"])
    assert "class='excluded'" in gone and "excluded: sensor &lt;unplugged&gt;" in gone
    assert '<span class="status excluded">' in gone and "title='SymH" not in gone
    assert f"<td>#{ids['bad']}</td><td class='l'>2026-05-09 00:00</td>" in _row(html, ids["bad"])
    assert '<span class="status retest">' in _row(html, ids["retest"])
    assert "2026-01-09 08:00" in _row(html, ids["worn"])
    other = _page(report, "EMA/7")
    assert "(stored)" in other.html.read_text()  # no test date: when it was stored
    assert other.fits is not None and other.fits.xlabel == "test # (no test dates recorded)"
    assert f"Latest check <a href='#t{ids['bad']}'>#{ids['bad']}</a>" in html


def test_flags_and_baseline_are_shown(fleet: tuple[str, dict[str, int]],
                                      report: FleetReport) -> None:
    _, ids = fleet
    html = _page(report, ODD).html.read_text()
    box = re.search(r"<div class='warn' id='flags'>.*?</div>", html)
    assert box is not None and "may not be trustworthy (1 warning)" in box.group(0)
    assert f"<a href='#t{ids['worn']}'>#{ids['worn']}</a>" in box.group(0)
    assert "<h2 id='baseline'>Baseline in use: default v1</h2>" in html
    assert "from tests #1-#5 (5 tests)" in html
    assert re.search(r"<td class='l'>D</td><td>[0-9.e-]+ ± [0-9.e-]+</td>"
                     r"<td class='l'>N m s/rad</td>", html)


def test_excluding_the_worn_test_changes_the_report(fleet: tuple[str, dict[str, int]],
                                                    tmp_path: Path) -> None:
    db, ids = fleet
    copy = tmp_path / "copy.db"
    shutil.copy(db, copy)
    with open_store(str(copy), create=False) as store:
        exclude_test(store, ids["worn"], "worn unit fitted")
        page = write_report(store, ODD, tmp_path / "r")
    html = page.html.read_text()
    assert "excluded: worn unit fitted" in _row(html, ids["worn"])
    assert "may not be trustworthy" not in html and "Baseline in use: default v2" in html
    d = next(t for t in page.trends if t.parameter == "D")
    i = d.test_ids.index(ids["bad"])
    assert d.status[i] == "no-go" and d.reaches_r1[i] and d.symptom[i] == 1.0
    np.testing.assert_allclose(d.implied, d.symptom, atol=1e-9)


def test_other_breakpoints_than_the_evaluation_are_explained(
        fleet: tuple[str, dict[str, int]], tmp_path: Path) -> None:
    db, ids = fleet
    cfg = load_monitor_config()
    # insisted on: breakpoints inside the healthy scatter are otherwise raised to it
    narrow = dataclasses.replace(cfg, r1={**cfg.r1, "R": 0.01}, r2={**cfg.r2, "R": 0.02},
                                 insist=frozenset({"R"}))
    with open_store(db, create=False) as store:
        page = write_report(store, ODD, tmp_path, narrow)
    d = page.trends[0]
    # the narrow bands disagree with the stored symptoms except where a bar reaches
    # both -r1 and +r1 (no direction measured: no symptom, as stored)
    both = d.width - np.abs(d.change) > d.r1
    assert set(page.notes) == {i for i, b in zip(d.test_ids, both) if not b} != set()
    assert all("stored symptom of R disagrees" in n for n in page.notes.values())
    assert "<div class='note'><b>Read with the table:</b>" in page.html.read_text()


def test_isolation_unit_page(report: FleetReport) -> None:
    page = _page(report, HST)
    html = page.html.read_text()
    assert "<h2>Isolations</h2>" in html and "fault isolated: Rv" in html
    assert "<td class='l'>Rv</td>" in html and "<b>+25.0 %</b>" in html
    assert ("title='estimate 1e+28 N m, nominal 1 N m, model error 1 noise σ, left out of "
            "the comparison'>rejected</td>") in html
    iso = page.isolations
    assert iso is not None and iso.isolation_ids == (2, 1)  # by date
    assert iso.xlabel == "test date (UTC)"
    assert np.isnan(iso.change["Tld"]).all()  # rejected from the comparison: not drawn
    assert iso.isolated["Rv"].tolist() == [False, True]
    assert page.trends == () and [f.name for f in page.figures] == [
        f"{page_name(HST)}-isolations.png"]


def test_undated_history_is_numbered_by_test_id() -> None:
    h = pd.DataFrame({"role": ["check", "check", "check"], "accepted": [True, False, True],
                      "excluded": [False, False, True], "status": ["no-go", "retest", "excluded"],
                      "baseline_id": [1, 1, 1], "R_change": [30.0, 0.0, 90.0],
                      "R_se": [0.001] * 3, "R_high": [2 / 3, 0.0, 1.0], "R_low": [0.0] * 3,
                      "test_date": [pd.NaT] * 3}, index=[4, 5, 6])
    from condmon.monitor.baseline import Baseline

    d = trend_data(h, "R", {1: Baseline(("R",), (1.0,), (0.05,), 5)}, 20.0, 40.0, 2.0)
    assert d.test_ids == (4,) and d.x.tolist() == [4.0]
    assert d.xlabel == "test # (no test dates recorded)"
    assert d.width.tolist() == pytest.approx([10.0])  # k·σ/mean·100, above the SE's 0.2
    high, _ = symptom_degree(30.0, 10.0, 20.0, 40.0)  # what the monitor computes
    assert d.implied.tolist() == pytest.approx([float(high)]) == [2 / 3]

    # an imported unit's own usage, when every test counts it: its cycles, not its ids
    d = trend_data(h.assign(cycle=[30.0, 35.0, 40.0]), "R",
                   {1: Baseline(("R",), (1.0,), (0.05,), 5)}, 20.0, 40.0, 2.0)
    assert d.test_ids == (4,) and d.x.tolist() == [30.0] and d.xlabel == "cycle"


def test_an_imported_unit_s_page_draws_its_cycles_and_no_empty_fit_figure(
        tmp_path: Path) -> None:
    """A table of measured capacities: no model fit to draw (the fit figure was
    an empty frame), and the trend runs along the cycles the table counts."""
    from condmon.workflows.imports import import_table

    table = tmp_path / "c.csv"
    table.write_text("cycle,capacity\n" + "".join(f"{10 * k},{1.9 - 0.004 * k:.4f}\n"
                                                    for k in range(1, 41)))
    decl = Path(__file__).parents[1] / "examples" / "batteries" / "li-ion-18650.toml"
    with open_store(f"sqlite:///{tmp_path / 'h.db'}") as store:
        import_table(store, table, decl, unit="C1")
        files = write_report(store, "C1", tmp_path / "out")
    names = sorted(p.name for p in files.figures)
    assert names == ["C1-symptoms.png", "C1-trends.png"], names
    assert files.trends[0].xlabel == "cycle"
    assert files.trends[0].x.tolist() == [10.0 * k for k in range(6, 41)]   # the checks


def test_report_cli_all_units_one_unit_and_read_only(
        fleet: tuple[str, dict[str, int]], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    db, _ = fleet
    assert main(["report", "--db", db, "--out", str(tmp_path / "all")]) == 0
    printed = capsys.readouterr().out
    assert "wrote 6 unit pages and the fleet index" in printed and "for EMA/7" in printed
    assert len(list((tmp_path / "all").glob("*.html"))) == 7
    one = tmp_path / "one"
    assert main(["report", "--db", db, "--out", str(one), "--unit", "EMA:7"]) == 0
    assert "wrote 1 unit page and the fleet index" in capsys.readouterr().out
    assert sorted(p.name for p in one.glob("*.html")) == sorted(
        [f"{page_name('EMA:7')}.html", "index.html"])
    index = (one / "index.html").read_text()
    assert f"<a href='{page_name('EMA:7')}.html'>" in index and "(no page written)" in index
    assert main(["report", "--db", db, "--out", str(one), "--unit", "nope"]) == 2
    assert "nope" in capsys.readouterr().err
    assert main(["report", "--db", str(tmp_path / "none.db"), "--out", str(tmp_path)]) == 2
    assert not (tmp_path / "none.db").exists()


@pytest.mark.parametrize("name", ["EMA-7", "EMA/7", "EMA:7", "a b", LONG, "x" * 200, "index",
                                  "INDEX", "con", "..", "Ölpumpe", "EMA-7.v2"])
def test_page_name_is_short_safe_and_keeps_plain_names(name: str) -> None:
    got = page_name(name)
    assert re.fullmatch(r"[A-Za-z0-9._-]+", got) and len(got) <= 91
    assert not got.startswith(".")
    plain = re.fullmatch(r"[A-Za-z0-9_-][A-Za-z0-9._-]{0,79}", name) is not None
    assert (got == name) == (plain and name.lower() not in ("index", "con"))
    assert page_name(name) == got  # stable


def test_the_baseline_in_use_its_version_and_what_it_holds(tmp_path: Path) -> None:
    """After an exclusion and a rebuild, the report's and the fleet page's unit
    pages say which baseline version is in use, when it was built, from which
    tests, and how many it holds per regime."""
    from _strokes import STROKE_DECLARATION as DECLARATION, write_stroke

    from condmon.report.web import create_app
    from condmon.workflows.manage import rebuild_baseline

    db = str(tmp_path / "h.db")
    speeds = [1.0, -1.0, 1.1, -1.1, 0.9, -0.9, 1.05]  # forward: #1 #3 #5 #7
    files = [str(write_stroke(tmp_path / f"r{i}.txt", v, seed=i))
             for i, v in enumerate(speeds)]
    assert main(["baseline", "add", *files, "--unit", "A", "--db", db,
                 "--model", str(DECLARATION)]) == 0

    def pages() -> tuple[str, str]:
        with open_store(db, create=False) as store:
            html = write_report(store, "A", tmp_path / "r").html.read_text()
            stored = store.latest_baseline("A")
        live = create_app(db).test_client().get("/units/A").get_data(as_text=True)
        assert stored is not None
        return html.replace("&#x27;", "'"), live.replace("&#39;", "'")

    def head(page: str) -> str:
        found = re.search(r"id=.in-use.>(.*?)</p>", page, re.S)
        assert found is not None
        return re.sub(r"<[^>]+>", "", found.group(1))

    with open_store(db, create=False) as store:
        exclude_test(store, 2, "a leaking fitting")  # a reverse stroke: 2 of them left
        built = store.latest_baseline("A")
    assert built is not None and built.version == 2
    want = (f"In use: baseline default v2, built {built.created_at:%Y-%m-%d %H:%M} UTC from "
            "tests #1,#3-#7 (6 tests: forward 4, reverse 2; too few to compare reverse).")
    for page in pages():
        assert head(page) == want
        assert "Baseline in use: default v2</h2>" in page
    with open_store(db, create=False) as store:
        rebuild_baseline(store, "A", reason="after overhaul", name="spring",
                         test_ids=[1, 3, 4, 5, 6])
        built = store.latest_baseline("A")
    assert built is not None and (built.name, built.version) == ("spring", 1)
    want = (f"In use: baseline spring v1, built {built.created_at:%Y-%m-%d %H:%M} UTC from "
            "tests #1,#3-#6 (5 tests: forward 3, reverse 2; too few to compare reverse).")
    for page in pages():
        assert head(page) == want
        assert "Baseline in use: spring v1</h2>" in page and "after overhaul" in page
        # the header counts the baseline in use, not how each test was added (it said
        # "7 baseline" here): #7 was added for the baseline and left out by the rebuild
        assert re.search(r"7 tests\s+\(5 in the baseline in use, 1 left out of it, 0 checks, "
                         r"1 excluded\)", page), page[:2000]
