"""Declared plant models: loading, validation, simulation against known truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import optimize, signal

from condmon.errors import ConfigError
from condmon.models.registry import load_plant_model
from condmon.simulate.plant import integrate, parameter_steps, simulate_plant, time_grid

HST_TABLE = {"wp": 152.0, "Dp": 4.45e-6, "Rlkgp": 1e13, "Kp": 5e10, "Dm": 4.45e-5,
             "Rlkgm": 1e11, "Km": 5e10, "Cd": 1.0, "rho": 900.0, "J": 6.18, "Rv": 11.271}

DC_MOTOR = """
name = "dc-motor"
[parameters]
R  = { value = 1.0,    unit = "ohm" }
L  = { value = 1.2e-3, unit = "H" }
Ke = { value = 0.0475, unit = "V s/rad" }
Kt = { value = 0.05,   unit = "N m/A" }
J  = { value = 5e-5,   unit = "kg m^2" }
D  = { value = 1e-4,   unit = "N m s/rad", fault = true }
[inputs]
V = { nominal = 0.0, unit = "V" }
[states]
i     = { derivative = "(V - R*i - Ke*omega)/L", unit = "A" }
omega = { derivative = "(Kt*i - D*omega)/J", unit = "rad/s" }
[sensors]
I     = { measures = "i", noise = 0.01, unit = "A" }
omega = { measures = "omega", noise = 0.1, unit = "rad/s" }
[test]
duration = 0.2
sample_rate = 1000.0
schedule = [{ input = "V", at = 0.0, value = 12.0 }]
"""


def test_shipped_hst_has_the_reference_parameters() -> None:
    m = load_plant_model("hst")
    values = m.parameter_values()
    for name, value in HST_TABLE.items():
        assert values[name] == value, name
    assert m.fault_candidates == ("Dp", "Rlkgp", "Dm", "Rlkgm", "Rv", "Tld")
    assert m.sensor_names == ("Ps", "omega_m")


def test_steady_state_matches_the_algebraic_solution() -> None:
    """The simulator settles where the derivatives are zero: ~39 bar, ~14 rad/s."""
    m = load_plant_model("hst")
    t = time_grid(m)
    from condmon.simulate.plant import input_signals

    u = input_signals(m, t)
    x = integrate(m.compile(), t, u)
    k = int(np.searchsorted(t, 19.99))
    root = optimize.fsolve(lambda z: m.compile().rhs(z * [1e6, 1e6, 1.0], u[k],
                                                     m.compile().parameter_vector())
                           / [1e6, 1e6, 1.0], x[k] / [1e6, 1e6, 1.0], xtol=1e-13)
    steady = root * [1e6, 1e6, 1.0]
    np.testing.assert_allclose(x[k], steady, rtol=2e-4)
    assert 38e5 < steady[0] < 41e5 and 13.5 < steady[2] < 15.0


def test_dc_motor_declared_as_data_matches_its_transfer_function(tmp_path: Path) -> None:
    """The actuator's model is expressible in the same declaration style."""
    path = tmp_path / "dc.toml"
    path.write_text(DC_MOTOR)
    m = load_plant_model(path)
    rec = simulate_plant(m, noise=False)
    R, L, Ke, Kt, J, D = 1.0, 1.2e-3, 0.0475, 0.05, 5e-5, 1e-4
    den = [L * J, L * D + R * J, R * D + Ke * Kt]
    t = rec["t"].to_numpy()
    _, w = signal.step(([Kt], den), T=t)
    _, i = signal.step(([J, D], den), T=t)
    np.testing.assert_allclose(rec["omega"], 12 * w, rtol=1e-4, atol=1e-4 * 12 * w.max())
    np.testing.assert_allclose(rec["I"], 12 * i, rtol=1e-4, atol=1e-4 * 12 * i.max())


def test_fault_steps_at_the_given_time() -> None:
    m = load_plant_model("hst")
    (step,) = parameter_steps(m, ["Rv=+40%@10s"])
    assert step.at == 10.0 and step.value == pytest.approx(11.271 * 1.4)
    healthy = simulate_plant(m, noise=False)
    faulty = simulate_plant(m, ["Rv=+40%@10s"], noise=False)
    before = healthy["t"] < 10.0
    np.testing.assert_allclose(healthy.loc[before, "Ps"], faulty.loc[before, "Ps"], rtol=1e-7)
    assert faulty["Ps"].iloc[1900] > 1.3 * healthy["Ps"].iloc[1900]


def test_noise_has_the_declared_spread() -> None:
    m = load_plant_model("hst")
    clean = simulate_plant(m, noise=False)
    noisy = simulate_plant(m, seed=3)
    assert np.std(noisy["Ps"] - clean["Ps"]) == pytest.approx(2.5e4, rel=0.05)
    assert np.std(noisy["omega_m"] - clean["omega_m"]) == pytest.approx(0.05236, rel=0.05)


def test_parameter_file_overrides_values(tmp_path: Path) -> None:
    p = tmp_path / "p.toml"
    p.write_text("[parameters]\nRv = 12.5\nTld = 3\n")
    m = load_plant_model("hst", p)
    assert m.parameter("Rv").value == 12.5 and m.parameter("Tld").value == 3.0
    p.write_text("Rvv = 1.0\n")
    with pytest.raises(ConfigError, match=r"p\.toml.*'Rvv'.*allowed: wp, Dp"):
        load_plant_model("hst", p)
    p.write_text('Rv = "high"\n')
    with pytest.raises(ConfigError, match="'Rv' must be a number"):
        load_plant_model("hst", p)


@pytest.mark.parametrize("edit,match", [
    (("Kp*(Dp*omega_p - Q - Ps/Rlkgp)", "Kp*(Dp*omega_p - Qx)"), r"states\.Ps.*unknown name 'Qx'"),
    (("Kp*(Dp*omega_p - Q - Ps/Rlkgp)", "__import__('os').getcwd()"), "unknown function|cannot use"),
    (("Kp*(Dp*omega_p - Q - Ps/Rlkgp)", "Kp*(Dp*omega_p"), "cannot read equation"),
    (("noise = 2.5e4", "noise = 0.0"), r"sensors\.Ps\]\.noise must be > 0"),
    (('input = "omega_p"', 'input = "speed"'), "unknown input 'speed'"),
])
def test_bad_declarations_are_refused_with_the_place(tmp_path: Path, edit: tuple[str, str],
                                                      match: str) -> None:
    from importlib import resources

    text = (resources.files("condmon") / "data" / "hst.toml").read_text()
    assert edit[0] in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(ConfigError, match=match):
        load_plant_model(path)


def test_unknown_fault_parameter_is_refused() -> None:
    with pytest.raises(ConfigError, match="no parameter 'Rx'; allowed: wp, Dp"):
        parameter_steps(load_plant_model("hst"), ["Rx=+10%@5s"])


def test_unknown_model_name() -> None:
    with pytest.raises(ConfigError, match="unknown model 'hsx'.*hst"):
        load_plant_model("hsx")
