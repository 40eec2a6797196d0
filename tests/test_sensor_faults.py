"""A sensor that reads wrong is not named a component fault: each sensor's
gain and offset error is a candidate beside the components, held to the same
F test; the components' faults are isolated as before."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from condmon.diagnose.isolation import isolate
from condmon.diagnose.sensor_faults import SensorFit, alike, own_sensor_faults, sensor_fits
from condmon.models.declared import PlantModel
from condmon.models.registry import load_plant_model
from condmon.simulate.plant import simulate_plant

OFFSETS = Path(__file__).parents[1] / "examples" / "hst-sensor-offsets" / "hst-sensor-offsets.toml"


@pytest.fixture(scope="module")
def hst() -> PlantModel:
    return load_plant_model("hst")


@pytest.fixture(scope="module")
def healthy(hst: PlantModel) -> pd.DataFrame:
    return simulate_plant(hst, seed=4)


def test_a_known_gain_and_offset_are_fitted_and_score_the_noise() -> None:
    rng = np.random.default_rng(1)
    t = np.linspace(0.0, 20.0, 2001)
    nominal = np.column_stack([3.0 + np.sin(t), 1.0 + 0.5 * np.cos(t)])
    noise = np.array([0.02, 0.01])
    y = nominal + noise * rng.standard_normal(nominal.shape)
    y[:, 0] *= 0.95                       # sensor a reads 5 % low
    y[:, 1] += 0.2                        # sensor b reads 0.2 high
    fits = {f.name: f for f in sensor_fits(y, nominal, noise, t >= 0, ["a", "b"])}
    assert set(fits) == {"a sensor gain", "a sensor offset", "b sensor gain", "b sensor offset"}
    # one error at a time: each fit explains its own sensor and leaves the other's
    assert fits["a sensor gain"].value == pytest.approx(-0.05, abs=0.002)
    assert fits["b sensor offset"].value == pytest.approx(0.2, abs=0.002)
    assert fits["a sensor gain"].error > 10 and fits["b sensor offset"].error > 5
    both = y.copy()
    both[:, 1] -= 0.2
    fit = {f.name: f for f in sensor_fits(both, nominal, noise, t >= 0, ["a", "b"])}
    assert fit["a sensor gain"].error == pytest.approx(1.0, abs=0.05)
    # a sensor the model holds at zero has no gain to fit, only an offset
    flat = sensor_fits(y, np.zeros_like(nominal), noise, t >= 0, ["a", "b"])
    assert [f.kind for f in flat] == ["offset", "offset"]


def test_only_candidates_within_the_f_test_of_the_best_are_alike() -> None:
    fits = [SensorFit("w", "gain", 0.1, 1.0), SensorFit("w", "offset", 1.3, 1.2)]
    sensors, components = alike(fits, {"Dp": 1.02, "Dm": 3.0}, 9808, 0.01, 10.0)
    assert [f.name for f in sensors] == ["w sensor gain"] and components == ("Dp",)
    # no sensor error explains the record within the limit: nothing changes
    assert alike([SensorFit("w", "gain", 0.1, 11.0)], {"Dp": 12.0}, 9808, 0.01, 10.0) == ((), ())
    # a component far better than any sensor error: nothing changes
    assert alike(fits, {"Dp": 0.9}, 9808, 0.01, 10.0) == ((), ())


@pytest.mark.parametrize("column,factor,name", [
    ("omega_m", 1.10, "omega_m sensor gain"),   # a speed pickup 10 % high (Dp was named)
    ("Ps", 0.97, "Ps sensor gain"),             # a pressure gauge 3 % low (Rv was named)
])
def test_a_sensor_reading_wrong_on_a_healthy_plant_is_not_named_a_component_fault(
        hst: PlantModel, healthy: pd.DataFrame, column: str, factor: float, name: str) -> None:
    rec = healthy.copy()
    rec[column] = rec[column] * factor
    res = isolate(rec, hst, workers=1)
    assert res.detected and res.decided
    assert res.isolated == ()
    assert res.sensor_faults[0].name == name
    assert res.sensor_faults[0].value == pytest.approx(factor - 1.0, abs=0.003)
    assert res.statement.startswith("no component fault: the " + column)
    doc = json.loads(json.dumps(res.to_dict()))
    assert doc["isolated"] == [] and doc["sensor_faults"][0]["sensor"] == column
    assert doc["sensor_faults"][0]["unit"] == "-" and not doc["ambiguous"]


def test_a_drifting_zero_is_named_as_the_sensor_s_offset(hst: PlantModel) -> None:
    """The offsets example's plant with its pressure sensor's zero 1 bar high
    from 10 s, isolated with the shipped model (no offset parameters)."""
    rec = simulate_plant(load_plant_model(OFFSETS), ["bPs=+1e5@10s"], seed=3)
    res = isolate(rec, hst, workers=1)
    assert "Ps sensor offset" in [f.name for f in res.sensor_faults]
    assert res.sensor_faults[0].value == pytest.approx(1e5, rel=0.1)
    assert res.sensor_faults[0].unit == "Pa" and "1e+05 Pa high" in res.statement
    assert len(res.isolated) != 1      # no component named alone


def test_two_faults_that_no_candidate_explains_name_nothing(hst: PlantModel) -> None:
    """Two machine faults at once: the best candidate (a pressure gain) still
    misses by several noise sd, so neither it nor a component is named."""
    res = isolate(simulate_plant(hst, ["Rv=+20%@10s", "Dm=-5%@10s"], seed=4), hst, workers=1)
    assert res.detected and not res.decided and res.isolated == ()
    assert "not isolated: no candidate explains the record: the best" in res.statement
    assert res.to_dict()["ambiguous"] is False
    assert "none of the candidates, several, or a sensor's" in res.statement


def test_component_faults_are_isolated_as_before(hst: PlantModel) -> None:
    for fault, truth in (("Dm=-25%@10s", "Dm"), ("Rv=+40%@10s", "Rv")):
        res = isolate(simulate_plant(hst, [fault], seed=4), hst, workers=1)
        assert res.isolated == (truth,) and res.sensor_faults == ()
        assert res.statement == f"fault isolated: {truth}"


def test_a_declaration_that_models_a_sensor_s_error_keeps_its_own_candidate() -> None:
    """The offsets example adds ``bPs`` and ``bw`` to its sensors' readings:
    their offsets are its own candidates, and only their gains are weighed
    beside them."""
    offsets = load_plant_model(OFFSETS)
    assert own_sensor_faults(offsets) == {("Ps", "offset"), ("omega_m", "offset")}
    rec = simulate_plant(offsets, ["bPs=+1e5@10s"], seed=3)
    res = isolate(rec, offsets, workers=1)
    assert res.isolated == ("bPs",) and res.sensor_faults == ()
    gained = simulate_plant(offsets, seed=1)
    gained["Ps"] *= 1.05                     # a gain the declaration does not model
    res = isolate(gained, offsets, workers=1)
    assert res.isolated == () and res.sensor_faults[0].name == "Ps sensor gain"


def test_structured_residuals_say_they_weigh_no_sensor_error(hst: PlantModel) -> None:
    res = isolate(simulate_plant(hst, ["Tld=+20@10s"], seed=4), hst, kind="structured",
                  workers=1)
    assert res.isolated == ("Tld",) and res.sensor_faults == ()
    assert any("simulation residuals only" in n for n in res.notes)
