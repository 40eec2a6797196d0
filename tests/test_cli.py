"""The command line: a thin layer; clear one-line errors with exit status 2."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from condmon.cli.main import main
from condmon.simulate import ActuatorRig, simulate_actuator


def test_demo_runs(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo"]) == 0
    out = capsys.readouterr().out
    assert "R=+40%" in out and "accepted" in out


def test_simulate_then_estimate_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "r.csv"
    assert main(["simulate", "actuator", "--out", str(rec), "--fault", "R=+40%", "--seed", "2"]) == 0
    capsys.readouterr()
    assert main(["estimate", str(rec), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["parameters"]["R"] == pytest.approx(1.4, rel=0.05)
    assert doc["accepted"] is True and doc["closed_loop_instruments"] is True
    assert set(doc["fits"]) == {"I", "omega"}
    assert main(["estimate", str(rec), "--json", "--excitation", "none", "--method", "iv"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["closed_loop_instruments"] is False and doc["method"] == "iv"


def test_parquet_and_column_mapping(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "r.parquet"
    simulate_actuator(seed=1).rename(columns={"V": "volts"}).to_parquet(rec)
    assert main(["estimate", str(rec), "--columns", "V=volts"]) == 0
    assert "accepted" in capsys.readouterr().out


def test_rejected_fit_exits_zero(rig: ActuatorRig, tmp_path: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    noisy = dataclasses.replace(rig, noise_I=2.0, noise_omega=10.0)
    rec = tmp_path / "bad.csv"
    simulate_actuator(noisy, seed=0).to_csv(rec, index=False)
    assert main(["estimate", str(rec), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["accepted"] is False and doc["fit_percent"] < 90


@pytest.mark.parametrize("args,message", [
    (["estimate", "missing.csv"], "missing.csv: file not found"),
    (["estimate", "{rec}", "--method", "oe"], "unknown --method 'oe'; allowed: sriv, iv, arx"),
    (["estimate", "{rec}", "--columns", "V=watts"], "column mapping names ['watts'] not in the file"),
    (["estimate", "{rec}", "--excitation", "xx"], "missing column(s) 'xx'"),
    (["simulate", "actuator", "--out", "{tmp}/x.csv", "--fault", "R+4"], "cannot read fault 'R+4'"),
])
def test_bad_input_is_one_line_exit_2(args: list[str], message: str, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "r.csv"
    simulate_actuator(seed=0).to_csv(rec, index=False)
    argv = [a.format(rec=rec, tmp=tmp_path) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err.replace("\n", "")
    assert "Traceback" not in err and err.strip().startswith("error:")


def test_usage_error_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["estimate"]) == 2
