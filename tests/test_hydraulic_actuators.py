"""Real routine records: two industrial hydraulic rotary actuators of one test stand,
read with examples/hydraulic-actuator/ as the stand wrote them.

Act_1 is healthy, Act_4 has a seal defect (same load). The default run takes
a sample of each; the whole of both is the slow study (and benchmarks/bench_routine.py).
"""

from __future__ import annotations

import json
import re
from collections import Counter
from pathlib import Path

import pytest

from condmon.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "external" / "hydraulic_actuators"
MODEL = str(ROOT / "examples" / "hydraulic-actuator" / "rotary-actuator.toml")

pytestmark = pytest.mark.skipif(not DATA.exists(),
                                reason="the hydraulic actuator records are not beside the repository")


def _files(actuator: str) -> list[str]:
    files = sorted(DATA.glob(f"{actuator}/*.txt"),
                   key=lambda p: int(re.search(r"_000_(\d+)_", p.name).group(1)))  # type: ignore[union-attr]
    return [str(p) for p in files]


def _check(db: str, record: str, capsys: pytest.CaptureFixture[str]) -> dict:  # type: ignore[type-arg]
    assert main(["check", record, "--unit", "Act_1", "--db", db, "--dry-run", "--json"]) == 0
    doc: dict = json.loads(capsys.readouterr().out)  # type: ignore[type-arg]
    return doc


def _flow(tmp_path: Path, capsys: pytest.CaptureFixture[str], step: int
          ) -> tuple[Counter[str], Counter[str], list[dict]]:  # type: ignore[type-arg]
    a1, a4 = _files("Act_1"), _files("Act_4")
    db = str(tmp_path / "h.db")
    assert main(["baseline", "add", *a1[:10], "--unit", "Act_1", "--db", db,
                 "--model", MODEL]) == 0
    out = capsys.readouterr().out
    assert "regimes: forward 5 tests, reverse 5 tests" in out
    healthy = Counter(_check(db, f, capsys)["status"] for f in a1[10::step])
    docs = [_check(db, f, capsys) for f in a4[::step]]
    return healthy, Counter(d["status"] for d in docs), docs


def test_every_record_estimates_with_the_declaration_alone(
        capsys: pytest.CaptureFixture[str]) -> None:
    for f in [*_files("Act_1")[::13], *_files("Act_4")[::13]]:
        assert main(["estimate", f, "--model", MODEL, "--json"]) == 0
        doc = json.loads(capsys.readouterr().out)
        assert doc["accepted"] and doc["regime"] in ("forward", "reverse")
        assert doc["identifiable"]["Tc"] and not doc["identifiable"]["J"]
        assert doc["parameters"]["Tc"] > 0 and doc["fit_percent"] > 90.0
        assert [w["regime"] for w in doc["windows"]][-1] == "holding"


def test_healthy_records_go_and_the_seal_defect_is_found(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    healthy, damaged, docs = _flow(tmp_path, capsys, step=7)
    assert healthy == Counter(go=sum(healthy.values()))
    flagged = damaged["advisory"] + damaged["no-go"]
    assert flagged / sum(damaged.values()) >= 0.9
    for d in docs:
        if d["status"] != "go":
            assert "Tc low" in d["summary"]
            assert all(v < -15.0 for v in d["percent_change"].values())


@pytest.mark.slow
def test_acceptance_every_record(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Baseline from Act_1's first 10 records; >= 95 % of Act_1's others go, >= 95 %
    of Act_4's flagged with a diagnosis naming the parameter."""
    healthy, damaged, docs = _flow(tmp_path, capsys, step=1)
    assert healthy["go"] / sum(healthy.values()) >= 0.95
    assert (damaged["advisory"] + damaged["no-go"]) / sum(damaged.values()) >= 0.95
    assert all("Tc" in d["summary"] for d in docs if d["status"] != "go")


def test_a_record_cut_to_its_hold_is_not_identifiable(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    a1 = _files("Act_1")
    db = str(tmp_path / "h.db")
    assert main(["baseline", "add", *a1[:6], "--unit", "Act_1", "--db", db,
                 "--model", MODEL]) == 0
    lines = Path(a1[20]).read_text().splitlines()
    hold = tmp_path / "hold.txt"
    hold.write_text("\n".join([lines[0], *lines[700:]]) + "\n")
    capsys.readouterr()
    assert main(["check", str(hold), "--unit", "Act_1", "--db", db, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["status"] == "retest" and not doc["accepted"]
    assert doc["reason"].startswith("not identifiable: no window of the record can be used")
    assert doc["test_id"] > 0
    from condmon.store import open_store

    with open_store(db) as store:
        values, _ = store.estimates_of([doc["test_id"]])
        assert values.empty or values.isna().all().all()  # nothing trended
        assert doc["test_id"] not in store.usable_tests("Act_1")
