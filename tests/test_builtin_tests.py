"""Every shipped and example declaration's built-in test is a record its own
estimate (or, for a model with no [estimation], its isolation) can read: the
parameters come back at their declared values and a healthy test raises no
fault."""

from __future__ import annotations

import json
import tomllib
import warnings
from pathlib import Path

import pandas as pd
import pytest

from condmon.cli.main import main
from condmon.errors import DataWarning
from condmon.models.registry import list_models

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _declarations() -> list[str]:
    """Shipped model names, and every example file that declares a plant."""
    files = [str(p) for p in sorted(EXAMPLES.rglob("*.toml"))
             if "states" in tomllib.loads(p.read_text())]
    return [*list_models(), *files]


def _declared(model: str) -> dict[str, float]:
    from condmon.models.registry import load_plant_model

    return load_plant_model(model).parameter_values()


def test_every_example_declaration_is_found() -> None:
    names = {Path(d).name for d in _declarations()}
    assert {"template.toml", "emps.toml", "rotary-actuator.toml"} <= names
    assert {"dc-motor", "dc-motor-coulomb", "hst"} <= names


def _cases() -> list[object]:
    """The declarations, the ones whose estimate is a long study (the cascaded
    tanks' 4,096 s record fitted by simulation error: about a minute) marked slow."""
    return [pytest.param(m, marks=pytest.mark.slow) if Path(m).stem == "cascaded-tanks" else m
            for m in _declarations()]


@pytest.mark.parametrize("model", _cases(), ids=lambda m: Path(str(m)).stem)
def test_builtin_test_is_estimable_by_its_own_model(
        model: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "builtin.csv"
    assert main(["simulate", "plant", model, "--out", str(rec), "--seed", "4"]) == 0
    capsys.readouterr()
    truth = _declared(model)
    from condmon.models.registry import get_model

    machine = get_model(model)
    if not machine.spec.unknowns:
        # a model monitored by isolation: a healthy built-in test shows no fault
        assert main(["estimate", str(rec), "--model", model]) == 2
        assert "condmon isolate" in capsys.readouterr().err
        assert main(["isolate", model, str(rec), "--json", "--workers", "1"]) == 0
        doc = json.loads(capsys.readouterr().out)
        assert doc["decided"] and not doc["detected"], doc["reason"]
        return
    with warnings.catch_warnings():
        # a rig's own columns that its [record] ignores are not simulated: said, not an error
        warnings.filterwarnings("ignore", ".*the record settings ignore column", DataWarning)
        code = main(["estimate", str(rec), "--model", model, "--json"])
    assert code == 0, capsys.readouterr().err
    doc = json.loads(capsys.readouterr().out)
    assert doc["accepted"], doc["reason"]
    assert doc["fit_percent"] > 95.0
    estimated = [k for k in doc["identifiable"] if doc["identifiable"][k] is True]
    assert estimated, doc["identifiable"]
    for name in estimated:
        if name not in truth:
            continue  # a derived quantity (Ke) is checked through its parameters
        value, se = doc["parameters"][name], doc["std_errors"][name]
        # within 4 standard errors of the declared value, or within 3 % of it
        # (the simulator smooths Coulomb friction slightly, so a tiny standard
        # error does not bound that bias)
        assert abs(value - truth[name]) < max(4.0 * se, 0.03 * abs(truth[name])), (
            name, value, se, truth[name])


def test_a_declaration_with_a_record_table_is_simulated_as_its_rig_writes(
        tmp_path: Path) -> None:
    model = str(EXAMPLES / "hydraulic-actuator" / "rotary-actuator.toml")
    raw, si = tmp_path / "raw.csv", tmp_path / "si.csv"
    assert main(["simulate", "plant", model, "--out", str(raw)]) == 0
    assert main(["simulate", "plant", model, "--out", str(si), "--si"]) == 0
    r, s = pd.read_csv(raw), pd.read_csv(si)
    assert list(r.columns) == ["Time", "Angle", "PG_1", "PG_2"]
    assert list(s.columns) == ["t", "theta", "pA", "pB"]
    assert r["Time"].iloc[:3].tolist() == [1, 2, 3]
    # counts: 3,000 psi full scale over 16383 counts; the balance pressure is ~386 counts
    assert r["PG_1"].max() == pytest.approx(9.0e5 / 1262.54)
    assert (r["Angle"] * 3.8349519697141e-4).to_numpy() == pytest.approx(s["theta"].to_numpy())


def test_a_record_whose_inputs_never_move_is_refused_naming_them(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = str(EXAMPLES / "emps" / "emps.toml")
    rec = tmp_path / "still.csv"
    assert main(["simulate", "plant", model, "--out", str(rec), "--duration", "6"]) == 0
    df = pd.read_csv(rec)
    df["vir"] = 0.0
    df.to_csv(rec, index=False)
    capsys.readouterr()
    assert main(["estimate", str(rec), "--model", model]) == 2
    err = capsys.readouterr().err
    assert "column 'vir' is constant: no excitation" in err and "overflow" not in err


@pytest.mark.parametrize("entry,message", [
    ('{ input = "u", signal = "chirp", amplitude = 1.0, period = 1.0 }',
     "'chirp' is not a signal; allowed: prbs, square, sine"),
    ('{ input = "w", signal = "prbs", amplitude = 1.0, hold = 0.05 }',
     "unknown input 'w'; allowed: u"),
    ('{ input = "u", signal = "prbs", amplitude = 1.0, hold = 1e-12 }',
     "hold: 1e-12 s is shorter than one sample (0.001 s at 1000 Hz)"),
    ('{ input = "u", signal = "sine", amplitude = 1.0, hold = 0.1 }',
     "unknown key 'hold'; a sine excitation takes amplitude, input, period, signal"),
    ('{ input = "u", signal = "square", amplitude = 1.0, period = -2 }',
     "period must be > 0 [s], not -2"),
])
def test_a_bad_excitation_is_refused_naming_the_entry(
        entry: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = (EXAMPLES / "template.toml").read_text()
    start = text.index("excitation = [")
    end = text.index("\n", start)
    decl = tmp_path / "m.toml"
    decl.write_text(text[:start] + f"excitation = [{entry}]" + text[end:])
    assert main(["simulate", "plant", str(decl), "--out", str(tmp_path / "r.csv")]) == 2
    err = capsys.readouterr().err
    assert "m.toml[test].excitation[0]" in err and message in " ".join(err.split()), err
