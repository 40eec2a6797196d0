"""What --json prints: every digit, JSON values as JSON, ids as integers."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from condmon.cli.main import main
from condmon.simulate import simulate_actuator
from condmon.store import open_store


def test_history_and_audit_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    files = []
    for s in range(4):
        p = tmp_path / f"h{s}.csv"
        simulate_actuator(seed=90 + s).to_csv(p, index=False)
        files.append(str(p))
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
