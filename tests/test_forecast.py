"""Forecasts to no-go against known truth: a linear rise, an exponential one,
a stable unit ("no trend"), and the refusals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from condmon.cli.main import main
from condmon.errors import DataError
from condmon.forecast.series import median_interval, forecast_series
from condmon.simulate import simulate_actuator
from condmon.store import open_store
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import add_baseline_tests


def test_a_linear_rise_is_forecast_within_its_interval() -> None:
    rng = np.random.default_rng(7)
    inside, errors = 0, []
    for _ in range(100):
        x = np.arange(1.0, 16.0)
        y = 4.0 * x + rng.normal(0.0, np.sqrt(3.0 ** 2 + 2.0 ** 2), 15)
        f = forecast_series(x, y, np.full(15, 3.0), 2.0, threshold=100.0, horizon=10.0)
        assert f.model in ("linear", "exponential")
        inside += f.remaining[1] <= 10.0 <= f.remaining[2]
        errors.append(abs(f.remaining[0] / 10.0 - 1.0))
    assert 80 <= inside <= 99        # the 90 % interval covers the truth about 90 % of the time
    assert np.median(errors) < 0.1


def test_in_whole_checks_the_first_check_past_no_go_is_forecast() -> None:
    """The no-go is a check whose measured change passes the threshold: with
    the checks' spacing the forecast counts whole checks to the first such
    check, and its mid-p interval holds that check (drawn with the same
    scatter as the series) about as often as it says: 90 % of 200 is 180 ±
    4.2 (binomial sd)."""
    rng = np.random.default_rng(11)
    sd = np.sqrt(3.0 ** 2 + 2.0 ** 2)
    hits = {"checks": 0}
    exact = 0
    for _ in range(200):
        x = np.arange(1.0, 16.0)
        y = 3.7 * x + rng.normal(0.0, sd, 15)
        ahead = np.arange(1.0, 40.0)
        seen = 3.7 * (15.0 + ahead) + rng.normal(0.0, sd, ahead.size)
        truth = float(ahead[np.argmax(seen >= 100.0)])      # the first check past no-go
        whole = forecast_series(x, y, np.full(15, 3.0), 2.0, threshold=100.0, step=1.0)
        assert whole.remaining is not None
        assert all(float(v).is_integer() for v in whole.remaining)
        hits["checks"] += whole.remaining[1] <= truth <= whole.remaining[2]
        exact += whole.remaining[0] == truth
    assert 170 <= hits["checks"] <= 190, hits
    assert exact >= 40      # the median is the very check more often than chance


def test_an_exponential_rise_is_chosen_and_forecast() -> None:
    x = np.arange(1.0, 16.0)
    y = 2.0 * np.exp(0.2 * x) + np.random.default_rng(3).normal(0.0, 0.5, 15)
    f = forecast_series(x, y, np.full(15, 0.5), 0.5, threshold=100.0, horizon=6.0)
    truth = np.log(50.0) / 0.2 - 15.0
    assert f.model == "exponential" and f.remaining[1] <= truth <= f.remaining[2]
    assert f.p_within is not None and f.p_within > 0.9


def test_a_stable_series_is_no_trend() -> None:
    x = np.arange(1.0, 16.0)
    f = forecast_series(x, np.random.default_rng(5).normal(0.0, 3.0, 15), np.full(15, 3.0),
                        2.0, threshold=40.0, horizon=10.0)
    assert f.model == "no trend" and f.remaining is None and f.p_within == 0.0
    assert f.slope_interval[0] < 0.0 < f.slope_interval[1]


@pytest.mark.parametrize("args,message", [
    (dict(x=[1.0, 2.0], change=[1.0, 2.0], se=[1.0, 1.0]), "not enough tests to forecast"),
    (dict(x=[1.0, 1.0, 2.0], change=[1.0, 2.0, 3.0], se=[1.0] * 3), "do not increase"),
    (dict(x=[1.0, 2.0, 3.0], change=[1.0, np.nan, 3.0], se=[1.0] * 3), "non-finite"),
])
def test_bad_series_are_refused(args: dict, message: str) -> None:
    with pytest.raises(DataError, match=message):
        forecast_series(spread=1.0, threshold=50.0, **args)
    with pytest.raises(DataError, match="horizon must be a finite number > 0"):
        forecast_series([1.0, 2.0, 3.0], [1.0, 2.0, 3.0], [1.0] * 3, 1.0, 50.0, horizon=0.0)


def test_a_unit_whose_friction_rises_is_forecast_by_date(
        wearing: tuple[Path, float], capsys: pytest.CaptureFixture[str]) -> None:
    db, truth = wearing
    capsys.readouterr()
    assert main(["forecast", "--unit", "WEAR", "--db", str(db), "--json",
                 "--horizon", "20"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["by"] == "days" and doc["earliest"] == "D" and doc["checks"] == 15
    d = next(p for p in doc["parameters"] if p["parameter"] == "D")
    assert d["model"] in ("linear", "exponential") and d["rule"] == "friction increase"
    # a check turns no-go short of r2 = +600 %: where the friction symptom's
    # degree reaches the diagnoser's no-go degree, its band taken in
    assert 450.0 < d["threshold_percent"] < 600.0
    assert d["remaining"]["median"] == pytest.approx(truth, rel=0.2)
    assert d["remaining"]["low"] <= truth <= d["remaining"]["high"]
    assert d["date"].startswith("2026-01-") and d["p_within_horizon"] > 0.9
    assert "." not in d["date"]          # to the second
    assert doc["horizon"] == 20.0
    assert main(["forecast", "--unit", "WEAR", "--db", str(db)]) == 0
    text = capsys.readouterr().out
    assert "earliest: D in" in text and "days left" in " ".join(text.split())
    assert "(friction increase)" in " ".join(text.replace("│", " ").split())


def test_a_past_no_go_date_says_the_unit_is_due_a_check(
        wearing: tuple[Path, float], capsys: pytest.CaptureFixture[str]) -> None:
    """The checks end on 2026-01-16: read then, the forecast has no note; read
    in November, its median no-go date is past, and a note says so."""
    import pandas as pd

    from condmon.forecast.unit import forecast_checks
    from condmon.store.forecasts import FleetHistory

    with open_store(str(wearing[0])) as store:
        baseline, checks = FleetHistory(store).checks("WEAR")
    read = {when: forecast_checks("WEAR", checks, baseline, {"D": 600.0}, {},
                                  now=pd.Timestamp(when, tz="UTC"))
            for when in ("2026-01-17", "2026-11-01")}
    assert not any("is past" in n for n in read["2026-01-17"].notes)
    late = read["2026-11-01"]
    assert late.by == "days" and late.parameters[0].parameter == "D"
    date = late.parameters[0].date
    assert date is not None and date < "2026-11-01"
    assert late.notes == (f"D's median no-go date {date[:10]} is past: the last check is "
                          "289 d old; check the unit again",)
    capsys.readouterr()
    assert main(["forecast", "--unit", "WEAR", "--db", str(wearing[0])]) == 0
    assert "is past" in " ".join(capsys.readouterr().out.split())


def test_checks_stored_out_of_date_order_are_forecast_in_date_order(
        wearing: tuple[Path, float], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two checks whose dates are swapped in the history (as when records are
    checked late): the forecast still counts days, in the order tested."""
    import shutil
    import sqlite3

    db = tmp_path / "late.db"
    shutil.copy(wearing[0], db)
    with sqlite3.connect(db) as c:
        rows = c.execute("SELECT t.id, t.test_date FROM tests t JOIN units u ON u.id = "
                         "t.unit_id WHERE u.name = 'WEAR' AND t.role = 'check' "
                         "ORDER BY t.id").fetchall()
        (a, da), (b, db_) = rows[4], rows[8]
        c.execute("UPDATE tests SET test_date = ? WHERE id = ?", (db_, a))
        c.execute("UPDATE tests SET test_date = ? WHERE id = ?", (da, b))
    capsys.readouterr()
    assert main(["forecast", "--unit", "WEAR", "--db", str(db), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["by"] == "days" and not any("counted in tests" in n for n in doc["notes"])
    d = next(p for p in doc["parameters"] if p["parameter"] == "D")
    assert d["remaining"]["median"] == pytest.approx(wearing[1], rel=0.2)


def test_a_stable_unit_has_no_trend(wearing: tuple[Path, float],
                                    capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["forecast", "--unit", "STABLE", "--db", str(wearing[0]), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["earliest"] is None
    assert all(p["model"] == "no trend" and p["remaining"] is None for p in doc["parameters"])


@pytest.mark.parametrize("args,message", [
    (["--unit", "WEAR", "--horizon", "0"], "--horizon must be a finite number > 0"),
    (["--unit", "WEAR", "--horizon", "inf"], "--horizon must be a finite number > 0"),
    (["--unit", "WEARR"], "did you mean 'WEAR'?"),
    (["--unit", "WAER"], "did you mean 'WEAR'?"),      # two letters swapped: one edit
])
def test_forecast_refusals_are_one_line(wearing: tuple[Path, float], args: list[str],
                                        message: str,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["forecast", *args, "--db", str(wearing[0])]) == 2
    err = capsys.readouterr().err
    assert message in " ".join(err.split()) and len(err.strip().splitlines()) <= 2


def test_too_few_checks_is_said(tmp_path: Path, demo_rig, capsys) -> None:  # type: ignore[no-untyped-def]
    db = tmp_path / "few.db"
    with open_store(str(db)) as store:
        add_baseline_tests(store, "U", [simulate_actuator(demo_rig, seed=s) for s in (1, 2, 3)])
        check_test(store, "U", simulate_actuator(demo_rig, seed=9))
    capsys.readouterr()
    assert main(["forecast", "--unit", "U", "--db", str(db)]) == 2
    assert "not enough tests to forecast: unit 'U' has 1 check(s)" in capsys.readouterr().err
    rec = tmp_path / "c.csv"
    simulate_actuator(demo_rig, seed=10).to_csv(rec, index=False)
    assert main(["check", str(rec), "--unit", "U", "--db", str(db), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["forecast"] is None
    assert doc["forecast_reason"].startswith("not enough tests to forecast: unit 'U' has 2")


def test_a_unit_with_regimes_is_forecast_per_regime(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """Each regime's parameter (Tc@forward, Tc@reverse) has its own series."""
    import warnings

    from condmon.errors import DataWarning

    from _strokes import STROKE_DECLARATION

    model = str(STROKE_DECLARATION)   # each record a test: its regimes apart
    files = []
    for s in range(6):
        f = tmp_path / f"r{s}.csv"
        assert main(["simulate", "plant", model, "--out", str(f), "--seed", str(s)]) == 0
        files.append(str(f))
    db = str(tmp_path / "r.db")
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", ".*the record settings ignore column", DataWarning)
        assert main(["baseline", "add", *files[:3], "--unit", "RA", "--model", model,
                     "--db", db]) == 0
        for f in files[3:]:
            assert main(["check", f, "--unit", "RA", "--db", db]) == 0
    capsys.readouterr()
    assert main(["forecast", "--unit", "RA", "--db", db, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    # two speeds each way tell the viscous part too (its truth 0, within its error)
    assert {p["parameter"] for p in doc["parameters"]} == {"Tc@forward", "Tc@reverse",
                                                          "Dv@forward", "Dv@reverse"}
    assert all(p["tests"] == 3 for p in doc["parameters"])
    units = {p["parameter"]: p["unit"] for p in doc["parameters"]}   # a regime's has its parameter's
    assert units["Tc@forward"] == units["Tc@reverse"] == "N m"
    assert units["Dv@forward"] == "N m s/rad"


def test_units_carry_the_earliest_forecast(wearing: tuple[Path, float],
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """``units --json``: the wearing unit's forecast is its friction's, its median
    within 20 % of the true days to no-go; the stable one has none, and says why."""
    db, truth = wearing
    capsys.readouterr()
    assert main(["units", "--db", str(db), "--json"]) == 0
    units = {u["unit"]: u for u in json.loads(capsys.readouterr().out)["units"]}
    f = units["WEAR"]["forecast"]
    assert set(f) == {"parameter", "unit", "by", "median", "low", "high", "date", "rule",
                      "at_hours", "at_no_go"}
    assert (f["parameter"], f["by"], f["rule"]) == ("D", "days", "friction increase")
    assert f["median"] == pytest.approx(truth, rel=0.2) and f["low"] <= truth <= f["high"]
    assert f["unit"] == "N m s/rad" and f["date"].startswith("2026-")
    assert units["WEAR"]["forecast_reason"] is None
    assert units["STABLE"]["forecast"] is None
    assert units["STABLE"]["forecast_reason"] == "no trend towards no-go"
    # the same as `condmon forecast` says
    assert main(["forecast", "--unit", "WEAR", "--db", str(db), "--json"]) == 0
    d = next(p for p in json.loads(capsys.readouterr().out)["parameters"]
             if p["parameter"] == "D")
    assert d["remaining"] == {k: f[k] for k in ("median", "low", "high")}


def test_units_sort_by_urgency(wearing: tuple[Path, float],
                               capsys: pytest.CaptureFixture[str],
                               monkeypatch: pytest.MonkeyPatch) -> None:
    """Fast wear first, slow wear next, the stable unit last; the table says when."""
    from _tables import row

    from condmon.forecast.unit import remaining_text

    db = str(wearing[0])
    capsys.readouterr()
    assert main(["units", "--db", db, "--json", "--sort", "forecast"]) == 0
    units = json.loads(capsys.readouterr().out)["units"]
    assert [u["unit"] for u in units] == ["WEAR", "SLOW", "STABLE"]
    fast, slow = units[0]["forecast"], units[1]["forecast"]
    assert fast["median"] < slow["median"] and fast["date"] < slow["date"]
    assert main(["units", "--db", db, "--json"]) == 0  # by name without --sort
    assert [u["unit"] for u in json.loads(capsys.readouterr().out)["units"]] == [
        "SLOW", "STABLE", "WEAR"]
    monkeypatch.setenv("COLUMNS", "80")
    assert main(["units", "--db", db, "--sort", "forecast"]) == 0
    text = capsys.readouterr().out
    assert text.index("WEAR") < text.index("SLOW") < text.index("STABLE")
    row(text, "unit", "model", "tests", "latest", "date", "status", "no-go in")
    for u in units:
        shown = remaining_text(u["forecast"], u["forecast_reason"])
        row(text, u["unit"], "dc-motor", str(u["tests"]), "record", u["latest_date"][:10],
            u["status"], shown)
    assert main(["units", "--db", db, "--sort", "urgency"]) == 2
    assert "--sort 'urgency': allowed: name, status, date, forecast" in capsys.readouterr().err


def test_check_says_the_forecast(wearing: tuple[Path, float], demo_rig, tmp_path: Path,  # type: ignore[no-untyped-def]
                                 capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    db = tmp_path / "h.db"
    shutil.copy(wearing[0], db)
    rig = demo_rig.with_faults(["D=*4.2", "coulomb_friction=*4.2"])  # day 16
    rec = tmp_path / "day16.csv"
    simulate_actuator(rig, seed=116).to_csv(rec, index=False)
    capsys.readouterr()
    assert main(["check", str(rec), "--unit", "WEAR", "--db", str(db), "--date",
                 "2026-01-17", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    f = doc["forecast"]
    assert f["parameter"] == "D" and f["by"] == "days" and doc["forecast_reason"] is None
    assert f["median"] == pytest.approx(wearing[1] - 1.0, rel=0.25)
    rec2 = tmp_path / "day17.csv"
    simulate_actuator(demo_rig.with_faults(["D=*4.4", "coulomb_friction=*4.4"]),
                      seed=117).to_csv(rec2, index=False)
    assert main(["check", str(rec2), "--unit", "WEAR", "--db", str(db), "--date",
                 "2026-01-18"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "forecast: D no-go in" in text and " d (" in text
    assert "(friction increase)" in text


def test_the_fleet_teaches_a_new_unit_its_rate(tmp_path: Path, demo_rig,  # type: ignore[no-untyped-def]
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """Two units of the group wore out (friction +100 % a day, to advisory and
    no-go); a new unit of the group starts on the same path: its forecast of
    D updates the fleet's prior (their shape and rate) and crosses when they
    did; a unit of another group learns nothing from them ("no fleet history")."""
    db = str(tmp_path / "fleet.db")
    with open_store(db) as store:
        for i, (unit, group, days) in enumerate((("OLD1", "line-a", 9), ("OLD2", "line-a", 9),
                                                 ("NEW", "line-a", 4), ("ELSE", "line-b", 4))):
            add_baseline_tests(store, unit, [simulate_actuator(demo_rig, seed=10 * i + s)
                                             for s in (1, 2, 3)], test_date="2026-01-01")
            for k in range(1, days + 1):
                rig = demo_rig.with_faults([f"D=*{1.0 + k}", f"coulomb_friction=*{1.0 + k}"])
                check_test(store, unit, simulate_actuator(rig, seed=300 + 10 * k + i),
                           test_date=f"2026-01-{1 + k:02d}", group=group)
        assert {str(s) for s in store.history("OLD1")["status"].dropna()} & {"advisory", "no-go"}
        # the day each worn unit's checks first turned no-go (the 5th for both)
        first_nogo = {u: int(store.history(u).query("status == 'no-go'")["test_date"].min().day) - 1
                      for u in ("OLD1", "OLD2")}
        # the worn units' wear was kept by their own checks: a prior reads it, not
        # their histories, and it is the wear their histories give
        from condmon.store.forecasts import FleetHistory

        kept = FleetHistory(store)
        read: list[str] = []
        real_history = store.history
        store.history = lambda u: read.append(u) or real_history(u)  # type: ignore[method-assign]
        assert kept.learning_peers("NEW") == ["OLD1", "OLD2"] and read == []
        store.history = real_history  # type: ignore[method-assign]
        fresh = FleetHistory(store)
        fresh.learning_peers("ELSE")
        for unit in ("OLD1", "OLD2"):
            assert kept._wear[(unit, "D", "days")] == pytest.approx(
                fresh._unit_wear(unit, "D", "days"))
        # rates kept before the exponential's amplitude was (three fields) are
        # not taken as current: the peers' histories are read again
        real_kept = store.kept_rates
        store.kept_rates = lambda units: {  # type: ignore[method-assign]
            u: (mark, {k: v if v is None else v[:3] for k, v in rates.items()})
            for u, (mark, rates) in real_kept(units).items()}
        store.history = lambda u: read.append(u) or real_history(u)  # type: ignore[method-assign]
        old = FleetHistory(store)
        old.learning_peers("NEW")
        assert old._unit_wear("OLD1", "D", "days") == pytest.approx(
            fresh._unit_wear("OLD1", "D", "days")) and "OLD1" in read
        store.history, store.kept_rates = real_history, real_kept  # type: ignore[method-assign]
    capsys.readouterr()
    assert main(["forecast", "--unit", "NEW", "--db", db, "--json"]) == 0
    d = next(p for p in json.loads(capsys.readouterr().out)["parameters"]
             if p["parameter"] == "D")
    prior = next(n for n in d["notes"] if n.startswith("fleet prior"))
    assert "from 2 units" in prior
    # the estimated friction of the worn units grew a little faster than the
    # true one (their daily rises 120, 100, 140, 90, 130, 150 %): their own
    # evidence chose a mildly curved exponential, but its slope grew less than
    # e-fold over their 9 days, so what they teach is their slope (a line)
    assert "(0 wore exponentially)" in prior
    slope = float(prior.split("slope ")[1].split(" ±")[0])
    assert slope == pytest.approx(125.0, rel=0.15)        # [%/day]
    # both turned no-go at their 5th day's check (+510 %, short of r2 = +600 %:
    # where the symptom's degree reaches no-go); the new unit, on the same path,
    # is due before its 5th day (its 4th day was its last check)
    assert first_nogo == {"OLD1": 5, "OLD2": 5}
    assert d["model"] == "linear" and 0.0 < d["remaining"]["median"] < 1.0
    assert main(["forecast", "--unit", "ELSE", "--db", db]) == 0
    assert "prior: no fleet history: vague prior" in capsys.readouterr().out
    # a unit of the group counted in tests (its checks undated): the worn units,
    # counted in days, teach it nothing, and their kept rates say so without a
    # read of their histories
    with open_store(db) as store:
        from condmon.store.forecasts import FleetHistory

        fleet = FleetHistory(store)
        read: list[str] = []
        real_history = store.history
        store.history = lambda u: read.append(u) or real_history(u)  # type: ignore[method-assign]
        assert fleet.learning_peers("NEW") == ["OLD1", "OLD2"]
        assert fleet._unit_wear("OLD1", "D", "tests") is None and read == []
        assert fleet.priors("NEW", ["D"], "tests")[("D", 1.0)].describe() == (
            "none of 2 degraded peer(s) has D counted in tests: vague prior")
        store.history = real_history  # type: ignore[method-assign]
        assert FleetHistory(store)._unit_wear("OLD1", "D", "tests") is None   # read: the same


def test_a_listing_forecasts_only_what_changed(wearing: tuple[Path, float],
                                               monkeypatch: pytest.MonkeyPatch,
                                               tmp_path: Path) -> None:
    """A check keeps its unit's forecast; a listing uses the kept ones, and
    forecasts again a unit whose history changed since (here: a test excluded)."""
    import shutil

    import condmon.store.kept as F

    db = str(tmp_path / "h.db")
    shutil.copy(wearing[0], db)
    with open_store(db) as store:
        first = {r["unit"]: r["forecast"] for r in F.fleet_summaries(store)}
        assert set(store.kept_forecasts()) == {"WEAR", "SLOW", "STABLE"}
        F._MADE.clear()
        made: list[str] = []
        real = F.try_forecast

        def counted(store_: object, unit: str, fleet: object = None,
                    summary: object = None) -> object:
            made.append(unit)
            return real(store_, unit, fleet, summary)  # type: ignore[arg-type]

        monkeypatch.setattr(F, "try_forecast", counted)
        again = {r["unit"]: r["forecast"] for r in F.fleet_summaries(store)}
        assert made == [] and again == first
        last = int(store.history("SLOW").index[-1])
        store.set_excluded(last, True, "a bad record")
        F.fleet_summaries(store)
        assert made == ["SLOW"]


def test_a_unit_with_operating_hours_is_forecast_in_hours(tmp_path: Path, demo_rig,  # type: ignore[no-untyped-def]
                                                          capsys: pytest.CaptureFixture[str]
                                                          ) -> None:
    """Friction rises 2 % an operating hour; checks every 10 to 40 h (uneven),
    one a day: the forecast counts hours, says the hours and the date at
    no-go (at the unit's usage, about 25 h a day)."""
    from condmon.workflows.records import EstimateOptions

    db = str(tmp_path / "hours.db")
    rng = np.random.default_rng(3)
    hours = np.cumsum(rng.uniform(10.0, 40.0, 10))
    with open_store(db) as store:
        add_baseline_tests(store, "H", [simulate_actuator(demo_rig, seed=s) for s in (1, 2, 3)],
                           test_date="2026-01-01")
        for k, h in enumerate(hours):
            f = 1.0 + 0.02 * h
            rig = demo_rig.with_faults([f"D=*{f}", f"coulomb_friction=*{f}"])
            check_test(store, "H", simulate_actuator(rig, seed=40 + k),
                       EstimateOptions(metadata={"hours": f"{h:.3f}"}),
                       test_date=f"2026-01-{2 + k:02d}")
        assert store.history("H")["hours"].dropna().to_numpy() == pytest.approx(hours, abs=1e-3)
        # the truth: the hours at which a check turns no-go (dry runs)
        at = next(h for h in np.arange(hours[-1], 2000.0, 5.0)
                  if check_test(store, "H", simulate_actuator(demo_rig.with_faults(
                      [f"D=*{1 + 0.02 * h}", f"coulomb_friction=*{1 + 0.02 * h}"]),
                      seed=int(h)), dry_run=True).status == "no-go")
    capsys.readouterr()
    assert main(["forecast", "--unit", "H", "--db", db, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["by"] == "hours" and doc["earliest"] == "D"
    d = next(p for p in doc["parameters"] if p["parameter"] == "D")
    # the truth is one check's crossing (its own scatter: about ±20 h here)
    assert d["remaining"]["median"] == pytest.approx(at - hours[-1], rel=0.4)
    assert d["remaining"]["low"] <= at - hours[-1] <= d["remaining"]["high"]
    assert d["at_hours"] == pytest.approx(hours[-1] + d["remaining"]["median"], abs=1e-3)
    assert d["at_hours"] == pytest.approx(at, rel=0.1) and d["date"].startswith("2026-01-1")
    assert main(["units", "--db", db, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["units"][0]["forecast"]["by"] == "hours"


def test_bad_hours_are_one_line(tmp_path: Path, demo_rig, capsys) -> None:  # type: ignore[no-untyped-def]
    rec = tmp_path / "r.csv"
    simulate_actuator(demo_rig, seed=5).to_csv(rec, index=False)
    db = str(tmp_path / "h.db")
    with open_store(db) as store:
        add_baseline_tests(store, "U", [simulate_actuator(demo_rig, seed=s) for s in (1, 2, 3)])
    capsys.readouterr()
    assert main(["check", str(rec), "--unit", "U", "--db", db, "--meta", "hours=-4"]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "r.csv: metadata 'hours' must be a finite number >= 0 [h], not -4" in err


def test_a_mistyped_history_is_not_made(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                        ) -> None:
    typo = tmp_path / "typo.db"
    assert main(["forecast", "--unit", "X", "--db", str(typo)]) == 2
    assert "no history database there" in capsys.readouterr().err and not typo.exists()


def test_the_axis_says_why_it_does_not_count_hours() -> None:
    """Operating hours that go back (a counter read wrong) leave the forecast in days, and say so."""
    import pandas as pd

    from condmon.forecast.unit import forecast_axis

    checks = pd.DataFrame({"test_date": ["2026-01-01", "2026-01-02", "2026-01-03"],
                           "hours": [1120.0, 1960.0, 100.0]}, index=[5, 6, 7])
    axis = forecast_axis(checks)
    assert axis.by == "days"
    assert axis.note == ("counted in days, not operating hours: test #7 has 100 h, not after "
                         "the check before it (1960 h)")


def test_no_history_here_points_at_the_demo_s(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "condmon-demo").mkdir()
    with open_store(str(tmp_path / "condmon-demo" / "condmon.db")):
        pass
    monkeypatch.chdir(tmp_path)
    assert main(["units"]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "`condmon demo` wrote its history to condmon-demo/condmon.db" in err


def test_the_bounded_minimum_is_scipys_to_the_bit() -> None:
    """The exponential's rate is found without importing scipy.optimize, by the
    same Brent steps as its bounded minimize_scalar."""
    from scipy.optimize import minimize_scalar

    from condmon.monitor.bounded import bounded_minimum

    rng = np.random.default_rng(11)
    functions = [lambda x: (x - 0.3) ** 2, lambda x: np.cos(3 * x) + 0.1 * x,
                 lambda x: abs(x - 0.71), lambda x: np.exp(x) - 2 * x]
    for f in functions:
        for _ in range(25):
            lo = float(rng.uniform(-3, 1))
            hi = lo + float(rng.uniform(1e-6, 4))
            ref = float(minimize_scalar(f, method="bounded", bounds=(lo, hi)).x)
            assert bounded_minimum(lambda v: float(f(v)), lo, hi) == ref
    with pytest.raises(ValueError, match="bounds"):
        bounded_minimum(lambda v: v, 1.0, 0.0)


def test_the_first_check_past_no_go_is_searched_from_where_it_can_pass() -> None:
    """A slow path (0.2 %/test, a check's scatter 1 %, no-go 100 % about 500
    tests on): the search starts where a check could pass (8 scatters short
    of no-go), and its distribution is the one of reading every check."""
    import math

    from condmon.forecast.series import _left

    coef = np.array([0.0, 0.2])

    def fixed(rng: np.random.Generator, size: int) -> np.ndarray:
        return np.tile(coef, (size, 1))

    fast = _left("linear", fixed, 1.0, 1.0, 100.0, 0.0, np.random.default_rng(1), 2000, step=1.0)
    rng = np.random.default_rng(2)
    k = np.arange(1.0, 701.0)
    seen = 0.2 * k[None, :] + rng.normal(0.0, 1.0, (2000, k.size))
    every = k[np.argmax(seen >= 100.0, axis=1)]
    assert all(float(v).is_integer() for v in fast)
    for q in (0.05, 0.5, 0.95):
        assert abs(np.quantile(fast, q) - np.quantile(every, q)) <= 1.0
    assert math.isclose(np.mean(fast), np.mean(every), abs_tol=0.5)


def _falling(key_change: list[float]) -> tuple[object, object]:
    """Five dated checks of D falling as given [%], and a baseline of D = 2.0 N m s ± 0.05."""
    import pandas as pd

    from condmon.monitor.baseline import Baseline

    n = len(key_change)
    checks = pd.DataFrame({"test_date": pd.date_range("2026-03-01", periods=n, freq="D"),
                           "D_change": key_change, "D_se": np.full(n, 0.02)},
                          index=range(10, 10 + n))
    return checks, Baseline(("D",), (2.0,), (0.05,), 5)


def test_no_go_that_cannot_come_is_no_trend() -> None:
    """A friction falling -20 %/day cannot reach -600 % (it is >= 0: -100 % at
    most), and with no major rule on its fall it cannot turn a check no-go
    at all: both are "no trend" with the reason, never a date; a rise of a
    parameter whose own rule is minor (advisory at most) likewise."""
    from condmon.forecast.unit import NoGo, forecast_checks

    checks, baseline = _falling([-20.0, -40.0, -60.0, -80.0, -95.0])
    cases = {"past its plausible values": (NoGo(300.0, 600.0, lower=0.0), "end at -100 %"),
             "no rule": (NoGo(300.0, 600.0, fall=float("inf")), "no major fault rule names a fall")}
    for nogo, said in cases.values():
        f = forecast_checks("U", checks, baseline, {"D": nogo}, {}).parameters[0]
        assert f.forecast.model == "no trend" and f.forecast.remaining is None and f.date is None
        assert said in " ".join(f.forecast.notes)
    plain = forecast_checks("U", checks, baseline, {"D": 600.0}, {}).parameters[0]
    assert plain.forecast.remaining is not None and plain.forecast.threshold == -600.0


def test_the_machine_says_where_each_parameter_turns_a_check_no_go() -> None:
    """The actuator's rules: a friction or resistance rise names a major fault
    (no-go at the diagnoser's degree), an inertia rise a minor one (never
    no-go alone), no fall names a fault; friction and resistance are >= 0."""
    from condmon.diagnose.diagnoser import nogo_degree
    from condmon.models.registry import get_model
    from condmon.store.forecasts import machine_nogo

    nogo, rules = machine_nogo(get_model("dc-motor"))
    degree = nogo_degree()
    assert 0.6 < degree < 0.8
    assert nogo["D"].rise == degree and nogo["R"].rise == degree
    assert nogo["J"].rise == float("inf") and nogo["D"].fall == float("inf")
    assert nogo["D"].lower == 0.0 and nogo["R"].lower == 0.0
    assert rules["high(D)"] == "friction increase"
    assert rules["high(R)"] == "winding resistance increase"   # "high(R) and not high(L)"
    # where a D check turns no-go: its degree reached at a 20 % half-width
    assert nogo["D"].change(20.0, True) == pytest.approx(300.0 + degree * 320.0 - 20.0)


def test_a_peer_that_wore_another_way_teaches_nothing() -> None:
    """Peers whose friction rose teach a rising unit; one whose friction fell,
    or did not move (it degraded on another parameter), is left out."""
    from condmon.forecast.prior import prior_from_wear, unit_wear

    x = np.arange(1.0, 21.0)
    rng = np.random.default_rng(3)

    def wear(slope: float) -> object:
        return unit_wear(x, slope * x + rng.normal(0.0, 1.0, 20), np.full(20, 1.0), 1.0)

    rose = [wear(s) for s in (4.0, 4.4, 3.6)]
    fell, flat = wear(-3.0), wear(0.0)
    assert [w.direction for w in (*rose, fell, flat)] == [1.0, 1.0, 1.0, -1.0, 0.0]
    prior = prior_from_wear([*rose, fell, flat], direction=1.0)
    assert prior.units == 3 and prior.linear.mean == pytest.approx(4.0, abs=0.3)
    mixed = prior_from_wear([*rose, fell, flat])
    assert mixed.units == 5 and mixed.linear.mean < 3.0
    assert prior_from_wear([fell, flat], direction=1.0).describe() == (
        "none of 2 degraded peer(s) wore this way (a rise): vague prior")


def test_forecasts_kept_by_an_older_method_are_made_again(
        wearing: tuple[Path, float], tmp_path: Path) -> None:
    """A history whose kept forecasts another forecast method made (one whose
    no-go was r2) has them dropped and made again when a listing reads it."""
    import shutil

    import sqlalchemy as sa

    from condmon.store import kept
    from condmon.store import schema as S

    db = tmp_path / "h.db"
    shutil.copy(wearing[0], db)
    with open_store(str(db)) as store:
        good = {r["unit"]: r["forecast"] for r in kept.fleet_summaries(store)}["WEAR"]
        assert store.forecast_method() == kept.FORECAST_METHOD
        stale = {**good, "median": 999.0}
        store.keep_forecasts([("WEAR", store.history_marks(["WEAR"])["WEAR"], 0, stale, None)])
        store._write(lambda c: c.execute(sa.update(S.meta).where(
            S.meta.c.key == "forecast_method").values(value="1")), lock=None)
        assert {r["unit"]: r["forecast"] for r in kept.fleet_summaries(store)}["WEAR"][
            "median"] == 999.0                 # this process already knew it current
        kept._CURRENT.discard(store.url)
        again = {r["unit"]: r["forecast"] for r in kept.fleet_summaries(store)}["WEAR"]
        assert again["median"] == pytest.approx(good["median"])
        assert store.forecast_method() == kept.FORECAST_METHOD


def test_no_go_the_way_the_last_checks_point_cannot_come_so_the_other_way_is_forecast() -> None:
    """A change that climbs from -30 % at +4 %/day, its last three checks still
    below 0: a fall of it names no rule, so the rise's no-go is forecast; a
    parameter whose rise and fall both name none says so."""
    from condmon.forecast.unit import NoGo, forecast_checks

    checks, baseline = _falling([-30.0, -26.0, -22.0, -18.0, -14.0, -10.0, -6.0, -2.0])
    f = forecast_checks("U", checks, baseline, {"D": NoGo(20.0, 40.0, fall=float("inf"))},
                        {"high(D)": "friction increase"}).parameters[0]
    assert f.forecast.trend and f.forecast.threshold == 40.0 and f.rule == "friction increase"
    assert f.forecast.remaining is not None
    assert f.forecast.remaining[0] == pytest.approx(10.5, abs=1.0)     # (40 + 2) / 4
    flat, _ = _falling([1.0, -1.0, 0.5, -0.5, 0.2, -0.3])
    never = NoGo(20.0, 40.0, rise=float("inf"), fall=float("inf"))
    g = forecast_checks("U", flat, baseline, {"D": never}, {}).parameters[0].forecast
    assert not g.trend and "nor the other way" in g.unreachable


def test_a_stable_series_trends_no_more_often_than_its_interval_says() -> None:
    """The slope's 90 % interval leaves 5 % above 0: stable series scattered
    as stated are called a trend towards a rise about that often, and less
    when they scatter less than stated (a trend must stand out of the tests'
    stated uncertainty)."""
    rng = np.random.default_rng(2)
    x = np.arange(1.0, 16.0)
    for sd, low, high in ((np.sqrt(3.0 ** 2 + 2.0 ** 2), 8, 32), (3.0, 0, 20)):
        trends = sum(forecast_series(x, rng.normal(0.0, sd, 15), np.full(15, 3.0), 2.0,
                                     threshold=40.0).trend for _ in range(400))
        assert low <= trends <= high, (sd, trends)      # 5 % of 400 is 20 ± 4.4


def test_the_whole_check_interval_ends_at_its_mid_p_quantiles() -> None:
    """A value counts half towards the tail it ends: 3 checks at 8 %, 4 at
    84 %, 5 at 8 % is the interval [4, 4] (its content 84 %, the nearest to
    90 % a whole-check interval can hold), where the 5 % and 95 % quantiles
    would give [3, 5] (100 %)."""
    left = np.repeat([3.0, 4.0, 5.0], [8, 84, 8])
    assert median_interval(left, whole=True) == (4.0, 4.0, 4.0)
    assert median_interval(left, whole=False) == (4.0, 3.0, 5.0)
    left = np.repeat([3.0, 4.0, 5.0, np.inf], [2, 30, 50, 18])   # inf: never
    assert median_interval(left, whole=True) == (5.0, 4.0, np.inf)


def test_a_steady_move_sets_the_way_not_the_last_checks() -> None:
    """A change that climbs from -30 % at +4 %/day, its last three checks still
    below 0, where both a rise and a fall can turn a check no-go: the rise's
    no-go is forecast (the slope's interval is clear of 0); a flat series
    whose last checks dip heads for the fall's, and says "no trend"."""
    from condmon.forecast.unit import NoGo, forecast_checks

    checks, baseline = _falling([-30.0, -26.0, -22.0, -18.0, -14.0, -10.0, -6.0, -2.0])
    f = forecast_checks("U", checks, baseline, {"D": NoGo(20.0, 40.0)}, {}).parameters[0]
    assert f.forecast.trend and f.forecast.threshold == 40.0
    flat, _ = _falling([1.0, -1.0, 0.5, -0.5, 0.2, -0.3, -0.2, -0.4])
    g = forecast_checks("U", flat, baseline, {"D": NoGo(20.0, 40.0)}, {}).parameters[0]
    assert not g.forecast.trend and g.forecast.threshold == -40.0


def test_checks_that_drift_together_are_not_a_trend_by_chance() -> None:
    """Stable series whose checks drift together (AR(1), ρ = 0.6, as the real
    actuators' Coulomb friction does): read as independent tests, 14 % of
    them would trend towards a rise; with the residuals' autocorrelation
    taken in, about the interval's 5 % (10 of 200, binomial sd 3.1)."""
    rng = np.random.default_rng(4)
    sd, rho = np.sqrt(3.0 ** 2 + 2.0 ** 2), 0.6
    trends = 0
    for _ in range(200):
        e = np.empty(30)
        e[0] = rng.normal(0.0, sd)
        for k in range(1, 30):
            e[k] = rho * e[k - 1] + rng.normal(0.0, sd * np.sqrt(1.0 - rho ** 2))
        trends += forecast_series(np.arange(1.0, 31.0), e, np.full(30, 3.0), 2.0,
                                  threshold=40.0).trend
    assert trends <= 19, trends


def _magnet(ke: float, kt: float, n: int = 12) -> tuple[object, object]:
    """``n`` dated checks of Ke and Kt changing ``ke`` and ``kt`` % a day,
    a baseline of both 0.05 ± 1 %."""
    import pandas as pd

    from condmon.monitor.baseline import Baseline

    day = np.arange(1.0, n + 1.0)
    noise = np.random.default_rng(8).normal(0.0, 0.3, (2, n))
    checks = pd.DataFrame({"test_date": pd.date_range("2026-03-01", periods=n, freq="D"),
                           "Ke_change": ke * day + noise[0], "Ke_se": np.full(n, 0.0005),
                           "Kt_change": kt * day + noise[1], "Kt_se": np.full(n, 0.0005)},
                          index=range(10, 10 + n))
    return checks, Baseline(("Ke", "Kt"), (0.05, 0.05), (0.0005, 0.0005), 5)


def test_a_fault_of_two_symptoms_turns_no_go_when_the_later_comes() -> None:
    """Magnet weakening is ``low(Ke) and low(Kt)``: neither names a fault
    alone, yet both falling turn a check no-go when the later reaches its
    no-go change. Kt falling faster waits for Ke; the unit's earliest is Ke's,
    the rule named with its partner. With Kt steady, Ke's fall cannot make a
    check no-go: "no trend", and why."""
    from condmon.models.registry import get_model
    from condmon.forecast.unit import forecast_checks
    from condmon.store.forecasts import machine_nogo

    nogo, rules = machine_nogo(get_model("dc-motor"))
    assert nogo["Ke"].fall_with == ("low(Kt)",) and rules["low(Ke)"] == "magnet weakening"
    checks, baseline = _magnet(-2.0, -3.0)
    f = forecast_checks("M", checks, baseline, nogo, rules)
    by = {p.parameter: p for p in f.parameters}
    assert by["Ke"].forecast.trend and by["Kt"].forecast.trend
    assert by["Kt"].waits_for == "Ke" and not by["Ke"].waits_for
    assert f.earliest is by["Ke"] and by["Ke"].rule == "magnet weakening, with Kt"
    threshold = by["Ke"].forecast.threshold
    assert threshold < 0
    truth = threshold / -2.0 - 12.0                 # days from the last check
    assert by["Ke"].forecast.remaining[1] <= truth <= by["Ke"].forecast.remaining[2]
    assert f.summary()["parameter"] == "Ke"
    checks, baseline = _magnet(-2.0, 0.0)
    g = {p.parameter: p for p in forecast_checks("M", checks, baseline, nogo, rules).parameters}
    assert not g["Ke"].forecast.trend and "needs low(Kt) too" in g["Ke"].forecast.unreachable


def test_a_series_whose_last_check_measured_past_no_go_is_at_no_go_now() -> None:
    """A check past the no-go change is at no-go: no draw says when (before, in
    whole checks, "1 test (1–1)"; in days "0 d (0–0.67)")."""
    x = np.arange(1.0, 11.0)
    for step in (1.0, None):
        f = forecast_series(x, 11.0 * x, np.full(10, 1.0), 2.0, threshold=105.0, step=step,
                            horizon=3.0)
        assert f.remaining == (0.0, 0.0, 0.0) and f.p_within == 1.0 and f.at_nogo
        assert "at no-go now" in f.notes[-1]
    # a path past no-go in days whose last check was not: due now, not at no-go
    g = forecast_series(x, np.r_[11.0 * x[:-1], 100.0], np.full(10, 1.0), 2.0, threshold=105.0,
                        step=None)
    assert not g.at_nogo
    from condmon.forecast.unit import remaining_text
    zero = {"median": 0.0, "low": 0.0, "high": 0.0, "by": "days"}
    assert remaining_text({**zero, "at_no_go": True}) == "at no-go now"
    assert remaining_text(zero) == "due now (its trend is past no-go)"
    assert remaining_text({"median": 1.0, "low": 1.0, "high": 2.0, "by": "tests"}) == "1 test (1–2)"


def test_the_report_index_lists_units_by_urgency(wearing: tuple[Path, float],
                                                 tmp_path: Path) -> None:
    """The static report's index: a "no-go in" column, the soonest first (WEAR
    before SLOW, the stable unit last, "no trend")."""
    import re

    from condmon.report.html import write_fleet_index

    with open_store(str(wearing[0]), create=False) as store:
        index = write_fleet_index(store, tmp_path).read_text()
    assert "<th class='l'>no-go in</th>" in index and "By urgency" in index
    order = [u for u in re.findall(r"<tr><td class='l'>(\w+)", index)]
    assert order == ["WEAR", "SLOW", "STABLE"], order
    stable = re.search(r"<tr><td class='l'>STABLE.*?</tr>", index)
    assert stable is not None and "no trend" in stable.group(0)


def test_a_check_past_its_no_go_change_whose_status_is_not_no_go_is_due_now() -> None:
    """Its measured change passed the no-go change, but its own (wider) symptom
    kept it advisory: the unit is due now, not at no-go now."""
    from condmon.forecast.unit import NoGo, forecast_checks

    checks, baseline = _falling([-10.0, -20.0, -30.0, -40.0, -45.0])
    for status, at in (("advisory", False), ("no-go", True)):
        checks["status"] = ["go", "go", "advisory", "advisory", status]
        f = forecast_checks("U", checks, baseline, {"D": NoGo(20.0, 40.0, lower=-100.0)}, {})
        p = f.parameters[0].forecast
        assert p.remaining == (0.0, 0.0, 0.0) and p.at_nogo is at, status
        assert f.summary() is not None and f.summary()["at_no_go"] is at


def test_check_prints_no_interval_words_for_a_unit_at_no_go(
        capsys: pytest.CaptureFixture[str]) -> None:
    """After a check at no-go, its forecast line gives no "median (90 %
    interval)" (there are no numbers); a forecast with numbers does."""
    from condmon.cli.check import _print_forecast

    base = {"parameter": "D", "by": "tests", "date": None, "rule": "friction increase"}
    capsys.readouterr()
    _print_forecast({"forecast": {**base, "median": 0.0, "low": 0.0, "high": 0.0,
                                  "at_no_go": True}})
    _print_forecast({"forecast": {**base, "median": 4.0, "low": 3.0, "high": 6.0,
                                  "at_no_go": False}})
    now, later = capsys.readouterr().out.splitlines()
    assert "at no-go now (friction increase)" in now and "interval" not in now
    assert "no-go in 4 tests (3–6)" in later and "median (90 % interval)" in later


def test_peers_wear_fitted_after_a_method_change_is_kept_for_the_next_check(
        tmp_path: Path, demo_rig) -> None:  # type: ignore[no-untyped-def]
    """After the kept forecasts are dropped (a new forecast method, a copied
    history), a check reads no peer's history: the peers whose wear is not
    kept are left out of its prior, and it says so. `condmon forecast` fits
    their wear and keeps it; the next check reads it back and reads no
    peer's history; the listing still forecasts each peer (the kept row
    holds no forecast)."""
    from condmon.store.forecasts import FleetHistory
    from condmon.store.kept import (
        FORECAST_METHOD, PEER_RATES_ONLY, fleet_summaries, keep_forecast,
    )
    from condmon.workflows.forecasting import forecast_unit

    db = str(tmp_path / "renew.db")
    with open_store(db) as store:
        for i, (unit, days) in enumerate((("OLD1", 6), ("OLD2", 6), ("NEW", 3))):
            add_baseline_tests(store, unit, [simulate_actuator(demo_rig, seed=10 * i + s)
                                             for s in (1, 2, 3)], test_date="2026-01-01")
            for k in range(1, days + 1):
                rig = demo_rig.with_faults([f"D=*{1.0 + k}", f"coulomb_friction=*{1.0 + k}"])
                check_test(store, unit, simulate_actuator(rig, seed=300 + 10 * k + i),
                           test_date=f"2026-01-{1 + k:02d}")
        store.renew_forecasts(FORECAST_METHOD)
        assert store.kept_rates(["OLD1", "OLD2"]) == {}
        read: list[str] = []
        real_history = store.history
        store.history = lambda u: read.append(u) or real_history(u)  # type: ignore[method-assign]
        check_test(store, "NEW", simulate_actuator(demo_rig.with_faults(["D=*5", "coulomb_friction=*5"]),
                                                   seed=999), test_date="2026-01-05")
        assert "OLD1" not in read and "OLD2" not in read   # the check fitted no peer
        cold = FleetHistory(store, fit_peers=False)
        assert cold.learning_peers("NEW") == [] and cold.unfitted == {"OLD1", "OLD2"}
        assert "the wear of 2 degraded peer(s) is not kept yet" in cold.priors(
            "NEW", ["D"], "days")[("D", 1.0)].why
        assert store.kept_forecasts(["NEW"])["NEW"][1] == PEER_RATES_ONLY  # listed afresh
        store.history = real_history  # type: ignore[method-assign]
        forecast_unit(store, "NEW")   # fits the peers' wear, and keeps it
        kept = store.kept_forecasts(["OLD1", "OLD2"])
        assert {u: v[1] for u, v in kept.items()} == {"OLD1": PEER_RATES_ONLY,
                                                      "OLD2": PEER_RATES_ONLY}
        store.history = lambda u: read.append(u) or real_history(u)  # type: ignore[method-assign]
        read.clear()
        again = FleetHistory(store, fit_peers=False)
        assert again.learning_peers("NEW") == ["OLD1", "OLD2"] and not again.unfitted
        again.priors("NEW", ["D"], "days")
        assert read == [] and again.fitted() == []
        keep_forecast(store, "NEW")
        assert read == ["NEW"]   # its own history only
        store.history = real_history  # type: ignore[method-assign]
        fresh = FleetHistory(store)
        fresh.learning_peers("NEW")
        fresh._current.clear()
        fresh._wear.clear()
        for unit in ("OLD1", "OLD2"):
            assert again._wear[(unit, "D", "days")] == pytest.approx(
                fresh._unit_wear(unit, "D", "days"))
        rows = {r["unit"]: r for r in fleet_summaries(store)}
        assert rows["OLD1"]["forecast_reason"] is not None or rows["OLD1"]["forecast"]
        assert store.kept_forecasts(["OLD1"])["OLD1"][1] != PEER_RATES_ONLY


def test_checks_within_one_session_are_forecast_per_clock_hour(
        tmp_path: Path, demo_rig, capsys: pytest.CaptureFixture[str]) -> None:  # type: ignore[no-untyped-def]
    """Checks 10 minutes apart gave slopes in %/day: a 26-minute session's
    trend extrapolated to a day (-30516 %/day). Friction rising 60 % of its
    healthy value an hour reads about +60 %/h; --json still counts days."""
    db = tmp_path / "h.db"
    with open_store(str(db)) as store:
        add_baseline_tests(store, "SHIFT", [simulate_actuator(demo_rig, seed=s) for s in (1, 2, 3)],
                           test_date="2026-01-01T07:00:00")
        for k in range(1, 9):
            f = 1.0 + 0.1 * k          # +10 % every 10 minutes
            rig = demo_rig.with_faults([f"D=*{f}", f"coulomb_friction=*{f}"])
            check_test(store, "SHIFT", simulate_actuator(rig, seed=500 + k),
                       test_date=f"2026-01-01T{8 + (k - 1) // 6:02d}:{10 * ((k - 1) % 6):02d}:00")
    assert main(["forecast", "--unit", "SHIFT", "--db", str(db), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    d = next(p for p in doc["parameters"] if p["parameter"] == "D")
    assert doc["by"] == "days" and d["slope"] == pytest.approx(60 * 24, rel=0.35)
    assert main(["forecast", "--unit", "SHIFT", "--db", str(db)]) == 0
    text = " ".join(capsys.readouterr().out.replace("│", " ").split())
    assert "slope [%/h]" in text and "clock hours left (90 %)" in text
    assert "the checks span 1.2 h: slopes and times left are per hour of clock time" in text
    row = text[text.index(" D ") + 3:].split()
    assert float(row[0]) == pytest.approx(d["slope"] / 24, rel=0.02)
    assert "earliest: D in" in text and "clock hours" in text.split("earliest: D in")[1][:30]
