"""A fleet that pages: `/api/units`, the index and `condmon units` show one page at a time,
with the counts of the whole fleet."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from condmon.cli.main import main
from condmon.report.web import create_app
from condmon.store import open_store


@pytest.fixture(scope="module")
def big(tmp_path_factory: pytest.TempPathFactory) -> str:
    """250 units, nothing stored for any yet (status none)."""
    db = str(tmp_path_factory.mktemp("pages") / "big.db")
    with open_store(db) as store:
        for i in range(250):
            store.unit_id(f"U{i:03d}", create=True)
    return db


def _get(client: Any, url: str, code: int = 200) -> Any:
    resp = client.get(url)
    assert resp.status_code == code, resp.get_data(as_text=True)
    return resp


def test_the_api_pages_and_counts_the_whole_fleet(big: str) -> None:
    client = create_app(big).test_client()
    first = _get(client, "/api/units").get_json()
    assert [u["unit"] for u in first["units"]] == [f"U{i:03d}" for i in range(100)]
    assert (first["page"], first["pages"], first["per_page"]) == (1, 3, 100)
    assert (first["matching"], first["total"], first["counts"]) == (250, 250, {"none": 250})
    last = _get(client, "/api/units?page=3").get_json()
    assert [u["unit"] for u in last["units"]] == [f"U{i:03d}" for i in range(200, 250)]
    small = _get(client, "/api/units?per_page=20&page=2&q=U1").get_json()
    assert [u["unit"] for u in small["units"]] == [f"U{i:03d}" for i in range(120, 140)]
    assert (small["pages"], small["matching"]) == (5, 100)
    assert len(_get(client, "/api/units?per_page=all").get_json()["units"]) == 250


@pytest.mark.parametrize("query,message", [
    ("page=4", "page 4: the 250 matching unit(s) fill 3 page(s) of 100"),
    ("per_page=0", "page 1, 0 a page: both must be >= 1"),
    ("per_page=abc", "per_page='abc': a whole number >= 1 or 'all'"),
    ("page=x", "page='x': a whole number >= 1"),
])
def test_a_bad_page_is_one_line(big: str, query: str, message: str) -> None:
    doc = _get(create_app(big).test_client(), f"/api/units?{query}", 400).get_json()
    assert doc["error"] == message


def test_the_index_pages_with_links_and_a_page_past_the_last_shows_the_last(big: str) -> None:
    client = create_app(big).test_client()
    html = _get(client, "/").get_data(as_text=True)
    assert html.count("<tr data-unit=") == 100 and "(page 1 of 3, 250 matching)" in html
    assert '<strong aria-current="page" data-page="1">1</strong>' in html
    assert 'href="?page=2" data-page="next ›"' in html and 'data-page="3"' in html
    assert '<span class="count" data-count="none">250</span>' in html  # the whole fleet's
    late = _get(client, "/?page=9&q=U").get_data(as_text=True)
    assert late.count("<tr data-unit=") == 50 and "(page 3 of 3, 250 matching)" in late
    assert 'href="?q=U&amp;page=2" data-page="‹ previous"' in late


def test_units_pages_as_the_api_does(big: str, capsys: pytest.CaptureFixture[str]) -> None:
    client = create_app(big).test_client()
    capsys.readouterr()
    assert main(["units", "--db", big, "--json", "--per-page", "100", "--page", "2"]) == 0
    assert json.loads(capsys.readouterr().out) == _get(client, "/api/units?page=2").get_json()
    assert main(["units", "--db", big, "--per-page", "100", "--page", "3"]) == 0
    text = capsys.readouterr().out
    assert "U249" in text and "U199" not in text and "page 3 of 3 (100 units a page" in text
    assert main(["units", "--db", big, "--per-page", "100", "--page", "4"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "error: page 4: the 250 matching unit(s) fill 3 page(s) of 100"


def test_units_json_of_the_whole_fleet_is_printed_a_chunk_at_a_time_as_the_api_gives_it(
        big: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    import condmon.report.web_data as W

    pages: list[tuple[int, int | None]] = []
    real = W.fleet_document

    def counted(store: Any, *args: Any, **kw: Any) -> Any:
        pages.append((kw.get("page", 1), kw.get("per_page")))
        return real(store, *args, **kw)

    client = create_app(big).test_client()
    whole = _get(client, "/api/units?per_page=all").get_json()
    monkeypatch.setattr(W, "fleet_document", counted)
    capsys.readouterr()
    assert main(["units", "--db", big, "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == whole and len(whole["units"]) == 250
    assert pages == [(1, 1), (1, 500)]   # the counts, then the units 500 at a time


def test_a_unit_page_pages_its_tests_the_latest_first(tmp_path: Path) -> None:
    import sqlalchemy as sa

    db = str(tmp_path / "long.db")
    with open_store(db) as store:
        uid = store.unit_id("LONG", create=True)
        with store.engine.begin() as conn:
            conn.execute(sa.text(
                "insert into tests (unit_id, created_at, source, file_hash, role, accepted, "
                "fits, method, closed_loop, constants, record_hash) values (:u, "
                "'2026-01-01 00:00:00', :s, :s, 'baseline', 1, '{}', 'ls', 0, '{}', :s)"),
                [{"u": uid, "s": f"r{k:03d}.csv"} for k in range(450)])
        ids = [int(i) for i in store.history("LONG").index]
    client = create_app(db).test_client()
    html = _get(client, "/units/LONG").get_data(as_text=True)
    assert html.count('<tr id="t') == 50 and f'id="t{ids[-1]}"' in html
    assert "50 of 450 tests (page 3 of 3; the figures show them all)" in html
    assert "450 tests (450 for the baseline, 0 checks" in html and 'href="?page=2#tests"' in html
    first = _get(client, "/units/LONG?page=1").get_data(as_text=True)
    assert first.count('<tr id="t') == 200 and f'id="t{ids[0]}"' in first
    assert f'id="t{ids[200]}"' not in first
    assert _get(client, "/units/LONG?page=0", 400).get_data(as_text=True).count("page 0") == 1


def test_page_numbers_are_checked_alike_everywhere(big: str,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    client = create_app(big).test_client()
    for url in ("/?page=0", "/api/units?page=0", "/api/units?page=-1"):
        assert _get(client, url, 400).status_code == 400
    assert 'value="status">most severe status first' in _get(client, "/").get_data(as_text=True)
    capsys.readouterr()
    for args in (["--json", "--page", "0"], ["--page", "0"], ["--json", "--page", "2"]):
        assert main(["units", "--db", big, *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: page 0, all a page: both must be >= 1"] * 2 + [
        "error: page 2: the 250 matching unit(s) fill 1 page (all on one)"]
    assert main(["units", "--db", big, "--json", "--sort", "status", "--per-page", "5"]) == 0
    assert json.loads(capsys.readouterr().out) == _get(
        client, "/api/units?sort=status&per_page=5").get_json()


def test_a_unit_page_draws_its_figures_once_per_state_of_its_history(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import condmon.report.figures as figures
    from condmon.simulate import simulate_actuator
    from condmon.workflows.checks import check_test
    from condmon.workflows.monitoring import add_baseline_tests

    db = str(tmp_path / "h.db")
    with open_store(db) as store:
        add_baseline_tests(store, "EMA-1", [simulate_actuator(seed=s) for s in range(3)])
        check_test(store, "EMA-1", simulate_actuator(seed=10))
    drawn: list[str] = []
    for name in ("fit_figure", "symptom_figure"):
        real = getattr(figures, name)
        monkeypatch.setattr(figures, name,
                            lambda *a, _r=real, _n=name, **k: (drawn.append(_n), _r(*a, **k))[1])
    client = create_app(db).test_client()
    first = _get(client, "/units/EMA-1").get_data(as_text=True)
    assert sorted(drawn) == ["fit_figure", "symptom_figure"]
    again = _get(client, "/units/EMA-1").get_data(as_text=True)
    assert again == first and len(drawn) == 2          # drawn once, shown twice
    with open_store(db) as store:                      # the history moves on
        check_test(store, "EMA-1", simulate_actuator(seed=11))
    after = _get(client, "/units/EMA-1").get_data(as_text=True)
    assert sorted(drawn) == ["fit_figure", "fit_figure", "symptom_figure", "symptom_figure"]
    old = first.split('src="data:image/png;base64,')[1].split('"')[0]
    assert old not in after                            # never the old figure
