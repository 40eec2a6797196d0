"""Reports that do not mislead: one numbering, escaped names, distinct files,
excluded tests shown but never trended, flags shown, links both ways."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from condmon.cli.main import main
from condmon.report.figures import trend_data
from condmon.report.html import page_name, write_fleet_report
from condmon.simulate import ActuatorRig, simulate_actuator
from condmon.store import HistoryStore, open_store
from condmon.workflows.manage import exclude_test
from condmon.workflows.monitoring import add_baseline_tests, check_test

ODD = "<b>EMA[/]7</b>"


def _records(rig: ActuatorRig, faults: list[str], seeds: range, label: str) -> list[pd.DataFrame]:
    out = []
    for s in seeds:
        df = simulate_actuator(rig.with_faults(faults), seed=s)
        df.attrs["source"] = f"{label}{s}.csv"
        out.append(df)
    return out


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory, rig: ActuatorRig) -> tuple[str, dict[str, int]]:
    db = str(tmp_path_factory.mktemp("rep") / "h.db")
    ids: dict[str, int] = {}
    with open_store(db) as store:
        healthy = _records(rig, [], range(1, 5), "h")
        worn = _records(rig, ["D=*7"], range(9, 10), "worn")
        added = add_baseline_tests(store, ODD, [*healthy, *worn])
        ids["worn"] = added.tests[-1].test_id
        ids["ok"] = check_test(store, ODD, _records(rig, [], range(21, 22), "c")[0],
                               test_date="2026-05-02").test_id
        ids["bad"] = check_test(store, ODD, _records(rig, ["D=*7"], range(22, 23), "c")[0],
                                test_date="2026-05-09").test_id
        for name in ("EMA/7", "EMA:7", "E" * 200):
            add_baseline_tests(store, name, healthy[:3])
    return db, ids


def test_names_are_escaped_and_files_distinct(fleet: tuple[str, dict[str, int]],
                                              tmp_path: Path) -> None:
    db, _ = fleet
    with open_store(db, create=False) as store:
        rep = write_fleet_report(store, tmp_path)
    names = [p.html.name for p in rep.pages]
    assert len(set(names)) == 4 and all(len(n.encode()) < 255 for n in names)
    assert page_name("EMA/7") != page_name("EMA:7")
    index = rep.index.read_text()
    assert "<b>EMA" not in index and "&lt;b&gt;EMA[/]7&lt;/b&gt;" in index
    for page in rep.pages:  # links both ways
        assert f"href='{page.html.name}'" in index
        assert "href='index.html'" in page.html.read_text()
        for fig in page.figures:
            assert fig.exists() and fig.name.startswith(page.html.stem)


def test_excluded_tests_are_shown_not_trended_and_flags_shown(
        fleet: tuple[str, dict[str, int]], tmp_path: Path) -> None:
    db, ids = fleet
    with open_store(db, create=False) as store:
        page = write_fleet_report(store, tmp_path, [ODD]).pages[0].html.read_text()
        # the contaminated baseline is flagged with the test to look at
        assert "may not be trustworthy" in page and f"#{ids['worn']}" in page
        hist = store.history(ODD)
    # one numbering: tests by their id, dates where known
    assert f"<td>#{ids['bad']}</td><td class='l'>2026-05-09 00:00</td>" in page
    assert " (stored)" in page  # the baseline tests have no test date
    base = _baseline(db, ODD)
    d = trend_data(hist, "D", *base["D"], k=2.0)
    assert d.test_ids == (ids["ok"], ids["bad"])
    assert d.status == tuple(hist.loc[list(d.test_ids), "status"])
    assert all(d.width >= d.spread - 1e-9)  # the symptom width is never below the spread


def test_exclude_changes_the_report(fleet: tuple[str, dict[str, int]], tmp_path: Path) -> None:
    db, ids = fleet
    import shutil

    copy = tmp_path / "copy.db"
    shutil.copy(db, copy)
    with open_store(str(copy)) as store:
        exclude_test(store, ids["worn"], "worn unit fitted")
        rep = write_fleet_report(store, tmp_path / "r", [ODD])
        hist = store.history(ODD)
    page = rep.pages[0].html.read_text()
    row = re.search(rf"<tr id='t{ids['worn']}' class='excluded'>.*?</tr>", page)
    assert row is not None and "excluded: worn unit fitted" in row.group(0)
    assert "may not be trustworthy" not in page  # the new baseline is clean
    assert hist.loc[ids["bad"], "status"] == "no-go"
    assert f"Baseline default v2" in page


def test_report_cli_all_units_and_read_only(fleet: tuple[str, dict[str, int]], tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    db, _ = fleet
    assert main(["report", "--db", db, "--out", str(tmp_path / "all")]) == 0
    assert "wrote 4 unit pages" in capsys.readouterr().out
    assert (tmp_path / "all" / "index.html").exists()
    assert main(["report", "--db", db, "--out", str(tmp_path / "one"), "--unit", "EMA/7"]) == 0
    assert (tmp_path / "one" / f"{page_name('EMA/7')}.html").exists()
    assert main(["report", "--db", str(tmp_path / "none.db"), "--out", str(tmp_path)]) == 2
    assert not (tmp_path / "none.db").exists()


def _baseline(db: str, unit: str) -> dict[str, tuple[float, float]]:
    with open_store(db, create=False) as store:
        stored = store.latest_baseline(unit)
        assert stored is not None
        b = stored.baseline
    return {p: (m, s) for p, m, s in zip(b.parameters, b.mean, b.std)}


def test_page_name_is_stable() -> None:
    assert page_name("EMA-7") == "EMA-7"
    assert page_name("a b") == "a_b-" + page_name("a b").rsplit("-", 1)[1]
    assert isinstance(HistoryStore, type)
