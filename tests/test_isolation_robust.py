"""Declared-plant diagnosis on bad records and bad models: it always ends, refuses
what cannot be right with one line, and never says "no fault" when the record
cannot tell."""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from condmon.cli._console import write_json
from condmon.cli.main import main
from condmon.diagnose import isolation as iso
from condmon.diagnose.checks import RecordSettings, validate_plant_record
from condmon.diagnose.isolation import IsolationSettings, healthy_normalisation, isolate
from condmon.diagnose.suspects import SuspectTask, plausible_range, run_suspects
from condmon.errors import ConfigError, DataError, DataWarning
from condmon.identify.steady_state import SteadyStateEstimate
from condmon.models.declared import PlantModel
from condmon.models.registry import load_plant_model
from condmon.models.expressions import smoothed
from condmon.simulate.plant import (
    SimulationLimits, SimulationTimeout, input_signals, integrate, sensor_readings,
    simulate_plant, time_grid,
)

COULOMB = """
name = "coulomb-mass"
description = "A mass pushed by a known force against viscous and Coulomb friction"
[parameters]
m  = { value = 1.0, unit = "kg" }
c  = { value = 0.5, unit = "N s/m", fault = true }
Fc = { value = 2.0, unit = "N", fault = true, range = [0.0, 20.0] }
[inputs]
F = { nominal = 0.0, unit = "N" }
[states]
x = { derivative = "v", unit = "m" }
v = { derivative = "(F - c*v - Fc*sign(v))/m", unit = "m/s" }
[sensors]
x = { measures = "x", noise = 1e-4, unit = "m" }
v = { measures = "v", noise = 1e-3, unit = "m/s" }
[smoothing]
eps = 1e-5
[test]
duration = 0.01
sample_rate = 10000.0
schedule = [{ input = "F", at = 0.002, value = 1.0 }, { input = "F", at = 0.005, value = 5.0 }]
"""


@pytest.fixture(scope="module")
def hst() -> PlantModel:
    return load_plant_model("hst")


@pytest.fixture(scope="module")
def healthy(hst: PlantModel) -> pd.DataFrame:
    return simulate_plant(hst, seed=1)


@pytest.fixture(scope="module")
def rv_fault(hst: PlantModel) -> pd.DataFrame:
    return simulate_plant(hst, ["Rv=+40%@10s"], seed=3)


# --- records refused with one line naming the file and column ------------------------


@pytest.mark.parametrize("edit,message", [
    (lambda r: r.assign(Ps=0.0, omega_m=0.0), r"rig\.csv: column 'Ps' stays within \[0, 0\] Pa"),
    (lambda r: r.assign(Ps=r["Ps"] / 1e5), r"rig\.csv: column 'Ps' .* \(bar for Pa\?\)"),
    (lambda r: r.assign(omega_p=1e300), r"rig\.csv: column 'omega_p' reaches 1e\+300 rad/s .*"
                                        r"range \[0, 320\] rad/s"),
    (lambda r: r.assign(Ps=r["Ps"] * 1e3), r"rig\.csv: column 'Ps' reaches .* more than 10 "
                                          r"spans outside the sensor's declared range \[0, 1e\+07\]"),
    (lambda r: r.assign(t=r["t"] / 1000), r"rig\.csv: the sample interval 1e-05 s is 1e\+03 "
                                         r"times shorter .* column 't' must be in seconds"),
    (lambda r: r.assign(t=r["t"] * 1000), r"rig\.csv: the sample interval 10 s is 1e\+03 times "
                                         r"longer"),
])
def test_records_that_cannot_be_right_are_refused(hst: PlantModel, healthy: pd.DataFrame,
                                                  edit: object, message: str) -> None:
    bad = edit(healthy.copy())  # type: ignore[operator]
    with pytest.raises(DataError, match=message):
        isolate(bad, hst, workers=1, source="rig.csv")


def test_mild_excursions_only_warn(hst: PlantModel, healthy: pd.DataFrame) -> None:
    rec = healthy.copy()
    rec.loc[100:200, "Ps"] = 1.2e7  # above the 100 bar sensor, by less than a span
    with pytest.warns(DataWarning, match="of column 'Ps' lies outside the sensor's range"):
        validate_plant_record(hst, rec, "rig.csv")
    rec = healthy.copy()
    rec["omega_p"] = -rec["omega_p"]
    with pytest.warns(DataWarning, match="column 'omega_p' lies outside the input's range"):
        validate_plant_record(hst, rec, "rig.csv")


def test_the_record_limits_are_settings(tmp_path: Path, hst: PlantModel,
                                        healthy: pd.DataFrame) -> None:
    p = tmp_path / "s.toml"
    p.write_text("[record]\nrefuse_outside_spans = 1000.0\nunit_share = 1.0\n")
    cfg = IsolationSettings.load(p)
    assert cfg.record.refuse_outside_spans == 1000.0 and cfg.record.unit_share == 1.0
    with pytest.warns(DataWarning, match="outside the sensor's range"):
        validate_plant_record(hst, healthy.assign(Ps=healthy["Ps"] * 1e3), "rig.csv", cfg.record)
    for bad in ("[isolation]\ntime_limit_floor = -1\n", "[isolation]\nrange_factor = 1\n",
                "[record]\ntime_base_factor = 0.5\n", "[simulation]\ntime_limit = 0\n"):
        p.write_text(bad)
        with pytest.raises(ConfigError):
            IsolationSettings.load(p)


# --- the flow always ends --------------------------------------------------------------


def test_a_runaway_suspect_is_stopped_and_the_others_still_finish(hst: PlantModel) -> None:
    """Dm = 70 m^3/rad (nominal 4.45e-5) integrates for ever without a limit; with
    one it stops in its worker, serially and in the pool alike."""
    t = time_grid(hst, 3.0)
    u = input_signals(hst, t)
    lim = SimulationLimits(time_limit=0.5, max_evaluations_per_sample=2000)
    tasks = [SuspectTask(hst, "Dm", 70.0, 1.0, t, u, lim),
             SuspectTask(hst, "Rv", 12.0, 1.0, t, u, lim)]
    for workers in (1, 2):
        start = time.monotonic()
        runaway, fine = run_suspects(tasks, workers)
        assert time.monotonic() - start < 4.0
        assert runaway.outputs is None and runaway.failure is not None
        assert runaway.failure.startswith("timed out: simulation of 'hst' stopped at t = ")
        assert fine.outputs is not None and fine.outputs.shape == (len(t), 2)


def test_an_evaluation_cap_stops_a_run_too(hst: PlantModel) -> None:
    t = time_grid(hst, 3.0)
    with pytest.raises(SimulationTimeout, match="evaluations per sample"):
        integrate(hst.compile(), t, input_signals(hst, t), params={"Dm": 70.0},
                  limits=SimulationLimits(max_evaluations_per_sample=5))


def test_isolation_reports_a_timed_out_suspect_and_still_isolates(
        hst: PlantModel, rv_fault: pd.DataFrame, monkeypatch: pytest.MonkeyPatch) -> None:
    """A suspect whose (accepted) estimate makes its model run away is reported as
    timed out; the true fault is still isolated by the others, with the pool."""
    real = iso._estimate

    def runaway_dm(model: PlantModel, parameter: str, windows: object, factor: float
                   ) -> tuple[SteadyStateEstimate, str | None]:
        if parameter == "Dm":
            return SteadyStateEstimate("Dm", 70.0, 4.45e-5, 1.0, True), None
        return real(model, parameter, windows, factor)  # type: ignore[arg-type]

    monkeypatch.setattr(iso, "_estimate", runaway_dm)
    settings = dataclasses.replace(IsolationSettings.load(), time_limit_floor=0.5,
                                   time_limit_factor=0.1)
    start = time.monotonic()
    res = isolate(rv_fault, hst, settings=settings, workers=2)
    assert time.monotonic() - start < 8.0
    assert res.time_limit == 0.5
    assert res.rejected["Dm"].startswith("timed out")
    assert res.decided and res.isolated == ("Rv",)
    # the statement alone says a candidate was not compared (it could have fitted better);
    # the ones the record rules out (Rlkgm, Rlkgp: implausible estimates) are not named
    assert res.statement == ("fault isolated: Rv; not compared: Dm (estimate or run failed; "
                             "see why)")
    doc = res.to_dict()
    assert doc["rejected"]["Dm"].startswith("timed out") and "Dm" not in doc["errors"]


def test_implausible_estimates_are_rejected_with_the_reason(hst: PlantModel,
                                                            healthy: pd.DataFrame) -> None:
    """All-zero sensors (the record check switched off): the estimates run off by
    orders of magnitude and are rejected; what is left explains nothing, so
    nothing is isolated and the result says why."""
    settings = dataclasses.replace(IsolationSettings.load(),
                                   record=RecordSettings(dead_fraction=0.0))
    start = time.monotonic()
    with pytest.warns(DataWarning, match="is constant"):
        res = isolate(healthy.assign(Ps=0.0, omega_m=0.0), hst, settings=settings, workers=1)
    assert time.monotonic() - start < 8.0
    assert res.detected and not res.decided and res.isolated == ()
    assert "outside the plausible range [1e+09, 1e+15] N s/m^5" in res.rejected["Rlkgp"]
    assert res.reason is not None and "no suspect's model explains the record" in res.reason
    json.dumps(res.to_dict(), allow_nan=False)


def test_plausible_ranges_from_the_declaration_or_a_factor(hst: PlantModel, tmp_path: Path
                                                           ) -> None:
    assert plausible_range(hst.parameter("Tld"), 100.0) == (-450.0, 450.0)
    lo, hi = plausible_range(hst.parameter("Dm"), 100.0)  # type: ignore[misc]
    assert lo == pytest.approx(4.45e-7) and hi == pytest.approx(4.45e-3)
    path = tmp_path / "m.toml"
    path.write_text(COULOMB.replace("range = [0.0, 20.0]", "range = [5.0, 20.0]"))
    with pytest.raises(ConfigError, match=r"parameters\.Fc\]: value 2 lies outside its range"):
        load_plant_model(path)


# --- a record that cannot decide says so ------------------------------------------------


def test_a_record_too_short_to_judge_is_undecided_not_healthy(hst: PlantModel,
                                                               healthy: pd.DataFrame) -> None:
    short = healthy[healthy["t"] < 1.2]
    with pytest.warns(DataWarning, match=r"short\.csv: the record lasts 1\.19 s"):
        res = isolate(short, hst, workers=1, source="short.csv")
    assert not res.detected and not res.decided
    assert res.reason is not None and res.reason.startswith("record too short to decide")
    assert res.statement.startswith("undecided") and "no fault" not in res.statement
    doc = res.to_dict()
    assert doc["decided"] is False and doc["reason"] == res.reason


def test_a_fault_near_the_end_of_the_record_is_detected_but_undecided(hst: PlantModel) -> None:
    rec = simulate_plant(hst, ["Rv=+40%@10s"], seed=3, duration=12.0)
    res = isolate(rec, hst, workers=1)
    assert res.detected and not res.decided and res.isolated == ()
    assert res.reason is not None and "before a steady window" in res.reason


def test_a_healthy_record_is_decided(hst: PlantModel, healthy: pd.DataFrame) -> None:
    res = isolate(healthy, hst, workers=1)
    assert not res.detected and res.decided and res.reason is None
    assert res.statement == "no fault detected"


# --- discontinuous terms ----------------------------------------------------------------


def test_smoothing_replaces_the_non_smooth_functions() -> None:
    import sympy as sp

    x, y = sp.symbols("x y", real=True)
    expr = sp.sign(x) + sp.Abs(y) + sp.Max(x, y) + sp.Min(x, y, 0)
    f = sp.lambdify((x, y), smoothed(expr, 1e-3))
    g = sp.lambdify((x, y), expr)
    for a, b in [(0.5, -2.0), (-1.0, 3.0), (2.0, 1.0)]:
        assert f(a, b) == pytest.approx(g(a, b), abs=1e-6)
    assert not smoothed(expr, 1e-3).atoms(sp.sign, sp.Abs, sp.Max, sp.Min)
    assert smoothed(expr, 0.0) == expr


def test_smoothed_guards_keep_their_sign() -> None:
    """max(x, 0) stays >= 0 and min(x, 0) <= 0 for every x once smoothed (the
    tanh form made max(x, 0) negative below 0), so sqrt(max(x, 0)) is finite:
    the guard a user writes for Torricelli's outflow guards."""
    import numpy as np
    import sympy as sp

    x = sp.Symbol("x", real=True)
    xs = np.concatenate([-np.logspace(-9, 3, 400), [0.0], np.logspace(-9, 3, 400)])
    for eps in (1e-6, 1e-3, 0.1):
        hi = sp.lambdify(x, smoothed(sp.Max(x, 0), eps), "numpy")(xs)
        lo = sp.lambdify(x, smoothed(sp.Min(x, 0), eps), "numpy")(xs)
        root = sp.lambdify(x, smoothed(sp.sqrt(sp.Max(x, 0)), eps), "numpy")(xs)
        assert np.all(hi >= 0) and np.all(lo <= 0) and np.all(np.isfinite(root))
        assert np.all(hi >= xs) and np.all(lo <= xs)             # never below (above) x
        assert np.max(np.abs(hi - np.maximum(xs, 0))) <= eps / 2 + 1e-15


def test_coulomb_friction_simulates_in_bounded_time(tmp_path: Path) -> None:
    path = tmp_path / "coulomb.toml"
    path.write_text(COULOMB)
    m = load_plant_model(path)
    start = time.monotonic()
    rec = simulate_plant(m, noise=False)
    assert time.monotonic() - start < 5.0
    stuck = rec[(rec["t"] > 0.0025) & (rec["t"] < 0.005)]  # 1 N < Fc: it stays put
    assert np.abs(stuck["v"]).max() < 1e-4
    assert rec["v"].iloc[-1] == pytest.approx((5.0 - 2.0) * 0.005, rel=0.02)  # slides
    default = dataclasses.replace(m, smoothing=None)  # undeclared: the settings' default eps
    start = time.monotonic()
    assert simulate_plant(default, noise=False)["v"].iloc[-1] == pytest.approx(0.015, rel=0.02)
    assert time.monotonic() - start < 5.0
    exact = dataclasses.replace(m, smoothing=0.0)  # the chattering original: stopped
    with pytest.raises(SimulationTimeout, match="coulomb-mass"):
        simulate_plant(exact, limits=SimulationLimits(time_limit=0.5))


def test_simulate_plant_cli_with_coulomb_friction(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "coulomb.toml"
    path.write_text(COULOMB)
    start = time.monotonic()
    assert main(["simulate", "plant", str(path), "--out", str(tmp_path / "c.csv")]) == 0
    assert time.monotonic() - start < 10.0
    assert len(pd.read_csv(tmp_path / "c.csv")) == 101
    path.write_text(COULOMB.replace("eps = 1e-5", "eps = -1.0"))
    capsys.readouterr()
    assert main(["simulate", "plant", str(path), "--out", str(tmp_path / "c.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert "[smoothing].eps must be >= 0" in err and len(err.splitlines()) == 1


def test_cli_a_chattering_model_beside_a_record_stops_with_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The exact (unsmoothed) Coulomb model run beside a record: stopped by the
    [simulation] time limit, one line naming the record, exit status 2."""
    smooth, exact = tmp_path / "smooth.toml", tmp_path / "exact.toml"
    smooth.write_text(COULOMB)
    exact.write_text(COULOMB.replace("eps = 1e-5", "eps = 0.0"))
    rec = tmp_path / "rig.csv"
    assert main(["simulate", "plant", str(smooth), "--out", str(rec)]) == 0
    settings = tmp_path / "s.toml"
    settings.write_text("[simulation]\ntime_limit = 0.5\n")
    capsys.readouterr()
    start = time.monotonic()
    assert main(["isolate", str(exact), str(rec), "--settings", str(settings),
                 "--workers", "1"]) == 2
    assert time.monotonic() - start < 10.0
    err = capsys.readouterr().err.strip()
    assert f"{rec}: the model cannot be run beside the record: simulation of 'coulomb-mass' " \
           "stopped at t = " in err
    assert len(err.splitlines()) == 1 and "Traceback" not in err


# --- JSON and non-finite values ---------------------------------------------------------


def test_json_never_holds_nan_or_inf(capsys: pytest.CaptureFixture[str]) -> None:
    write_json({"a": float("inf"), "b": [np.float64(np.nan), np.array([1.0, -np.inf])],
                "c": {"d": np.int64(3), "e": (np.bool_(True), None)}})
    doc = json.loads(capsys.readouterr().out)
    assert doc == {"a": None, "b": [None, [1.0, None]], "c": {"d": 3, "e": [True, None]}}


def test_non_finite_estimates_are_null_in_the_result(hst: PlantModel,
                                                     rv_fault: pd.DataFrame) -> None:
    res = isolate(rv_fault, hst, workers=1)
    bad = dataclasses.replace(res, estimates={
        **res.estimates, "Dm": SteadyStateEstimate("Dm", float("inf"), 4.45e-5, float("nan"),
                                                   False)},
                              errors={**res.errors, "Tld": float("inf")})
    doc = bad.to_dict()
    json.dumps(doc, allow_nan=False)
    assert doc["estimates"]["Dm"] is None and doc["consistency"]["Dm"] is None
    assert doc["errors"]["Tld"] is None


def test_non_finite_residuals_are_refused_naming_the_column(hst: PlantModel,
                                                            healthy: pd.DataFrame) -> None:
    """A sensor without a declared range and a reading near the float limit: the
    residual overflows; one line, not a traceback."""
    sensors = tuple(dataclasses.replace(s, range=(-np.inf, np.inf)) for s in hst.sensors)
    wide = dataclasses.replace(hst, sensors=sensors)
    rec = healthy.copy()
    rec.loc[50, "Ps"] = -1.7e308
    rec.loc[50:, "omega_m"] = -1.7e308
    with pytest.raises(DataError, match=r"rig\.csv: residual 'r_omega_m' of column 'omega_m' "
                                        r"overflows at row 50"):
        isolate(rec, wide, workers=1, source="rig.csv")


# --- operating points for a continuously varying input ---------------------------------


def _ramp_records(hst: PlantModel, n: int, duration: float = 10.0) -> list[pd.DataFrame]:
    t = time_grid(hst, duration)
    u = np.linspace(152.0, 100.0, len(t))[:, None]
    c = hst.compile()
    y = sensor_readings(c, integrate(c, t, u), u, (), t)
    out = []
    for s in range(n):
        rng = np.random.default_rng(s)
        out.append(pd.DataFrame({"t": t, "Ps": y[:, 0] + rng.normal(0, 2.5e4, len(t)),
                                 "omega_m": y[:, 1] + rng.normal(0, 0.05236, len(t)),
                                 "omega_p": u[:, 0] * (1 + 1e-3 * rng.standard_normal(len(t)))}))
    return out


def test_a_continuously_varying_input_gets_pooled_normalisation(hst: PlantModel) -> None:
    *train, rec = _ramp_records(hst, 4)
    norm = healthy_normalisation(hst, train)
    assert len(norm.points) == 0 and np.all(np.isfinite(norm.std))
    assert norm.notes and "vary continuously" in norm.notes[0]
    res = isolate(rec, hst, normalisation=norm, workers=1)
    assert not res.detected and res.decided
    assert np.all(np.isfinite(res.detection.normalised))
    assert any("vary continuously" in n for n in res.notes)
    assert "vary continuously" in res.to_dict()["normalisation"]["notes"][0]


def test_an_operating_point_held_too_briefly_uses_the_pooled_figures(hst: PlantModel) -> None:
    t = time_grid(hst)
    u = np.where(t < 14.0, 152.0, np.where(t < 14.5, 130.0, 114.0))[:, None]
    c = hst.compile()
    y = sensor_readings(c, integrate(c, t, u), u, (), t)
    train = []
    for s in range(3):
        rng = np.random.default_rng(50 + s)
        train.append(pd.DataFrame({"t": t, "Ps": y[:, 0] + rng.normal(0, 2.5e4, len(t)),
                                   "omega_m": y[:, 1] + rng.normal(0, 0.05236, len(t)),
                                   "omega_p": u[:, 0]}))
    norm = healthy_normalisation(hst, train)
    assert sorted(float(p[0]) for p in norm.points) == [114.0, 152.0]
    assert np.all(np.isfinite(norm.point_std)) and np.all(norm.point_std > 0)
    assert norm.notes == ("1 of 3 operating points held less than 2 s: pooled figures there",)


# --- the command line -------------------------------------------------------------------


@pytest.mark.parametrize("edit,message", [
    (lambda r: r.assign(Ps=0.0, omega_m=0.0), "column 'Ps' stays within [0, 0] Pa"),
    (lambda r: r.assign(Ps=r["Ps"] / 1e5), "(bar for Pa?)"),
    (lambda r: r.assign(omega_p=1e300), "column 'omega_p' reaches 1e+300 rad/s"),
    (lambda r: r.assign(t=r["t"] / 1000), "column 't' must be in seconds"),
])
def test_cli_refuses_bad_records_with_one_line(tmp_path: Path, healthy: pd.DataFrame,
                                               capsys: pytest.CaptureFixture[str],
                                               edit: object, message: str) -> None:
    path = tmp_path / "bad.csv"
    edit(healthy.copy()).to_csv(path, index=False)  # type: ignore[operator]
    capsys.readouterr()
    start = time.monotonic()
    assert main(["isolate", "hst", str(path), "--workers", "1"]) == 2
    assert time.monotonic() - start < 10.0
    err = capsys.readouterr().err.strip()
    assert message in err and str(path) in err
    assert len(err.splitlines()) == 1 and "Traceback" not in err


@pytest.mark.filterwarnings("always::condmon.errors.DataWarning")
def test_cli_says_undecided_for_a_short_record(tmp_path: Path, healthy: pd.DataFrame,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "short.csv"
    healthy[healthy["t"] < 1.2].to_csv(path, index=False)
    capsys.readouterr()
    assert main(["isolate", "hst", str(path), "--json", "--workers", "1"]) == 0
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    assert doc["detected"] is False and doc["decided"] is False
    assert doc["reason"].startswith("record too short to decide")
    assert "warning:" in captured.err and "lasts 1.19 s" in captured.err
    assert main(["isolate", "hst", str(path), "--workers", "1"]) == 0
    assert "undecided" in capsys.readouterr().out


@pytest.mark.parametrize("column,change,match", [
    ("Ps", -1.0, "column 'Ps' is negative .* likely a sign error"),
    ("omega_m", -1.0, "column 'omega_m' is negative .* likely a sign error"),
    ("Ps", 10.0, "beyond 3 x its sensor.s range .* likely a unit error"),
])
def test_unit_and_sign_errors_of_a_sensor_are_refused(hst: PlantModel, healthy: pd.DataFrame,
                                                      column: str, change: float,
                                                      match: str) -> None:
    bad = healthy.assign(**{column: healthy[column] * change})
    with pytest.raises(DataError, match=match):
        validate_plant_record(hst, bad, "rig.csv")
