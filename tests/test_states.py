"""Each unit's kept state (``unit_states``): it follows every write, equals the
state worked out from the whole history, and pages the fleet in the database
as the in-memory listing does; on SQLite and PostgreSQL."""

from __future__ import annotations

import shutil
from datetime import datetime, timezone
import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import sqlalchemy as sa

from condmon.identify import estimate
from condmon.monitor import make_baseline
from condmon.report.web_data import fleet_document, readonly_url
from condmon.simulate import ActuatorRig, simulate_actuator
from condmon.store import open_store, schema
from condmon.store.states import state_rows

KEPT = ("status", "latest_source", "summary", "tests", "isolations", "degraded")


@dataclass(frozen=True)
class _Diagnosis:
    status: str
    condition: float = 0.5
    summary: str = "a check"
    faults: tuple[Any, ...] = ()


@pytest.fixture(scope="module")
def results(rig: ActuatorRig) -> list[Any]:
    return [estimate(simulate_actuator(rig, seed=s), source=f"rec{s}.csv") for s in range(4)]


def _baseline(res: list[Any]) -> Any:
    names = list(res[0].parameters)
    return make_baseline([[r.parameters[p] for p in names] for r in res], names)


def _kept(store: Any) -> dict[int, dict[str, Any]]:
    with store.engine.connect() as c:
        return {r.unit_id: {k: getattr(r, k) for k in KEPT}
                for r in c.execute(sa.select(schema.unit_states))}


def _worked_out(store: Any) -> dict[int, dict[str, Any]]:
    with store.engine.connect() as c:
        return {r["unit_id"]: {k: r[k] for k in KEPT} for r in state_rows(c, None)}


def _status(store: Any, unit: str) -> str | None:
    return {r["unit"]: r["status"] for r in store.unit_summaries()}[unit]


def test_the_kept_state_follows_every_write(store_url: str, results: list[Any]) -> None:
    with open_store(store_url) as store:
        store.unit_id("EMA-0", create=True)
        assert _status(store, "EMA-0") is None
        ids = [store.add_test("EMA-1", r, role="baseline", digest=f"b{i}")
               for i, r in enumerate(results[:3])]
        assert _status(store, "EMA-1") == "building"
        bid = store.save_baseline("EMA-1", _baseline(results[:3]), ids)
        assert _status(store, "EMA-1") == "baseline"
        check = store.add_test("EMA-1", results[3], role="check", digest="c0", baseline_id=bid,
                               symptoms={}, diagnosis=_Diagnosis("advisory"))
        assert _status(store, "EMA-1") == "advisory"
        assert store.units_with_status() == {"EMA-1": ("dc-motor", None)}
        assert _kept(store) == _worked_out(store)
        bid2 = store.save_baseline("EMA-1", _baseline([*results[1:3], results[1]]), ids[1:])
        assert store.save_evaluation("EMA-1", check, bid2, {}, _Diagnosis("go", summary="ok"))
        row = next(r for r in store.unit_summaries() if r["unit"] == "EMA-1")
        assert (row["status"], row["summary"], row["tests"]) == ("go", "ok", 4)
        assert store.units_with_status() == {"EMA-1": ("dc-motor", None)}  # it has degraded once
        store.set_excluded(check, True, "sensor fault")
        assert _status(store, "EMA-1") == "baseline"
        assert store.units_with_status() == {}
        assert _kept(store) == _worked_out(store)
        marks = store.history_marks()
        store.set_excluded(check, False, None)
        assert store.history_marks(["EMA-1"])["EMA-1"] > marks["EMA-1"]
        assert store.history_marks(["EMA-0"]) == {"EMA-0": marks["EMA-0"]}


def test_a_unit_with_undated_checks_takes_its_last_stored_as_its_latest(
        store_url: str, results: list[Any]) -> None:
    """Checks dated in the past with an undated one between them: the undated
    one's storing time is not when it was tested, so the latest is the last
    stored (as its forecast orders them); with every check dated, the latest
    by test date (a record checked late goes where it was tested)."""
    def dated(day: int) -> datetime:
        return datetime(2026, 2, day, tzinfo=timezone.utc)

    with open_store(store_url) as store:
        ids = [store.add_test("MIX", r, role="baseline", digest=f"mb{i}")
               for i, r in enumerate(results[:3])]
        bid = store.save_baseline("MIX", _baseline(results[:3]), ids)
        for i, (day, status) in enumerate([(1, "go"), (None, "go"), (3, "no-go")]):
            store.add_test("MIX", results[3], role="check", digest=f"mc{i}", baseline_id=bid,
                           test_date=None if day is None else dated(day), symptoms={},
                           diagnosis=_Diagnosis(status))
        assert _status(store, "MIX") == "no-go"
        assert _kept(store) == _worked_out(store)
        ids = [store.add_test("LATE", r, role="baseline", digest=f"lb{i}")
               for i, r in enumerate(results[:3])]
        bid = store.save_baseline("LATE", _baseline(results[:3]), ids)
        for i, (day, status) in enumerate([(5, "advisory"), (2, "go")]):   # checked late
            store.add_test("LATE", results[3], role="check", digest=f"lc{i}", baseline_id=bid,
                           test_date=dated(day), symptoms={}, diagnosis=_Diagnosis(status))
        assert _status(store, "LATE") == "advisory"


def test_a_unit_write_waits_for_a_batch_over_the_same_unit(store_url: str,
                                                            results: list[Any]) -> None:
    """A fleet's batch and a single write of the same unit do not overlap (on
    PostgreSQL the unit's lock is taken under the schema's, held shared), so
    neither works the unit's kept state out from a snapshot that misses the
    other's test."""
    import threading
    import time

    with open_store(store_url) as store:
        ids = [store.add_test("EMA-1", r, role="baseline", digest=f"b{i}")
               for i, r in enumerate(results[:3])]
        bid = store.save_baseline("EMA-1", _baseline(results[:3]), ids)
    held, ended = threading.Event(), {}

    def single() -> None:
        held.wait(10)
        with open_store(store_url) as other:
            other.add_test("EMA-1", results[3], role="check", digest="c-single",
                           baseline_id=bid, symptoms={}, diagnosis=_Diagnosis("go"))
        ended["single"] = time.monotonic()

    thread = threading.Thread(target=single)
    thread.start()
    with open_store(store_url) as store:
        with store.batch():
            store.add_test("EMA-1", results[3], role="check", digest="c-batch",
                           baseline_id=bid, symptoms={}, diagnosis=_Diagnosis("advisory"))
            held.set()
            time.sleep(0.5)         # the single write is waiting, not writing
            ended["batch"] = time.monotonic()
        thread.join(20)
        assert ended["single"] > ended["batch"]
        assert _kept(store) == _worked_out(store)
        row = next(r for r in store.unit_summaries() if r["unit"] == "EMA-1")
        assert (row["tests"], row["status"]) == (5, "go")


def _fleet(store: Any, results: list[Any]) -> None:
    """24 units: building, baseline, and checks at go / advisory / no-go, dated."""
    from datetime import datetime, timedelta, timezone

    t0 = datetime(2026, 3, 1, tzinfo=timezone.utc)
    statuses = ["go", "advisory", "no-go", None, "go", "building"]
    with store.batch():
        for n in range(24):
            unit, kind = f"Unit-{n:02d}" if n % 5 else f"unit-x{n:02d}", statuses[n % 6]
            store.unit_id(unit, create=True)
            k = 2 if kind == "building" else 3
            ids = [store.add_test(unit, r, role="baseline", digest=f"{unit}b{i}",
                                  test_date=t0 + timedelta(days=i))
                   for i, r in enumerate(results[:k])]
            if kind == "building":
                continue
            bid = store.save_baseline(unit, _baseline(results[:3]), ids)
            if kind is not None:
                store.add_test(unit, results[3], role="check", digest=f"{unit}c",
                               test_date=t0 + timedelta(days=10 + (n * 7) % 13),
                               baseline_id=bid, symptoms={}, diagnosis=_Diagnosis(kind))


@pytest.fixture(scope="module")
def fleet_db(tmp_path_factory: pytest.TempPathFactory, results: list[Any]) -> Path:
    db = tmp_path_factory.mktemp("states") / "fleet.db"
    with open_store(str(db)) as store:
        _fleet(store, results)
    return db


@pytest.mark.parametrize("args", [
    {}, {"per_page": 5, "page": 2}, {"status": ["go,no-go"], "per_page": 4, "page": 2},
    {"q": "X", "per_page": 3}, {"sort": "status", "per_page": 7, "page": 2},
    {"sort": "date", "per_page": 10, "page": 1}, {"status": ["building"]},
    {"sort": "status", "status": ["advisory", "baseline"]},
])
def test_the_database_pages_as_the_listing_does(fleet_db: Path, args: dict[str, Any]) -> None:
    with open_store(str(fleet_db)) as store:
        in_sql = fleet_document(store, **args)
        in_memory = fleet_document(store, **args, rows=store.unit_summaries())
    assert in_sql == in_memory and in_sql["total"] == 24
    assert in_sql["counts"] == {"no-go": 4, "advisory": 4, "go": 8, "building": 4,
                                "baseline": 4}


def test_rows_another_tool_added_are_seen_read_only_and_kept_when_writable(
        tmp_path: Path, fleet_db: Path) -> None:
    db = tmp_path / "fleet.db"
    shutil.copy(fleet_db, db)
    with sqlite3.connect(db) as c:   # another tool excludes nothing but adds a unit and a test
        c.execute("insert into units (name, model, created_at, baseline_name) "
                  "values ('Unit-zz', 'dc-motor', '2026-03-01 00:00:00', 'default')")
        c.execute("insert into tests (unit_id, created_at, source, file_hash, role, accepted, "
                  "fits, method, closed_loop, constants, record_hash) select id, created_at, "
                  "'r.csv', 'h', 'baseline', 1, '{}', 'ls', 0, '{}', 'h' from units "
                  "where name = 'Unit-zz'")
    with open_store(readonly_url(db)) as store:
        assert not store.states_current()
        doc = fleet_document(store, status=["building"])
        assert "Unit-zz" in [u["unit"] for u in doc["units"]] and doc["matching"] == 5
    with open_store(str(db)) as store:
        assert store.states_current() and _kept(store) == _worked_out(store)
        assert fleet_document(store, status=["building"]) == doc


def test_a_v7_history_gets_its_states_on_opening(tmp_path: Path, fleet_db: Path) -> None:
    db = tmp_path / "v7.db"
    shutil.copy(fleet_db, db)
    with open_store(str(db)) as store:
        before = store.unit_summaries()
    with sqlite3.connect(db) as c:
        c.execute("DROP TABLE unit_states")
        c.execute("UPDATE condmon_meta SET value = '7' WHERE key = 'schema_version'")
    with open_store(str(db)) as store:
        assert store.schema_version == schema.SCHEMA_VERSION == 13
        assert store.unit_summaries() == before and _kept(store) == _worked_out(store)


def test_an_isolated_unit_says_why_it_has_no_forecast(tmp_path: Path) -> None:
    from condmon.errors import DataError
    from condmon.store.forecasts import ISOLATED, read_forecast, try_forecast

    db = str(tmp_path / "iso.db")
    with open_store(db) as store:
        uid = store.unit_id("HST-1", create=True, model="hst")
        with store.engine.begin() as c:
            c.execute(sa.insert(schema.isolations).values(
                unit_id=uid, created_at=datetime(2026, 1, 1, tzinfo=timezone.utc),
                source="i.csv", file_hash="0" * 64, record_hash="0" * 64, model="hst",
                detected=True, decided=True, statement="Rv", suspects="[]", isolated="[]",
                result="{}"))
        assert try_forecast(store, "HST-1") == (None, ISOLATED)
        with pytest.raises(DataError, match="isolated against a plant model"):
            read_forecast(store, "HST-1")
        store.unit_id("EMPTY", create=True)
        assert try_forecast(store, "EMPTY")[1] == "no baseline yet"


def test_the_degraded_units_are_read_by_aggregate_and_by_the_few_needed(fleet_db: Path) -> None:
    """What a fleet prior reads of the degraded units, from the kept states:
    their counts by model and group, whether given units degraded, and the
    most recently changed few, as the whole list and their marks say."""
    with open_store(str(fleet_db)) as store:
        every = store.units_with_status()
        assert len(every) == 8
        assert store.degraded_counts() == {("dc-motor", None): 8}
        assert store.degraded_among(store.units()) == set(every)
        assert store.degraded_among([]) == set()
        marks = store.history_marks(list(every))
        newest = sorted(every, key=lambda u: (-marks.get(u, 0), u))
        assert store.recent_degraded("dc-motor", None, 3) == newest[:3]
        assert store.recent_degraded("dc-motor", "line-z", 3) == []
        assert store.recent_degraded("hst", None, 3) == []
