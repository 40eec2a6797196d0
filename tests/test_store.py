"""History store: the same tests on SQLite and PostgreSQL."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
import sqlalchemy as sa

from condmon.errors import CondmonError
from condmon.identify import estimate
from condmon.monitor import make_baseline
from condmon.simulate import ActuatorRig, simulate_actuator
from condmon.store import DuplicateTestError, StoreError, frame_hash, schema
from condmon.store import open_store as _open_store


_OPEN: list = []  # type: ignore[type-arg]


def open_store(url: str):  # type: ignore[no-untyped-def]
    store = _open_store(url)
    _OPEN.append(store)
    return store


@pytest.fixture(autouse=True)
def _close_stores():  # type: ignore[no-untyped-def]
    yield
    while _OPEN:
        _OPEN.pop().close()


@pytest.fixture(scope="module")
def results(rig: ActuatorRig) -> list:  # type: ignore[type-arg]
    return [estimate(simulate_actuator(rig, seed=s), source=f"rec{s}.csv") for s in range(4)]


def _count(store, table: sa.Table) -> int:  # type: ignore[no-untyped-def]
    with store.engine.connect() as conn:
        return int(conn.execute(sa.select(sa.func.count()).select_from(table)).scalar_one())


def test_tests_and_estimates_round_trip(store_url: str, results: list) -> None:  # type: ignore[type-arg]
    store = open_store(store_url)
    ids = [store.add_test("EMA-1", r, role="baseline", digest=f"h{i}") for i, r in enumerate(results)]
    got_ids, table = store.accepted_estimates("EMA-1")
    assert got_ids == ids
    assert list(table.columns) == ["R", "L", "Ke", "Kt", "J", "D"]
    assert table.iloc[2]["R"] == pytest.approx(results[2].parameters["R"], rel=1e-12)
    hist = store.history("EMA-1")
    assert list(hist["source"]) == [f"rec{s}.csv" for s in range(4)]
    assert json.loads(hist.iloc[0]["fits"])["I"] == pytest.approx(results[0].fit.fits_percent["I"])


def test_same_file_twice_is_detected_not_duplicated(store_url: str, results: list) -> None:  # type: ignore[type-arg]
    store = open_store(store_url)
    first = store.add_test("EMA-1", results[0], role="baseline", digest="same")
    with pytest.raises(DuplicateTestError, match=r"already in the history of 'EMA-1' \(test #\d+\)") as err:
        store.add_test("EMA-1", results[0], role="check", digest="same")
    assert err.value.test_id == first
    assert _count(store, schema.tests) == 1 and _count(store, schema.estimates) == 6
    store.add_test("EMA-2", results[0], role="baseline", digest="same")  # another unit may hold it


def test_a_failed_write_leaves_no_half_test(store_url: str, results: list) -> None:  # type: ignore[type-arg]
    store = open_store(store_url)
    bad_symptoms = {"R": {"percent_change": "not a number", "high": 0.0, "low": 0.0}}
    with pytest.raises(ValueError):
        store.add_test("EMA-1", results[0], role="check", digest="x", symptoms=bad_symptoms,
                       baseline_id=1)
    assert _count(store, schema.tests) == 0
    assert _count(store, schema.estimates) == 0


def test_rejected_tests_are_stored_but_not_trended(store_url: str, results: list, rig: ActuatorRig) -> None:  # type: ignore[type-arg]
    import dataclasses

    store = open_store(store_url)
    for i, r in enumerate(results[:3]):
        store.add_test("EMA-1", r, role="baseline", digest=f"h{i}")
    noisy = dataclasses.replace(rig, noise_I=2.0, noise_omega=10.0)
    bad = estimate(simulate_actuator(noisy, seed=0))
    assert not bad.accepted
    store.add_test("EMA-1", bad, role="baseline", digest="bad")
    ids, table = store.accepted_estimates("EMA-1")
    assert len(ids) == 3 and len(table) == 3
    hist = store.history("EMA-1")
    assert hist["accepted"].tolist() == [True, True, True, False]
    assert "below the threshold" in hist.iloc[3]["reason"]


def test_baseline_snapshots(store_url: str, results: list) -> None:  # type: ignore[type-arg]
    store = open_store(store_url)
    ids = [store.add_test("EMA-1", r, role="baseline", digest=f"h{i}") for i, r in enumerate(results[:3])]
    _, table = store.accepted_estimates("EMA-1")
    b = make_baseline(table.to_numpy(), list(table.columns))
    first = store.save_baseline("EMA-1", b, ids)
    assert store.save_baseline("EMA-1", b, ids) == first  # identical: reused
    assert _count(store, schema.baseline_values) == 6


def test_schema_version_and_migration(store_url: str, monkeypatch: pytest.MonkeyPatch) -> None:
    current = schema.SCHEMA_VERSION
    store = open_store(store_url)
    assert store.schema_version == current == 13
    store.close()

    def add_operator(conn: sa.Connection) -> None:
        conn.execute(sa.text("ALTER TABLE tests ADD COLUMN operator VARCHAR(64)"))

    monkeypatch.setattr(schema, "SCHEMA_VERSION", current + 1)
    monkeypatch.setitem(schema.MIGRATIONS, current, add_operator)
    store = open_store(store_url)
    assert store.schema_version == current + 1
    cols = {c["name"] for c in sa.inspect(store.engine).get_columns("tests")}
    assert "operator" in cols
    store.close()
    monkeypatch.setattr(schema, "SCHEMA_VERSION", current)
    with pytest.raises(StoreError, match=f"schema v{current + 1} is newer than this condmon"):
        open_store(store_url)


def test_unknown_unit_is_named(store_url: str) -> None:
    store = open_store(store_url)
    store.unit_id("EMA-1", create=True)
    with pytest.raises(CondmonError, match=r"unknown unit 'EMA-9'.*did you mean 'EMA-1'\? \(units: EMA-1;"):
        store.history("EMA-9")


def test_unreachable_database_is_one_clear_error() -> None:
    with pytest.raises(StoreError, match="cannot open the history database"):
        open_store("postgresql://nobody@127.0.0.1:1/none")


def test_frame_hash_is_content_based(rig: ActuatorRig) -> None:
    a = simulate_actuator(rig, seed=1)
    assert frame_hash(a) == frame_hash(a.copy())
    assert frame_hash(a) != frame_hash(simulate_actuator(rig, seed=2))
    assert isinstance(pd.DataFrame, type)


def test_a_v6_history_without_its_later_columns_is_completed(tmp_path: Path) -> None:
    """A history written while v6 was being made (no operating hours, no
    forecast urgency columns) gets them on opening, and is current."""
    import sqlite3

    db = tmp_path / "v6.db"
    with open_store(str(db)):
        pass
    with sqlite3.connect(db) as c:
        c.execute("ALTER TABLE tests DROP COLUMN hours")
        c.execute("ALTER TABLE forecasts DROP COLUMN median")
        c.execute("ALTER TABLE forecasts DROP COLUMN crossing_date")
        c.execute("UPDATE condmon_meta SET value = '6' WHERE key = 'schema_version'")
    with open_store(str(db)) as store:
        assert store.schema_version == 13
    with sqlite3.connect(db) as c:
        assert "hours" in {r[1] for r in c.execute("PRAGMA table_info(tests)")}
        assert {"median", "crossing_date"} <= {r[1] for r in
                                               c.execute("PRAGMA table_info(forecasts)")}


def test_a_v10_history_gets_the_systematic_and_conditions_columns(tmp_path: Path) -> None:
    """Estimates stored before v11 have no systematic part, tests no conditions
    (NULL): the columns are added on opening."""
    import sqlite3

    db = tmp_path / "v10.db"
    with open_store(str(db)):
        pass
    with sqlite3.connect(db) as c:
        c.execute("ALTER TABLE estimates DROP COLUMN systematic")
        c.execute("ALTER TABLE tests DROP COLUMN conditions")
        c.execute("UPDATE condmon_meta SET value = '10' WHERE key = 'schema_version'")
    with open_store(str(db)) as store:
        assert store.schema_version == 13
        assert store.systematic_of([]).empty
    with sqlite3.connect(db) as c:
        assert "systematic" in {r[1] for r in c.execute("PRAGMA table_info(estimates)")}
        assert "conditions" in {r[1] for r in c.execute("PRAGMA table_info(tests)")}


def test_a_v8_history_gets_the_content_hash_index(tmp_path: Path) -> None:
    """The look-up of a record's copies under other units uses an index of
    the content hash (v9), added on opening a v8 history."""
    import sqlite3

    db = tmp_path / "v8.db"
    with open_store(str(db)):
        pass
    plan = ("EXPLAIN QUERY PLAN SELECT units.name, tests.id FROM tests JOIN units ON "
            "units.id = tests.unit_id WHERE tests.record_hash = 'x' AND units.name != 'u' "
            "ORDER BY tests.id")
    with sqlite3.connect(db) as c:
        assert "ix_tests_record_hash" in " ".join(str(r) for r in c.execute(plan))
        c.execute("DROP INDEX ix_tests_record_hash")
        c.execute("UPDATE condmon_meta SET value = '8' WHERE key = 'schema_version'")
    with sqlite3.connect(db) as c:
        assert "SCAN tests" in " ".join(str(r) for r in c.execute(plan))
    with open_store(str(db)) as store:
        assert store.schema_version == 13
    with sqlite3.connect(db) as c:
        assert "ix_tests_record_hash" in " ".join(str(r) for r in c.execute(plan))
