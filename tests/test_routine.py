"""Routine records: a rig's raw files, windows and regimes, identifiability, the steady route.

Records are synthetic strokes of a hydraulic rotary actuator with known
friction (tests/_strokes.py), written as the test stand writes them.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from _strokes import DECLARATION, TRUTH, stroke, write_stroke
from condmon.cli.main import main
from condmon.errors import ConfigError, DataError, ModelError
from condmon.identify import estimate
from condmon.identify.estimate import estimate_joint
from condmon.identify.identifiability import assess_identifiability
from condmon.identify.windows import cut_windows, parse_window
from condmon.io import read_record
from condmon.io.rig import (
    RecordSettings, apply_record_settings, parse_record_settings, settings_from_options,
)
from condmon.models.registry import get_model
from condmon.models.regimes import parse_condition, parse_regimes

MODEL = str(DECLARATION)


# --- the [record] settings ------------------------------------------------------------

def test_record_settings_turn_counts_into_si_columns() -> None:
    s = parse_record_settings({"sample_rate": 250, "ignore": ["junk"], "columns": {
        "t": "Time", "theta": {"column": "Angle", "scale": 0.5, "offset": -1.0}}},
        "rig.toml[record]")
    raw = pd.DataFrame({"Time": [1, 2, 3], "Angle": [10, 12, 14], "junk": ["a", "b", "c"]})
    df = apply_record_settings(raw, s, "rig.txt")
    assert list(df.columns) == ["t", "theta"]
    assert df["t"].tolist() == [0.0, 0.004, 0.008]
    assert df["theta"].tolist() == [4.0, 5.0, 6.0]
    assert "sample rate 250 Hz" in df.attrs["record_settings"]


def test_a_missing_time_column_is_made_from_the_sample_rate() -> None:
    df = apply_record_settings(pd.DataFrame({"x": [1.0, 2.0]}), RecordSettings(sample_rate=2.0))
    assert df["t"].tolist() == [0.0, 0.5]


def test_later_settings_win_key_by_key() -> None:
    decl = RecordSettings({"p": "PG_1"}, 250.0, {"p": 1.0}, sources=("decl",))
    unit = RecordSettings(scale={"p": 2.0}, ignore=("x",), sources=("unit.toml",))
    cli = settings_from_options(sample_rate=100.0)
    m = decl.merged(unit).merged(cli)
    assert m.columns == {"p": "PG_1"} and m.scale == {"p": 2.0} and m.sample_rate == 100.0
    assert m.ignore == ("x",) and m.sources == ("decl", "unit.toml", "command line")


@pytest.mark.parametrize("table,message", [
    ({"sample_rate": 0}, r"sample_rate must be > 0"),
    ({"sample_rate": -250}, r"sample_rate must be > 0"),
    ({"scale": {"theta": math.inf}}, r"scale.theta must be a finite number"),
    ({"scale": {"theta": 0.0}}, r"must not be 0"),
    ({"offset": {"theta": math.nan}}, r"offset.theta must be a finite number"),
    ({"columns": {"a": "X", "b": "X"}}, r"file column 'X' is mapped to more than one"),
    ({"rate": 250}, r"unknown key 'rate'; allowed: columns, sample_rate"),
    ({"columns": {"a": {"col": "X"}}}, r"unknown key 'col'"),
])
def test_bad_record_settings_name_the_entry(table: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_record_settings(table, "rig.toml[record]")


def test_a_time_column_that_does_not_count_samples_is_refused() -> None:
    df = pd.DataFrame({"t": [0.0, 0.002, 0.004]})
    with pytest.raises(DataError, match="does not count samples"):
        apply_record_settings(df, RecordSettings(sample_rate=250.0), "rig.csv")


@pytest.mark.parametrize("t,fs,seconds", [
    ([0.0, 0.004, 0.008], 250.0, [0.0, 0.004, 0.008]),   # seconds at the stated rate
    ([0.0, 4.0, 8.0, 12.0], 0.25, [0.0, 4.0, 8.0, 12.0]),  # (a counter read 16 s apart)
    ([1.0, 2.0, 3.0, 4.0], 0.25, [0.0, 4.0, 8.0, 12.0]),   # a counter
    ([1.0, 2.0, 4.0, 5.0], 0.25, [0.0, 4.0, 12.0, 16.0]),  # a counter that lost a sample
])
def test_a_time_column_is_a_counter_or_seconds_at_the_stated_rate(
        t: list[float], fs: float, seconds: list[float]) -> None:
    """The cascaded tanks' declaration states 0.25 Hz; a record whose t was
    already in seconds (0, 4, 8, ...) was read as a counter: every rate 4x
    off, still a 99 % fit."""
    got = apply_record_settings(pd.DataFrame({"t": t}), RecordSettings(sample_rate=fs), "r")
    assert got["t"].tolist() == pytest.approx(seconds, abs=1e-12)


def test_a_time_column_stepping_by_neither_one_nor_the_period_is_refused() -> None:
    df = pd.DataFrame({"t": [0.0, 2.0, 4.0, 6.0]})
    with pytest.raises(DataError, match=r"column 't' steps by 2: a sample counter steps by 1, "
                                        r"and seconds at the stated 0\.25 Hz by 4; which is it"):
        apply_record_settings(df, RecordSettings(sample_rate=0.25), "rig.csv")


def test_a_mapped_column_missing_from_the_file_is_named() -> None:
    with pytest.raises(DataError, match="map column 'PG_9'.*its columns are"):
        apply_record_settings(pd.DataFrame({"PG_1": [1]}), RecordSettings({"p": "PG_9"}), "r")


# --- regime conditions and windows ------------------------------------------------------

@pytest.mark.parametrize("text,message", [
    ("omega > ", "cannot read"),
    ("__import__('os')", "unknown function"),
    ("omega.real > 0", "cannot use"),
    ("omega ** omega > 1", "exponent must be a number"),
    ("omega ** 99 > 1", "exponent must be a number"),
    ("lambda: 1", "cannot use"),
    ("x" * 3000, "characters long"),
    ("abs(" * 60 + "omega" + ")" * 60 + " > 0", "nested|deep"),
    ("1e999 > omega", "beyond|cannot use"),
])
def test_hostile_conditions_are_refused(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_condition(text, "m.toml[regimes.a]")


def test_conditions_over_signals_and_metadata() -> None:
    c = parse_condition("abs(w) > 0.5 and (load == 'ball' or T < 40)", "m.toml[regimes.a]")
    w = np.array([0.0, 1.0, -1.0])
    assert c.evaluate({"w": w, "T": np.array([50.0, 50.0, 30.0])}, {"load": "disc"}, 3).tolist() \
        == [False, False, True]
    with pytest.raises(DataError, match="names 'T', which is neither a column"):
        c.evaluate({"w": w}, {"load": "ball"}, 3, "rec.csv")
    with pytest.raises(DataError, match="cannot evaluate"):
        parse_condition("load * 2 > 1", "m").evaluate({}, {"load": "ball"}, 3)


def test_windows_leave_out_transients_holds_and_short_runs() -> None:
    spec = parse_regimes({"settle": 1.0, "min_duration": 2.0,
                          "fwd": {"when": "w > 0.5"}, "rev": {"when": "w < -0.5"},
                          "held": {"when": "abs(w) <= 0.5", "use": False, "why": "at the stop"}},
                         "m.toml")
    t = np.arange(40.0)
    w = np.r_[np.ones(10), np.zeros(10), -np.ones(3), np.full(17, 0.2)]
    wins = cut_windows(t, {"w": w}, spec, source="r")
    assert [(x.regime, x.used) for x in wins] == [("fwd", True), ("held", False),
                                                 ("rev", False), ("held", False)]
    assert (wins[0].first, wins[0].stop) == (1, 9)  # one second settled at each end
    assert wins[1].why == "at the stop" and "shorter than 2" in str(wins[2].why)
    by_hand = cut_windows(t, {"w": w}, spec, source="r", span=(0.0, 5.0))
    assert by_hand[0].end <= 5.0
    with pytest.raises(DataError, match="lies outside the record"):
        cut_windows(t, {"w": w}, spec, source="r", span=(50.0, 60.0))


def test_metadata_splits_regimes() -> None:
    spec = parse_regimes({"metadata": ["load"], "m": {"when": "w > 0"}}, "m.toml")
    wins = cut_windows(np.arange(5.0), {"w": np.ones(5)}, spec, {"load": "ball"})
    assert wins[0].regime == "m, load=ball"


@pytest.mark.parametrize("text,message", [("3", "START:END"), ("b:2", "numbers"),
                                          ("4:2", "below END")])
def test_bad_window_option(text: str, message: str) -> None:
    with pytest.raises(DataError, match=message):
        parse_window(text)


# --- identifiability ----------------------------------------------------------------------

def test_identifiability_keeps_the_preferred_unknowns_it_can_tell_apart() -> None:
    rng = np.random.default_rng(0)
    speed = 1.0 + 0.3 * rng.standard_normal(200)
    X = np.column_stack([np.ones(200), speed, np.ones(200), np.zeros(200)]) * 100
    idf = assess_identifiability(X, ("Tc", "Dv", "Tl", "J"))
    assert idf.identifiable == ("Tc", "Dv")
    assert "collinear with Tc" in idf.reasons["Tl"]
    assert idf.reasons["J"] == "the equations the route uses do not contain it"
    assert len(idf.singular_values) == 3 and idf.singular_values[-1] < 1e-8
    # Tc carries the held Tl: 10 % more Tl, 10 % less Tc; Dv does not lean on it
    assert idf.dependence == {"Tc": {"Tl": pytest.approx(-1.0)}}
    assert idf.to_dict()["dependence"] == idf.dependence
    weak = assess_identifiability(X[:, :2] * 1e-3, ("Tc", "Dv"))
    assert weak.identifiable == () and "not excited" in weak.reasons["Tc"]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), p=st.integers(1, 5), rows=st.integers(1, 12),
       tie=st.floats(0.0, 1.0), scale=st.floats(-4.0, 3.0))
def test_identifiability_whole_set_equals_the_greedy_choice(seed: int, p: int, rows: int,
                                                           tie: float, scale: float) -> None:
    """The one-SVD answer when every unknown passes together is the greedy
    choice's, figure for figure (an ``absent`` entry naming no unknown makes
    the greedy loop run)."""
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((rows, p)) * 10.0 ** scale
    if p > 1:   # from independent to nearly collinear last two columns
        X[:, -1] = tie * X[:, -2] + (1.0 - tie) * X[:, -1]
    names = tuple(f"p{k}" for k in range(p))
    fast = assess_identifiability(X, names)
    loop = assess_identifiability(X, names, absent={"(none)": "-"})
    assert fast.identifiable == loop.identifiable
    assert fast.reasons == loop.reasons
    assert fast.relative_se == loop.relative_se
    assert fast.collinearity == loop.collinearity
    assert fast.singular_values == loop.singular_values
    assert fast.directions == loop.directions


# --- the steady route on raw stand files --------------------------------------------------

def test_one_stroke_identifies_one_friction_level(tmp_path: Path) -> None:
    rec = read_record(write_stroke(tmp_path / "r.txt", 1.0, seed=1))
    res = estimate(rec, MODEL)
    assert res.accepted and res.route == "steady" and res.regime == "forward"
    # the friction at that speed and direction: Tc + Dv*omega + Tl
    assert res.parameters["Tc"] == pytest.approx(TRUTH["Tc"] + TRUTH["Dv"] + TRUTH["Tl"],
                                                 rel=5e-3)
    assert res.identified == ("Tc",)
    assert res.held == {"Dv": "nominal", "Tl": "nominal", "J": "nominal"}
    assert "collinear with Tc" in res.identifiability.reasons["Dv"]  # type: ignore[union-attr]
    assert "steady" in res.identifiability.reasons["J"]  # type: ignore[union-attr]
    assert [w.regime for w in res.windows] == ["forward", "holding"]
    assert not res.windows[1].used and "end stop" in str(res.windows[1].why)
    assert res.fit_percent > 99.0


def test_held_values_from_a_baseline_give_the_coulomb_part(tmp_path: Path) -> None:
    rec = read_record(write_stroke(tmp_path / "r.txt", -1.2, seed=2))
    res = estimate(rec, MODEL, hold={"Dv": TRUTH["Dv"], "Tl@reverse": TRUTH["Tl"]})
    assert res.regime == "reverse"
    assert res.parameters["Tc"] == pytest.approx(TRUTH["Tc"], rel=5e-3)
    assert res.held["Dv"] == "baseline" and res.held["Tl"] == "baseline"


def test_strokes_at_several_speeds_both_ways_identify_all_friction(tmp_path: Path) -> None:
    recs = [read_record(write_stroke(tmp_path / f"r{i}.txt", s, seed=i))
            for i, s in enumerate((0.8, -0.8, 1.0, -1.0, 1.3, -1.3))]
    res = estimate_joint(recs, MODEL)
    assert res.regime == "forward + reverse"
    assert res.identified == ("Tc", "Dv", "Tl")
    for k, v in TRUTH.items():
        assert res.parameters[k] == pytest.approx(v, rel=0.03, abs=0.1)
        assert abs(res.parameters[k] - v) < 4 * res.std_errors[k] + 1e-3


def test_a_hold_alone_is_not_identifiable_and_never_trended(tmp_path: Path) -> None:
    rec = read_record(write_stroke(tmp_path / "hold.txt", 1.0, hold_only=True))
    res = estimate(rec, MODEL)
    assert not res.accepted and res.not_identifiable
    assert res.reason.startswith("not identifiable: no window")  # type: ignore[union-attr]
    assert res.stored_values() == {} and res.identified == ()


def test_an_accelerating_window_is_not_steady(tmp_path: Path) -> None:
    df = stroke(1.0, seed=3)
    n = len(df)
    ramp = np.clip((np.arange(n) - 12) / 400.0, 0.0, 1.0) ** 2 * 1.6 * 0.5  # quadratic angle
    df["Angle"] = np.round((1.0 + ramp * 30.0) / (2 * math.pi / 16384)).astype(int)
    path = tmp_path / "acc.txt"
    df.to_csv(path, sep="\t", index=False)
    res = estimate(read_record(path), MODEL, constants={"J": 40.0})
    assert not res.accepted
    assert "not steady" in str(res.reason) or any("not steady" in str(w.why)
                                                  for w in res.windows)


def test_constants_fix_an_unknown_for_the_run(noisy_record: pd.DataFrame) -> None:
    res = estimate(noisy_record, "dc-motor", constants={"D": 1.0e-4})
    assert res.parameters["D"] == 1.0e-4 and "D" not in res.identified
    assert res.held["D"] == "given" and any("D fixed at" in n for n in res.notes)
    assert res.to_dict()["held"]["D"]["reason"] == "given a value for this estimate (--constants)"
    assert res.parameters["R"] == pytest.approx(1.0, rel=0.02)
    with pytest.raises(ModelError, match="unknown constant 'Q'.*not a parameter"):
        estimate(noisy_record, "dc-motor", constants={"Q": 1.0})


# --- the command line: bad input is one line, exit 2, nothing stored ---------------------

@pytest.fixture()
def raw(tmp_path: Path) -> Path:
    return write_stroke(tmp_path / "r.txt", 1.0, seed=4)


@pytest.mark.parametrize("args,message", [
    (["--sample-rate", "0"], "--sample-rate must be > 0"),
    (["--sample-rate", "-250"], "--sample-rate must be > 0"),
    (["--scale", "theta=inf"], "--scale theta must be a finite number"),
    (["--scale", "theta=nan"], "--scale theta must be a finite number"),
    (["--offset", "pA=abc"], "--offset pA must be a number"),
    (["--window", "20:30"], "lies outside the record"),
    (["--constants", "Q=3"], "unknown constant 'Q'.*not a parameter"),
    (["--meta", "load"], "write NAME=VALUE"),
])
def test_bad_options_are_one_line(raw: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                  args: list[str], message: str) -> None:
    db = tmp_path / "h.db"
    for cmd in (["estimate", str(raw), "--model", MODEL],
                ["baseline", "add", str(raw), "--unit", "A", "--db", str(db), "--model", MODEL]):
        assert main([*cmd, *args]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and pytest.importorskip("re").search(message, err)
        assert not db.exists()


def test_a_regime_naming_an_unknown_column_is_one_line(raw: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    text = DECLARATION.read_text().replace('when = "omega > 0.1"', 'when = "temp > 40"')
    decl = tmp_path / "act.toml"
    decl.write_text(text)
    for name in ("rotary-actuator-monitor.toml", "rotary-actuator-rules.toml"):
        (tmp_path / name).write_text((DECLARATION.parent / name).read_text())
    assert main(["estimate", str(raw), "--model", str(decl)]) == 2
    err = capsys.readouterr().err
    assert "names 'temp', which is neither a column of the record" in err
    assert len(err.strip().splitlines()) == 1


def test_estimate_json_reports_windows_regime_and_identifiability(
        raw: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["estimate", str(raw), "--model", MODEL, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["regime"] == "forward" and doc["route"] == "steady"
    assert [w["regime"] for w in doc["windows"]] == ["forward", "holding"]
    assert doc["identifiable"] == {"Tc": True, "Dv": False, "Tl": False, "J": False}
    assert doc["held"]["J"]["from"] == "nominal" and "steady" in doc["held"]["J"]["reason"]
    assert doc["fits"] == {"balance omega": pytest.approx(doc["fit_percent"])}
    assert doc["identifiability"]["limits"]["max_collinearity"] == 10.0


def test_a_declaration_without_monitor_is_monitored_generically(
        tmp_path: Path, record_files: object, capsys: pytest.CaptureFixture[str]) -> None:
    # the shipped DC-motor declaration without its [monitor] table
    body = (Path(__file__).resolve().parents[1] / "src" / "condmon" / "data"
            / "dc-motor.toml").read_text()
    decl = tmp_path / "motor.toml"
    decl.write_text(body[:body.index("[monitor]")] + body[body.index("[estimation]"):])
    assert get_model(str(decl)).monitored_generically
    files = record_files(tmp_path, [1, 2, 3, 4])  # type: ignore[operator]
    db = str(tmp_path / "h.db")
    assert main(["baseline", "add", *files[:3], "--unit", "M", "--db", db,
                 "--model", str(decl)]) == 0
    assert "no [monitor] table: generic monitoring" in capsys.readouterr().out
    assert main(["check", files[3], "--unit", "M", "--db", db, "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["status"] == "go"
    worn = tmp_path / "worn.csv"
    assert main(["simulate", "actuator", "--out", str(worn), "--fault", "R=+40%",
                 "--seed", "9"]) == 0
    assert main(["check", str(worn), "--unit", "M", "--db", db, "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["status"] == "no-go"
    assert any(f["name"] == "winding resistance (R) increase" for f in res["faults"])


# --- the steady route on a machine whose balances need unmeasured states ------------------

def test_the_transmission_steady_state_is_a_case_of_the_steady_route(tmp_path: Path) -> None:
    """The HST's declaration with an [estimation] table: the motor pressure is
    not measured, so the route solves the model's whole steady state in each
    window (the fault isolation's solver). One operating point cannot tell a
    viscous load from a constant one; two can."""
    from condmon.models.registry import load_plant_model
    from condmon.models.machine import DATA_DIR
    from condmon.simulate.plant import simulate_plant

    src = DATA_DIR / "hst.toml"
    decl = tmp_path / "hst-est.toml"
    decl.write_text(src.read_text() + """
[regimes]
settle = 4.0
min_duration = 2.0
[regimes.full]
when = "omega_p > 140"
[regimes.part]
when = "omega_p <= 140"

[estimation]
estimate = ["Rv", "Tld"]
route = "steady"
""")
    rec = simulate_plant(load_plant_model("hst"), ["Tld=+20@0s"], seed=3)
    one = estimate(rec, str(decl))
    assert one.regime == "full" and one.identified == ("Rv",)
    assert "collinear with Rv" in one.identifiability.reasons["Tld"]  # type: ignore[union-attr]
    both = estimate_joint([rec], str(decl))
    assert both.regime == "full + part" and both.identified == ("Rv", "Tld")
    assert both.parameters["Rv"] == pytest.approx(11.271, rel=0.01)
    assert both.parameters["Tld"] == pytest.approx(20.0, abs=3 * both.std_errors["Tld"] + 0.5)
    assert both.fit_percent > 99.0


def test_a_fixed_unknown_must_be_physically_possible(tmp_path: Path) -> None:
    rec = read_record(write_stroke(tmp_path / "r.txt", 1.0, seed=5))
    with pytest.raises(ModelError, match=r"--constants Tc=-5: Tc must be >= 0"):
        estimate(rec, MODEL, constants={"Tc": -5.0})
    res = estimate(rec, MODEL, constants={"Dv": TRUTH["Dv"], "Tl": TRUTH["Tl"]})
    assert res.parameters["Tc"] == pytest.approx(TRUTH["Tc"], rel=5e-3)
    assert res.held["Dv"] == "given" and res.held["Tl"] == "given"


@pytest.mark.filterwarnings("default::condmon.errors.DataWarning")
def test_ignoring_a_column_the_file_lacks_is_said(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    raw = write_stroke(tmp_path / "r.txt", 1.0, seed=6)
    assert main(["estimate", str(raw), "--model", MODEL, "--ignore", "Nope"]) == 0
    captured = capsys.readouterr()
    assert "ignore column(s) 'Nope', which the file does not have" in captured.err
    assert "3 column(s) ignored" in captured.out  # the declaration's three, not four


def test_metadata_the_regimes_need_or_do_not_use_is_said(tmp_path: Path) -> None:
    rec = read_record(write_stroke(tmp_path / "r.txt", 1.0, seed=7))
    res = estimate(rec, MODEL, metadata={"lod": "ball"})
    assert any("metadata lod not used" in n for n in res.notes)


def test_pooled_windows_keep_their_regime_and_record(tmp_path: Path) -> None:
    recs = [read_record(write_stroke(tmp_path / f"r{i}.txt", s, seed=i))
            for i, s in enumerate((0.8, -1.0))]
    res = estimate_joint(recs, MODEL)
    used = [(Path(w.source).name, w.regime) for w in res.windows if w.used]
    assert used == [("r0.txt", "forward"), ("r1.txt", "reverse")]
    assert res.regime == "forward + reverse"


def test_a_broken_link_in_a_unit_folder_is_refused(tmp_path: Path) -> None:
    from condmon.workflows.fleet_inbox import inbox_records

    (tmp_path / "A1").mkdir()
    (tmp_path / "A1" / "gone.txt").symlink_to(tmp_path / "nowhere.txt")
    recs = inbox_records(tmp_path)
    assert len(recs) == 1 and "a link to" in str(recs[0].error)
    assert "which does not exist" in str(recs[0].error)
