"""The actuator test-bed: faults, exactness of the linear path, nonlinear effects."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from condmon.errors import ConfigError
from condmon.models import DCMotorParameters, dc_motor_tf, tf_c2d
from condmon.simulate import ActuatorRig, load_actuator_rig, parse_fault, simulate_actuator


@pytest.mark.parametrize("spec,kind,amount", [
    ("R=+40%", "relative", 0.40), ("R=-10%", "relative", -0.10), ("D=*7", "factor", 7.0),
    ("L=+0.25mH", "increment", 0.25e-3), ("R=1.4", "value", 1.4), ("J=+2e-5", "increment", 2e-5),
])
def test_parse_fault(spec: str, kind: str, amount: float) -> None:
    f = parse_fault(spec)
    assert f.kind == kind and f.amount == pytest.approx(amount)


def test_parse_fault_with_step_time() -> None:
    assert parse_fault("Rv=+40%@10s").at == 10.0


@pytest.mark.parametrize("spec", ["R+40%", "R=40%", "=3", "R=*7mH"])
def test_bad_fault_is_explained(spec: str) -> None:
    with pytest.raises(ConfigError):
        parse_fault(spec)


def test_faults_on_the_rig(rig: ActuatorRig) -> None:
    f = rig.with_faults(["R=+40%", "L=+0.25mH", "D=*7", "Kt=-10%"])
    assert f.R == pytest.approx(1.4) and f.L == pytest.approx(1.45e-3)
    assert f.D == pytest.approx(7e-4) and f.Ke == pytest.approx(0.95 * 0.045)
    with pytest.raises(ConfigError, match="unknown actuator parameter 'Q'"):
        rig.with_faults(["Q=+1%"])


def test_linear_record_satisfies_the_discrete_model_exactly(rig: ActuatorRig) -> None:
    quiet = dataclasses.replace(rig, noise_I=0.0, noise_omega=0.0)
    rec = simulate_actuator(quiet, seed=3, linear=True)
    p = DCMotorParameters(**rec.attrs["truth"])
    gd = tf_c2d(dc_motor_tf(p), 1e-3)
    y = gd.simulate(rec["V"].to_numpy())
    np.testing.assert_allclose(y[:, 0], rec["I"], atol=1e-10 * np.abs(rec["I"]).max())
    np.testing.assert_allclose(y[:, 1], rec["omega"], atol=1e-10 * np.abs(rec["omega"]).max())


def test_seed_reproducibility(rig: ActuatorRig) -> None:
    a = simulate_actuator(rig, seed=4)
    b = simulate_actuator(rig, seed=4)
    c = simulate_actuator(rig, seed=5)
    assert a.equals(b) and not a.equals(c)


def test_coulomb_friction_slows_the_motor(rig: ActuatorRig) -> None:
    base = simulate_actuator(rig, seed=1)
    braked = simulate_actuator(dataclasses.replace(rig, coulomb_friction=0.02), seed=1)
    assert braked["omega"].std() < 0.9 * base["omega"].std()


def test_voltage_saturation_and_quantisation(rig: ActuatorRig) -> None:
    r = dataclasses.replace(rig, v_max=2.0, current_quantisation=0.05)
    rec = simulate_actuator(r, seed=1)
    assert rec["V"].abs().max() == pytest.approx(2.0)
    q = rec["I"].to_numpy() / 0.05
    np.testing.assert_allclose(q, np.round(q), atol=1e-9)
    lin = simulate_actuator(r, seed=1, linear=True)
    assert lin["V"].abs().max() > 2.0


def test_params_file_overrides_defaults(tmp_path: Path) -> None:
    p = tmp_path / "rig.toml"
    p.write_text("[motor]\nR = 2.0\n")
    assert load_actuator_rig(p).R == 2.0
    p.write_text("[motor]\nRR = 2.0\n")
    with pytest.raises(ConfigError, match="unknown key 'RR'"):
        load_actuator_rig(p)


def test_unstable_gains_are_reported(rig: ActuatorRig) -> None:
    with pytest.raises(ConfigError, match="diverged"):
        simulate_actuator(dataclasses.replace(rig, k_current=5.0, saturation=False), seed=0)


def test_band_limited_noise_has_its_bandwidth() -> None:
    from condmon.simulate import band_limited_noise

    x = band_limited_noise(20000, 2.0, 50.0, 1000.0, np.random.default_rng(0))
    assert np.std(x) == pytest.approx(2.0)
    spec = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(x.size, 1e-3)
    assert spec[f > 200].sum() < 1e-3 * spec.sum()
