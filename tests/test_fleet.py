"""Fleet runs: an inbox of many units on a dask.distributed cluster, one history."""

from __future__ import annotations

import json
import shutil
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from _tables import flat, row, unfold
from condmon.cli.main import main
from condmon.errors import ConfigError
from condmon.io import read_record
from condmon.store import open_store
from condmon.workflows.fleet import (
    OUTCOMES, RecordTask, inbox_records, local_cluster, process_record, read_manifest, run_fleet,
)
from condmon.workflows.inbox import SimulatedUnit, simulated_inbox
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import add_baseline_tests

FLEET = [SimulatedUnit("EMA-1"), SimulatedUnit("EMA-2"), SimulatedUnit("EMA-3", fault="D=*7"),
         SimulatedUnit("EMA-4")]


@pytest.fixture(scope="module")
def inbox(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """4 actuator units x 5 records (EMA-3: friction x7 from its 4th), a record
    without omega, a Parquet copy of a record, one short HST record with a fault."""
    root = tmp_path_factory.mktemp("fleet") / "inbox"
    files = simulated_inbox(root, FLEET, seed=100)
    simulated_inbox(root, [SimulatedUnit("HST-1", "hst", records=1, fault="Dm=-25%@5s",
                                         fault_from=1, duration=16)], seed=200)
    pd.read_csv(files["EMA-2"][0]).drop(columns="omega").to_csv(root / "EMA-2" / "rec-06-bad.csv",
                                                                 index=False)
    # every digit: pandas' own parser is off in the last one before pandas 3.1
    read_record(files["EMA-1"][1]).to_parquet(root / "EMA-1" / "rec-02-copy.parquet")
    return root


@pytest.fixture(scope="module")
def first_run(inbox: Path, tmp_path_factory: pytest.TempPathFactory
              ) -> tuple[Path, dict[str, Any], float]:
    db = tmp_path_factory.mktemp("fleetdb") / "fleet.db"
    started = time.perf_counter()
    doc = _run_json(["fleet", "run", str(inbox), "--db", str(db), "--workers", "1"])
    return db, doc, time.perf_counter() - started


def _run_json(args: list[str]) -> dict[str, Any]:
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*args, "--json"]) == 0
    return dict(json.loads(buf.getvalue()))


def _by_file(doc: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {f"{Path(r['file']).parent.name}/{Path(r['file']).name}": r for r in doc["records"]}


def test_every_record_is_accounted_for(first_run: tuple[Path, dict[str, Any], float]) -> None:
    _, doc, seconds = first_run
    recs = _by_file(doc)
    assert len(recs) == 23 and sum(doc[o] for o in OUTCOMES) == 23
    assert (doc["stored"], doc["skipped"], doc["rejected"], doc["refused"]) == (21, 1, 0, 1)
    assert doc["workers"] == 1 and doc["engine"] == "local"
    print(f"\nfleet of 23 records, 1 worker: {seconds:.1f} s")


def test_the_faulty_unit_is_flagged_and_the_healthy_ones_are_go(
        first_run: tuple[Path, dict[str, Any], float]) -> None:
    db, doc, _ = first_run
    recs = _by_file(doc)
    for unit in ("EMA-1", "EMA-2", "EMA-3", "EMA-4"):
        assert [recs[f"{unit}/rec-0{i}.csv"]["status"] for i in (1, 2, 3)] == ["baseline"] * 3
    assert [recs[f"EMA-3/rec-0{i}.csv"]["status"] for i in (4, 5)] == ["no-go", "no-go"]
    assert "friction" in recs["EMA-3/rec-04.csv"]["reason"]
    for unit in ("EMA-1", "EMA-2", "EMA-4"):
        assert [recs[f"{unit}/rec-0{i}.csv"]["status"] for i in (4, 5)] == ["go", "go"]
    units = {u["unit"]: u for u in doc["units"]}
    assert {u: units[u]["status"] for u in units} == {
        "EMA-1": "go", "EMA-2": "go", "EMA-3": "no-go", "EMA-4": "go", "HST-1": "no-go"}
    hst = recs["HST-1/rec-01.csv"]
    assert (hst["kind"], hst["status"], hst["reason"]) == ("isolation", "no-go",
                                                           "fault isolated: Dm")
    with open_store(db, create=False) as store:
        assert store.latest_baseline("EMA-3") is not None
        hist = store.history("EMA-3")
        assert list(hist["status"]) == ["baseline"] * 3 + ["no-go"] * 2
        assert hist["D_change"].iloc[3:].min() > 400
        assert store.unit_model("HST-1") == "hst" and len(store.isolations("HST-1")) == 1


def test_bad_file_is_refused_and_copy_skipped_with_reasons(
        first_run: tuple[Path, dict[str, Any], float]) -> None:
    _, doc, _ = first_run
    recs = _by_file(doc)
    bad = recs["EMA-2/rec-06-bad.csv"]
    assert bad["outcome"] == "refused" and bad["status"] is None
    assert "rec-06-bad.csv" in bad["reason"] and "omega" in bad["reason"]
    assert len(bad["reason"].splitlines()) == 1
    copy = recs["EMA-1/rec-02-copy.parquet"]
    assert copy["outcome"] == "skipped" and "EMA-1/rec-02.csv" in copy["reason"]


def test_running_again_stores_nothing(inbox: Path,
                                      first_run: tuple[Path, dict[str, Any], float]) -> None:
    db, first, _ = first_run
    again = run_fleet(inbox, db, workers=1)
    assert (again.stored, again.count("rejected"), again.count("refused")) == (0, 0, 1)
    assert again.skipped == 22 and again.failed   # a record file that cannot be read, still
    with open_store(db, create=False) as store:
        assert sum(s["tests"] + s["isolations"] for s in store.unit_summaries()) == 21


@pytest.mark.tables
def test_the_printed_summary_is_the_json_one(inbox: Path,
                                              first_run: tuple[Path, dict[str, Any], float],
                                              tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """The same inbox into a new history, printed: the units under each status, the
    counts of the run."""
    _, doc, _ = first_run
    monkeypatch.setenv("COLUMNS", "80")
    capsys.readouterr()
    assert main(["fleet", "run", str(inbox), "--db", str(tmp_path / "f.db"),
                 "--workers", "1"]) == 0
    out = capsys.readouterr().out
    row(out, "status", "units", "which")
    statuses: dict[str, list[str]] = {}
    for u in doc["units"]:
        statuses.setdefault(u["status"], []).append(u["unit"])
    assert statuses == {"no-go": ["EMA-3", "HST-1"], "go": ["EMA-1", "EMA-2", "EMA-4"]}
    shown = [row(out, status, str(len(statuses[status])), ", ".join(statuses[status]))
             for status in ("no-go", "go")]
    assert unfold(out).index(shown[0]) < unfold(out).index(shown[1])  # no-go first
    assert (f"23 records: {doc['stored']} stored, {doc['skipped']} skipped, {doc['rejected']} "
            f"rejected, {doc['refused']} refused — 5 units, 1 worker") in flat(out)


def test_the_fleet_answers_as_baseline_add_and_check(
        inbox: Path, first_run: tuple[Path, dict[str, Any], float], tmp_path: Path) -> None:
    """The same records through the one-record flows give the same statuses and changes."""
    db, _, _ = first_run
    files = sorted((inbox / "EMA-3").glob("rec-0*.csv"))
    with open_store(tmp_path / "one.db") as store:
        add_baseline_tests(store, "EMA-3", files[:3])
        for f in files[3:]:
            check_test(store, "EMA-3", f)
        solo = store.history("EMA-3")
    with open_store(db, create=False) as store:
        fleet = store.history("EMA-3")
    assert list(fleet["status"]) == list(solo["status"])
    cols = [c for c in solo.columns if c.endswith(("_change", "_high", "_low", "_se"))]
    pd.testing.assert_frame_equal(fleet[cols].reset_index(drop=True),
                                  solo[cols].reset_index(drop=True))


def test_manifest_dates_order_the_baseline_on_an_existing_cluster(
        inbox: Path, tmp_path: Path, store_url: str) -> None:
    """Dates given in reverse name order: the three earliest build the baseline.
    A unit offered with another model than its history's is refused."""
    names = ["rec-05.csv", "rec-04.csv", "rec-03.csv", "rec-02.csv"]
    rows = ["unit,file,model,date"]
    rows += [f"EMA-9,{inbox / 'EMA-4' / n},,2026-03-0{i + 1}" for i, n in enumerate(names)]
    rows += [f"EMA-8,{inbox / 'EMA-1' / 'rec-01.csv'},dc-motor,"]
    (tmp_path / "m.csv").write_text("\n".join(rows) + "\n")
    with local_cluster(1) as client:
        address = str(client.scheduler.address)  # type: ignore[union-attr]
        res = run_fleet(tmp_path / "m.csv", store_url, scheduler=address)
    assert res.engine == address and res.workers == 1
    got = {Path(r.file).name: r for r in res.records if r.unit == "EMA-9"}
    assert [got[n].status for n in names] == ["baseline", "baseline", "baseline", "go"]
    assert got["rec-03.csv"].test_date is not None
    assert res.records[0].unit == "EMA-8" and res.records[0].outcome == "stored"
    (tmp_path / "m2.csv").write_text(f"unit,file,model\nEMA-8,{inbox / 'HST-1' / 'rec-01.csv'},hst\n")
    again = run_fleet(tmp_path / "m2.csv", store_url, workers=1)
    (only,) = again.records
    assert only.outcome == "refused" and "monitored with model 'dc-motor'" in str(only.reason)
    assert str(inbox / "HST-1" / "rec-01.csv") in str(only.reason)


# -- without an engine -----------------------------------------------------------------


def test_manifest_csv_and_toml(tmp_path: Path) -> None:
    (tmp_path / "m.toml").write_text(
        '[[records]]\nunit = "A"\nfile = "r/a1.csv"\nmodel = "my.toml"\ndate = 2026-03-01\n'
        '[[records]]\nunit = "A"\nfile = "/abs/a2.csv"\nmodel = "my.toml"\n')
    a1, a2 = read_manifest(tmp_path / "m.toml")
    assert a1.path == tmp_path / "r" / "a1.csv" and a2.path == Path("/abs/a2.csv")
    assert a1.model == str(tmp_path / "my.toml") and a1.test_date is not None
    (tmp_path / "m.csv").write_text("unit,file,date\nA,a.csv,yesterday\n\nB,b.csv,\n")
    a, b = read_manifest(tmp_path / "m.csv")
    assert a.error is not None and "row 2: date" in a.error and b.error is None


@pytest.mark.parametrize("text,message", [
    ("unit,model\nA,hst\n", "missing column 'file'"),
    ("unit,file,colour\nA,a.csv,red\n",
     r"unknown column 'colour' \(columns: unit, file, model, date, group, metadata, columns, "
     r"sample_rate, scale, offset, ignore, name_time\)$"),
    ("Unit,Flie\nA,a.csv\n", r"unknown column 'Flie' \(columns: unit, file, model, date, group, "
     r"metadata, columns, sample_rate, scale, offset, ignore, name_time\)$"),
    ("unit,file\nA,\nB,b.csv\n\n,c.csv\n", "row 2: needs a unit and a file; row 5: needs a unit "
     "and a file$"),
])
def test_bad_manifest_is_a_usage_error(tmp_path: Path, text: str, message: str) -> None:
    (tmp_path / "m.csv").write_text(text)
    with pytest.raises(ConfigError, match=message):
        read_manifest(tmp_path / "m.csv")


def test_inbox_layout(tmp_path: Path) -> None:
    for name in ("U1/rec-10.csv", "U1/rec-9.parquet", "U1/2026/rec-1.csv", "U1/notes.md",
                 "U1/.hidden.csv", "U1/.git/x.csv", "U2/x.csv", "U2/my.toml", "stray.csv",
                 "README.md"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("t\n")
    (tmp_path / "U2" / "unit.toml").write_text('model = "my.toml"\n')
    recs = inbox_records(tmp_path)
    assert [(r.unit, str(r.path.relative_to(tmp_path))) for r in recs] == [
        ("U1", "U1/2026/rec-1.csv"), ("U1", "U1/notes.md"), ("U1", "U1/rec-9.parquet"),
        ("U1", "U1/rec-10.csv"), ("U2", "U2/x.csv"), ("", "stray.csv")]
    assert [r.error is None for r in recs] == [True, False, True, True, True, False]
    assert recs[4].fallback_model == str(tmp_path / "U2" / "my.toml")
    assert recs[4].fallback_source == str(tmp_path / "U2" / "unit.toml")
    with pytest.raises(ConfigError, match="not a folder"):
        inbox_records(tmp_path / "none")


def test_a_failing_record_is_an_outcome_not_an_exception(tmp_path: Path) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("t,V,I,omega\n0,1,2,3\n0.001,1,2,x\n")
    out = process_record(RecordTask("U", str(bad), "estimate", "dc-motor"))
    assert out.error is not None and str(bad) in out.error and len(out.error.splitlines()) == 1
    out = process_record(RecordTask("U", str(bad), "estimate", "no-such-model"))
    assert out.error is not None and str(bad) in out.error


@pytest.mark.parametrize("args,message", [
    (["fleet", "run", "--db", "{db}"], "give an INBOX folder or --manifest FILE"),
    (["fleet", "run", "{inbox}", "--db", "{db}", "--baseline-count", "2"],
     "baseline count must be >= 3, got 2"),
    (["fleet", "run", "{missing}", "--db", "{db}"], "not a folder"),
    (["fleet", "run", "--manifest", "{missing}", "--db", "{db}"], "manifest not found"),
    (["fleet", "run", "{inbox}", "--db", "{db}", "--workers", "0"], "workers must be >= 1"),
    (["fleet", "run", "{inbox}", "--db", "{db}", "--workers", "2", "--scheduler",
      "tcp://127.0.0.1:9"], "an existing cluster"),
])
def test_usage_errors_give_one_line_and_status_2(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str],
                                                 args: list[str], message: str) -> None:
    paths = {"db": tmp_path / "f.db", "inbox": tmp_path, "missing": tmp_path / "none.csv"}
    assert main([a.format(**{k: str(v) for k, v in paths.items()}) for a in args]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1 and "Traceback" not in err


def test_an_empty_inbox_needs_no_engine(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fleet", "run", str(tmp_path), "--db", str(tmp_path / "f.db")]) == 0
    assert "no records" in capsys.readouterr().out


def _written(db: Path) -> int:
    """Tests and isolations in a SQLite history (0 while it has none)."""
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=1) as con:
            return int(sum(con.execute(f"SELECT count(*) FROM {t}").fetchone()[0]
                           for t in ("tests", "isolations")))
    except sqlite3.Error:
        return 0


def _condmon(*args: str) -> list[str]:
    return [sys.executable, "-m", "condmon.cli.main", *args]


def test_ctrl_c_keeps_what_is_stored_and_says_so(inbox: Path, tmp_path: Path) -> None:
    """SIGINT to the process group (as a terminal sends) once the first results are
    committed: one line on stderr, status 130, the count as in the database; running
    again stores the rest."""
    db = tmp_path / "f.db"
    proc = subprocess.Popen(_condmon("fleet", "run", str(inbox), "--db", str(db),
                                     "--workers", "1"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    deadline = time.monotonic() + 120
    while _written(db) == 0 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    stored = _written(db)
    assert proc.returncode == 130, err
    assert 0 < stored < 21
    assert err == f"interrupted: {stored} of 23 records stored; run again to finish\n"
    assert out == ""
    again = run_fleet(inbox, db, workers=1)
    assert again.stored + again.count("rejected") == 21 - stored and _written(db) == 21


def test_a_bad_scheduler_is_one_line_at_once_and_makes_no_database(tmp_path: Path) -> None:
    (tmp_path / "inbox" / "U").mkdir(parents=True)
    (tmp_path / "inbox" / "U" / "a.csv").write_text("t,V,I,omega\n0,1,2,3\n")
    started = time.monotonic()
    done = subprocess.run(_condmon("fleet", "run", str(tmp_path / "inbox"), "--db",
                                   str(tmp_path / "f.db"), "--scheduler", "bogus://x"),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and time.monotonic() - started < 15
    assert done.stderr.startswith("error: cannot reach the scheduler 'bogus://x': unknown "
                                  "address scheme 'bogus'")
    assert len(done.stderr.splitlines()) == 1 and done.stdout == ""
    assert not (tmp_path / "f.db").exists()


def test_every_file_of_a_unit_is_accounted_for(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """Files no reader takes are refused with the readable suffixes; hidden files
    and unit.toml are not records; nothing computed: no rate, no database."""
    unit = tmp_path / "inbox5" / "Z1"
    unit.mkdir(parents=True)
    for name in ("a.dat", "b.csv.gz", "noext", "notes.xyz", ".hidden.csv"):
        (unit / name).write_text("t\n")
    (unit / "unit.toml").write_text('model = "dc-motor"\n')
    db = tmp_path / "f.db"
    assert main(["fleet", "run", str(tmp_path / "inbox5"), "--db", str(db)]) == 2
    got = capsys.readouterr()
    readable = ".csv, .parquet, .pq, .txt, .tsv, .mat, .tdms"
    assert got.err.splitlines() == [
        f"refused {unit / name}: not a record file ({what}); readable: {readable}"
        for name, what in (("a.dat", ".dat"), ("b.csv.gz", ".csv.gz"), ("noext", "no suffix"),
                           ("notes.xyz", ".xyz"))] + [
        "nothing new was stored: 4 record(s) refused and none taken (exit 2)"]
    assert "4 records: 0 stored, 0 skipped, 0 rejected, 4 refused (4 of them no unit's " \
        "record) — 1 unit, nothing new to estimate, no worker started" in " ".join(
            got.out.split())
    assert "records/s" not in got.out and not db.exists()


def test_a_unit_folder_given_as_the_inbox_is_a_usage_error(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    unit = tmp_path / "inbox.orig" / "EMA-1"
    unit.mkdir(parents=True)
    for i in range(3):
        (unit / f"rec-0{i}.csv").write_text("t\n")
    assert main(["fleet", "run", str(unit), "--db", str(tmp_path / "f.db")]) == 2
    assert capsys.readouterr().err == (f"error: {unit} holds record files, not unit folders — "
                                       f"did you mean {tmp_path / 'inbox.orig'}?\n")
    assert not (tmp_path / "f.db").exists()


def test_a_bad_model_in_unit_toml_names_it(tmp_path: Path) -> None:
    (tmp_path / "U").mkdir()
    (tmp_path / "U" / "x.csv").write_text("t\n")
    (tmp_path / "U" / "unit.toml").write_text('model = "no-such-model"\n')
    (only,) = run_fleet(tmp_path, tmp_path / "f.db").records
    assert only.outcome == "refused"
    assert str(only.reason).startswith(f"{tmp_path / 'U' / 'x.csv'}: "
                                       f"{tmp_path / 'U' / 'unit.toml'}: unknown model")


def test_manifest_rows_take_their_units_model_and_conflicts_are_the_rows_own(
        tmp_path: Path) -> None:
    (tmp_path / "m.csv").write_text("Unit;File;Model;Date\nZ1;a.csv;;\nZ1;b.csv;dc-motor;\n"
                                    "Z1;c.csv;;2026-03-01\nZ1;d.csv;x;\nZ2;e.csv;;\n")
    a, b, c, d, e = read_manifest(tmp_path / "m.csv")
    assert [r.model for r in (a, b, c, e)] == ["dc-motor", "dc-motor", "dc-motor", None]
    assert [r.error for r in (a, b, c, e)] == [None] * 4 and c.test_date is not None
    assert d.error == (f"{tmp_path / 'm.csv'}: unit 'Z1' has one model: row 5 gives 'x', "
                       "row 3 gave 'dc-motor'")


def test_a_file_listed_twice_is_skipped_as_such(tmp_path: Path) -> None:
    (tmp_path / "m.toml").write_text('[[records]]\nunit = "A"\nfile = "a.csv"\n'
                                     '[[records]]\nUnit = "A"\nFile = "./a.csv"\n'
                                     '[[records]]\nunit = "A"\nfile = "b.csv"\ncolour = "red"\n')
    first, second, third = run_fleet(tmp_path / "m.toml", tmp_path / "f.db").records
    assert (first.outcome, first.reason) == ("refused", f"{tmp_path / 'a.csv'}: file not found")
    assert (second.outcome, second.reason) == (
        "skipped", f"{tmp_path / 'a.csv'}: listed twice in the manifest (rows 1 and 2)")
    assert third.outcome == "refused" and str(third.reason).endswith(
        "row 3: unknown column 'colour' (columns: unit, file, model, date, group, metadata, "
        "columns, sample_rate, scale, offset, ignore, name_time)")
    assert not (tmp_path / "f.db").exists()


def test_a_missing_manifest_is_named_in_full(tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError) as info:
        read_manifest("lists/none.csv")
    assert str(info.value) == (f"{tmp_path / 'lists' / 'none.csv'}: manifest not found "
                               "(relative files are found from the manifest's folder)")


# -- acceptance study --------------------------------------------------------------------


@pytest.mark.slow
def test_acceptance_50_units_x_8_records_mixed(tmp_path: Path) -> None:
    """34 actuator units (4 with friction x7, 4 with R +40 % from record 5) and 16
    HST units (2 with Dm -25 %, 2 with Rv +40 % from record 5), 8 records each;
    5 bad files and 3 Parquet copies besides: every record accounted for, the
    faulty units flagged, the healthy ones not; running again stores nothing."""
    import numpy as np

    ema = [SimulatedUnit(f"EMA-{i:02d}", records=8, fault_from=5,
                         fault="D=*7" if i <= 4 else "R=+40%" if i <= 8 else None)
           for i in range(1, 35)]
    hst = [SimulatedUnit(f"HST-{i:02d}", "hst", records=8, fault_from=5,
                         fault="Dm=-25%@10s" if i <= 2 else "Rv=+40%@10s" if i <= 4 else None)
           for i in range(1, 17)]
    t0 = time.perf_counter()
    files = simulated_inbox(tmp_path / "inbox", [*ema, *hst], seed=5000)
    inbox = tmp_path / "inbox"
    df = pd.read_csv(files["EMA-10"][0])
    df.drop(columns="I").to_csv(inbox / "EMA-10" / "rec-09-no-current.csv", index=False)
    df.assign(t=df["t"] * 1000).to_csv(inbox / "EMA-11" / "rec-09-ms.csv", index=False)
    (inbox / "EMA-12" / "rec-09-empty.csv").write_text("")
    (inbox / "EMA-13" / "rec-09-garbage.parquet").write_bytes(b"\x00not parquet" * 10)
    h = pd.read_csv(files["HST-10"][0])
    h.loc[100:110, "Ps"] = np.nan
    h.to_csv(inbox / "HST-10" / "rec-09-nan.csv", index=False)
    for unit in ("EMA-20", "EMA-21", "HST-11"):
        pd.read_csv(files[unit][2]).to_parquet(inbox / unit / "rec-03-copy.parquet")
    made = time.perf_counter() - t0

    db = tmp_path / "fleet.db"
    t0 = time.perf_counter()
    res = run_fleet(inbox, db, workers=2)
    took = time.perf_counter() - t0
    total = 50 * 8 + 5 + 3
    counts = {o: res.count(o) for o in OUTCOMES}
    assert len(res.records) == total and sum(counts.values()) == total
    assert counts["refused"] == 5 and counts["skipped"] == 3
    refused = [r for r in res.records if r.outcome == "refused"]
    assert all(Path(r.file).name in str(r.reason) and "\n" not in str(r.reason) for r in refused)
    assert {Path(r.file).name for r in refused} == {
        "rec-09-no-current.csv", "rec-09-ms.csv", "rec-09-empty.csv",
        "rec-09-garbage.parquet", "rec-09-nan.csv"}

    def statuses(unit: str) -> list[str | None]:
        return [r.status for r in res.records if r.unit == unit and r.outcome != "refused"
                and "copy" not in r.file]

    faulty = [u.name for u in [*ema, *hst] if u.fault is not None]
    flagged = sum(s == "no-go" for u in faulty for s in statuses(u)[4:])
    early_alarms = sum(s == "no-go" for u in faulty for s in statuses(u)[:4])
    healthy_checks = [s for u in [*ema, *hst] if u.fault is None
                      for s in statuses(u.name) if s not in ("baseline", None)]
    false_nogo = sum(s == "no-go" for s in healthy_checks)
    advisory = sum(s == "advisory" for s in healthy_checks)
    units = {u.unit: u.status for u in res.units}
    missed = [(r.unit, Path(r.file).name, r.status, r.reason) for u in faulty
              for r in [x for x in res.records if x.unit == u and x.outcome != "refused"
                        and "copy" not in x.file][4:] if r.status != "no-go"]
    print(f"\n50 units x 8 records (+5 bad, +3 copies): {total} records, generated in "
          f"{made:.0f} s, run in {took:.0f} s on {res.workers} workers "
          f"({total / took:.1f} records/s); {counts}; faulty records flagged no-go "
          f"{flagged}/{4 * len(faulty)} (no-go before the fault: {early_alarms}); healthy "
          f"checks {len(healthy_checks)}: no-go {false_nogo}, advisory {advisory}; "
          f"units no-go {sum(s == 'no-go' for s in units.values())}; missed: {missed}")
    for r in refused:
        print(f"refused {r.reason}")
    assert flagged >= 0.95 * 4 * len(faulty) and early_alarms == 0
    assert all(units[u] == "no-go" for u in faulty)
    assert false_nogo <= 0.02 * len(healthy_checks)
    assert all(units[u.name] == "go" for u in [*ema, *hst] if u.fault is None)

    t0 = time.perf_counter()
    again = run_fleet(inbox, db, workers=2)
    print(f"again: {again.to_dict()['stored']} stored, {again.skipped} skipped, "
          f"{again.count('refused')} refused in {time.perf_counter() - t0:.0f} s")
    assert again.stored == 0 and again.skipped == total - 5 and again.count("refused") == 5


def test_a_record_in_two_units_folders_is_warned(tmp_path: Path) -> None:
    files = simulated_inbox(tmp_path / "inbox", [SimulatedUnit("A", records=3)], seed=300)
    (tmp_path / "inbox" / "B").mkdir()
    shutil.copy(files["A"][1], tmp_path / "inbox" / "B" / "rec-01.csv")
    res = run_fleet(tmp_path / "inbox", tmp_path / "f.db", workers=1)
    by_unit = {r.unit: r for r in res.records if r.unit == "B"}
    b = by_unit["B"]
    assert b.outcome == "stored"
    assert any("the same record is also test #2 of 'A'" in w for w in b.warnings), b.warnings
    assert not any(r.warnings for r in res.records if r.unit == "A")
    assert "the same record is also" in json.dumps(b.to_dict())


def test_local_workers_keep_glibcs_adaptive_allocator() -> None:
    """dask's MALLOC_TRIM_THRESHOLD_ (set for long-lived workers) makes every large
    array a fresh mmap; the fleet's own workers do without it, one BLAS thread each."""
    import os

    with local_cluster(1) as client:
        env = list(client.run(lambda: (os.environ.get("MALLOC_TRIM_THRESHOLD_"),
                                       os.environ.get("OPENBLAS_NUM_THREADS"))).values())
    assert env == [(None, "1")]


def test_a_run_that_stores_nothing_and_refuses_something_exits_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Every record refused once exited 0, as if all was well."""
    (tmp_path / "inbox" / "EMA-1").mkdir(parents=True)
    (tmp_path / "inbox" / "EMA-1" / "r1.csv").write_text("x,y\n1,2\n")
    db = str(tmp_path / "f.db")
    assert main(["fleet", "run", str(tmp_path / "inbox"), "--db", db, "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "nothing new was stored: 1 record(s) refused and none taken (exit 2)" in err
    assert main(["fleet", "run", str(tmp_path / "inbox"), "--db", db, "--workers", "1",
                 "--json"]) == 2


def test_a_stray_file_does_not_fail_an_up_to_date_fleet(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A notes.md in a unit's folder made every later run exit 2 (nothing new
    stored, one file refused), and the rate counted the records skipped. It is
    still named at every run; a record file that cannot be read still fails."""
    root = tmp_path / "inbox"
    simulated_inbox(root, [SimulatedUnit("EMA-1", records=1)], seed=5)
    (root / "EMA-1" / "notes.md").write_text("serviced 2026-03-02\n")
    db = str(tmp_path / "f.db")
    assert main(["fleet", "run", str(root), "--db", db]) == 0
    first = capsys.readouterr()
    assert "records stored/s" in first.out
    assert main(["fleet", "run", str(root), "--db", db]) == 0
    again = capsys.readouterr()
    assert again.err.startswith(f"refused {root / 'EMA-1' / 'notes.md'}: not a record file")
    assert "0 stored, 1 skipped, 0 rejected, 1 refused" in again.out
    assert "/s)" not in again.out and "nothing new was stored" not in again.err
    (root / "README.txt").write_text("the inbox of line 3\n")   # beside the unit folders
    assert main(["fleet", "run", str(root), "--db", db]) == 0
    assert "2 refused (2 of them no unit's record)" in capsys.readouterr().out
    (root / "EMA-1" / "r9.csv").write_text("x,y\n1,2\n")
    assert main(["fleet", "run", str(root), "--db", db]) == 2
    assert "nothing new was stored: 3 record(s) refused and none taken (exit 2)" in \
        capsys.readouterr().err


def test_a_small_fleet_runs_in_process_with_the_clusters_results(
        inbox: Path, first_run: tuple[Path, dict[str, Any], float], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Without --workers, 23 records (fewer than SMALL_FLEET) are processed in
    this process: no cluster is started, and every record's outcome and every
    stored estimate are those of the run on a local cluster."""
    from condmon.workflows.fleet import SMALL_FLEET

    assert 23 < SMALL_FLEET
    db, doc, _ = first_run
    res = run_fleet(inbox, tmp_path / "here.db")
    assert (res.engine, res.workers, res.engine_start) == ("in-process", 1, 0.0)
    here = {f"{Path(r.file).parent.name}/{Path(r.file).name}": r.outcome for r in res.records}
    assert here == {k: v["outcome"] for k, v in _by_file(doc).items()}
    with open_store(db) as a, open_store(tmp_path / "here.db") as b:
        for unit in ("EMA-1", "EMA-3"):
            cols = ["R", "L", "Ke", "Kt", "J", "D", "status"]
            pd.testing.assert_frame_equal(a.history(unit)[cols].reset_index(drop=True),
                                          b.history(unit)[cols].reset_index(drop=True))
    assert main(["fleet", "run", str(inbox), "--db", str(tmp_path / "cli.db")]) == 0
    assert "in this process (fewer than" in " ".join(capsys.readouterr().out.split())
