"""A test of several records: a stroke each way estimated together, grouped into
cycles, stored and checked as one test; the gauges' offsets cancel in it.

Records are synthetic strokes of the hydraulic rotary actuator with known
friction (tests/_strokes.py), written as the test stand writes them.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from _strokes import DECLARATION, DM, PRESSURE_SCALE, stroke, write_stroke
from condmon.cli.main import main
from condmon.errors import ConfigError
from condmon.identify import estimate, estimate_joint
from condmon.identify.identifiability import assess_identifiability
from condmon.io import read_record
from condmon.models.registry import get_model
from condmon.monitor.generic import peer_sigmas
from condmon.workflows.cycles import cycles_of
from condmon.workflows.records import Cycle, EstimateOptions

MODEL = str(DECLARATION)
#: Friction of the strokes here: no viscous part, so one stroke each way holds all.
FRICTION = {"Tc": 40.0, "Dv": 0.0, "Tl": 2.0}
#: A zero offset of gauge PG_1 [counts]: 60 counts = 75.8 kPa = 6.2 N m of torque.
OFFSET = 60


def _pair(tmp_path: Path, *, offset: int = 0, noisy: float = 3.0, seed: int = 0
          ) -> list[Path]:
    """A forward stroke (3 counts of gauge noise) and a reverse one (``noisy``
    counts), both read through a PG_1 that is ``offset`` counts off."""
    out = []
    for k, (speed, noise) in enumerate(((1.0, 3.0), (-1.0, noisy))):
        df = stroke(speed, seed=seed + k, friction=FRICTION, noise_counts=noise)
        df["PG_1"] += offset
        path = tmp_path / f"Base_000_{seed + k}_s.txt"
        df.to_csv(path, sep="\t", index=False)
        out.append(path)
    return out


def test_a_stroke_each_way_tells_friction_from_load_even_when_one_is_noisy(
        tmp_path: Path) -> None:
    """Known truth: Tc 40, Tl 2 N m. The reverse stroke's gauges read 20 times the
    forward's noise: weighted by it, Tc and Tl lean on one window (the index on
    the weighted rows is 14-20 > 10), yet the two windows tell them apart exactly,
    and holding Tl at 0 would put its 2 N m in Tc."""
    recs = [read_record(p) for p in _pair(tmp_path, noisy=60.0)]
    res = estimate_joint(recs, MODEL)
    assert res.regime == "forward + reverse"
    assert "Tl" in res.identified and "Tc" in res.identified
    for k in ("Tc", "Tl"):
        assert abs(res.parameters[k] - FRICTION[k]) < 4 * res.std_errors[k], (k, res.parameters)


def test_the_collinearity_index_is_taken_on_the_windows_not_their_noise() -> None:
    # two windows, +1 and -1 for Tc and 1 for Tl, one 20 times noisier (weight 1/20),
    # each a relative change over a noise of 1 %
    weighted = [[100.0, 100.0], [-5.0, 5.0]]
    design = [[1.0, 1.0], [-1.0, 1.0]]
    assert "Tl" not in assess_identifiability(weighted, ("Tc", "Tl")).identifiable
    both = assess_identifiability(weighted, ("Tc", "Tl"), design=design)
    assert both.identifiable == ("Tc", "Tl") and both.collinearity == pytest.approx(1.0)


def test_a_gauge_offset_moves_the_load_torque_not_the_cycles_friction(tmp_path: Path) -> None:
    """PG_1 60 counts high: a single stroke's Tc moves by Dm × 60 × 1262.54 Pa =
    6.2 N m; the cycle's Tc does not, its Tl takes it. The systematic part says
    the same: the gauges' zero drift (6.0 N m at ±0.25 % of 20.684 MPa) stays in
    a stroke's Tc, and only their span error's part in the cycle's."""
    shift = DM * OFFSET * PRESSURE_SCALE
    (tmp_path / "clean").mkdir()
    clean = estimate_joint([read_record(p) for p in _pair(tmp_path / "clean", seed=5)], MODEL)
    pair = _pair(tmp_path, offset=OFFSET, seed=5)
    off = estimate_joint([read_record(p) for p in pair], MODEL)
    assert off.parameters["Tc"] == pytest.approx(clean.parameters["Tc"], abs=0.05)
    assert off.parameters["Tl"] - clean.parameters["Tl"] == pytest.approx(shift, rel=0.02)
    alone = estimate(read_record(pair[0]), MODEL)
    # one stroke: Tl held at 0, so its Tc holds the load torque and the offset both
    assert alone.parameters["Tc"] - clean.parameters["Tc"] == pytest.approx(
        shift + FRICTION["Tl"], rel=0.05)
    gauges = DM * 51710.0 * math.sqrt(2.0)
    assert alone.systematic["Tc@forward"] == pytest.approx(gauges, rel=1e-3)
    assert off.systematic["Tc@forward + reverse"] < 0.05 * gauges
    assert off.systematic["Tl@forward + reverse"] == pytest.approx(gauges, rel=1e-3)


def test_features_and_conditions_of_a_cycle_cover_both_strokes(tmp_path: Path) -> None:
    fwd = stroke(1.0, seed=1, friction=FRICTION, vibration=20.0, oil=12000.0)
    rev = stroke(-1.0, seed=2, friction=FRICTION, vibration=40.0, oil=12400.0)
    res = estimate_joint([fwd, rev], MODEL)
    vib, _ = res.features["vib1@forward + reverse"]
    assert 20.0 < vib < 40.0 and vib == pytest.approx(30.0, rel=0.1)
    oil, _ = res.conditions["oil@forward + reverse"]
    assert oil == pytest.approx(12200.0, abs=20.0)


def _strokes(tmp_path: Path, speeds: list[float], seed: int = 0) -> list[str]:
    return [str(write_stroke(tmp_path / f"Base_000_{i}_r.txt", s, seed=seed + i,
                             friction=FRICTION)) for i, s in enumerate(speeds)]


def test_records_are_joined_into_cycles_and_a_lone_stroke_is_left_out_and_said(
        tmp_path: Path) -> None:
    # the stand did not keep the record after the third: two forwards meet
    files = _strokes(tmp_path, [1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 1.0])
    tests, left = cycles_of(EstimateOptions(model=MODEL), files)
    assert [t.records for t in tests if isinstance(t, Cycle)] == [
        (files[0], files[1]), (files[3], files[4]), (files[5], files[6])]
    assert [name for name, _ in left] == [files[2]]
    assert "left out (forward only)" in left[0][1] and "holds forward again" in left[0][1]
    # a model without a cycle: each record is a test
    assert cycles_of(EstimateOptions(), ["a.csv", "b.csv"]) == (["a.csv", "b.csv"], [])


def test_a_cycle_is_stored_and_checked_as_one_test(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    files = _strokes(tmp_path, [1.0, -1.0] * 4 + [1.0])
    db = str(tmp_path / "h.db")
    assert main(["baseline", "add", *files[:8], "--unit", "A", "--db", db,
                 "--model", MODEL]) == 0
    assert "from 4 accepted healthy tests" in capsys.readouterr().out
    from condmon.store import open_store

    with open_store(db) as store:
        hist = store.history("A")
        assert list(hist["source"]) == [f"{a} + {b}" for a, b in zip(files[0:8:2],
                                                                      files[1:8:2])]
        assert store.latest_baseline("A").baseline.parameters[0] == "Tc@forward + reverse"
    assert main(["check", files[2], files[3], "--unit", "A", "--db", db, "--json"]) == 2
    assert "already in the history of 'A'" in capsys.readouterr().err   # the same test
    again = tmp_path / "again"
    again.mkdir()
    pair = _strokes(again, [1.0, -1.0], seed=100)
    assert main(["check", *pair, "--unit", "A", "--db", db, "--json"]) == 0
    check = json.loads(capsys.readouterr().out)
    assert check["status"] == "go" and check["regime"] == "forward + reverse"
    assert check["source"] == " + ".join(pair)
    # two strokes the same way are no cycle, three records more than one, a
    # stroke alone is no cycle: one line each, nothing stored
    for records, said in (([files[0], files[2]], "these records make no cycle and leave"),
                          (files[4:7], "these records make one test of 2 of them and leave"),
                          ([files[8]], "holds forward only; a test of hydraulic-rotary-"
                                       "actuator is one cycle")):
        assert main(["check", *records, "--unit", "A", "--db", db]) == 2
        err = capsys.readouterr().err.strip()
        assert said in err and len(err.splitlines()) == 1 and "nothing was stored" in err
    # the same cycle given the other way round is the same test
    assert main(["check", files[3], files[2], "--unit", "A", "--db", db]) == 2
    assert "already in the history of 'A'" in capsys.readouterr().err
    # a lone stroke is left out, and said
    assert main(["baseline", "add", files[8], "--unit", "A", "--db", db]) == 1   # none added
    assert "left out (forward only)" in capsys.readouterr().err


@pytest.mark.parametrize("cycle, message", [
    ('["forward", "sideways"]', r"cycle: 'sideways' is not a declared regime the "
                                r"estimation uses; allowed: forward, reverse$"),
    ('["forward", "holding"]', r"'holding' is not a declared regime the estimation uses "
                               r"\(use = false"),
    ('[]', r"cycle must name two regimes or more"),
    ('["forward"]', r"cycle must name two regimes or more"),
    ('["forward", "forward"]', r"cycle must name two regimes or more"),
    ('"forward"', r"cycle must be a list of names"),
])
def test_a_bad_cycle_is_refused_naming_the_regimes(tmp_path: Path, cycle: str,
                                                   message: str) -> None:
    text = DECLARATION.read_text().replace('cycle = ["forward", "reverse"]', f"cycle = {cycle}")
    decl = tmp_path / "rotary-actuator.toml"
    decl.write_text(text)
    for f in DECLARATION.parent.glob("rotary-actuator-*.toml"):
        (tmp_path / f.name).write_text(f.read_text())
    with pytest.raises(ConfigError, match=message):
        get_model(str(decl))


def test_peer_breakpoints_sit_where_a_healthy_peer_is_flagged_at_alpha() -> None:
    from statistics import NormalDist

    z, z2 = peer_sigmas(0.01, 1)
    assert z == pytest.approx(NormalDist().inv_cdf(0.995)) and z2 == 2 * z
    # Šidák over 5 parameters: each at 1 - 0.99^(1/5), two-sided
    z5, _ = peer_sigmas(0.01, 5)
    assert 2 * (1 - NormalDist().cdf(z5)) == pytest.approx(1 - 0.99 ** 0.2)


def test_two_units_gauges_may_differ_by_both_their_accuracies(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Healthy units A and B, the same friction, their PG_1 gauges 35 counts (44 kPa,
    within the ±51.7 kPa of ±0.25 % of 20.684 MPa) low and high: each unit's
    gauges may move its load torque by 6.0 N m (both gauges at their bound);
    their load torques differ by 7.2 N m, beyond one unit's 6.0 but inside what
    two units' gauges allow together (6.0 × √2 = 8.5 N m). B against A is no
    fault."""
    def cycles(unit: str, offset: int, n: int, seed: int) -> list[str]:
        folder = tmp_path / unit
        folder.mkdir()
        out = []
        for i in range(n):
            for k, speed in enumerate((1.0, -1.0)):
                df = stroke(speed, seed=seed + 2 * i + k, friction=FRICTION)
                df["PG_1"] += offset
                path = folder / f"Base_000_{2 * i + k}_s.txt"
                df.to_csv(path, sep="\t", index=False)
                out.append(str(path))
        return out

    db = str(tmp_path / "h.db")
    assert main(["baseline", "add", *cycles("A", -35, 4, 0), "--unit", "A", "--db", db,
                 "--model", MODEL]) == 0
    capsys.readouterr()
    pair = cycles("B", 35, 1, 100)
    assert main(["check", *pair, "--unit", "B", "--against", "A", "--model", MODEL,
                 "--db", db, "--dry-run", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    # A reads Tl 2 - 3.62 N m, B 2 + 3.62 N m
    a_tl = 2.0 - 35 * PRESSURE_SCALE * DM
    moved = doc["percent_change"]["Tl@forward + reverse"] / 100.0 * abs(a_tl)
    assert moved == pytest.approx(2 * 35 * PRESSURE_SCALE * DM, rel=0.1)
    assert doc["status"] == "go", doc["summary"]


def test_fleet_run_says_a_cycle_declared_unit_is_checked_record_by_record(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`fleet run` checks one record at a time: a unit whose model declares a
    cycle is named with what that means, in the summary and the JSON; one
    whose model declares none is not."""
    from _strokes import STROKE_DECLARATION

    for unit, model in (("A", DECLARATION), ("B", STROKE_DECLARATION)):
        folder = tmp_path / "inbox" / unit
        folder.mkdir(parents=True)
        (folder / "unit.toml").write_text(f'model = "{model.as_posix()}"\n')
        for i, speed in enumerate((0.5, -0.5, 0.5, -0.5)):
            write_stroke(folder / f"s{i}.txt", speed, seed=i)
    db = str(tmp_path / "f.db")
    assert main(["fleet", "run", str(tmp_path / "inbox"), "--db", db]) == 0
    said = capsys.readouterr().out
    assert "A: its model declares a cycle (forward, reverse" in said
    assert "`condmon check A B` estimate and check whole cycles" in said
    assert "B: " not in said
    assert main(["fleet", "run", str(tmp_path / "inbox"), "--db", db, "--json"]) == 0
    units = {u["unit"]: u for u in json.loads(capsys.readouterr().out)["units"]}
    assert "declares a cycle" in units["A"]["note"] and "note" not in units["B"]


def test_watch_says_once_a_cycle_declared_unit_is_checked_test_by_test(
        tmp_path: Path) -> None:
    """`watch` checks each streamed test, and each dropped record file, on
    its own: a unit whose model declares a cycle is named once with what
    that means, whichever way it comes; one whose model declares none is
    not."""
    import threading
    import time

    from _strokes import STROKE_DECLARATION
    from condmon.store import open_store
    from condmon.workflows.watch import Watcher
    from condmon.workflows.watch_folder import watch_folder

    lines: list[str] = []
    with open_store(str(tmp_path / "w.db")) as store:
        w = Watcher(store, model=str(DECLARATION), log=lines.append)
        for unit in ("A", "A"):
            w.machine_of(unit)
        Watcher(store, model=str(STROKE_DECLARATION), log=lines.append).machine_of("B")
        w.close()
    assert len(lines) == 1 and lines[0].startswith("A: its model declares a cycle"), lines
    assert "each streamed test" in lines[0]

    for unit, model in (("A", DECLARATION), ("B", STROKE_DECLARATION)):
        folder = tmp_path / "inbox" / unit
        folder.mkdir(parents=True)
        (folder / "unit.toml").write_text(f'model = "{model.as_posix()}"\n')
        for i, speed in enumerate((0.5, -0.5)):
            write_stroke(folder / f"s{i}.txt", speed, seed=i)
    said: list[str] = []
    stop = threading.Event()
    th = threading.Thread(target=lambda: watch_folder(
        tmp_path / "inbox", str(tmp_path / "f.db"), settle=0.2, poll=0.1, stop=stop,
        log=said.append), daemon=True)
    th.start()
    deadline = time.monotonic() + 60.0
    while not any("declares a cycle" in s for s in said) and time.monotonic() < deadline:
        time.sleep(0.1)
    for i, speed in enumerate((0.5, -0.5), start=2):   # a second batch: not said again
        write_stroke(tmp_path / "inbox" / "A" / f"s{i}.txt", speed, seed=i)
    while sum(": stored" in s or "s3.txt" in s for s in said) < 1 and (
            time.monotonic() < deadline):
        time.sleep(0.1)
    time.sleep(1.0)
    stop.set()
    th.join(30.0)
    noted = [s for s in said if "declares a cycle" in s]
    assert len(noted) == 1 and noted[0].startswith("A: "), said
    assert "each record is its own test" in noted[0]
