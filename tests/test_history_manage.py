"""A history you can trust: duplicates by content, exclude/include, versioned
baselines, contaminated-baseline flags, dates, audit, store faults in one line."""

from __future__ import annotations

import json
import re
import shutil
import sqlite3
from pathlib import Path

import pandas as pd
import pytest
import sqlalchemy as sa

from condmon.cli.main import main
from condmon.errors import CondmonError
from condmon.simulate import ActuatorRig, simulate_actuator
from condmon.store import StoreBusyError, StoreError, open_store
from condmon.workflows.manage import exclude_test, include_test, rebuild_baseline
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import add_baseline_tests

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory, rig: ActuatorRig) -> dict[str, Path]:
    """Four healthy records, one worn (D x 7) record, a healthy and a worn check."""
    d = tmp_path_factory.mktemp("recs")
    out = {}
    for name, seed, faults in [("h1", 1, ()), ("h2", 2, ()), ("h3", 3, ()), ("h4", 4, ()),
                               ("worn", 9, ("D=*7",)), ("c_ok", 21, ()),
                               ("c_worn", 22, ("D=*7",))]:
        p = d / f"{name}.csv"
        simulate_actuator(rig.with_faults(list(faults)), seed=seed).to_csv(p, index=False)
        out[name] = p
    return out


def test_resaved_and_converted_copies_are_the_same_test(files: dict[str, Path],
                                                         tmp_path: Path) -> None:
    """CRLF, a trailing newline and Parquet: 3/3 recognised; the baseline keeps N and spread."""
    src = files["h1"]
    text = src.read_bytes()
    crlf = tmp_path / "h1-crlf.csv"
    crlf.write_bytes(text.replace(b"\n", b"\r\n"))
    trailing = tmp_path / "h1-trailing.csv"
    trailing.write_bytes(text + b"\n")
    parquet = tmp_path / "h1.parquet"
    pd.read_csv(src).to_parquet(parquet)
    db = str(tmp_path / "h.db")
    with open_store(db) as store:
        first = add_baseline_tests(store, "U1", [files["h1"], files["h2"], files["h3"]])
        again = add_baseline_tests(store, "U1", [crlf, trailing, parquet])
        assert [t.duplicate for t in again.tests] == [True, True, True]
        assert {t.test_id for t in again.tests} == {first.tests[0].test_id}
        assert again.baseline == first.baseline  # N and spread unchanged
        assert len(store.history("U1")) == 3 and store.integrity_problems() == []


def test_exclude_changes_baseline_symptoms_and_report_and_include_restores(
        files: dict[str, Path], tmp_path: Path) -> None:
    db = str(tmp_path / "h.db")
    with open_store(db) as store:
        added = add_baseline_tests(store, "EMA", [files[k] for k in ("h1", "h2", "h3", "h4", "worn")])
        worn_id = added.tests[-1].test_id
        # the worn record contaminates the baseline: flagged, with the test to look at;
        # the spread it causes is the outlier's, flagged once (as the outlier) and
        # only noted as D's scatter against its standard errors
        assert [f["kind"] for f in added.flags] == ["outlier"]
        assert all(f["tests"] == [worn_id] and f["parameter"] == "D" for f in added.flags)
        assert "D" in {n["parameter"] for n in added.info if n["kind"] == "scatter"}
        ok = check_test(store, "EMA", files["c_ok"])
        worn = check_test(store, "EMA", files["c_worn"])
        assert ok.status == "go" and worn.baseline_flags
        before = store.history("EMA")
        res = exclude_test(store, worn_id, "worn actuator fitted by mistake")
        assert res.new_version and res.baseline is not None and res.baseline.flags == ()
        assert worn_id not in res.baseline.test_ids and res.baseline.version == 2
        assert res.reevaluated[worn.test_id][1] == "no-go"  # the hidden D x 7 now shows
        after = store.history("EMA")
        assert after.loc[worn_id, "status"] == "excluded"
        assert after.loc[worn.test_id, "status"] == "no-go"
        assert after.loc[worn.test_id, "D_change"] != before.loc[worn.test_id, "D_change"]
        back = include_test(store, worn_id, "was right after all")
        assert back.baseline is not None and back.baseline.version == 3
        restored = store.history("EMA")
        cols = ["status", "R_change", "D_change", "D_high"]
        pd.testing.assert_frame_equal(restored[cols], before[cols])
        actions = list(store.audit("EMA")["action"])
        assert actions.count("test excluded") == 1 and actions.count("test included") == 1
        assert len(store.baselines("EMA")) == 3  # nothing overwritten


def test_healthy_baselines_are_not_flagged(demo_rig: ActuatorRig) -> None:
    with open_store("sqlite://") as store:
        for u in range(3):
            recs = []
            for s in range(5):
                df = simulate_actuator(demo_rig, seed=100 + 10 * u + s)
                df.attrs["source"] = f"u{u}-{s}.csv"
                recs.append(df)
            res = add_baseline_tests(store, f"U{u}", recs)
            assert res.baseline is not None and res.flags == (), res.flags


def test_a_baseline_takes_healthy_checks_but_not_a_no_go(files: dict[str, Path],
                                                         tmp_path: Path) -> None:
    with open_store(str(tmp_path / "h.db")) as store:
        ids = [t.test_id for t in add_baseline_tests(
            store, "EMA", [files[k] for k in ("h1", "h2", "h3")]).tests]
        ok = check_test(store, "EMA", files["c_ok"])
        worn = check_test(store, "EMA", files["c_worn"])
        assert (ok.status, worn.status) == ("go", "no-go")
        with pytest.raises(CondmonError, match=rf"#{worn.test_id} \(a check judged no-go"):
            rebuild_baseline(store, "EMA", reason="x", test_ids=[*ids, worn.test_id])
        again = rebuild_baseline(store, "EMA", reason="with a check",
                                 test_ids=[*ids, ok.test_id])
        assert again.baseline is not None and ok.test_id in again.baseline.test_ids


def test_rebuild_from_chosen_tests_and_errors(files: dict[str, Path], tmp_path: Path) -> None:
    with open_store(str(tmp_path / "h.db")) as store:
        ids = [t.test_id for t in add_baseline_tests(
            store, "EMA", [files[k] for k in ("h1", "h2", "h3", "h4")]).tests]
        res = rebuild_baseline(store, "EMA", reason="after overhaul", name="2026-spring",
                               test_ids=ids[1:])
        assert res.baseline is not None and res.baseline.name == "2026-spring"
        assert store.active_baseline_name("EMA") == "2026-spring"
        assert list(res.baseline.test_ids) == ids[1:]
        chk = check_test(store, "EMA", files["c_ok"])
        assert store.history("EMA").loc[chk.test_id, "baseline_id"] == res.baseline.id
        with pytest.raises(CondmonError, match="needs a reason"):
            rebuild_baseline(store, "EMA", reason=" ")
        with pytest.raises(CondmonError, match=r"#99 \(not a test of 'EMA'\)"):
            rebuild_baseline(store, "EMA", reason="x", test_ids=[*ids, 99])
        with pytest.raises(CondmonError, match="at least 3"):
            rebuild_baseline(store, "EMA", reason="x", test_ids=ids[:2])
        exclude_test(store, ids[1], "bad sensor")
        with pytest.raises(CondmonError, match="already excluded"):
            exclude_test(store, ids[1], "again")
        with pytest.raises(CondmonError, match="is not excluded"):
            include_test(store, ids[0])
        with pytest.raises(CondmonError, match="no test #999"):
            exclude_test(store, 999, "x")
        # one test left in the chosen baseline: checks are refused until more are added
        exclude_test(store, ids[2], "bad sensor")
        with pytest.raises(CondmonError, match=r"has 1 accepted healthy test\(s\) \(baseline "
                           r"'2026-spring' v1 after exclusions\)"):
            check_test(store, "EMA", files["c_worn"])


def test_cli_management_and_dates(files: dict[str, Path], tmp_path: Path,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    db = str(tmp_path / "h.db")
    recs = [str(files[k]) for k in ("h1", "h2", "h3", "worn")]
    assert main(["baseline", "add", *recs, "--unit", "E1", "--db", db, "--date", "2026-03-01"]) == 0
    captured = capsys.readouterr()
    assert "look at #4" in captured.err.replace("\n", " ")
    assert main(["check", str(files["c_worn"]), "--unit", "E1", "--db", db,
                 "--date", "2026-03-09T10:00"]) == 0
    capsys.readouterr()
    assert main(["check", str(files["c_ok"]), "--unit", "E1", "--db", db, "--dry-run",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["test_id"] == -1
    assert main(["exclude", "4", "--db", db, "--reason", "worn actuator"]) == 0
    out = capsys.readouterr().out.replace("\n", " ")
    assert "baseline 'default' v2 from 3 tests" in out
    assert re.search(r"1 changed status: #5 (go|advisory) -> no-go", out)
    assert main(["history", "--unit", "E1", "--db", db, "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["status"] for r in rows] == ["baseline"] * 3 + ["excluded", "no-go"]
    assert rows[4]["test_date"].startswith("2026-03-09T10:00")
    assert rows[3]["excluded_reason"] == "worn actuator"
    assert main(["baseline", "list", "--unit", "E1", "--db", db, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [b["version"] for b in doc["baselines"]] == [1, 2] and doc["active"] == "default"
    assert main(["audit", "--unit", "E1", "--db", db, "--json"]) == 0
    trail = json.loads(capsys.readouterr().out)["audit"]
    assert any(a["action"] == "test excluded" and a["reason"] == "worn actuator" for a in trail)
    assert all(a["actor"] for a in trail)
    assert main(["check", str(files["c_ok"]), "--unit", "E1", "--db", db, "--date", "yesterday"]) == 2
    assert "is not a date" in capsys.readouterr().err
    # a baseline test excluded with too few left: the version stays, and history says
    # it no longer stands (it showed the version as if whole)
    assert main(["exclude", "2", "--db", db, "--reason", "wrong sensor"]) == 0
    assert "would keep 2 test(s)" in capsys.readouterr().out.replace("\n", " ")
    assert main(["history", "--unit", "E1", "--db", db]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "baseline 'default' v2 (N = 3): #1-#3 #2 excluded since: this version no longer " \
        "stands" in out


def test_date_from_the_record_metadata(files: dict[str, Path], tmp_path: Path) -> None:
    """A date-time time column dates the test; --date overrides it."""
    stamped = []
    for k in ("h1", "h2", "h3"):
        df = pd.read_csv(files[k])
        df["t"] = pd.Timestamp("2026-02-01 08:00") + pd.to_timedelta(df["t"], unit="s")
        p = tmp_path / f"{k}-stamped.csv"
        df.to_csv(p, index=False)
        stamped.append(p)
    with open_store(str(tmp_path / "h.db")) as store:
        add_baseline_tests(store, "E", stamped[:2])
        add_baseline_tests(store, "E", stamped[2:], test_date="2026-02-03")
        dates = store.history("E")["test_date"]
    assert [d.strftime("%Y-%m-%d %H:%M") for d in dates] == [
        "2026-02-01 08:00", "2026-02-01 08:00", "2026-02-03 00:00"]


def test_a_version_2_history_is_migrated(tmp_path: Path, files: dict[str, Path]) -> None:
    """A file written with schema v2: evaluations and versions kept, then usable."""
    db = tmp_path / "history.db"
    shutil.copy(DATA / "history-v2.db", db)
    with open_store(str(db)) as store:
        hist = store.history("EMA-v2")
        assert list(hist["status"]) == ["baseline", "baseline", "baseline", "go", "no-go",
                                        "baseline"]
        assert [b.version for b in store.baselines("EMA-v2")] == [1, 2]
        assert list(store.latest_baseline("EMA-v2").test_ids) == [1, 2, 3, 6]  # type: ignore[union-attr]
        assert store.integrity_problems() == []
        # the migrated file hash still catches the same file
        again = add_baseline_tests(store, "EMA-v2", [files["h1"]])
        assert again.tests[0].duplicate is False or again.tests[0].test_id == 1
        res = exclude_test(store, 6, "not healthy")
        assert res.baseline is not None and list(res.baseline.test_ids) == [1, 2, 3] + (
            [again.tests[0].test_id] if not again.tests[0].duplicate else [])


# -- store faults: one line, exit 2; read-only commands never create a file -----------------

def test_read_only_commands_never_create_a_file(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "typo.db"
    for args in (["history", "--unit", "U"], ["units"], ["report", "--unit", "U", "--out",
                                                         str(tmp_path / "r")],
                 ["audit"], ["baseline", "list", "--unit", "U"],
                 ["exclude", "1", "--reason", "x"], ["include", "1"],
                 ["baseline", "rebuild", "--unit", "U", "--reason", "x"]):
        assert main([*args, "--db", str(db)]) == 2, args
        assert "no history database there" in capsys.readouterr().err
    assert not db.exists()


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.startswith("error: ")
    assert len(err.strip().splitlines()) == 1 or len(err) < 400
    return err


def test_foreign_sqlite_file_is_refused_untouched(tmp_path: Path, files: dict[str, Path],
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "crm.db"
    con = sqlite3.connect(db)
    con.execute("CREATE TABLE customers (id INTEGER PRIMARY KEY, name TEXT)")
    con.commit()
    con.close()
    before = db.read_bytes()
    assert main(["baseline", "add", str(files["h1"]), "--unit", "U", "--db", str(db)]) == 2
    assert "not a condmon history (it holds other tables: customers)" in _one_error_line(capsys)
    assert db.read_bytes() == before
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"this is not a database at all" * 100)
    assert main(["units", "--db", str(junk)]) == 2
    assert "not a readable SQLite database" in _one_error_line(capsys)


def test_unreadable_schema_version_is_one_line(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "h.db"
    open_store(str(db)).close()
    con = sqlite3.connect(db)
    con.execute("UPDATE condmon_meta SET value = 'v1' WHERE key = 'schema_version'")
    con.commit()
    con.close()
    assert main(["units", "--db", str(db)]) == 2
    assert "unreadable schema version 'v1'" in _one_error_line(capsys)


def test_read_only_database_and_full_disk_are_one_line(tmp_path: Path, rig: ActuatorRig) -> None:
    from condmon.identify import estimate

    db = tmp_path / "h.db"
    open_store(str(db)).close()
    res = estimate(simulate_actuator(rig, seed=1), source="r.csv")
    with open_store(f"sqlite:///file:{db}?mode=ro&uri=true") as ro:
        with pytest.raises(StoreError, match="read-only here") as err:
            ro.add_test("U", res, role="baseline", digest="x")
    assert "\n" not in str(err.value)
    with open_store(str(db)) as store:
        @sa.event.listens_for(store.engine, "connect")
        def _tiny(dbapi_conn, _):  # type: ignore[no-untyped-def]
            dbapi_conn.execute("PRAGMA max_page_count = 12")
        store.engine.dispose()
        with pytest.raises(StoreError, match="the disk is full; nothing was written"):
            for i in range(200):
                store.add_test("U", res, role="baseline", digest=f"d{i}")


def test_long_names_and_busy_database(store_url: str, rig: ActuatorRig) -> None:
    """Same answer on both back-ends: a 201-character name is refused before
    writing; a database held by another writer waits, then fails in one line."""
    from condmon.identify import estimate

    res = estimate(simulate_actuator(rig, seed=1), source="r.csv")
    with open_store(store_url) as store:
        with pytest.raises(CondmonError, match="is 201 characters long; at most 200"):
            store.add_test("E" * 201, res, role="baseline", digest="a")
        assert store.add_test("E" * 200, res, role="baseline", digest="a") > 0
    if "://" in store_url:  # PostgreSQL: another session holds the unit's lock
        import zlib

        from condmon.store.engine import database_url

        engine = sa.create_engine(database_url(store_url))
        key = zlib.crc32(b"U") + (1 << 40)
        with engine.connect() as holder:
            holder.execute(sa.select(sa.func.pg_advisory_lock(key)))
            try:
                with open_store(store_url, timeout=0.3) as store:
                    with pytest.raises(StoreBusyError, match="busy for more than 0.3 s"):
                        store.add_test("U", res, role="baseline", digest="b")
            finally:
                holder.execute(sa.select(sa.func.pg_advisory_unlock(key)))
                holder.commit()
        engine.dispose()
        return
    holder = sqlite3.connect(store_url, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")
    try:
        with open_store(store_url, timeout=0.3) as store:
            with pytest.raises(StoreBusyError, match="busy for more than 0.3 s"):
                store.add_test("U", res, role="baseline", digest="b")
    finally:
        holder.execute("ROLLBACK")
        holder.close()
