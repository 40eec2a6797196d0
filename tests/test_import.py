"""``condmon import``: measured indicators in, an absolute end of life, bad input refused."""

from __future__ import annotations

import json
import re
import sqlite3
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from condmon.cli.main import main
from condmon.errors import ConfigError, DataError
from condmon.models.indicators import load_indicators, parse_end_of_life
from condmon.store import open_store
from condmon.workflows.imports import import_table

ROOT = Path(__file__).resolve().parents[1]
DECL = ROOT / "examples" / "batteries" / "li-ion-18650.toml"
NASA = ROOT.parent / "shared" / "external" / "batteries" / "nasa"


def _cell(path: Path, n: int = 60, start: float = 1.9, rate: float = 0.006,
          seed: int = 0) -> Path:
    """A capacity series [Ah]: a steady fade with recoveries, known truth."""
    rng = np.random.default_rng(seed)
    k = np.arange(1, n + 1)
    cap = start - rate * k + 0.004 * rng.standard_normal(n)
    path.write_text("cycle,capacity\n" + "".join(f"{c},{v:.6f}\n" for c, v in zip(k, cap)))
    return path


def _tests(db: Path) -> int:
    if not db.exists():
        return 0
    with sqlite3.connect(db) as c:
        try:
            return int(c.execute("select count(*) from tests").fetchone()[0])
        except sqlite3.OperationalError:
            return 0


def test_import_then_forecast_to_an_absolute_end_of_life(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    """60 cycles fading 0.006 Ah a cycle from 1.9 Ah: the cell reaches 1.4 Ah
    near cycle 83, about 23 cycles after the last; the forecast's 90 %
    interval holds that, counted in cycles, and `units` lists its status."""
    db = tmp_path / "h.db"
    cell = _cell(tmp_path / "C1.csv")
    assert main(["import", str(cell), "--unit", "C1", "--model", str(DECL), "--db",
                 str(db)]) == 0
    assert "60 rows stored by cycle, the first 5 the baseline" in capsys.readouterr().out
    assert main(["forecast", "--unit", "C1", "--db", str(db), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["by"] == "cycles"
    p = doc["parameters"][0]
    assert p["parameter"] == "capacity" and p["unit"] == "Ah" and p["model"] == "path"
    assert p["rule"] == "capacity fade at < 1.4 Ah"
    truth = (1.9 - 1.4) / 0.006 - 60
    r = p["remaining"]
    assert r["low"] <= truth <= r["high"] and abs(r["median"] - truth) < 0.3 * truth
    assert any("held the true remaining life" in n for n in p["notes"])
    # the table says what its interval means too, not only the JSON
    assert main(["forecast", "--unit", "C1", "--db", str(db)]) == 0
    said = capsys.readouterr().out
    assert "interval: capacity: its 90 % interval held the true remaining life" in said
    assert "not on units like this one" in " ".join(said.split())
    assert main(["history", "--unit", "C1", "--db", str(db)]) == 0
    header = [ln for ln in capsys.readouterr().out.splitlines() if "status" in ln][0]
    assert "cycle" in header and "capacity" in header and "fit %" not in header
    assert main(["units", "--db", str(db), "--json"]) == 0
    units = json.loads(capsys.readouterr().out)
    row = units["units"][0] if isinstance(units, dict) else units[0]
    assert row["unit"] == "C1" and row["status"] in ("advisory", "no-go")


def test_a_unit_s_own_end_of_life_and_a_healthy_cell_raises_no_alarm(tmp_path: Path) -> None:
    """--no-go 'capacity<0.88' is kept for the unit and moves its forecast
    later; a cell that holds its capacity stays go on every check."""
    db = tmp_path / "h.db"
    cell = _cell(tmp_path / "C1.csv")
    with open_store(f"sqlite:///{db}") as store:
        import_table(store, cell, DECL, unit="C1", no_go=["capacity<0.88"])
        assert store.end_of_life("C1") == {"capacity": "<0.88"}
        model = store.indicator_model("C1")
        assert model.indicator("capacity").end_of_life.value == 0.88
        from condmon.workflows.forecasting import forecast_unit
        f = forecast_unit(store, "C1").parameters[0].forecast
        assert f.remaining is not None and f.remaining[0] > 100   # (1.9-0.88)/0.006 - 60 = 110
        flat = tmp_path / "flat.csv"
        rng = np.random.default_rng(3)
        flat.write_text("cycle,capacity\n" + "".join(
            f"{k},{1.9 + 0.004 * rng.standard_normal():.6f}\n" for k in range(1, 61)))
        import_table(store, flat, DECL, unit="C2")
        statuses = store.history("C2")["status"]
        assert set(statuses[store.history("C2")["role"] == "check"]) == {"go"}


def test_a_changed_end_of_life_is_said_kept_and_dates_are_not_invented(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Importing the same table again with --no-go stores no row twice but keeps
    the unit's new end of life and says what changed (from the declaration's
    < 1.4 Ah to 0.88 Ah: the forecast moves later by (1.4-0.88)/0.006 = 87
    cycles); `units` shows no date for a table counted in cycles (its import
    time is not when the capacity was measured)."""
    db = tmp_path / "h.db"
    cell = _cell(tmp_path / "C1.csv")
    args = ["import", str(cell), "--unit", "C1", "--model", str(DECL), "--db", str(db)]
    assert main(args) == 0
    assert "changed" not in capsys.readouterr().out
    assert main(["forecast", "--unit", "C1", "--db", str(db), "--json"]) == 0
    before = json.loads(capsys.readouterr().out)["parameters"][0]["remaining"]["median"]
    assert main([*args, "--no-go", "capacity<0.88"]) == 0
    said = " ".join(capsys.readouterr().out.split())
    assert "0 rows stored" in said and "60 already stored" in said
    assert "capacity: end of life changed from < 1.4 Ah to < 0.88 Ah" in said
    with open_store(f"sqlite:///{db}") as store:
        assert store.end_of_life("C1") == {"capacity": "<0.88"}
    assert main(["forecast", "--unit", "C1", "--db", str(db), "--json"]) == 0
    after = json.loads(capsys.readouterr().out)["parameters"][0]["remaining"]["median"]
    assert 60 < after - before < 115
    # the same end of life again: nothing changed, nothing said
    assert main([*args, "--no-go", "capacity<0.88", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["units"][0]["end_of_life_changed"] == []
    assert main(["units", "--db", str(db), "--json"]) == 0
    units = json.loads(capsys.readouterr().out)
    row = units["units"][0] if isinstance(units, dict) else units[0]
    assert row["latest_date"] is None
    # the listing's forecast is of the new end of life too (the change is audited)
    assert row["forecast"]["median"] == pytest.approx(after, abs=1.0)
    assert main(["audit", "--db", str(db)]) == 0
    assert "end of life changed" in capsys.readouterr().out


def _dated_forecast(tmp_path: Path, days: np.ndarray) -> Any:
    """The capacity forecast of 60 cycles fading 0.006 Ah a cycle from 1.9 Ah,
    cycle k dated ``days[k - 1]`` days after 2026-01-01."""
    k = np.arange(1, 61)
    cap = 1.9 - 0.006 * k + 0.004 * np.random.default_rng(0).standard_normal(60)
    dates = pd.Timestamp("2026-01-01") + pd.to_timedelta(days, unit="D")
    table = tmp_path / "D1.csv"
    pd.DataFrame({"date": dates.strftime("%Y-%m-%d"), "cycle": k, "capacity": cap}
                 ).to_csv(table, index=False)
    with open_store(f"sqlite:///{tmp_path / 'h.db'}") as store:
        import_table(store, table, DECL, unit="D1")
        from condmon.workflows.forecasting import forecast_unit
        return forecast_unit(store, "D1").parameters[0]


def test_a_table_with_dates_and_cycles_forecasts_a_date(tmp_path: Path) -> None:
    """Three cycles a day from 2026-01-01, counted in cycles: the no-go date
    follows the cycles left at the unit's own pace (59 cycles in 19 days), so
    the median's date is its cycles left times 19/59 days after the last (to the day)."""
    p = _dated_forecast(tmp_path, np.arange(60) // 3)
    assert p.forecast.remaining is not None and p.date is not None
    expected = pd.Timestamp("2026-01-20") + pd.Timedelta(days=p.forecast.remaining[0] * 19 / 59)
    assert abs((pd.Timestamp(p.date).tz_localize(None) - expected).total_seconds()) <= 86400


def test_a_changed_pace_is_said_beside_the_no_go_date(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """One cycle every 3 days for 40 cycles, then 5 a day: the no-go date at the
    history's mean pace (about half a cycle a day) lies weeks after the date at
    the latest checks' pace, and the forecast says both, in its table too."""
    p = _dated_forecast(tmp_path, np.concatenate([np.arange(40) * 3, 120 + np.arange(20) // 5]))
    said = [n for n in p.forecast.notes if n.startswith("the date is at the history's mean pace")]
    assert len(said) == 1 and "cycles a day) it is 2026-05" in said[0], p.forecast.notes
    assert p.date is not None and p.date > "2026-06"
    assert main(["forecast", "--unit", "D1", "--db", str(tmp_path / "h.db")]) == 0
    assert f"pace: capacity: {said[0]}" in " ".join(capsys.readouterr().out.split())


def test_a_grown_table_imports_only_its_new_rows(tmp_path: Path) -> None:
    db = tmp_path / "h.db"
    full = _cell(tmp_path / "full.csv", n=40)
    part = tmp_path / "part.csv"
    part.write_text("".join(full.read_text().splitlines(keepends=True)[:21]))
    with open_store(f"sqlite:///{db}") as store:
        assert import_table(store, part, DECL, unit="C1")[0].added == 20
        again = import_table(store, full, DECL, unit="C1")[0]
        assert (again.added, again.skipped) == (20, 20)
        assert len(store.history("C1")) == 40


def test_a_table_of_many_units_in_long_and_wide_form(tmp_path: Path) -> None:
    rows = ["unit,cycle,capacity,capacity_se"]
    for u in ("A", "B"):
        rows += [f"{u},{k},{1.9 - 0.005 * k:.4f},0.002" for k in range(1, 21)]
    long = tmp_path / "long.csv"
    long.write_text("\n".join(rows) + "\n")
    wide = tmp_path / "wide.csv"
    wide.write_text("cycle,C,D\n" + "".join(f"{k},{1.9 - 0.005 * k:.4f},{1.8 - 0.004 * k:.4f}\n"
                                             for k in range(1, 21)))
    with open_store("sqlite://") as store:
        got = import_table(store, long, DECL)
        assert [(u.unit, u.added) for u in got] == [("A", 20), ("B", 20)]
        hist = store.history("A")
        assert set(hist["method"]) == {"import"}
        se = store.estimates_of(list(hist.index))[1]["capacity"]
        assert np.allclose(se.to_numpy(), 0.002)
        got = import_table(store, wide, DECL, indicator="capacity")
        assert [(u.unit, u.added) for u in got] == [("C", 20), ("D", 20)]


@pytest.mark.parametrize("content, needle", [
    ("cycle,capacity\n1,1.9\n2,1.89\n3,abc\n4,1.88\n", "row 3 (line 4), column 'capacity': 'abc'"),
    ("cycle,capacity\n1,1.9\n2,1.89\n2,1.88\n4,1.87\n", "row 3 (line 4), column 'cycle': 2"),
    ("cycle,capcity\n1,1.9\n2,1.89\n", "column 'capcity' is not one of the declaration's"),
    ("cycle,capacity\n1,1.9\n2,\n3,1.88\n", "row 2 (line 3), column 'capacity': '' is empty"),
    ("capacity\n1.9\n1.89\n", "no axis column"),
])
def test_bad_tables_get_one_line_exit_2_and_nothing_stored(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str, needle: str) -> None:
    db = tmp_path / "h.db"
    bad = tmp_path / "bad.csv"
    bad.write_text(content + "".join(f"{k},{1.8 - 0.001 * k}\n" for k in range(10, 20)
                                     if content.startswith("cycle")))
    assert main(["import", str(bad), "--unit", "C1", "--model", str(DECL), "--db",
                 str(db)]) == 2
    err = capsys.readouterr().err
    assert needle in err and "bad.csv" in err, err
    assert len(err.strip().splitlines()) <= 2   # one message (wrapped at most once)
    assert _tests(db) == 0


def test_an_end_of_life_in_other_units_is_refused(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "h.db"
    cell = _cell(tmp_path / "C1.csv")
    assert main(["import", str(cell), "--unit", "C1", "--model", str(DECL), "--db", str(db),
                 "--no-go", "capacity<880 mAh"]) == 2
    err = capsys.readouterr().err
    assert "is in 'mAh', but 'capacity' is in 'Ah'" in err
    assert _tests(db) == 0
    assert main(["import", str(cell), "--unit", "C1", "--model", str(DECL), "--db", str(db),
                 "--no-go", "voltage<3.0"]) == 2
    assert "no indicator 'voltage'" in capsys.readouterr().err
    assert _tests(db) == 0


def test_going_back_against_the_stored_cycles_is_refused(tmp_path: Path) -> None:
    first = _cell(tmp_path / "a.csv", n=20)
    older = tmp_path / "b.csv"
    older.write_text("cycle,capacity\n15.5,1.5\n30,1.4\n")
    with open_store("sqlite://") as store:
        import_table(store, first, DECL, unit="C1")
        with pytest.raises(DataError, match=r"row 1 \(line 2\), column 'cycle': 15.5 is not "
                                            r"after the last one stored"):
            import_table(store, older, DECL, unit="C1")
        assert len(store.history("C1")) == 20


def test_the_end_of_life_forms() -> None:
    assert parse_end_of_life("< 1.4 Ah", "capacity", "Ah").level(1.9) == 1.4
    rated = parse_end_of_life("< 70 % rated", "capacity", "Ah", rated=2.0)
    assert rated.level(1.9, rated=2.0) == pytest.approx(1.4)
    change = parse_end_of_life("-30 %", "capacity", "Ah")
    assert change.level(2.0) == pytest.approx(1.4) and change.below
    rise = parse_end_of_life("> 25 mohm", "R", "mohm")
    assert not rise.below and rise.reached(26.0, 20.0) and not rise.reached(24.0, 20.0)
    with pytest.raises(ConfigError, match="declares no 'rated' value"):
        parse_end_of_life("< 70 % rated", "capacity", "Ah")
    with pytest.raises(ConfigError, match="is not an end of life"):
        parse_end_of_life("below 1.4", "capacity", "Ah")


def test_the_shipped_declaration_reads() -> None:
    m = load_indicators(DECL)
    cap = m.indicator("capacity")
    assert (m.method, cap.unit, cap.rated, cap.end_of_life.level(1.9)) == ("path", "Ah", 2.0, 1.4)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64),
                          st.text(max_size=4)), min_size=8, max_size=30))
def test_any_column_of_cells_is_stored_whole_or_refused_with_its_row(
        tmp_path: Path, cells: list[object]) -> None:
    """Whatever the cells hold, the import stores every row or refuses, naming
    the file (and the row and column of a bad cell), and then stores nothing."""
    table = tmp_path / "t.csv"
    # (a comma, a line feed or a carriage return would make other cells or rows)
    text = ["cycle,capacity"] + [f"{k},{str(c).replace(',', ';').replace(chr(10), ' ')}"
                                 .replace(chr(13), " ") for k, c in enumerate(cells, 1)]
    table.write_text("\n".join(text) + "\n")
    with open_store("sqlite://") as store:
        try:
            got = import_table(store, table, DECL, unit="U")
        except DataError as err:
            msg = str(err)   # a cell's row and column, the baseline's, or the file's
            assert "t.csv" in msg and "nothing was stored" in msg, msg
            assert store.imported_hashes("U") == set()
        else:
            assert got[0].added == len(cells)


@pytest.mark.skipif(not (NASA / "B0005.csv").is_file(), reason="the NASA cells are not here")
def test_the_shipped_nasa_csv_goes_in_as_it_is(tmp_path: Path) -> None:
    with open_store("sqlite://") as store:
        got = import_table(store, NASA / "B0005.csv", DECL, unit="B0005")[0]
        assert (got.added, got.baseline, got.status) == (168, 5, "no-go")
        hist = store.history("B0005")
        checks = hist[hist["role"] == "check"]
        first_nogo = checks.index[checks["status"] == "no-go"][0]
        assert hist.loc[first_nogo, "cycle"] == 125   # the README's first cycle below 1.4 Ah


def test_a_parquet_table_goes_in_through_the_notebook_api(tmp_path: Path) -> None:
    import pandas as pd

    import condmon

    table = tmp_path / "cells.parquet"
    pd.DataFrame({"unit": ["P1"] * 12, "hours": np.arange(1.0, 13.0) * 10.0,
                  "capacity": 1.9 - 0.01 * np.arange(12)}).to_parquet(table)
    with condmon.History(tmp_path / "h.db") as h:
        got = h.import_table(table, DECL)
        assert [(u.unit, u.added, u.axis) for u in got] == [("P1", 12, "hours")]
        assert h.forecast("P1").result.by == "hours"


@pytest.mark.parametrize("content, needle", [
    ("cycle,capacity\n" + "".join(f"{k},{1.85 - 0.001 * k}\n" for k in range(1, 11))
     + "11,1824.6\n", "row 11 (line 12), column 'capacity': 1824.6 is 988 times its baseline"),
    ("cycle,capacity\n" + "".join(f"{k},{1.85 - 0.001 * k}\n" for k in range(1, 11))
     + "11,0\n", "of the other sign than its baseline, or 0"),
    ("cycle,capacity\n" + "".join(f"{k},{1.85 - 0.001 * k}\n" for k in range(1, 11))
     + "11,1e300\n", "row 11 (line 12), column 'capacity': '1e300' is beyond 1e+15"),
    ("date,capacity\n" + "".join(f"{k:02d}/01/2024,{1.85 - 0.001 * k}\n"
                                   for k in range(1, 11)), "is not an ISO 8601 date"),
    ("Cycle,capacity\n1,1.9\n", "names are case-sensitive: 'Cycle'"),
    ("date,capacity\n" + "".join(f"2026-01-{k:02d},{1.85 - 0.001 * k}\n" for k in range(1, 11))
     + "2199-01-01,1.8\n", "row 11 (line 12), column 'date': '2199-01-01' is more than a day "
                           "in the future"),
    ("cycle,capacity\n" + "".join(f"{k},{1850 - k}\n" for k in range(1, 11)),
     "rows 1-5 (the baseline of unit 'C1'), column 'capacity': their mean 1847 is 924 times "
     "the declared rated value (2 Ah); values in another unit than Ah?"),
    ("cycle,capacity\n" + "".join(f"{k},{1.85 - 0.001 * k}\n" for k in range(1, 11))
     + '11,"1,750"\n', "row 11 (line 12), column 'capacity': '1,750' has a comma, and the "
                        "table's cells are separated by commas: a thousands separator or a "
                        "decimal comma?"),
    ("cycle;capacity\n" + "".join(f"{k};{1.85 - 0.001 * k}\n" for k in range(1, 11))
     + "11;1,750\n", "row 11 (line 12), column 'capacity': '1,750' has a comma, and row 1 of "
                      "the column has a decimal point"),
    ("cycle,capacity\n", "no rows under the header"),
])
def test_values_a_unit_cannot_have_are_refused(tmp_path: Path, content: str,
                                               needle: str) -> None:
    """A value in other units (mAh for Ah), a missing reading written as 0, a
    huge number, a day-first date, a header in other case, no rows; a whole
    table in mAh against the declared 2 Ah; a comma that may separate
    thousands (it was read as a decimal comma: "1,750" became 1.75)."""
    bad = tmp_path / "bad.csv"
    bad.write_text(content)
    with open_store("sqlite://") as store:
        with pytest.raises(DataError, match=re.escape(needle)):
            import_table(store, bad, DECL, unit="C1")
        assert store.imported_hashes("C1") == set()


def test_a_table_must_keep_its_unit_s_axis_and_end_of_life(tmp_path: Path) -> None:
    cell = _cell(tmp_path / "c.csv", n=20)
    by_hours = tmp_path / "h.csv"
    by_hours.write_text("hours,capacity\n1000,1.7\n1010,1.69\n")
    past = tmp_path / "p.csv"
    with open_store("sqlite://") as store:
        import_table(store, cell, DECL, unit="C1")
        with pytest.raises(DataError, match="is counted in cycle"):
            import_table(store, by_hours, DECL, unit="C1")
        with pytest.raises(DataError, match="already past its end of life"):
            import_table(store, cell, DECL, unit="C2", no_go="capacity>1.5")
        assert store.imported_hashes("C2") == set()
    past.write_text("cycle;capacity\n" + "".join(f"{k};{1.85 - 0.001 * k:.4f}".replace(".", ",")
                                                  + "\n" for k in range(1, 11)))
    with open_store("sqlite://") as store:   # a ';' table with decimal commas reads
        assert import_table(store, past, DECL, unit="S")[0].added == 10


def test_another_declaration_of_the_same_name_is_refused_for_a_unit(tmp_path: Path) -> None:
    """A copy of the declaration with another end of life, imported into a unit
    of the shipped one, would change its end of life without a word."""
    copy = tmp_path / "cell.toml"
    copy.write_text(DECL.read_text().replace('end_of_life = "< 1.4 Ah"',
                                             'end_of_life = "< 1.7 Ah"'))
    full = _cell(tmp_path / "c.csv", n=30)
    part = tmp_path / "p.csv"
    part.write_text("".join(full.read_text().splitlines(keepends=True)[:21]))
    with open_store("sqlite://") as store:
        import_table(store, part, DECL, unit="C1")
        with pytest.raises(DataError, match="another declaration of 'li-ion-18650'"):
            import_table(store, full, copy, unit="C1")
        assert len(store.history("C1")) == 20
        assert import_table(store, full, DECL, unit="C1")[0].added == 10


@pytest.mark.parametrize("decl, start, end, last", [
    ('thickness = { unit = "mm", end_of_life = "< 3 mm" }', 12.0, 2.5, "no-go"),
    ('thickness = { unit = "mm", rated = 12.0, end_of_life = "< 25 % rated" }', 12.0, 2.5,
     "no-go"),
    ('thickness = { unit = "mm", end_of_life = "-75 %" }', 12.0, 2.5, "no-go"),
    ('velocity = { unit = "mm/s", end_of_life = "> 7.1 mm/s" }', 2.0, 8.0, "no-go"),
    ('thickness = { unit = "mm", end_of_life = "< 3 mm" }', 12.0, 0.9, None),
    ('thickness = { unit = "mm", end_of_life = "< 3 mm" }', 1200.0, 1150.0, None),
])
def test_a_unit_heading_for_its_end_of_life_is_believed_on_its_way(
        tmp_path: Path, decl: str, start: float, end: float, last: str | None) -> None:
    """A brake pad from 12 mm to its 3 mm limit, a bearing from 2 mm/s to its
    7.1 mm/s trip: the end of life is more than three times from the healthy
    value, and every reading on the way was refused as a unit error, so the unit
    could never reach no-go. Readings are believed up to three times beyond the
    span from the baseline to the end of life: a pad read at 0.9 mm (past a third
    of its limit) is still refused, and so is a table in hundredths of a mm."""
    name = decl.split(" ", 1)[0]
    model = tmp_path / "m.toml"
    model.write_text(f'name = "wear"\n[indicators]\n{decl}\n')
    table = tmp_path / "t.csv"
    values = np.linspace(start, end, 30)
    table.write_text(f"cycle,{name}\n" + "".join(f"{k + 1},{v:.4f}\n"
                                                  for k, v in enumerate(values)))
    with open_store("sqlite://") as store:
        if last is None:
            with pytest.raises(DataError, match="likely a unit error|values in another unit"):
                import_table(store, table, model, unit="P1")
            assert store.imported_hashes("P1") == set()
        else:
            got = import_table(store, table, model, unit="P1")
            assert (got[0].added, got[0].status) == (30, last)


def test_units_of_different_lives_in_one_wide_table(tmp_path: Path) -> None:
    """Run-to-failure cells end at different cycles: in a table of a column per
    unit, an empty cell is no reading of that unit (the whole fleet's table was
    refused at the first cycle after the shortest life); text is still refused."""
    lines = ["cycle,C,D"]
    for k in range(1, 21):
        d = "" if k > 15 or k == 7 else f"{1.8 - 0.004 * k:.4f}"
        lines.append(f"{k},{1.9 - 0.005 * k:.4f},{d}")
    wide = tmp_path / "wide.csv"
    wide.write_text("\n".join(lines) + "\n")
    with open_store("sqlite://") as store:
        got = import_table(store, wide, DECL, indicator="capacity")
        assert [(u.unit, u.added) for u in got] == [("C", 20), ("D", 14)]
    frame = pd.DataFrame({"cycle": np.arange(1.0, 11.0), "E": np.r_[np.linspace(1.9, 1.85, 8),
                                                                    np.nan, np.nan]})
    with open_store("sqlite://") as store:
        assert import_table(store, frame, DECL, indicator="capacity")[0].added == 8
    gap = pd.DataFrame({"cycle": [1.0, 2.0, 3.0], "capacity": [1.9, np.nan, 1.88]})
    with open_store("sqlite://") as store, pytest.raises(DataError, match=re.escape(
            "row 2 (line 3), column 'capacity': '' is empty")):   # not np.float64(nan)
        import_table(store, gap, DECL, unit="X")
    empty = tmp_path / "empty.csv"
    empty.write_text("cycle,C,F\n1,1.9,\n2,1.89,\n")
    with open_store("sqlite://") as store, pytest.raises(DataError, match=re.escape(
            "column 'F' has no reading; nothing was stored")):
        import_table(store, empty, DECL, indicator="capacity")


def test_a_bad_cell_of_a_wide_table_names_the_file_s_column(tmp_path: Path) -> None:
    """A column per unit (``--indicator``): a bad cell is named by its unit's
    column, not by the indicator's name, which the file does not have; ``--unit``
    beside it is refused, not ignored."""
    wide = tmp_path / "w.csv"
    wide.write_text("cycle,A1,A2\n" + "".join(f"{k},{1.9 - 0.001 * k},{1.8 - 0.001 * k}\n"
                                               for k in range(1, 10)) + "10,1.89,bad\n")
    with open_store("sqlite://") as store:
        with pytest.raises(DataError, match=re.escape(
                "row 10 (line 11), column 'A2': 'bad' is not a finite number")):
            import_table(store, wide, DECL, indicator="capacity")
        with pytest.raises(DataError, match=re.escape(
                "--unit Z with --indicator capacity: a table of a column per unit names its "
                "units by its columns ('A1', 'A2'); omit --unit")):
            import_table(store, wide, DECL, indicator="capacity", unit="Z")
        assert store.imported_hashes("A1") == set()


def test_a_row_edited_since_its_import_is_named_as_such(tmp_path: Path) -> None:
    """The same table again with one capacity changed: the row is a stored
    test's cycle with other values (it was refused as a cycle that does not
    come after the last one stored); the same table under another declaration
    is refused for the declaration, not for its cycles."""
    cell = _cell(tmp_path / "c.csv", n=20)
    edited = tmp_path / "e.csv"
    lines = cell.read_text().splitlines()
    cycle, value = lines[11].split(",")
    lines[11] = f"{cycle},{float(value) + 0.05:.5f}"
    edited.write_text("\n".join(lines) + "\n")
    other = tmp_path / "other.toml"
    other.write_text(DECL.read_text().replace('name = "li-ion-18650"', 'name = "li-ion-b"'))
    with open_store("sqlite://") as store:
        import_table(store, cell, DECL, unit="C1")
        with pytest.raises(DataError, match=re.escape(
                f"row 11 (line 12): cycle {float(cycle)} of unit 'C1' is stored already "
                "(test #11) with other values: a row edited since it was imported?")):
            import_table(store, edited, DECL, unit="C1")
        with pytest.raises(DataError, match="is another declaration of 'li-ion-b'"):
            import_table(store, cell, other, unit="C1")
        assert len(store.history("C1")) == 20


def test_a_refused_import_leaves_no_history_file_behind(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    """"Nothing was stored": not even an empty history file the command made."""
    bad = tmp_path / "bad.csv"
    bad.write_text("cycle,capacity\n1,1.9\n2,oops\n")
    db = tmp_path / "h.db"
    assert main(["import", str(bad), "--unit", "C1", "--model", str(DECL), "--db",
                 str(db)]) == 2
    assert "'oops' is not a finite number" in capsys.readouterr().err
    assert not db.exists()
    cell = _cell(tmp_path / "c.csv", n=20)
    assert main(["import", str(cell), "--unit", "C1", "--model", str(DECL), "--db",
                 str(db)]) == 0
    assert main(["import", str(bad), "--unit", "C2", "--model", str(DECL), "--db",
                 str(db)]) == 2
    assert db.exists()   # (a history that was there stays)


def test_several_cycles_a_day_import_when_the_cycle_orders_them() -> None:
    """A cycler runs ten cycles a day: with a cycle column, the date only dates
    the rows (it was refused, "2024-03-01 is not after 2024-03-01"); a date
    that goes back is still refused, and a date alone must increase."""
    k = np.arange(1, 31)
    days = [f"2024-03-{1 + (i - 1) // 10:02d}" for i in k]
    table = pd.DataFrame({"cycle": k.astype(float), "date": days, "capacity": 1.9 - 0.003 * k})
    with open_store("sqlite://") as store:
        assert import_table(store, table, DECL, unit="X")[0].added == 30
        back = table.assign(cycle=table["cycle"] + 30)
        back.loc[5, "date"] = "2024-02-01"
        with pytest.raises(DataError, match=re.escape(
                "row 6 (line 7), column 'date': 2024-02-01 is before 2024-03-01")):
            import_table(store, back, DECL, unit="X")
    with open_store("sqlite://") as store, pytest.raises(DataError, match=re.escape(
            "column 'date': 2024-03-01 is not after 2024-03-01")):
        import_table(store, table.drop(columns="cycle"), DECL, unit="Y")
