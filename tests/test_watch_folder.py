"""`condmon watch FOLDER` when files arrive as loggers write them: a pause
longer than --settle, a marker beside the file, a rename into place; and what
an idle watch costs over many files."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from condmon.simulate import simulate_actuator
from condmon.store import open_store
from condmon.workflows.fleet_inbox import MAX_UNIT_FILE, read_unit_file
from condmon.workflows.watch_folder import _Files, watch_folder


def _watch(inbox: Path, db: str, **kw: Any) -> tuple[threading.Thread, dict[str, Any],
                                                     threading.Event, list[str]]:
    stop, lines, result = threading.Event(), [], {}
    th = threading.Thread(target=lambda: result.update(summary=watch_folder(
        inbox, db, poll=0.1, stop=stop, log=lines.append, **kw)), daemon=True)
    th.start()
    return th, result, stop, lines


def _wait(predicate: Any, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.1)


def test_a_file_written_on_after_a_long_pause_is_stored_once(tmp_path: Path) -> None:
    """The issue's attack: a pause longer than --settle stored the file twice,
    cut in half and whole. The part is now excluded as replaced."""
    inbox = tmp_path / "inbox"
    (inbox / "EMA-1").mkdir(parents=True)
    db = str(tmp_path / "w.db")
    for seed in (1, 2, 3):
        simulate_actuator(seed=seed).to_csv(tmp_path / f"b{seed}.csv", index=False)
        os.replace(tmp_path / f"b{seed}.csv", inbox / "EMA-1" / f"b{seed}.csv")
    th, result, stop, lines = _watch(inbox, db, settle=0.4)
    _wait(lambda: any("b3.csv" in ln for ln in lines) or len(lines) > 3)
    record = simulate_actuator(seed=9)
    target = inbox / "EMA-1" / "check.csv"
    record.iloc[:2000].to_csv(target, index=False)   # the logger pauses here
    _wait(lambda: sum("check.csv" in ln for ln in lines) >= 1)
    record.iloc[2000:].to_csv(target, index=False, header=False, mode="a")
    _wait(lambda: sum("check.csv" in ln for ln in lines) >= 3)
    stop.set()
    th.join(60)
    summary = result["summary"]
    assert summary.replaced == 1, lines
    from condmon.io.digest import content_hash
    with open_store(db) as store:
        whole = store.find_test("EMA-1", content_hash(record))
        assert whole is not None
        hist = store.history("EMA-1")
    assert len(hist) == 5 and list(hist.index[hist["excluded"]]) == [whole - 1], lines
    assert any("excluded, replaced: check.csv was stored while still being written; its "
               f"complete version is test #{whole}" in ln for ln in lines), lines


def test_with_markers_a_file_waits_for_its_marker(tmp_path: Path) -> None:
    inbox = tmp_path / "inbox"
    (inbox / "EMA-1").mkdir(parents=True)
    files = _Files(inbox, "marker", settle=0.0)
    rec = inbox / "EMA-1" / "r1.csv"
    rec.write_text("t,V\n0,1\n")
    assert files.ready() == []
    (inbox / "EMA-1" / "r1.csv.done").write_text("")
    assert files.ready() == [rec]
    files.handed([rec])
    assert files.ready() == []


def test_a_record_dropped_at_the_top_is_refused_not_left_unseen(tmp_path: Path) -> None:
    """A record file dropped beside the unit folders was never looked at: no
    line said it would never be stored. It is handed over and refused as
    `fleet run` refuses it; other files there are no records."""
    from condmon.workflows.fleet import run_fleet

    inbox = tmp_path / "inbox"
    (inbox / "EMA-1").mkdir(parents=True)
    files = _Files(inbox, "rename", settle=0.0)
    stray = inbox / "r1.csv"
    stray.write_text("t,V\n0,1\n")
    (inbox / "notes.md").write_text("the inbox of line 3\n")
    assert files.ready() == [stray]
    res = run_fleet(inbox, str(tmp_path / "w.db"), files=[stray])
    assert [(r.outcome, r.reason) for r in res.records] == [
        ("refused", f"{stray}: not in a unit's folder (INBOX/UNIT/record files)")]


def test_renamed_into_place_is_complete_at_once_and_temporaries_wait(tmp_path: Path) -> None:
    inbox = tmp_path / "inbox"
    (inbox / "EMA-1").mkdir(parents=True)
    files = _Files(inbox, "rename", settle=5.0)
    (inbox / "EMA-1" / "r1.csv.part").write_text("t,V\n0,1\n")
    (inbox / "EMA-1" / ".r2.csv").write_text("t,V\n0,1\n")
    assert files.ready() == []
    os.replace(inbox / "EMA-1" / "r1.csv.part", inbox / "EMA-1" / "r1.csv")
    assert files.ready() == [inbox / "EMA-1" / "r1.csv"]


def test_an_idle_watch_lists_no_folder_again_and_looks_at_no_old_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """60-79 % of a core went on listing and statting every file ever seen, twice a
    second. A folder is listed again only when it changes; a file handed over
    long ago is not looked at."""
    import condmon.workflows.watch_folder as wf

    inbox = tmp_path / "inbox"
    for u in range(20):
        (inbox / f"U{u}").mkdir(parents=True)
        for k in range(50):
            (inbox / f"U{u}" / f"r{k}.csv").write_text("t\n0\n")
    files = _Files(inbox, "rename", settle=0.0)
    first = files.ready()
    assert len(first) == 1000
    files.handed(first)
    monkeypatch.setattr(wf, "RECHECK", 0.0)
    listed, statted = [], []
    real_scandir, real_stat = os.scandir, Path.stat
    monkeypatch.setattr(wf.os, "scandir", lambda p: listed.append(p) or real_scandir(p))
    monkeypatch.setattr(Path, "stat", lambda self, **kw: statted.append(self)
                        or real_stat(self, **kw))
    for _ in range(5):
        assert files.ready() == []
    assert listed == [] and statted == []
    (inbox / "U3" / "new.csv").write_text("t\n0\n")
    assert files.ready() == [inbox / "U3" / "new.csv"]
    assert listed == [inbox / "U3"]


def test_a_unit_file_too_large_is_refused_unread(tmp_path: Path) -> None:
    (tmp_path / "U1").mkdir()
    with open(tmp_path / "U1" / "unit.toml", "wb") as f:
        f.truncate(MAX_UNIT_FILE + 1)
    unit = read_unit_file(tmp_path / "U1")
    assert unit.error is not None and "beyond the 1000000 a unit file may hold" in unit.error


def test_a_unit_s_folder_or_stream_settings_are_refused_before_watching(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`watch inbox/HST-A` watched the unit's folder and never read its
    records; `--settings` was ignored by a watched folder, even a CSV."""
    from condmon.cli.main import main

    unit = tmp_path / "inbox" / "U1"
    unit.mkdir(parents=True)
    simulate_actuator(seed=1).to_csv(unit / "r1.csv", index=False)
    db = str(tmp_path / "h.db")
    assert main(["watch", str(unit), "--db", db, "--duration", "1"]) == 2
    assert capsys.readouterr().err.strip().endswith(
        f"{unit} holds record files, not unit folders — did you mean {unit.parent}?")
    settings = tmp_path / "iso.toml"
    settings.write_text("[detection]\nz = 1000.0\n")
    assert main(["watch", str(unit.parent), "--db", db, "--duration", "1",
                 "--settings", str(settings)]) == 2
    assert "applies to an --mqtt stream; a watched folder's records are processed as " \
        "`condmon fleet run` processes them" in capsys.readouterr().err
    assert not Path(db).exists()
