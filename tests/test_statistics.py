"""Calibrated detection beside the fuzzy status: rates against known truth, and where users see it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from condmon.cli.main import main
from condmon.errors import ConfigError, DataError
from condmon.monitor.fuzzy import load_monitor_config
from condmon.monitor.statistics import StatisticsConfig, check_statistics
from condmon.simulate import simulate_actuator
from condmon.store import open_store
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import add_baseline_tests

_CORR = np.array([[1.0, 0.3, 0.9], [0.3, 1.0, 0.5], [0.9, 0.5, 1.0]])
_NAMES = ("R", "L", "Ke", "Kt")   # Kt is Ke again: a rank-deficient scatter


def _draws(rng: np.random.Generator, n: int, shift: float = 0.0) -> np.ndarray:
    x = rng.standard_normal((n, 3)) @ np.linalg.cholesky(_CORR).T
    return np.column_stack([x, x[:, 2]]) + shift


def _rates(n: int, units: int, alpha: float, seed: int) -> tuple[float, float, set[str]]:
    rng = np.random.default_rng(seed)
    level = drift = total = dtotal = 0
    methods = set()
    for _ in range(units):
        base = _draws(rng, n)
        mean = base.mean(axis=0)
        checks = _draws(rng, 6) - mean
        for k in range(6):
            s = check_statistics(_NAMES, checks[k], np.ones(4), base - mean, np.ones((n, 4)),
                                 checks[:k + 1], StatisticsConfig(alpha, alpha))
            methods.add(s.method)
            level += s.alarm
            total += 1
            if s.drift_alarm is not None:
                drift += s.drift_alarm
                dtotal += 1
    return level / total, drift / dtotal, methods


@pytest.mark.parametrize("n,methods_", [(10, {"hotelling", "max-t"}), (3, {"max-t"})])
def test_healthy_checks_alarm_at_the_stated_rate(n: int, methods_: set[str]) -> None:
    """2,400 healthy checks (1,600 with a drift test) at alpha 0.05: both rates
    within 0.6-1.5x alpha (T² and max-t combined by Simes; max-t alone
    conservative, correlated)."""
    level, drift, methods = _rates(n, 400, 0.05, seed=n)
    assert methods == methods_
    assert (0.6 if n > 3 else 0.3) * 0.05 <= level <= 1.5 * 0.05
    assert 0.6 * 0.05 <= drift <= 1.5 * 0.05


def test_a_change_and_a_drift_are_found_and_the_rank_is_counted_once() -> None:
    rng = np.random.default_rng(7)
    base = _draws(rng, 12)
    mean = base.mean(axis=0)
    s = check_statistics(_NAMES, np.array([6.0, 0.0, 0.0, 0.0]), np.ones(4), base - mean,
                         np.ones((12, 4)), np.zeros((1, 4)))
    assert s.method == "hotelling" and s.rank == 3 and s.alarm and s.drift_alarm is None
    # a slow drift along the scatter's own grain (R, with what moves with it),
    # +0.2 spreads a check, over 30 units: the drift test finds it as the level
    # test does, by its slope (the level test's first passage is its match here)
    firsts: dict[str, list[int]] = {"alarm": [], "drift_alarm": []}
    for _ in range(30):
        base = _draws(rng, 12)
        mean = base.mean(axis=0)
        ramp = _draws(rng, 30) - mean + np.outer(np.arange(1.0, 31.0) * 0.2, [1, .3, .9, .9])
        runs = [check_statistics(_NAMES, ramp[k], np.ones(4), base - mean, np.ones((12, 4)),
                                 ramp[:k + 1]) for k in range(30)]
        for kind in firsts:
            firsts[kind].append(next((k for k, r in enumerate(runs) if getattr(r, kind)), 30))
    assert np.median(firsts["drift_alarm"]) <= 16 and np.median(firsts["alarm"]) <= 16
    assert sum(k < 30 for k in firsts["drift_alarm"]) >= 28
    assert runs[-1].drift_slope["R"] == pytest.approx(0.2, abs=0.1)


def test_an_offset_baseline_raises_no_drift_alarm() -> None:
    """Healthy checks 6 spreads off an unlucky baseline: the level test alarms,
    the drift test (level free) does not."""
    rng = np.random.default_rng(3)
    base = _draws(rng, 10)
    mean = base.mean(axis=0)
    checks = _draws(rng, 8, shift=6.0) - mean
    s = check_statistics(_NAMES, checks[-1], np.ones(4), base - mean, np.ones((10, 4)), checks)
    assert s.alarm and s.drift_alarm is False


def test_a_poorly_estimated_test_is_not_taken_as_a_change() -> None:
    rng = np.random.default_rng(5)
    base = _draws(rng, 10)
    mean = base.mean(axis=0)
    d = np.array([4.0, 0.0, 0.0, 0.0])
    sharp = check_statistics(_NAMES, d, np.ones(4), base - mean, np.ones((10, 4)), d[None])
    vague = check_statistics(_NAMES, d, np.array([5.0, 1, 1, 1]), base - mean, np.ones((10, 4)),
                             d[None])
    assert vague.p_value > sharp.p_value


@pytest.mark.parametrize("kwargs,message", [
    ({"base": np.zeros((2, 4))}, "need 3"),
    ({"change": [np.nan, 0, 0, 0]}, "not finite"),
    ({"change": [0, 0, 0]}, "differ in shape"),
])
def test_bad_inputs_are_refused(kwargs: dict, message: str) -> None:  # type: ignore[type-arg]
    args = {"change": np.zeros(4), "base": np.random.default_rng(0).normal(size=(5, 4)), **kwargs}
    with pytest.raises(DataError, match=message):
        check_statistics(_NAMES, args["change"], np.ones(len(args["change"])), args["base"],
                         np.ones(args["base"].shape), np.zeros((1, 4)))


@pytest.mark.parametrize("table,message", [
    ("alpha = 0.7", r"\[statistics\] alpha must be a false-alarm probability in \(0, 0.5\)"),
    ("drift_alpha = 0", "drift_alpha must be"),
    ("alpha = 'often'", "must be a number"),
    ("beta = 0.1", "unknown \\[statistics\\] key"),
])
def test_a_bad_statistics_table_names_the_file(tmp_path: Path, table: str, message: str) -> None:
    f = tmp_path / "m.toml"
    f.write_text("[breakpoints]\nR = { r1 = 20.0, r2 = 40.0 }\n[statistics]\n" + table + "\n")
    with pytest.raises(ConfigError, match=f"m.toml: .*{message}"):
        load_monitor_config(f)


def test_the_shipped_monitor_files_state_their_rates() -> None:
    assert load_monitor_config().statistics == StatisticsConfig(0.01, 0.01)


@pytest.fixture(scope="module")
def checked(tmp_path_factory: pytest.TempPathFactory, demo_rig) -> tuple[Path, Path]:  # type: ignore[no-untyped-def]
    """A unit with a 10-test baseline, 3 healthy checks, then friction x2 (+100 %,
    far below the fuzzy breakpoints of D: 300 / 600 %)."""
    db = tmp_path_factory.mktemp("stats") / "h.db"
    recs = tmp_path_factory.mktemp("recs")
    with open_store(str(db)) as store:
        add_baseline_tests(store, "U", [simulate_actuator(demo_rig, seed=s) for s in range(10)])
        for k in range(3):
            check_test(store, "U", simulate_actuator(demo_rig, seed=40 + k))
    for name, rig in (("healthy", demo_rig), ("worn", demo_rig.with_faults(["D=*2"]))):
        simulate_actuator(rig, seed=50).to_csv(recs / f"{name}.csv", index=False)
    return db, recs


def test_check_json_carries_the_statistics(checked: tuple[Path, Path],
                                           capsys: pytest.CaptureFixture[str]) -> None:
    db, recs = checked
    capsys.readouterr()
    assert main(["check", str(recs / "healthy.csv"), "--unit", "U", "--db", str(db),
                 "--json", "--dry-run"]) == 0
    healthy = json.loads(capsys.readouterr().out)
    keys = {"statistic", "p_value", "alpha", "alarm", "drift_statistic", "drift_alarm"}
    assert keys <= set(healthy["statistics"])
    assert healthy["status"] == "go" and healthy["statistics"]["alarm"] is False
    assert healthy["statistics"]["checks"] == 4 and healthy["statistics"]["drift_alarm"] is False
    assert healthy["statistics"]["alpha"] == 0.01
    assert main(["check", str(recs / "worn.csv"), "--unit", "U", "--db", str(db),
                 "--dry-run", "--alpha", "0.005"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "go" in text and "statistics: ALARM (change" in text and "(α 0.005)" in text
    assert "statistical alarm under go" in text


@pytest.mark.parametrize("args,message", [
    (["--alpha", "0.5"], "--alpha must be a false-alarm probability in (0, 0.5), not 0.5"),
    (["--drift-alpha", "-0.1"], "--drift-alpha must be a false-alarm probability"),
])
def test_a_bad_alpha_is_one_line(checked: tuple[Path, Path], args: list[str], message: str,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    db, recs = checked
    capsys.readouterr()
    assert main(["check", str(recs / "healthy.csv"), "--unit", "U", "--db", str(db),
                 *args]) == 2
    err = capsys.readouterr().err
    assert message in " ".join(err.split()) and len(err.strip().splitlines()) == 1


def test_serially_correlated_checks_are_not_taken_for_a_drift() -> None:
    """Healthy checks that wander (AR(1), ρ = 0.8: a machine's warm-up from
    test to test) against a baseline spread over sessions: without allowing for
    the correlation, 24 % of checks raise a drift alarm at alpha 0.01."""
    rng = np.random.default_rng(11)
    alarms = total = 0
    for _ in range(100):
        x = np.zeros(30)
        x[0] = rng.standard_normal()
        for i in range(1, 30):
            x[i] = 0.8 * x[i - 1] + 0.6 * rng.standard_normal()
        base = rng.standard_normal((10, 1))
        checks = x[:, None] - base.mean()
        for k in range(3, 30):
            s = check_statistics(("Tc",), checks[k], [1.0], base - base.mean(), np.ones((10, 1)),
                                 checks[:k + 1])
            alarms += bool(s.drift_alarm)
            total += 1
    assert alarms / total < 0.11


def test_a_baseline_narrower_than_the_checks_is_said() -> None:
    rng = np.random.default_rng(4)
    base = rng.normal(0.0, 1.0, (10, 2))
    mean = base.mean(axis=0)
    wide = rng.normal(0.0, 4.0, (12, 2)) - mean
    s = check_statistics(("R", "D"), wide[-1], [1.0, 1.0], base - mean, np.ones((10, 2)), wide)
    assert not s.calibrated and s.scatter_ratio["R"] > 4.0
    assert "NOT at the stated rates" in s.describe("go")
    # under a diagnosed fault the scatter may be the fault's own change: no advice
    # to rebuild the baseline from it
    faulty = s.describe("advisory")
    assert "a diagnosed fault's own change" in faulty and "rebuild" not in faulty
    # a fault growing under go (a feature no rule names): the alarm's change is
    # the scatter, and rebuilding the baseline from it would bury it
    ramp = wide + np.outer(np.arange(12.0) * 3.0, [1.0, 0.0])
    grown = check_statistics(("R", "D"), ramp[-1], [1.0, 1.0], base - mean, np.ones((10, 2)),
                             ramp)
    assert grown.any_alarm and not grown.calibrated
    text = grown.describe("go")
    assert "do not rebuild the baseline" in text and "NOT at the stated rates" not in text
    same = rng.normal(0.0, 1.0, (12, 2)) - mean
    assert check_statistics(("R", "D"), same[-1], [1.0, 1.0], base - mean, np.ones((10, 2)),
                            same).calibrated


def test_a_boolean_is_no_alpha() -> None:
    from condmon.monitor.statistics import checked_alpha

    with pytest.raises(DataError, match="must be a number in \\(0, 0.5\\), not True"):
        checked_alpha(True)


# --- the t and F tails without scipy: scipy's figures ----------------------------


@pytest.mark.parametrize("dof", [0.7, 1.0, 2.0, 2.5, 4.66, 9.0, 30.0, 200.0])
def test_the_t_distribution_is_scipys(dof: float) -> None:
    from scipy.special import stdtr

    from condmon.monitor.distributions import t_cdf

    for t in (-1e4, -30.0, -10.0, -3.0, -1.0, -0.25, 0.0, 0.5, 2.0):
        assert t_cdf(dof, t) == pytest.approx(float(stdtr(dof, t)), rel=1e-12, abs=1e-300)
    assert t_cdf(dof, -math.inf) == 0.0 and t_cdf(dof, math.inf) == 1.0


@pytest.mark.parametrize("dfn", [0.66, 1.0, 1.33, 3.0, 6.0, 29.0])
def test_the_f_distribution_is_scipys(dfn: float) -> None:
    from scipy.special import fdtrc

    from condmon.monitor.distributions import f_sf

    x = np.array([0.0, 1e-6, 0.1, 0.5, 1.0, 2.0, 5.0, 30.0, 1e4, 1e8])
    for dfd in (1.0, 2.5, 5.0, 20.0, 49.0):
        ours = f_sf(dfn, dfd, x)
        assert isinstance(ours, np.ndarray) and ours.shape == x.shape
        np.testing.assert_allclose(ours, fdtrc(dfn, dfd, x), rtol=1e-12, atol=1e-300)
    assert f_sf(dfn, 4.0, np.inf) == 0.0 and math.isnan(float(f_sf(dfn, 4.0, -1.0)))


def test_one_parameter_moved_among_many_is_found() -> None:
    """Nine parameters (features beside the physical ones), 15 baseline tests,
    one parameter 6.3 scatters out: Hotelling's T² alone spreads its power over
    the nine directions (p 0.13 here, no alarm at 0.01, and the check was
    called "within the healthy scatter"); each parameter's own t finds it."""
    rng = np.random.default_rng(11)
    names = tuple(f"x{i}" for i in range(9))
    base = rng.standard_normal((15, 9))
    base -= base.mean(axis=0)
    change = np.zeros(9)
    change[0] = 6.3 * base[:, 0].std(ddof=1)
    s = check_statistics(names, change, np.full(9, 0.1), base, np.full((15, 9), 0.1),
                         change[None, :])
    assert s.alarm and s.method == "max-t" and s.p_value < 0.002, s
    # the line names the parameter, not only the statistic: a quiet parameter's
    # small change in % may be the one
    assert s.largest == "x0" and "change max |t| 6.1 (x0)" in s.describe("go")
    assert s.to_dict()["largest_t"] == "x0"
    # and a healthy check of the same baseline does not alarm
    quiet = check_statistics(names, 0.5 * base[3], np.full(9, 0.1), base,
                             np.full((15, 9), 0.1), base[3][None, :] * 0.5)
    assert not quiet.alarm
