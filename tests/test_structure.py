"""Fault signature matrices derived from the declared equations."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from condmon.diagnose.structure import fault_signature, residual_generators, suspects
from condmon.models.registry import load_plant_model

SIX = ("Dp", "Rlkgp", "Dm", "Rlkgm", "Rv", "Tld")


@pytest.fixture(scope="module")
def three_sensor_hst(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shipped declaration with one more line: a motor-pressure sensor."""
    text = (resources.files("condmon") / "data" / "hst.toml").read_text()
    line = 'Pm = { measures = "Pm", unit = "Pa", noise = 2.5e4, range = [0.0, 1.0e7] }\n'
    text = text.replace("[sensors]\n", "[sensors]\n" + line)
    path = tmp_path_factory.mktemp("m") / "hst3.toml"
    path.write_text(text)
    return path


def test_two_sensor_hst_fsm_is_all_ones_monitorable_not_isolable() -> None:
    fsm = fault_signature(load_plant_model("hst"))
    assert fsm.residuals == ("r_Ps", "r_omega_m")
    assert fsm.faults == SIX
    for f in SIX:
        assert fsm.signature(f) == (1, 1) and fsm.mb[f] == 1 and fsm.ib[f] == 0
    assert not fsm.isolable[~np.eye(6, dtype=bool)].any()


def test_simulation_residuals_integrate_the_whole_model() -> None:
    gens = residual_generators(load_plant_model("hst"))
    assert [g.sensor for g in gens] == ["Ps", "omega_m"]
    assert all(g.integrated == ("Ps", "Pm", "omega_m") and g.inputs == () for g in gens)


def test_a_third_sensor_changes_fsm_and_isolability_without_code(three_sensor_hst: Path) -> None:
    two = load_plant_model("hst")
    three = load_plant_model(three_sensor_hst)
    sim3 = fault_signature(three)
    assert sim3.residuals == ("r_Pm", "r_Ps", "r_omega_m")   # a residual per sensor
    st2, st3 = fault_signature(two, "structured"), fault_signature(three, "structured")
    assert len(st3.residuals) > len(st2.residuals)
    # isolability only grows, and strictly: Dm becomes isolable from every other fault
    assert (st3.isolable >= st2.isolable).all() and (st3.isolable > st2.isolable).any()
    assert st2.ib["Dm"] == 0 and st3.ib["Dm"] == 1
    # what stays structurally together: a pump displacement or leak, a load or friction
    for a, b in (("Dp", "Rlkgp"), ("Rv", "Tld")):
        i, j = SIX.index(a), SIX.index(b)
        assert not st3.isolable[i, j] and not st3.isolable[j, i]
    # a local residual: the motor-speed equation with measured Pm sees only Dm, Rv, Tld
    local = next(g for g in residual_generators(three, "structured") if g.name == "r_omega_m|Pm")
    assert local.integrated == ("omega_m",) and set(local.faults) == {"Dm", "Rv", "Tld"}
    assert st3.model_isolable.sum() > st2.model_isolable.sum()


def test_suspects_under_single_fault_hypothesis(three_sensor_hst: Path) -> None:
    fsm2 = fault_signature(load_plant_model("hst"))
    assert suspects(fsm2, ["r_Ps"]) == SIX
    assert suspects(fsm2, []) == ()
    st3 = fault_signature(load_plant_model(three_sensor_hst), "structured")
    assert suspects(st3, ["r_Ps|Pm"]) == ("Dp", "Rlkgp")
    assert suspects(st3, ["r_omega_m|Pm", "r_Pm|Ps,omega_m"]) == ("Dm",)
