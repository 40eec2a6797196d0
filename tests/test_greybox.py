"""Grey-box estimation from a declaration: the linear route (symbolic transfer
functions), the inverse-model route (IDIM-LS), the registry and the structure check."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from condmon.errors import ConfigError, DataError, ModelError
from condmon.identify import estimate
from condmon.models import dc_motor_from_discrete, get_model, list_models, register_model
from condmon.simulate import ActuatorRig, simulate_actuator

ROOT = Path(__file__).parents[1]
EMPS_TOML = ROOT / "examples" / "emps" / "emps.toml"
EMPS_MAT = ROOT.parent / "shared" / "external" / "emps" / "DATA_EMPS.mat"
PUBLISHED = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}


def test_registry_lists_shipped_models_and_refuses_unknown_names() -> None:
    assert {"dc-motor", "hst"} <= set(list_models())
    with pytest.raises(ModelError, match="unknown model 'pump'.*dc-motor, dc-motor-coulomb, hst"):
        get_model("pump")
    with pytest.raises(ModelError, match="declares no \\[estimation\\]"):
        estimate(simulate_actuator(seed=0), "hst")


def test_dc_motor_declaration_gives_the_closed_form_estimates() -> None:
    """The declared (symbolic) route against the closed-form DC-motor map."""
    for seed in range(5):
        res = estimate(simulate_actuator(seed=seed))
        assert res.discrete is not None
        ref, cov = dc_motor_from_discrete(res.discrete.model, res.discrete.covariance, 0.95)
        for i, (k, v) in enumerate(ref.as_dict().items()):
            assert res.parameters[k] == pytest.approx(v, rel=1e-9), k
            assert res.std_errors[k] == pytest.approx(np.sqrt(cov[i, i]), rel=1e-7), k


def test_symbolic_transfer_functions_of_the_dc_motor() -> None:
    lin = get_model("dc-motor").linear()
    assert [str(c) for c in lin.coefficients] == [
        "D/J + R/L", "(D*R + Kt**2*gamma)/(J*L)", "1/L", "D/(J*L)", "0", "Kt/(J*L)"]
    assert lin.free == (0, 1, 2, 3, 5)  # the speed numerator's s-term is structurally 0


def _write(tmp: Path, name: str, text: str) -> Path:
    p = tmp / name
    p.write_text(text, encoding="utf-8")
    return p


def _emps_axis(M: float = 95.0, Fv: float = 200.0, Fc: float = 20.0, offset: float = -3.0,
               gtau: float = 35.15, seed: int = 0, duration: float = 20.0) -> pd.DataFrame:
    """A positioning axis under PD position control, with Coulomb friction, 1 kHz."""
    rng = np.random.default_rng(seed)
    dt, sub = 1e-3, 10
    n = int(duration / dt)
    t = np.arange(n) * dt
    # reference: smoothed random steps between +-0.2 m
    steps = np.repeat(rng.uniform(-0.2, 0.2, n // 2000 + 1), 2000)[:n]
    ref = np.convolve(steps, np.ones(300) / 300, mode="same")
    kp, kv = 160.0, 240.0
    q = v = 0.0
    qm = np.empty(n)
    vir = np.empty(n)
    h = dt / sub
    for k in range(n):
        qm[k] = q + 2e-7 * rng.standard_normal()
        u = kp * (ref[k] - qm[k]) * 1.0 - kv * v * 0.01
        vir[k] = u
        for _ in range(sub):
            acc = (gtau * u - Fv * v - Fc * np.tanh(v / 1e-4) - offset) / M
            v += h * acc
            q += h * v
    return pd.DataFrame({"t": t, "qm": qm, "vir": vir, "qg": ref})


def test_inverse_route_recovers_a_simulated_axis() -> None:
    truth = {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": -3.0}
    res = estimate(_emps_axis(**truth), EMPS_TOML)
    assert res.accepted, res.reason
    assert res.route == "inverse" and res.method == "idim-ls"
    for k, v in truth.items():
        assert res.parameters[k] == pytest.approx(v, rel=0.02 if k != "offset" else 0.05), k
        assert 0 < res.std_errors[k] < 0.05 * abs(v), k


def _viscous_text() -> str:
    """The EMPS declaration without Coulomb friction and offset (and without its
    [monitor] files, which live beside the original)."""
    text = EMPS_TOML.read_text()
    start = text.index("[monitor]")
    text = text[:start] + text[text.index("[estimation]"):]
    head, est = text[:text.index("[estimation]")], text[text.index("[estimation]"):]
    est = "\n".join(ln for ln in est.splitlines() if not ln.startswith(("Fc =", "offset =")))
    text = head + est + "\n"
    return text.replace('"(gtau*vir - Fv*qd - Fc*sign(qd) - offset)/M"',
                        '"(gtau*vir - Fv*qd)/M"').replace(
        'estimate = ["M", "Fv", "Fc", "offset"]', 'estimate = ["M", "Fv"]')


def test_viscous_only_model_is_flagged_as_a_structure_mismatch(tmp_path: Path) -> None:
    text = _viscous_text()
    text = text.replace('"(gtau*vir - Fv*qd - Fc*sign(qd) - offset)/M"', '"(gtau*vir - Fv*qd)/M"')
    text = text.replace('estimate = ["M", "Fv", "Fc", "offset"]', 'estimate = ["M", "Fv"]')
    path = _write(tmp_path, "viscous.toml", text)
    res = estimate(_emps_axis(), path)
    assert not res.accepted
    assert res.reason is not None and res.reason.startswith("structure mismatch")


@pytest.mark.skipif(not EMPS_MAT.exists(), reason="the EMPS data set is not beside the repository")
def test_emps_real_data_matches_the_published_parameters(tmp_path: Path) -> None:
    import scipy.io as sio

    d = sio.loadmat(EMPS_MAT)
    df = pd.DataFrame({k: d[k].ravel() for k in ("t", "qm", "vir", "qg")})
    df.attrs["constants"] = {"gtau": float(d["gtau"].item())}
    res = estimate(df, EMPS_TOML, source="DATA_EMPS.mat")
    assert res.accepted, res.reason
    for k in ("M", "Fv", "Fc"):
        assert res.parameters[k] == pytest.approx(PUBLISHED[k], rel=0.01), k
    assert res.parameters["offset"] == pytest.approx(PUBLISHED["offset"], rel=0.03)
    # the filtered residuals are correlated: the standard errors are widened for it, and said
    assert res.diagnostics["se_widening"] > 3.0
    assert any("Newey-West" in n for n in res.notes), res.notes
    # the same declaration, unchanged, on another record of the axis (second half)
    half = df.iloc[len(df) // 2:].reset_index(drop=True)
    half["t"] -= half["t"].iloc[0]
    half.attrs = df.attrs
    other = estimate(half, EMPS_TOML, source="second half")
    assert other.accepted
    for k in ("M", "Fv", "Fc"):
        assert other.parameters[k] == pytest.approx(PUBLISHED[k], rel=0.01), k
    # viscous-only: a structure mismatch, never accepted
    viscous = estimate(df, _write(tmp_path, "v.toml", _viscous_text()), source="DATA_EMPS.mat")
    assert not viscous.accepted and "structure mismatch" in str(viscous.reason)


_RC = """
name = "rc"
[parameters]
Rr = { value = 1000.0, unit = "ohm", fault = true }
C = { value = 1.0e-6, unit = "F", fault = true }
[inputs]
u = { nominal = 0.0, unit = "V" }
[states]
vc = { derivative = "(u - vc)/(Rr*C)", unit = "V" }
[sensors]
vm = { measures = "vc", noise = 0.01, unit = "V" }
[test]
duration = 2.0
sample_rate = 10000.0
[estimation]
estimate = ["Rr"]
sample_interval = [1.0e-6, 1.0e-2]
[estimation.plausible]
Rr = { gt = 0.0 }
"""


def test_a_users_linear_declaration_estimates_through_the_linear_route(tmp_path: Path) -> None:
    from scipy.signal import lfilter

    path = _write(tmp_path, "rc.toml", _RC)
    machine = register_model("my-rc", path)
    assert "my-rc" in list_models() and machine.linear().order == 1
    dt, tau = 1e-4, 2200.0 * 1e-6
    rng = np.random.default_rng(1)
    u = np.repeat(rng.standard_normal(2000), 10)
    a = np.exp(-dt / tau)
    vc = lfilter([0.0, 1 - a], [1.0, -a], u)
    df = pd.DataFrame({"t": np.arange(u.size) * dt, "u": u,
                       "vm": vc + 0.005 * rng.standard_normal(u.size)})
    res = estimate(df, "my-rc")
    assert res.route == "linear" and res.accepted
    assert res.parameters["Rr"] == pytest.approx(2200.0, rel=0.01)
    # a known constant overridden at the call
    res2 = estimate(df, "my-rc", constants={"C": 2e-6})
    assert res2.parameters["Rr"] == pytest.approx(1100.0, rel=0.01)


@pytest.mark.parametrize("change,match", [
    ('estimate = ["Rr"]', None),
    ('estimate = ["Rx"]', "unknown parameter 'Rx'"),
    ('estimate = "Rr"', "must be a list of names"),
    ('estimate = ["Rr"]\nroute = "magic"', "unknown route 'magic'"),
    ('estimate = ["Rr"]\nbogus = 1', "unknown key 'bogus'"),
    ('estimate = ["Rr"]\ncutoff = -5', "cutoff must be a frequency > 0"),
    ('estimate = ["Rr"]\nderived = { tau = { equation = "Rr*C*" } }', "derived.tau"),
])
def test_estimation_table_errors_name_the_entry(tmp_path: Path, change: str,
                                                match: str | None) -> None:
    path = _write(tmp_path, "rc.toml", _RC.replace('estimate = ["Rr"]', change))
    if match is None:
        assert get_model(path).spec.unknowns == ("Rr",)
        return
    with pytest.raises(ConfigError, match=match):
        get_model(path)


def test_unsuitable_routes_say_why(tmp_path: Path) -> None:
    text = _RC.replace('"(u - vc)/(Rr*C)"', '"(u - vc - 0.1*sign(vc))/(Rr*C)"').replace(
        '[estimation]', '[estimation]\nroute = "linear"')
    with pytest.raises(ModelError, match="is not linear in the states and the input"):
        estimate(pd.DataFrame({"t": np.arange(100) * 1e-3, "u": np.sin(np.arange(100)),
                               "vm": np.cos(np.arange(100))}), _write(tmp_path, "n.toml", text))
    text2 = _RC.replace('"(u - vc)/(Rr*C)"', '"(u - vc)/(Rr*Rr*C)"').replace(
        '[estimation]', '[estimation]\nroute = "inverse"')
    with pytest.raises(ModelError, match="not linear in the unknowns"):
        get_model(_write(tmp_path, "q.toml", text2)).inverse()


def test_the_template_declaration_estimates_a_simulated_record() -> None:
    from scipy.signal import cont2discrete, lfilter

    num, den, _ = cont2discrete(([10.0], [2.0, 5.0, 800.0]), 1e-3, method="zoh")
    rng = np.random.default_rng(0)
    u = np.repeat(rng.standard_normal(500), 20)
    y = lfilter(np.ravel(num), den, u)
    df = pd.DataFrame({"t": np.arange(u.size) * 1e-3, "u": u,
                       "pos": y + 1e-5 * rng.standard_normal(u.size)})
    res = estimate(df, ROOT / "examples" / "template.toml")
    assert res.accepted and res.route == "linear"
    for k, v in {"m": 2.0, "c": 5.0, "k": 800.0}.items():
        assert res.parameters[k] == pytest.approx(v, rel=0.01), k


def test_coulomb_model_by_output_error_removes_the_friction_bias(demo_rig: ActuatorRig) -> None:
    """On the nonlinear rig the linear model folds Coulomb friction into D (+100 %);
    the declared Coulomb model, by output error, finds D and Tc within their errors."""
    rec = simulate_actuator(demo_rig, seed=4)
    truth = {**demo_rig.physical(), "Tc": demo_rig.coulomb_friction}
    linear = estimate(rec)
    assert linear.parameters["D"] > 1.5 * truth["D"]
    res = estimate(rec, model="dc-motor-coulomb")
    assert res.accepted and res.route == "oe", res.reason
    assert set(res.parameters) == {"R", "L", "Ke", "Kt", "J", "D", "Tc"}
    for k in ("R", "L", "Kt", "J", "D", "Tc"):
        assert abs(res.parameters[k] - truth[k]) < 3 * res.std_errors[k], k
    assert res.std_errors["Tc"] < 0.3 * truth["Tc"]
    assert res.to_dict()["diagnostics"]["nrmse omega"] < 0.2


def test_output_error_route_needs_measured_nonlinear_signals(tmp_path: Path) -> None:
    from condmon.models.semilinear import semilinear_structure

    text = (ROOT / "src" / "condmon" / "data" / "dc-motor-coulomb.toml").read_text()
    text = text[:text.index("[monitor]")] + text[text.index("[estimation]"):]
    text = text.replace('omega = { measures = "omega", noise = 2.0, unit = "rad/s", '
                        'description = "speed sensor" }\n', "")
    with pytest.raises(ModelError, match="nonlinear in omega, which no sensor measures"):
        semilinear_structure(get_model(_write(tmp_path, "c.toml", text)))


def test_several_records_at_once(demo_rig: ActuatorRig) -> None:
    from condmon.identify import estimate_joint

    recs = [simulate_actuator(demo_rig, seed=s) for s in range(3)]
    one = estimate(recs[0], model="dc-motor-coulomb")
    joint = estimate_joint(recs, "dc-motor-coulomb", sources=["a.csv", "b.csv", "c.csv"])
    assert joint.accepted and joint.route == "oe" and joint.source == "a.csv + b.csv + c.csv"
    truth = {**demo_rig.physical(), "Tc": demo_rig.coulomb_friction}
    for k in ("R", "L", "Kt", "J", "D", "Tc"):
        assert abs(joint.parameters[k] - truth[k]) < 3 * joint.std_errors[k], k
    # three records: standard errors shrink by about sqrt(3)
    assert joint.std_errors["D"] < 0.75 * one.std_errors["D"]
    axis = estimate_joint([_emps_axis(seed=1, duration=8.0), _emps_axis(seed=2, duration=8.0)],
                          EMPS_TOML)
    assert axis.route == "inverse" and axis.parameters["M"] == pytest.approx(95.0, rel=0.01)
    with pytest.raises(DataError, match="b.csv: missing column"):
        estimate_joint([recs[0], recs[1].drop(columns=["omega"])], "dc-motor-coulomb",
                       sources=["a.csv", "b.csv"])


def test_a_held_parameter_is_solved_by_gauss_newton_as_by_the_search(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """With D held (basic IV does not fix it), the four others solve an
    over-determined coefficient map: the Gauss-Newton point, accepted as
    stationary, is the one the trust-region search finds from both starts."""
    import importlib

    coefficients = importlib.import_module("condmon.identify.coefficients")
    rec = simulate_actuator(seed=1)
    res = estimate(rec, method="iv")
    assert res.held == {"D": "nominal"}
    monkeypatch.setattr(coefficients, "_stationary", lambda *args: False)
    ref = estimate(rec, method="iv")
    for k, v in ref.parameters.items():
        assert res.parameters[k] == pytest.approx(v, rel=1e-9, abs=1e-15), k
        assert res.std_errors[k] == pytest.approx(ref.std_errors[k], rel=1e-6, abs=1e-15), k


PENDULUM = """
name = "pendulum"
[parameters]
J = { value = 0.05, unit = "kg m^2" }
b = { value = 0.02, unit = "N m s/rad" }
mgl = { value = 0.8, unit = "N m" }
km = { value = 0.1, unit = "N m/V" }
[inputs]
u = { nominal = 0.0, unit = "V"HOLD }
[states]
th = { derivative = "w", unit = "rad" }
w = { derivative = "(km*u - b*w - mgl*sin(th))/J", unit = "rad/s" }
[sensors]
thm = { measures = "th", noise = 0.002, unit = "rad" }
[test]
duration = 30.0
sample_rate = 100.0
[estimation]
estimate = ["J", "b", "mgl"]
route = "inverse"
min_duration = 5.0
sample_interval = [1.0e-3, 0.05]
"""


@pytest.mark.parametrize("hold", ["", ', intersample = "bl"'])
def test_an_input_held_over_each_sample_is_read_so_by_the_inverse_route(
        tmp_path: Path, hold: str) -> None:
    """A pendulum driven by a command held over each sample (as condmon's own
    simulation holds it). Read at the sample times, the command leads the motion
    by half a sample, and the gravity torque's lead reads as damping: b came out
    3 % low, 9 standard errors. Held (the default), every parameter is within
    three standard errors of the truth; declared "bl", the bias is back."""
    from condmon.simulate.recorded import simulate_recorded

    model = _write(tmp_path, "p.toml", PENDULUM.replace("HOLD", hold))
    truth = {"J": 0.04, "b": 0.03, "mgl": 0.6, "km": 0.1}
    c = get_model(str(model)).plant.compile()
    n = 3000
    rng = np.random.default_rng(3)
    u = np.repeat(rng.choice([-5.0, 5.0], n // 30 + 1), 30)[:n]
    sim = simulate_recorded(c, u[:, None], 0.01, np.zeros(2), c.parameter_vector(truth),
                            substeps=8)
    rec = pd.DataFrame({"t": 0.01 * np.arange(n), "u": u,
                        "thm": sim.outputs[:, 0] + 0.002 * rng.standard_normal(n)})
    res = estimate(rec, str(model))
    assert res.accepted
    off = {k: abs(res.parameters[k] - truth[k]) / res.std_errors[k] for k in ("J", "b", "mgl")}
    if "bl" in hold:
        assert off["b"] > 5.0
    else:
        assert max(off.values()) < 3.0, off


def test_an_unknown_intersample_is_refused_with_the_allowed_values(tmp_path: Path) -> None:
    model = _write(tmp_path, "p.toml", PENDULUM.replace("HOLD", ', intersample = "foh"'))
    with pytest.raises(ConfigError, match=r"\[inputs.u\].intersample: 'foh'; allowed: 'zoh' "
                                          r"\(held over each sample\), 'bl' \(the values at "
                                          r"the sample times\)"):
        get_model(str(model))


def test_an_inverse_fit_below_its_threshold_names_the_simulation_route() -> None:
    """The inverse route differentiates a filtered record; where that fails
    (a gearbox's J came out 70 standard errors off at fit -179 %), the
    rejection names the route that does not differentiate."""
    import dataclasses

    from condmon.identify.fit import FitCheck

    res = estimate(_emps_axis(duration=6.0), EMPS_TOML)
    assert res.accepted and res.route == "inverse"
    poor = dataclasses.replace(res, fit=FitCheck(res.fit.r2, -179.0, 90.0, False))
    assert poor.reason is not None and "--route simulation fits the model" in poor.reason
    linear = estimate(simulate_actuator(seed=1))
    worse = dataclasses.replace(linear, fit=FitCheck(linear.fit.r2, 50.0, 90.0, False))
    assert worse.reason == "fit 50.0 % below the threshold 90 %"


def test_a_mode_faster_than_the_inverse_route_s_cut_off_is_refused() -> None:
    """The Coulomb DC motor's own built-in test by the inverse route: its
    electrical mode (L/R about one sample, 116 Hz) lies above the route's 50 Hz
    low-pass, and L was read 6 % high (18 standard errors), accepted. Now
    refused, naming the routes that simulate it; the model's own route (oe)
    estimates L within its errors."""
    from condmon.models.registry import get_model
    from condmon.simulate.plant import simulate_plant

    machine = get_model("dc-motor-coulomb")
    rec = simulate_plant(machine.plant, seed=1)
    res = estimate(rec, model="dc-motor-coulomb", route="inverse")
    assert not res.accepted and res.reason is not None
    assert "fastest mode" in res.reason and "above the route's low-pass cut-off 50 Hz" in \
        res.reason and "--route oe or --route simulation" in res.reason
    oe = estimate(rec, model="dc-motor-coulomb")
    assert oe.accepted and oe.route == "oe"
    L = machine.nominal()["L"]
    assert abs(oe.parameters["L"] - L) < 3 * oe.std_errors["L"]
