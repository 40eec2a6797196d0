"""Peer baselines: a simulated fleet of DC-motor units with a manufacturing spread, one group."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from condmon.cli.main import main
from condmon.errors import DataError
from condmon.monitor.baseline import Baseline
from condmon.monitor.group import group_baseline, unlike_group
from condmon.simulate import ActuatorRig, load_actuator_rig, simulate_actuator
from condmon.store import open_store
from condmon.store.db import HistoryStore
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import add_baseline_tests

NAMES = ("R", "L", "Kt", "J", "D")
SPREAD = 0.05  # manufacturing tolerance: each parameter uniform within +-5 %
SIGMA = SPREAD / np.sqrt(3.0)  # its standard deviation


def _unit(rng: np.random.Generator, base: ActuatorRig, **factor: float) -> ActuatorRig:
    f = {k: (1.0 + rng.uniform(-SPREAD, SPREAD)) * factor.get(k, 1.0) for k in NAMES}
    return dataclasses.replace(base, **{k: getattr(base, k) * f[k] for k in NAMES})


def _records(rig: ActuatorRig, seeds: range, label: str) -> list:  # type: ignore[type-arg]
    out = []
    for s in seeds:
        rec = simulate_actuator(rig, seed=s)
        rec.attrs["source"] = f"{label}-{s}"
        out.append(rec)
    return out


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[HistoryStore, dict[str, ActuatorRig]]]:
    """20 units, 3 healthy tests each, in group 'line-A'."""
    rng = np.random.default_rng(7)
    base = load_actuator_rig()
    rigs = {f"EMA-{i:02d}": _unit(rng, base) for i in range(20)}
    store = open_store(str(tmp_path_factory.mktemp("groups") / "g.db"))
    for j, (unit, rig) in enumerate(rigs.items()):
        add_baseline_tests(store, unit, _records(rig, range(1000 + 10 * j, 1003 + 10 * j), unit),
                           group="line-A")
    yield store, rigs
    store.close()


def test_healthy_units_against_the_group_raise_few_false_flags(
        fleet: tuple[HistoryStore, dict[str, ActuatorRig]]) -> None:
    store, rigs = fleet
    statuses = []
    for j, (unit, rig) in enumerate(rigs.items()):
        for rec in _records(rig, range(5000 + 10 * j, 5002 + 10 * j), unit):
            res = check_test(store, unit, rec, dry_run=True, against="line-A")
            assert res.against == "group line-A"
            statuses.append(res.status)
    assert statuses.count("go") / len(statuses) >= 0.98, statuses


def test_a_new_unit_is_judged_against_its_group(
        fleet: tuple[HistoryStore, dict[str, ActuatorRig]]) -> None:
    store, _ = fleet
    rng = np.random.default_rng(99)
    worn = _unit(rng, load_actuator_rig(), R=1.2)
    flagged = 0
    for rec in _records(worn, range(9000, 9003), "R20"):
        res = check_test(store, "EMA-R20", rec, dry_run=True, group="line-A")
        assert res.against == "group line-A"
        flagged += res.status in ("advisory", "no-go")
        assert res.diagnosis is not None
        assert res.diagnosis.faults[0].name == "winding resistance increase"
    assert flagged == 3
    healthy = _unit(rng, load_actuator_rig())
    res = check_test(store, "EMA-NEW", _records(healthy, range(9100, 9101), "new")[0],
                     dry_run=True, group="line-A")
    assert res.status == "go"


def test_units_flags_a_unit_unlike_its_peers(
        fleet: tuple[HistoryStore, dict[str, ActuatorRig]], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    store, _ = fleet
    rng = np.random.default_rng(98)
    odd = _unit(rng, load_actuator_rig())
    odd = dataclasses.replace(odd, R=load_actuator_rig().R * (1.0 + 4.0 * SIGMA))
    add_baseline_tests(store, "EMA-ODD", _records(odd, range(9200, 9203), "odd"), group="line-A")
    rows = {r["unit"]: r for r in store.unit_summaries()}
    assert [f["parameter"] for f in rows["EMA-ODD"]["group_flags"]] == ["R"]
    assert not any(rows[u]["group_flags"] for u in rows if u != "EMA-ODD")
    assert rows["EMA-ODD"]["group"] == "line-A"
    assert main(["units", "--db", str(store.url)]) == 0
    assert "EMA-ODD is unlike its group 'line-A': R +" in capsys.readouterr().err


def test_the_group_stores_what_a_check_was_compared_with(
        fleet: tuple[HistoryStore, dict[str, ActuatorRig]]) -> None:
    store, rigs = fleet
    # the peers' baseline tests (an earlier test of the module may have added a peer)
    peers = [u for u in store.units() if store.unit_group(u) == "line-A"]
    expected = sorted(i for u in peers for i in store.latest_baseline(u).test_ids)
    assert len(peers) >= 20 and len(expected) == 3 * len(peers)
    rig = rigs["EMA-03"]
    res = check_test(store, "EMA-NEW2", _records(rig, range(9300, 9301), "n2")[0],
                     group="line-A")
    assert res.test_id > 0 and store.unit_group("EMA-NEW2") == "line-A"
    kept = [b for b in store.baselines("EMA-NEW2") if b.name == "group:line-A"]
    assert len(kept) == 1 and sorted(kept[0].test_ids) == expected   # every peer's tests
    assert store.latest_baseline("EMA-NEW2") is None  # not its own baseline


def test_a_group_without_baselines_is_refused(tmp_path: Path, record_files: object,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    files = record_files(tmp_path, [1])  # type: ignore[operator]
    db = str(tmp_path / "h.db")
    with open_store(db) as store:
        store.set_group("EMA-1", "empty")
    assert main(["check", files[0], "--unit", "EMA-2", "--db", db, "--group", "empty"]) == 2
    err = capsys.readouterr().err
    assert "group 'empty' has no unit of model 'dc-motor' with a baseline" in err
    assert main(["check", files[0], "--unit", "EMA-2", "--db", db, "--against", "nobody"]) == 2
    assert "no such unit or group" in capsys.readouterr().err
    with open_store(db) as store:
        assert store.units() == ["EMA-1"]  # nothing stored


def test_random_effects_keep_within_and_between_apart() -> None:
    rng = np.random.default_rng(0)
    levels = 1.0 + 0.05 * rng.standard_normal(30)
    base = {f"U{i}": Baseline(("R",), (float(m + 0.01 * rng.standard_normal()),),
                              (0.01,), 5) for i, m in enumerate(levels)}
    g = group_baseline("g", base)
    assert g.between[0] == pytest.approx(0.05, rel=0.3)
    assert g.within[0] == pytest.approx(0.01)
    assert g.predictive().std[0] == pytest.approx(np.hypot(g.between[0], 0.01), rel=0.05)
    with pytest.raises(DataError, match="needs at least 3"):
        group_baseline("g", dict(list(base.items())[:2]))
    odd = Baseline(("R",), (1.0 + 5 * 0.05,), (0.01,), 5)
    assert unlike_group("odd", odd, base, 3.0)[0]["z"] > 3.0
    assert unlike_group("U0", base["U0"], base, 5.0) == []


def test_units_json_has_group_and_regime(fleet: tuple[HistoryStore, dict[str, ActuatorRig]],
                                         capsys: pytest.CaptureFixture[str]) -> None:
    store, _ = fleet
    assert main(["units", "--db", str(store.url), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    row = next(u for u in doc["units"] if u["unit"] == "EMA-00")
    assert row["group"] == "line-A" and row["latest_regime"] is None
    assert row["group_flags"] == []
