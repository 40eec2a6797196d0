"""Hints a user acts on: a record of another model is recognised as such, a
mistyped unit gets the close names, and a hint never names an option the
command does not have."""

from __future__ import annotations

import re
import shutil
import warnings
from pathlib import Path

import pytest

from condmon.cli.main import main
from condmon.errors import DataWarning
from condmon.models.registry import recognise_record
from condmon.store import open_store

ROTARY = str(Path(__file__).resolve().parents[1] / "examples" / "hydraulic-actuator"
             / "rotary-actuator.toml")


@pytest.fixture(scope="module")
def records(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Simulated records of three models, and a history with a unit of two of them."""
    root = tmp_path_factory.mktemp("hints")
    out = {}
    for s in (1, 2, 3):
        out[f"dc{s}"] = root / f"dc{s}.csv"
        assert main(["simulate", "actuator", "--out", str(out[f"dc{s}"]), "--seed", str(s)]) == 0
        out[f"ra{s}"] = root / f"ra{s}.csv"
        assert main(["simulate", "plant", ROTARY, "--out", str(out[f"ra{s}"]),
                     "--seed", str(s)]) == 0
    out["hst"] = root / "hst.csv"
    assert main(["simulate", "hst", "--out", str(out["hst"]), "--duration", "8"]) == 0
    out["db"] = root / "h.db"
    db = str(out["db"])
    assert main(["baseline", "add", *(str(out[f"dc{s}"]) for s in (1, 2, 3)),
                 "--unit", "EMA-1", "--db", db]) == 0
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", ".*the record settings ignore column", DataWarning)
        assert main(["baseline", "add", *(str(out[f"ra{s}"]) for s in (1, 2, 3)),
                     "--unit", "ACT-1", "--model", ROTARY, "--db", db]) == 0
    return out


def _tests_of(db: Path) -> dict[str, int]:
    with open_store(str(db)) as store:
        return {u: len(store.history(u)) for u in store.units()}


@pytest.mark.parametrize("record,unit,looks_like,missing", [
    ("hst", "EMA-1", "'hst'", "V, I, omega"),
    ("dc1", "ACT-1", "'dc-motor' or 'dc-motor-coulomb'", "Time, Angle, PG_1, PG_2"),
    ("hst", "ACT-1", "'hst'", "Time, Angle, PG_1, PG_2"),
])
def test_a_record_of_another_model_is_recognised(
        records: dict[str, Path], record: str, unit: str, looks_like: str, missing: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    before = _tests_of(records["db"])
    capsys.readouterr()
    assert main(["check", str(records[record]), "--unit", unit, "--db",
                 str(records["db"])]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert f"this looks like a record of model {looks_like}" in err, err
    assert f"(missing {missing}): is the model, or the unit, the right one?" in err
    assert "mapping" not in err and "--columns" not in err
    assert _tests_of(records["db"]) == before


def test_isolate_and_estimate_recognise_a_record_of_another_model(
        records: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["isolate", "hst", str(records["dc1"])]) == 2
    assert "looks like a record of model 'dc-motor' or 'dc-motor-coulomb'" in " ".join(
        capsys.readouterr().err.split())
    assert main(["estimate", str(records["hst"]), "--model", "dc-motor-coulomb"]) == 2
    assert "looks like a record of model 'hst'" in capsys.readouterr().err


def test_recognition_needs_every_sensor_of_the_other_model() -> None:
    assert recognise_record(["t", "Ps", "omega_p"], "dc-motor") == []  # omega_m missing
    assert recognise_record(["t", "Ps", "omega_m"], "dc-motor") == ["hst"]
    assert recognise_record(["t", "Ps", "omega_m"], "hst") == []  # its own record


@pytest.mark.parametrize("unit,close", [
    ("EMA-2", "'EMA-1'"), ("ema-1", "'EMA-1'"), ("ACT_1", "'ACT-1'"), ("XYZ", None)])
def test_a_mistyped_unit_gets_the_close_names_and_no_unit_is_made(
        records: dict[str, Path], unit: str, close: str | None,
        capsys: pytest.CaptureFixture[str]) -> None:
    before = _tests_of(records["db"])
    capsys.readouterr()
    assert main(["check", str(records["dc1"]), "--unit", unit, "--db",
                 str(records["db"])]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert f"unknown unit {unit!r}" in err and "units: ACT-1, EMA-1" in err, err
    if close is None:
        assert "did you mean" not in err
    else:
        assert f"did you mean {close}?" in err
    assert "has 0 accepted healthy test" not in err
    assert _tests_of(records["db"]) == before


def _options_of(command: list[str], capsys: pytest.CaptureFixture[str]) -> set[str]:
    assert main([*command, "--help"]) == 0
    return set(re.findall(r"--[a-z][a-z-]+", capsys.readouterr().out))


@pytest.mark.parametrize("command", [
    ["estimate", "{bad}"], ["check", "{bad}", "--unit", "EMA-1", "--db", "{db}"],
    ["baseline", "add", "{bad}", "--unit", "EMA-1", "--db", "{db}"],
    ["isolate", "hst", "{bad}"], ["fleet", "run", "{inbox}", "--db", "{db}", "--workers", "1"]])
def test_a_hint_names_only_options_the_command_has(
        records: dict[str, Path], command: list[str], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("t,volts,amps\n0,1,2\n0.001,1,2\n")
    inbox = tmp_path / "inbox" / "EMA-1"
    inbox.mkdir(parents=True)
    shutil.copy(bad, inbox / "bad.csv")
    db = tmp_path / "h.db"
    shutil.copy(records["db"], db)
    paths = {"bad": bad, "db": db, "inbox": tmp_path / "inbox"}
    args = [a.format(**{k: str(v) for k, v in paths.items()}) for a in command]
    capsys.readouterr()
    main(args)
    captured = capsys.readouterr()
    said = captured.out + captured.err
    assert "missing column" in said, said
    named = set(re.findall(r"--[a-z][a-z-]+", said)) - {"--help"}
    has = _options_of(args[:2] if args[0] in ("baseline", "fleet") else args[:1], capsys)
    assert named <= has, (named - has, said)
