"""The yardstick of a check: the healthy scatter with the sensors' stated accuracy."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from condmon.errors import ConfigError
from condmon.io.rig import parse_record_settings
from condmon.monitor.baseline import Baseline
from condmon.monitor.fuzzy import MonitorConfig, compute_symptoms
from condmon.monitor.generic import judged_config, yardstick

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "hydraulic-actuator"
GAUGE = "0.25 %"          # of 20.684 MPa (3,000 psi): 51,710 Pa
DM = 8.2e-5               # [m^3/rad], the example's displacement


def _declaration(tmp_path: Path) -> Path:
    for f in EXAMPLE.glob("*.toml"):
        text = f.read_text()
        for g in ("PG_1", "PG_2"):
            text = text.replace(f'column = "{g}", scale = 1262.54 }}',
                                f'column = "{g}", scale = 1262.54, accuracy = "{GAUGE}", '
                                'full_scale = 2.0684e7 }')
        (tmp_path / f.name).write_text(text)
    return tmp_path / "rotary-actuator.toml"


def test_the_systematic_part_of_friction_is_the_gauges_accuracy_through_the_balance(
        tmp_path: Path) -> None:
    """Tc = Dm (pA - pB) - ...: each gauge's ±51,710 Pa moves Tc by Dm × 51,710 Pa; two
    gauges, root-sum-square: b = Dm × 51,710 × √2 = 5.997 N m."""
    from condmon.identify import estimate
    from condmon.io.rig import rig_layout
    from condmon.models.registry import get_model, load_plant_model
    from condmon.simulate.plant import simulate_plant

    decl = _declaration(tmp_path)
    machine = get_model(str(decl))
    assert machine.record.accuracy == {"pA": pytest.approx(51710.0),
                                       "pB": pytest.approx(51710.0)}
    rec = rig_layout(simulate_plant(load_plant_model(str(decl)), seed=2), machine.record)
    res = estimate(rec.assign(F_Names="", F_Values=0.0, Prediction=0.0), str(decl))
    truth = DM * 51710.0 * math.sqrt(2.0)
    for key in ("Tc@forward", "Tc@reverse"):
        assert res.systematic[key] == pytest.approx(truth, rel=1e-3)
    assert res.to_dict()["systematic"]["Tc@forward"] == pytest.approx(truth, rel=1e-3)
    # the record's own noise is another, smaller thing
    assert res.stored_values()["Tc@forward"][1] < truth


@pytest.mark.parametrize("spec, message", [
    ({"column": "PG_1", "accuracy": 0}, "accuracy must be > 0"),
    ({"column": "PG_1", "accuracy": -3.0}, "accuracy must be > 0"),
    ({"column": "PG_1", "accuracy": "0.25 %"}, "add full_scale"),
    ({"column": "PG_1", "full_scale": 2e7}, "add accuracy"),
])
def test_a_bad_accuracy_is_refused_naming_the_column(spec: dict[str, object],
                                                      message: str) -> None:
    with pytest.raises(ConfigError, match=r"rig\.toml\[record\]\.columns\.pA.*" + message):
        parse_record_settings({"columns": {"pA": spec}}, "rig.toml[record]")


def test_a_declared_breakpoint_inside_the_scatter_is_raised_unless_insisted() -> None:
    # 30 tests of 40 N m scattering 2 N m (5 %): 4 x 5 % x t(29)/z = 20.8 % > 15 %
    base = Baseline(("Tc@forward",), (40.0,), (2.0,), 30)
    s = yardstick(base)["Tc@forward"]
    assert s == pytest.approx(5.0 * 2.045229642132703 / 1.959963984540054, rel=1e-6)
    cfg, raised = judged_config(MonitorConfig({"Tc": 15.0}, {"Tc": 30.0}), base)
    assert cfg.r1["Tc@forward"] == pytest.approx(4 * s) and cfg.r2["Tc@forward"] == 8 * s
    assert "lies inside the healthy scatter" in raised[0]
    kept, none = judged_config(MonitorConfig({"Tc": 15.0}, {"Tc": 30.0},
                                             insist=frozenset({"Tc"})), base)
    assert kept.r1["Tc@forward"] == 15.0 and none == ()
    # a tight baseline leaves the declared breakpoints alone
    tight, none = judged_config(MonitorConfig({"Tc": 15.0}, {"Tc": 30.0}),
                                Baseline(("Tc@forward",), (40.0,), (0.2,), 30))
    assert tight.r1["Tc@forward"] == 15.0 and none == ()


def test_a_change_inside_the_sensors_accuracy_raises_no_symptom() -> None:
    """A no-load actuator: friction 12 N m from two gauges whose accuracy alone
    can move it by 6 N m (50 %). A +40 % change is within what the gauges can
    drift: no symptom; without the systematic part it would be a full one."""
    base = Baseline(("Tc@forward",), (12.0,), (0.12,), 30)
    declared = MonitorConfig({"Tc": 10.0}, {"Tc": 20.0})
    judged, raised = judged_config(declared, base, {"Tc@forward": 6.0})
    s = yardstick(base)["Tc@forward"]
    assert judged.r1["Tc@forward"] == pytest.approx(50.0 + 4 * s)
    assert judged.r2["Tc@forward"] == pytest.approx(50.0 + 8 * s)
    assert "sensors' accuracy" in raised[0]
    assert compute_symptoms([16.8], base, judged, [0.05]).row(0)["Tc@forward"]["high"] == 0.0
    plain = judged_config(declared, base)[0]
    assert compute_symptoms([16.8], base, plain, [0.05]).row(0)["Tc@forward"]["high"] == 1.0
    # beyond the gauges' reach and the scatter: a symptom again
    assert compute_symptoms([21.0], base, judged, [0.05]).row(0)["Tc@forward"]["high"] > 0.5


def test_a_check_evaluated_again_is_governed_as_a_new_one(tmp_path: Path) -> None:
    """Breakpoints insisted on far inside the healthy scatter make the fuzzy
    monitor call a healthy check no-go; the change test, which finds nothing
    beyond the scatter, keeps it go, whether it is checked or evaluated again
    against a new baseline version."""
    from _strokes import STROKE_DECLARATION as DECLARATION, stroke
    from condmon.store import open_store
    from condmon.workflows.checks import check_test
    from condmon.workflows.monitoring import (
        add_baseline_tests, reevaluate, save_current_baseline,
    )
    from condmon.workflows.records import EstimateOptions

    rng = np.random.default_rng(3)
    opts = EstimateOptions(model=str(DECLARATION))

    def rec(k: int) -> object:
        return stroke(1.0, seed=k, friction={"Tc": 40.0 * (1 + 0.02 * rng.standard_normal())})

    # narrow, but wider than the symptom band (2 sigma of the 3 % scatter), so that
    # the +4 % change reads high, not both ways (which is no symptom at all)
    narrow = MonitorConfig({"Tc": 5.0}, {"Tc": 6.0}, insist=frozenset({"Tc"}))
    with open_store(str(tmp_path / "g.db")) as store:
        added = add_baseline_tests(store, "A", [rec(k) for k in range(10)], opts)
        res = check_test(store, "A", stroke(1.0, seed=50, friction={"Tc": 44.0}), opts,
                         monitor=narrow)
        assert res.status == "go" and "not shown beyond the healthy scatter" in res.diagnosis.summary
        ids = [t.test_id for t in added.tests][:9]         # a new version: one test fewer
        version, _ = save_current_baseline(store, "A", ids, reason="one test fewer")
        changed = reevaluate(store, "A", version, monitor=narrow)
        assert changed and all(now == "go" for _, now in changed.values())
        hist = store.history("A")
        assert "not shown beyond the healthy scatter" in str(hist.loc[res.test_id, "summary"])


def test_breakpoints_nobody_declared_follow_the_scatter_the_check_is_judged_with() -> None:
    """Generic breakpoints are made from the baseline's raw spread at
    ``baseline add``; a check judged at its operating conditions (a warm-up
    taken out) has a smaller scatter, and its breakpoints come down with it,
    with no note of a "declared" breakpoint raised. Declared ones stay."""
    from condmon.monitor.generic import generic_config

    raw = Baseline(("b",), (2.0,), (0.091,), 15)        # 4.55 % with the warm-up in
    judged = Baseline(("b",), (2.0,), (0.058,), 15)     # 2.9 % about the oil's prediction
    cfg, raised = judged_config(generic_config(raw), judged)
    assert cfg.r1["b"] == pytest.approx(4 * yardstick(judged)["b"])
    assert cfg.r1["b"] < 0.7 * generic_config(raw).r1["b"]
    assert raised == ()
    declared, _ = judged_config(MonitorConfig({"b": 30.0}, {"b": 60.0}), judged)
    assert declared.r1["b"] == 30.0


def test_a_spread_stated_of_the_logarithm_reaches_the_same_rise(tmp_path: Path) -> None:
    """vib = { log = 25 }: healthy units differ by ratios. At the peers' breakpoint z
    (3.09 for α 1 % over two values), z log-spreads is a rise of exp(0.25 z) - 1 =
    117 %; the spread in percent that reaches it at z is 117 % / z = 37.7 %."""
    from condmon.monitor.fuzzy import load_monitor_config
    from condmon.monitor.generic import peer_sigmas, peer_spread

    f = tmp_path / "m.toml"
    f.write_text("[breakpoints]\nTc = { r1 = 10.0, r2 = 20.0 }\n"
                 "[between_units]\nTc = 10.0\nvib = { log = 25.0 }\n")
    cfg = load_monitor_config(f)
    assert cfg.between_log == frozenset({"vib"}) and cfg.between_units["vib"] == 25.0
    ref = Baseline(("Tc@forward", "vib@forward"), (40.0, 10.0), (0.4, 1e-9), 30)
    widened, _ = peer_spread(ref, cfg)
    z = peer_sigmas(0.01, 2)[0]
    assert z * widened.std[1] / 10.0 * 100.0 == pytest.approx(100.0 * math.expm1(0.25 * z))
    assert widened.std[0] == pytest.approx(math.hypot(math.sqrt(2.0) * 0.4, 4.0))
    f.write_text("[breakpoints]\nTc = { r1 = 10.0, r2 = 20.0 }\n"
                 "[between_units]\nvib = { ln = 25.0 }\n")
    with pytest.raises(ConfigError, match=r"\[between_units\] vib must be a spread"):
        load_monitor_config(f)


@pytest.mark.parametrize("entry, message", [
    ("Tcc = 10.0", r"breakpoints or spreads name unknown"),
    ('vib1 = "25 %"', r"\[between_units\] vib1 must be a spread > 0 \[% of the mean\] or "
                      r"\{ log = s \}"),
    ("vib1 = { log = -25.0 }", r"vib1 must be .* got -25.0 \[% of ln x\]"),
    ("vib1 = { ln = 25.0 }", r"vib1 must be .* got \{'ln': 25.0\}"),
])
def test_a_bad_spread_between_units_is_refused_naming_it(tmp_path: Path, entry: str,
                                                        message: str) -> None:
    """A misspelt name would leave its parameter judged without the spread."""
    from condmon.models.registry import get_model
    from condmon.monitor.generic import machine_monitor

    for f in EXAMPLE.glob("*.toml"):
        text = f.read_text()
        if f.name == "rotary-actuator-monitor.toml":
            text = text.replace("Tc = 10.0\n", f"Tc = 10.0\n{entry}\n")
            if entry.startswith("vib1"):
                text = text.replace("vib1 = { log = 25.0 }\n", "", 1)
        (tmp_path / f.name).write_text(text)
    with pytest.raises(ConfigError, match=message):
        machine_monitor(get_model(str(tmp_path / "rotary-actuator.toml")))
