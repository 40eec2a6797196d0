"""Issue acceptance: the reference experiments, false alarms, rejected tests.

All on the simulated test-bed with its nonlinear effects on (the demo rig) at
the paper's noise level.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from condmon.workflows.demo import DemoResult
from condmon.identify import estimate
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import add_baseline_tests
from condmon.simulate import ActuatorRig, simulate_actuator
from condmon.store import open_store

UNCHANGED_CORE = ("R", "L", "Ke", "Kt", "J")

if TYPE_CHECKING:
    from conftest import DemoRun


@pytest.fixture(scope="module")
def demo(demo_run: DemoRun) -> DemoResult:
    """The result of ``condmon demo`` (run once for the run)."""
    result: DemoResult = demo_run.result
    return result


def _checks(demo: DemoResult, unit: str) -> list:  # type: ignore[type-arg]
    return [c for c in demo.checks if c.unit == unit]


def test_friction_experiment(demo: DemoResult) -> None:
    checks = _checks(demo, "EMA-friction")
    assert [c.label for c in checks][0] == "healthy"
    factors = [1, 2, 3, 4, 5, 6, 7]
    for c, k in zip(checks, factors):
        if k <= 4:  # up to +300 %: harmless on this rig
            assert c.result.status == "go", (k, c.result.diagnosis)
        assert c.top_fault in ("friction increase", "no fault")
        assert c.cross_coupling_ratio < 0.1, (k, c.result.percent_change)
    assert checks[-1].top_fault == "friction increase"
    assert checks[-1].result.status == "no-go"
    d = [c.result.percent_change["D"] for c in checks]
    assert all(b > a for a, b in zip(d, d[1:]))  # friction identified as rising


def test_resistance_experiment(demo: DemoResult) -> None:
    r20, r40 = _checks(demo, "EMA-resistance")
    assert r40.top_fault == "winding resistance increase" and r40.result.status == "no-go"
    assert r20.result.status == "go"  # +20 % is at r1: not yet a fault
    assert r20.result.percent_change["R"] == pytest.approx(20, abs=3)
    assert r40.result.percent_change["R"] == pytest.approx(40, abs=3)


def test_inductance_and_resistance_experiment(demo: DemoResult) -> None:
    small, large = _checks(demo, "EMA-winding")
    assert large.top_fault == "winding fault" and large.result.status == "no-go"
    assert small.top_fault == "winding fault"
    assert large.result.percent_change["L"] == pytest.approx(50, abs=4)


@pytest.fixture(scope="module")
def healthy_estimates(demo_rig: ActuatorRig) -> np.ndarray:
    """R, L, Ke, Kt, J, D of 8 healthy records (seeds 700-707), one row each."""
    return np.array([[estimate(simulate_actuator(demo_rig, seed=s)).parameters[p]
                      for p in ("R", "L", "Ke", "Kt", "J", "D")] for s in range(700, 708)])


@pytest.mark.parametrize("faults,changed", [
    (["R=+40%"], ("R",)),
    (["L=+50%", "R=+20%"], ("L", "R")),
    (["D=*7", "coulomb_friction=*7"], ("D",)),
])
def test_cross_coupling_is_an_order_of_magnitude_smaller(
        demo_rig: ActuatorRig, healthy_estimates: np.ndarray, faults: list[str],
        changed: tuple[str, ...]) -> None:
    """Systematic part (mean over 8 seeds) of the change of each unchanged
    parameter, against the smallest true change."""
    healthy = healthy_estimates
    faulty_rig = demo_rig.with_faults(faults)
    faulty = np.array([[estimate(simulate_actuator(faulty_rig, seed=s)).parameters[p]
                        for p in ("R", "L", "Ke", "Kt", "J", "D")] for s in range(800, 808)])
    change = 100 * (faulty.mean(axis=0) / healthy.mean(axis=0) - 1)
    truth = {p: 100 * (faulty_rig.physical()[p] / demo_rig.physical()[p] - 1)
             for p in ("R", "L", "Ke", "Kt", "J", "D")}
    smallest = min(abs(truth[p]) for p in changed)
    for i, p in enumerate(("R", "L", "Ke", "Kt", "J", "D")):
        if p in changed or (p == "D" and "D" not in changed):
            continue  # D's test-to-test scatter (~17 %) is reported, not asserted, here
        assert abs(change[i]) < 0.1 * smallest, (p, change[i], smallest)


def test_inductance_and_resistance_symptoms(demo_rig: ActuatorRig) -> None:
    """L +60 % with R +40 %: SymH(L) = 1, SymH(R) close to 1 and exactly 1 whenever
    the measured change reaches r2 = 40 % (SymH = 1 iff r >= r2: with an unbiased
    estimate of a true +40 % that is about every other test), every other symptom
    <= 0.05."""
    exact = 0
    for s in range(12):
        with open_store("sqlite://") as store:
            add_baseline_tests(store, "U", [simulate_actuator(demo_rig, seed=5000 + 10 * s + i)
                                            for i in range(5)])
            res = check_test(store, "U", simulate_actuator(
                demo_rig.with_faults(["L=+60%", "R=+40%"]), seed=9000 + s))
        sym = res.symptoms
        assert sym["L"]["high"] == 1.0
        assert sym["R"]["high"] >= 0.85
        assert (sym["R"]["high"] == 1.0) == (res.percent_change["R"] >= 40.0)
        exact += sym["R"]["high"] == 1.0
        others = [v for p, d in sym.items() for k, v in d.items()
                  if not (k == "high" and p in ("R", "L"))]
        assert max(others) <= 0.05
        assert res.diagnosis is not None and res.diagnosis.faults[0].name == "winding fault"
    assert exact >= 1  # the reference's reading occurs (seeds 2 and 4, among others)


@pytest.mark.parametrize("units", [1, pytest.param(4, marks=pytest.mark.slow)])
def test_false_alarms_over_healthy_tests(demo_rig: ActuatorRig, units: int) -> None:
    """50 healthy tests (new seeds) against each of ``units`` independent
    5-test baselines: no no-go, at most 2 % advisory. The default run takes
    the first 50 (about 8 s); the slow study, which ``.ci/run`` runs, all 200
    (the default's 50 among them)."""
    statuses = []
    for unit in range(units):
        with open_store("sqlite://") as store:
            add_baseline_tests(store, "U", [simulate_actuator(demo_rig, seed=20_000 + 100 * unit + i)
                                            for i in range(5)])
            for t in range(50):
                rec = simulate_actuator(demo_rig, seed=30_000 + 1000 * unit + t)
                statuses.append(check_test(store, "U", rec).status)
    assert len(statuses) == 50 * units
    assert statuses.count("no-go") == 0
    assert statuses.count("advisory") <= len(statuses) // 50
    assert statuses.count("retest") == 0


def test_rejected_fit_changes_no_symptom_or_trend(demo_rig: ActuatorRig) -> None:
    healthy = [simulate_actuator(demo_rig, seed=40 + i) for i in range(5)]
    noisy = dataclasses.replace(demo_rig, noise_I=2.0, noise_omega=10.0)
    bad = simulate_actuator(noisy, seed=1)
    probe = simulate_actuator(demo_rig.with_faults(["R=+30%"]), seed=2)
    with open_store("sqlite://") as a, open_store("sqlite://") as b:
        add_baseline_tests(a, "U", healthy)
        add_baseline_tests(b, "U", healthy)
        rejected = add_baseline_tests(a, "U", [bad])            # as a baseline test
        assert not rejected.tests[0].accepted and rejected.baseline is not None
        assert rejected.baseline.n == 5                          # not in the baseline
        res = check_test(a, "U", simulate_actuator(noisy, seed=3))  # another noisy test
        assert res.status == "retest" and res.diagnosis is None and not res.estimate.accepted
        hist = a.history("U")
        assert hist["accepted"].tolist().count(False) == 2
        pa = check_test(a, "U", probe)
        pb = check_test(b, "U", probe)
        assert pa.percent_change == pytest.approx(pb.percent_change)
        assert pa.symptoms == pb.symptoms and pa.status == pb.status


def test_demo_files_are_a_report_a_person_can_open(demo: DemoResult) -> None:
    index = demo.report.read_text()
    for unit in ("EMA-friction", "EMA-resistance", "EMA-winding"):
        assert f"{unit}.html" in index
        page = (demo.report.parent / f"{unit}.html").read_text()
        assert "<img src=" in page and "Latest check" in page
        assert Path(demo.report.parent / f"{unit}-symptoms.png").exists()
    # the HST isolations are in the history, on the fleet index and on their pages
    assert "<a href='HST-Rv.html'>HST-Rv</a></td><td class='l'><span class=\"status no-go\">" in index
    page = (demo.report.parent / "HST-Rv.html").read_text()
    assert "<h2>Isolations</h2>" in page and "fault isolated: Rv" in page


def test_demo_isolates_the_hydrostatic_transmission_faults(demo: DemoResult) -> None:
    by_fault = {d.fault: d for d in demo.isolations}
    assert set(by_fault) == {"Rv=+25%@10s", "Dm=-25%@10s", "Dp=-10%@10s", "Rlkgm=-50%@10s",
                             "Tld=+20@10s", "Rlkgp=+50%@10s"}
    for fault, d in by_fault.items():
        if d.parameter == "Rlkgp":  # too small to move the outputs beyond the noise
            assert not d.result.detected and d.result.isolated == ()
            continue
        assert d.result.isolated == (d.parameter,), fault
        assert d.result.estimates[d.parameter].value == pytest.approx(d.true_value, rel=0.03)
    index = demo.report.read_text()
    assert "Hydrostatic transmission" in index and "hst/1-Rv/residuals.png" in index
    assert (demo.report.parent / "hst" / "2-Dm" / "model-errors.png").stat().st_size > 20_000
