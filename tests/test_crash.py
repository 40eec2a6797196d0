"""Killing the process in the middle of `baseline add` leaves a consistent history."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from condmon.cli.main import main
from condmon.simulate import simulate_actuator


def _count(db: Path, sql: str) -> int:
    with sqlite3.connect(db) as conn:
        return int(conn.execute(sql).fetchone()[0])


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_sigkill_during_baseline_add_of_20_files(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    files = []
    for s in range(20):
        p = tmp_path / f"h{s:02d}.csv"
        simulate_actuator(seed=s).to_csv(p, index=False)
        files.append(str(p))
    db = tmp_path / "h.db"
    cmd = [sys.executable, "-c", "import sys; from condmon.cli.main import run; "
           "sys.argv[0] = 'condmon'; run()", "baseline", "add", *files, "--unit", "U",
           "--db", str(db)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    killed_at = None
    while time.monotonic() < deadline:  # wait until a few tests are committed
        if db.exists():
            try:
                n = _count(db, "SELECT COUNT(*) FROM tests")
            except sqlite3.Error:
                n = 0
            if n >= 3:
                os.kill(proc.pid, signal.SIGKILL)
                killed_at = n
                break
        time.sleep(0.005)
    proc.wait(timeout=30)
    assert killed_at is not None, "the process finished or stalled before it could be killed"
    with sqlite3.connect(db) as conn:
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    n_tests = _count(db, "SELECT COUNT(*) FROM tests")
    assert 3 <= n_tests < 20
    # every stored test is whole: six estimates each, no orphans
    assert _count(db, "SELECT COUNT(*) FROM estimates") == 6 * n_tests
    assert _count(db, "SELECT COUNT(*) FROM estimates WHERE test_id NOT IN "
                      "(SELECT id FROM tests)") == 0
    # running the same command again completes the job without duplicates
    assert main(["baseline", "add", *files, "--unit", "U", "--db", str(db)]) == 0
    assert _count(db, "SELECT COUNT(*) FROM tests") == 20
    assert _count(db, "SELECT COUNT(DISTINCT file_hash) FROM tests") == 20
    assert capsys.readouterr().err.count("already in the history") == n_tests
