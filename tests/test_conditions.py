"""Operating conditions as covariates: a healthy value predicted at the check's conditions."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from _strokes import STROKE_DECLARATION as DECLARATION, write_stroke
from condmon.cli.main import main
from condmon.errors import ConfigError
from condmon.models.features import parse_conditions
from condmon.monitor.baseline import Baseline
from condmon.monitor.conditions import condition_keys, conditioned_baseline
from condmon.store import open_store

#: Friction of the synthetic unit against its oil temperature [N m per count]:
#: 48 N m cold (12,100 counts), 32 N m warm (12,300).
SLOPE = -0.08


def _tc(oil: float) -> float:
    return 40.0 + SLOPE * (oil - 12200.0)


def test_the_prediction_and_its_spread_are_the_regressions() -> None:
    """Known truth: y = 2 + 3 c + noise 0.1; the prediction at c0 and the
    spread of a new value there, s·sqrt(1 + h0)."""
    rng = np.random.default_rng(4)
    c = np.linspace(0.0, 10.0, 40)
    y = 2.0 + 3.0 * c + rng.normal(0.0, 0.1, c.size)
    base = Baseline(("P",), (float(y.mean()),), (float(y.std(ddof=1)),), c.size)
    out = conditioned_baseline(base, {"P": y}, {"load": c}, {"load": 7.0})
    assert out.not_judged is None and out.fitted == {"P": ("load",)}
    assert out.baseline.mean[0] == pytest.approx(23.0, abs=0.05)
    X = np.column_stack([np.ones(c.size), c - c.mean()])
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    s2 = float(np.sum((y - X @ beta) ** 2)) / (c.size - 2)
    x0 = np.array([1.0, 7.0 - c.mean()])
    h0 = float(x0 @ np.linalg.inv(X.T @ X) @ x0)
    # stated over n - q tests, so that the monitor's (1 + 1/(n - q)) gives s²(1 + h0) back
    assert out.baseline.std[0] ** 2 * (1 + 1 / 39) == pytest.approx(s2 * (1 + h0))
    assert out.baseline.count_array[0] == 39
    assert 0.07 < out.baseline.std[0] < 0.13


def test_a_check_outside_the_baselines_conditions_is_not_judged() -> None:
    c = np.linspace(30.0, 40.0, 10)
    base = Baseline(("Tc@forward",), (40.0,), (1.0,), 10)
    out = conditioned_baseline(base, {"Tc@forward": 40.0 - 0.1 * c},
                               {"oil@forward": c}, {"oil@forward": 41.5}, {"oil": "degC"})
    assert out.not_judged == "oil@forward = 41.5 degC outside the baseline's 30 .. 40"
    few = conditioned_baseline(base, {"Tc@forward": np.array([1.0, 2.0, 3.0])},
                               {"oil@forward": np.array([30.0, 35.0, 40.0])},
                               {"oil@forward": 33.0})
    assert few.fitted == {} and "cannot fit it against oil@forward (needs 4)" in few.notes[0]


def test_the_conditions_of_a_regime_and_the_regime_free_ones_apply() -> None:
    assert condition_keys("vib@reverse", ["oil@forward", "oil@reverse", "load"]) == [
        "oil@reverse", "load"]
    assert condition_keys("R", ["oil@forward", "load"]) == ["load"]


@pytest.mark.parametrize("entry, message", [
    ({"unit": "K"}, "needs exactly one of channel"),
    ({"channel": "T1", "metadata": "load"}, "needs exactly one of channel"),
    ({"metadata": "load", "statistic": "mean"}, r"statistic is for a channel's condition"),
    ({"channel": "T1", "between_units": "yes"}, "between_units must be true or false"),
    ({"channel": "T1", "statistic": "median"}, "unknown statistic 'median'"),
    ({"channel": "T1", "smoothing": 3}, "unknown key 'smoothing'"),
])
def test_bad_conditions_are_refused_naming_the_file_and_the_condition(
        entry: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=r"rig\.toml\[conditions\.oil\]"):
        parse_conditions({"oil": entry}, "rig.toml")
    with pytest.raises(ConfigError, match=message):
        parse_conditions({"oil": entry}, "rig.toml")


def _check(record: Path, db: str, capsys: pytest.CaptureFixture[str]) -> dict[str, object]:
    capsys.readouterr()
    assert main(["check", str(record), "--unit", "A", "--db", db, "--json"]) == 0
    doc: dict[str, object] = json.loads(capsys.readouterr().out)
    return doc


def test_a_unit_is_judged_at_its_own_oil_temperature(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The example's declaration (oil temperature as a condition): a healthy unit
    whose friction falls 16 N m from cold to warm is go at every temperature of
    its baseline; a seal leak of -25 % in the cold is found, though it leaves
    friction near the baseline's mean; a check warmer than any baseline
    record is not judged, stored and shown so, and never trended."""
    db = str(tmp_path / "h.db")
    rng = np.random.default_rng(7)
    oils = np.linspace(12100.0, 12300.0, 12)
    files = [str(write_stroke(tmp_path / f"b{k}.txt", 1.0, seed=k, oil=float(o),
                              friction={"Tc": _tc(o) + rng.normal(0.0, 0.2)}))
             for k, o in enumerate(oils)]
    capsys.readouterr()
    assert main(["baseline", "add", *files, "--unit", "A", "--db", db,
                 "--model", str(DECLARATION)]) == 0
    # the baseline warms up record by record: its temperature explains the trend
    assert "trend" not in capsys.readouterr().err
    for k, oil in enumerate((12110.0, 12190.0, 12290.0)):
        doc = _check(write_stroke(tmp_path / f"h{k}.txt", 1.0, seed=50 + k, oil=oil,
                                  friction={"Tc": _tc(oil)}), db, capsys)
        assert doc["status"] == "go", doc["summary"]
        assert any("judged against its prediction at oil@forward" in j
                   for j in doc["judgement"])  # type: ignore[union-attr]
    leak = _check(write_stroke(tmp_path / "leak.txt", 1.0, seed=60, oil=12110.0,
                               friction={"Tc": 0.75 * _tc(12110.0)}), db, capsys)
    assert leak["status"] in ("advisory", "no-go"), leak["summary"]
    assert "seal" in str(leak["summary"])
    # the same leak is 11.5 % below the baseline's mean: without the condition it hides
    plain = tmp_path / "plain"
    plain.mkdir()
    for f in DECLARATION.parent.glob("*.toml"):
        text = f.read_text()
        if f.name == DECLARATION.name:
            start = text.index("[conditions.oil]")
            text = text[:start] + text[text.index("[monitor]"):]
        (plain / f.name).write_text(text)
    other = str(tmp_path / "plain.db")
    capsys.readouterr()
    assert main(["baseline", "add", *files, "--unit", "A", "--db", other,
                 "--model", str(plain / DECLARATION.name)]) == 0
    assert "Tc@forward: the baseline's tests trend" in capsys.readouterr().err  # unexplained
    assert _check(tmp_path / "leak.txt", other, capsys)["status"] == "go"
    warm = _check(write_stroke(tmp_path / "warm.txt", 1.0, seed=61, oil=12400.0,
                               friction={"Tc": _tc(12400.0)}), db, capsys)
    assert warm["status"] == "not judged"
    assert str(warm["not_judged"]).startswith("oil@forward = 12400 count outside the "
                                              "baseline's 12100 .. 12300")
    assert warm["summary"] == f"not judged: {warm['not_judged']}"
    with open_store(db) as store:
        hist = store.history("A")
    assert (hist["status"] == "not judged").sum() == 1
    assert str(hist.loc[hist["status"] == "not judged", "summary"].iloc[0]).startswith(
        "not judged: oil@forward")
    capsys.readouterr()
    assert main(["history", "--unit", "A", "--db", db]) == 0
    listing = capsys.readouterr().out
    assert "not judged" in listing
    assert "vib1" in listing or "left out" in listing   # the features are listed too
    # the latest check is not judged: the listing and the report say so
    assert main(["units", "--db", db, "--json"]) == 0
    (listed,) = json.loads(capsys.readouterr().out)["units"]
    assert listed["status"] == "not judged"
    assert main(["report", "--db", db, "--out", str(tmp_path / "rep")]) == 0
    page = next((tmp_path / "rep").glob("*A*.html")).read_text()
    assert "status not-judged" in page and "not judged: oil@forward" in page
    # healthy records of the warm unit extend the baseline: the warm check is judged now
    more = [str(write_stroke(tmp_path / f"w{k}.txt", 1.0, seed=80 + k, oil=float(o),
                             friction={"Tc": _tc(o) + rng.normal(0.0, 0.2)}))
            for k, o in enumerate(np.linspace(12320.0, 12420.0, 4))]
    assert main(["baseline", "add", *more, "--unit", "A", "--db", db]) == 0
    with open_store(db) as store:
        hist = store.history("A")
    assert (hist["status"] == "not judged").sum() == 0
    assert hist.loc[hist["source"].str.endswith("warm.txt"), "status"].iloc[0] == "go"


def test_a_fleet_run_judges_at_the_conditions_and_says_when_it_cannot(
        tmp_path: Path) -> None:
    """The same unit as a folder of `fleet run`: its first 12 records the
    baseline (cold to warm), then a healthy check within them (go), one warmer
    than all of them (not judged) and a cold seal leak (flagged)."""
    inbox = tmp_path / "inbox" / "A"
    inbox.mkdir(parents=True)
    (inbox / "unit.toml").write_text(f'model = "{DECLARATION}"\n')
    rng = np.random.default_rng(8)
    for k, o in enumerate(np.linspace(12100.0, 12300.0, 12)):
        write_stroke(inbox / f"r{k:02d}.txt", 1.0, seed=k, oil=float(o),
                     friction={"Tc": _tc(o) + rng.normal(0.0, 0.2)})
    write_stroke(inbox / "r12.txt", 1.0, seed=40, oil=12200.0, friction={"Tc": _tc(12200.0)})
    write_stroke(inbox / "r13.txt", 1.0, seed=41, oil=12450.0, friction={"Tc": _tc(12450.0)})
    write_stroke(inbox / "r14.txt", 1.0, seed=42, oil=12110.0,
                 friction={"Tc": 0.75 * _tc(12110.0)})
    db = str(tmp_path / "f.db")
    assert main(["fleet", "run", str(tmp_path / "inbox"), "--db", db,
                 "--baseline-count", "12", "--workers", "1"]) == 0
    with open_store(db) as store:
        hist = store.history("A")
    status = dict(zip(hist["source"].map(lambda s: Path(str(s)).name), hist["status"]))
    assert status["r12.txt"] == "go"
    assert status["r13.txt"] == "not judged"
    assert status["r14.txt"] in ("advisory", "no-go")


def test_a_new_unit_checked_against_a_peer_keeps_the_declared_model(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A unit first seen in a check against another unit is made with the model
    it was checked with (it was made a DC motor, and its next record refused);
    one peer's scatter is widened by the stated spread between units."""
    db = str(tmp_path / "p.db")
    files = [str(write_stroke(tmp_path / f"b{k}.txt", 1.0, seed=k, oil=12200.0 + k))
             for k in range(8)]
    assert main(["baseline", "add", *files, "--unit", "A", "--db", db,
                 "--model", str(DECLARATION)]) == 0
    for k in range(2):
        rec = write_stroke(tmp_path / f"c{k}.txt", 1.0, seed=20 + k)
        capsys.readouterr()
        assert main(["check", str(rec), "--unit", "B", "--against", "A", "--model",
                     str(DECLARATION), "--db", db, "--json"]) == 0
        doc = json.loads(capsys.readouterr().out)
        assert doc["status"] == "go" and doc["against"] == "unit A"
        assert any("not used against unit A" in j for j in doc["judgement"])
    with open_store(db) as store:
        assert store.unit_model("B") == str(DECLARATION.resolve())


def _session_declaration(folder: Path) -> Path:
    """The example's declaration with the time since the session started as its
    condition instead of the oil's temperature (a pause over 10 min ends one)."""
    folder.mkdir()
    for f in DECLARATION.parent.glob("*.toml"):
        text = f.read_text()
        if f.name == DECLARATION.name:
            start = text.index("[conditions.oil]")
            text = (text[:start] + '[conditions.warm]\nsince = "session start"\ngap = 600\n'
                    'description = "the stand warms up through a session"\n\n'
                    + text[text.index("[monitor]"):])
        (folder / f.name).write_text(text)
    return folder / DECLARATION.name


def _at(folder: Path, when: str, tc: float, seed: int) -> Path:
    """A stroke whose file name holds its start time as the stand writes it."""
    return write_stroke(folder / f"Base_000_{seed}_{when}.txt", 1.0, seed=seed,
                        friction={"Tc": tc})


def test_the_time_since_the_session_started_is_a_condition(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Known truth: friction falls 0.4 N m per 12 s cycle as the stand warms
    up. The start times come from the file names ([record] name_time); a
    session is the records no more than 10 min apart. A check on the line at
    its session's time is go, on the next day's session too; a seal leak of
    -25 % late in the session is found; a check later in its session than any
    baseline record is not judged; a fleet run judges the same."""
    model = _session_declaration(tmp_path / "model")
    db = str(tmp_path / "h.db")
    rng = np.random.default_rng(9)

    def tc(elapsed: float) -> float:
        return 48.0 - 0.4 * elapsed / 12.0

    base = [_at(tmp_path, f"9-11-2019-8-{k // 5:02d}-{12 * (k % 5):02d} AM",
                tc(12.0 * k) + rng.normal(0.0, 0.15), k) for k in range(12)]
    capsys.readouterr()
    assert main(["baseline", "add", *map(str, base), "--unit", "A", "--db", db,
                 "--model", str(model)]) == 0
    assert "trend" not in capsys.readouterr().err   # the session's time explains it
    with open_store(db) as store:
        conds = store.conditions_of(store.usable_tests("A"))[0]
    assert conds["warm"].tolist() == [12.0 * k for k in range(12)]
    capsys.readouterr()
    assert main(["history", "--unit", "A", "--db", db, "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["conditions"] for r in rows[:2]] == [{"warm": 0.0}, {"warm": 12.0}]
    assert rows[1]["test_date"] == "2019-09-11T08:00:12Z"   # from the file's name
    assert main(["history", "--unit", "A", "--db", db]) == 0
    assert "2019-09-11 08:00:12" in capsys.readouterr().out   # cycles a minute: seconds
    same = _check(_at(tmp_path, "9-11-2019-8-01-00 AM", tc(60.0), 40), db, capsys)
    assert same["status"] == "go", same["summary"]
    assert any("judged against its prediction at warm" in j
               for j in same["judgement"])  # type: ignore[union-attr]
    # the next day, a new session: its first record is as cold as the first one
    first = _check(_at(tmp_path, "9-12-2019-7-00-00 AM", tc(0.0), 41), db, capsys)
    assert first["status"] == "go", first["summary"]
    leak = _check(_at(tmp_path, "9-12-2019-7-02-00 AM", 0.75 * tc(120.0), 42), db, capsys)
    assert leak["status"] in ("advisory", "no-go") and "seal" in str(leak["summary"])
    # 4 min into the session: later than the baseline's 132 s
    late = _check(_at(tmp_path, "9-12-2019-7-04-00 AM", tc(240.0), 43), db, capsys)
    assert late["status"] == "not judged"
    assert str(late["not_judged"]).startswith("warm = 240 s outside the baseline's 0 .. 132")
    # a fleet run of the same records judges alike
    inbox = tmp_path / "inbox" / "B"
    inbox.mkdir(parents=True)
    (inbox / "unit.toml").write_text(f'model = "{model}"\n')
    for f in [*base, *(tmp_path / Path(str(d["source"])).name for d in (first, late))]:
        (inbox / Path(f).name).write_bytes(Path(f).read_bytes())
    assert main(["fleet", "run", str(tmp_path / "inbox"), "--db", db,
                 "--baseline-count", "12", "--workers", "1"]) == 0
    with open_store(db) as store:
        hist = store.history("B")
    status = {Path(str(s)).name[:16]: v for s, v in zip(hist["source"], hist["status"])}
    assert status["Base_000_41_9-12"] == "go" and status["Base_000_43_9-12"] == "not judged"


def test_a_record_without_a_start_time_says_its_session_time_is_not_known() -> None:
    from datetime import datetime, timezone

    import condmon
    from condmon.models.features import ConditionSpec
    from condmon.monitor.conditions import with_session_time

    res = condmon.estimate(condmon.simulate_actuator(seed=2))
    assert res.conditions == {}
    spec = (ConditionSpec("warm", session_gap=600.0),)
    out = with_session_time(res, spec, None, [0.0])
    assert out.conditions == {} and "condition warm not known" in out.notes[-1]
    when = datetime(1970, 1, 1, 0, 30, tzinfo=timezone.utc)   # 1,800 s
    assert with_session_time(res, spec, when, [1000.0, 1500.0, 3000.0]).conditions == {
        "warm": (800.0, 0.0)}
    assert with_session_time(res, spec, when, [100.0]).conditions == {"warm": (0.0, 0.0)}


@pytest.mark.parametrize("entry, message", [
    ({"since": "boot"}, "since must be 'session start'"),
    ({"since": "session start", "gap": 0}, "gap must be the longest pause"),
    ({"since": "session start", "gap": "10 min"}, "gap must be the longest pause"),
    ({"metadata": "load", "gap": 60}, "gap is for since"),
    ({"since": "session start", "unit": "h"}, "is in s, not 'h'"),
    ({"since": "session start", "channel": "T1"}, "needs exactly one of channel"),
])
def test_bad_session_conditions_are_refused(entry: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_conditions({"warm": entry}, "rig.toml")


@pytest.mark.parametrize("fmt, message", [
    ("%Q-%Y", "%Q is not a directive"),
    ("%Y-%m-%d", "has no %H or %I"),
    ("day", "has no %Y or %y"),
    (12, "must be a strptime format"),
])
def test_a_bad_name_time_is_refused_naming_the_key(fmt: object, message: str) -> None:
    from condmon.io.rig import parse_record_settings

    with pytest.raises(ConfigError, match=r"rig\.toml\[record\]\.name_time.*" + message):
        parse_record_settings({"name_time": fmt}, "rig.toml[record]")
