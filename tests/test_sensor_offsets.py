"""Sensor offsets declared as candidate faults (examples/hst-sensor-offsets):
a drifting sensor is isolated as such, the machine's faults as before, and a
healthy record raises nothing. (The shipped plant weighs its sensors' own
gain and offset errors: tests/test_sensor_faults.py.)"""

from __future__ import annotations

from pathlib import Path

import pytest

from condmon.diagnose.isolation import isolate
from condmon.models.declared import PlantModel
from condmon.models.registry import load_plant_model
from condmon.simulate.plant import simulate_plant

EXAMPLE = Path(__file__).parents[1] / "examples" / "hst-sensor-offsets" / "hst-sensor-offsets.toml"


@pytest.fixture(scope="module")
def model() -> PlantModel:
    return load_plant_model(EXAMPLE)


def test_each_offset_fires_only_its_own_sensor_s_residual(model: PlantModel) -> None:
    from condmon.diagnose.structure import fault_signature

    fsm = fault_signature(model)
    assert fsm.residuals == ("r_Ps", "r_omega_m")
    assert fsm.signature("bPs") == (1, 0) and fsm.signature("bw") == (0, 1)
    assert all(fsm.signature(f) == (1, 1) for f in ("Dp", "Rlkgp", "Dm", "Rlkgm", "Rv", "Tld"))


@pytest.mark.parametrize("fault,truth,value", [
    ("bPs=+1e5@10s", "bPs", 1e5),       # 1 bar: 4 times the sensor's stated accuracy
    ("bw=-1.5@10s", "bw", -1.5),
    ("Rv=+40%@10s", "Rv", 1.4 * 11.271),
])
def test_a_sensor_offset_is_named_as_such_and_a_machine_fault_as_before(
        model: PlantModel, fault: str, truth: str, value: float) -> None:
    res = isolate(simulate_plant(model, [fault], seed=4), model, workers=1)
    assert res.isolated == (truth,), res.statement
    assert res.estimates[truth].value == pytest.approx(value, rel=0.05)
    assert "but even" not in res.statement


def test_a_healthy_record_raises_nothing(model: PlantModel) -> None:
    res = isolate(simulate_plant(model, seed=6), model, workers=1)
    assert not res.detected and res.isolated == ()
