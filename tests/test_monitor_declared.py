"""The monitoring flow on a declared model other than the DC motor (the EMPS
axis, its own breakpoints and rules), and the store's migration of model constants."""

from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path

import pytest

from condmon.cli.main import main
from condmon.store import open_store

from test_greybox import EMPS_TOML, _emps_axis

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def axis_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    tmp = tmp_path_factory.mktemp("axis")
    files = {}
    cases = {f"h{s}": {"seed": s} for s in range(3)}
    cases |= {"healthy": {"seed": 10}, "coulomb x2": {"seed": 11, "Fc": 40.0},
              "viscous x2": {"seed": 12, "Fv": 400.0}}
    for name, kw in cases.items():
        p = tmp / f"{name.replace(' ', '-')}.csv"
        _emps_axis(duration=10.0, **kw).to_csv(p, index=False)
        files[name] = str(p)
    return files


@pytest.mark.tables
def test_monitoring_flow_on_a_declared_axis(axis_files: dict[str, str], tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    db = str(tmp_path / "axis.db")
    healthy = [axis_files[f"h{s}"] for s in range(3)]
    assert main(["baseline", "add", *healthy, "--unit", "AX-1", "--db", db,
                 "--model", str(EMPS_TOML)]) == 0
    assert "baseline of 'AX-1' from 3 accepted healthy tests" in capsys.readouterr().out
    # later commands find the unit's model by themselves
    statuses = {}
    for name in ("healthy", "coulomb x2", "viscous x2"):
        assert main(["check", axis_files[name], "--unit", "AX-1", "--db", db, "--json"]) == 0
        doc = json.loads(capsys.readouterr().out)
        statuses[name] = (doc["status"], [f["name"] for f in doc["faults"]])
    assert statuses["healthy"] == ("go", [])
    assert statuses["coulomb x2"] == ("no-go", ["friction increase"])
    assert statuses["viscous x2"] == ("no-go", ["friction increase"])
    assert main(["history", "--unit", "AX-1", "--db", db]) == 0
    out = capsys.readouterr().out
    assert "Fc" in out and "offset" in out and "no-go: friction increase" in out
    assert main(["report", "--unit", "AX-1", "--db", db, "--out", str(tmp_path / "rep")]) == 0
    assert (tmp_path / "rep" / "AX-1.html").exists()
    # a record offered with another model than the unit's is refused
    assert main(["check", axis_files["healthy"], "--unit", "AX-1", "--db", db,
                 "--model", "dc-motor"]) == 2
    assert "is monitored with model" in capsys.readouterr().err
    with open_store(db) as store:
        assert store.unit_model("AX-1") == str(EMPS_TOML.resolve())


def test_a_version_1_history_is_migrated(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """A file written by condmon with schema v1 (a gamma column) is upgraded in place."""
    db = tmp_path / "history.db"
    shutil.copy(DATA / "history-v1.db", db)
    with open_store(str(db)) as store:
        assert store.schema_version == 13
        ids, table = store.accepted_estimates("EMA-v1")
        assert ids == [1, 2, 3] and list(table.columns) == ["R", "L", "Ke", "Kt", "J", "D"]
        hist = store.history("EMA-v1")
        # v2 -> v3: evaluations keyed by baseline, versions numbered, nothing excluded
        assert list(hist["status"])[:3] == ["baseline"] * 3
        assert hist["status"].iloc[3] in ("go", "advisory", "no-go")
        assert hist["R_change"].notna().iloc[3] and not hist["excluded"].any()
        assert [b.version for b in store.baselines("EMA-v1")] == [1]
        assert store.integrity_problems() == []
    con = sqlite3.connect(db)
    cols = [r[1] for r in con.execute("PRAGMA table_info(tests)")]
    constants = [json.loads(r[0]) for r in con.execute("SELECT constants FROM tests")]
    con.close()
    assert "gamma" not in cols and constants == [{"gamma": 0.95}] * 4
    assert main(["history", "--unit", "EMA-v1", "--db", str(db)]) == 0
    assert "h3.csv" in capsys.readouterr().out


def test_shipped_coulomb_model_monitors_with_its_own_rules(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import dataclasses

    from condmon.workflows.demo import load_demo_config
    from condmon.simulate import load_actuator_rig, simulate_actuator

    rig = dataclasses.replace(load_actuator_rig(), **load_demo_config().get("rig", {}))
    files = []
    for s in range(3):
        p = tmp_path / f"h{s}.csv"
        simulate_actuator(rig, seed=s).to_csv(p, index=False)
        files.append(str(p))
    worn = tmp_path / "worn.csv"
    simulate_actuator(rig.with_faults(["D=*7"]), seed=9).to_csv(worn, index=False)
    db = str(tmp_path / "c.db")
    assert main(["baseline", "add", *files, "--unit", "C1", "--db", db,
                 "--model", "dc-motor-coulomb"]) == 0
    capsys.readouterr()
    assert main(["check", str(worn), "--unit", "C1", "--db", db, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["status"] == "no-go" and [f["name"] for f in doc["faults"]] == ["friction increase"]
    assert set(doc["parameters"]) == {"R", "L", "Ke", "Kt", "J", "D", "Tc"}


def test_plant_models_come_from_the_one_registry(tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    from condmon.models.registry import list_plant_models, load_plant_model

    assert {"dc-motor", "dc-motor-coulomb", "hst"} <= set(list_plant_models())
    assert load_plant_model("dc-motor-coulomb").state_names == ("I", "omega")
    (tmp_path / "hst").mkdir()  # a folder named like a model does not hide it
    monkeypatch.chdir(tmp_path)
    assert load_plant_model("hst").name == "hst"
