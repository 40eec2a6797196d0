"""What --json prints: every digit, JSON values as JSON, ids as integers."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from condmon.cli.main import main
from condmon.store import open_store

if TYPE_CHECKING:
    from conftest import RecordFiles


def test_history_and_audit_json(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                record_files: RecordFiles) -> None:
    files = record_files(tmp_path, range(90, 94))
    db = str(tmp_path / "h.db")
    assert main(["baseline", "add", *files[:3], "--unit", "U", "--db", db]) == 0
    assert main(["check", files[3], "--unit", "U", "--db", db]) == 0
    capsys.readouterr()
    assert main(["history", "--unit", "U", "--db", db, "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    with open_store(db, create=False) as store:
        hist = store.history("U")
    for row in rows:
        assert isinstance(row["fits"], dict) and set(row["fits"]) == {"I", "omega"}
        assert row["R"] == float(hist.loc[row["test_id"], "R"])  # every digit
    assert rows[-1]["status"] == "go" and rows[-1]["R_change"] is not None
    assert main(["audit", "--db", db, "--json"]) == 0
    trail = json.loads(capsys.readouterr().out)["audit"]
    assert all(isinstance(r["id"], int) for r in trail)
    assert all(r["test_id"] is None or isinstance(r["test_id"], int) for r in trail)
    assert any(isinstance(r["detail"], dict) for r in trail)
    assert all(r["at"].endswith("Z") or "+" in r["at"] for r in trail)  # a zone is given


def test_one_record_filed_under_two_units_is_warned(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str],
                                                     record_files: RecordFiles) -> None:
    files = record_files(tmp_path, range(95, 99))
    db = str(tmp_path / "h.db")
    assert main(["baseline", "add", *files[:3], "--unit", "A", "--db", db]) == 0
    assert "warning" not in capsys.readouterr().err
    assert main(["baseline", "add", files[3], files[0], "--unit", "B", "--db", db]) == 0
    err = capsys.readouterr().err
    assert f"warning: {files[0]}: the same record is also test #1 of 'A'" in err
    assert files[3] not in err
    assert main(["check", files[1], "--unit", "A", "--db", db, "--json"]) == 2  # A's own
    capsys.readouterr()
    assert main(["baseline", "add", files[1], files[2], "--unit", "B", "--db", db]) == 0
    capsys.readouterr()
    assert main(["check", files[3], "--unit", "A", "--db", db, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["warning"].startswith("the same record is also test #4 of 'B'")
