"""The degradation-path forecast: calibrated on its own model, right on known
paths, honest on a series that does not head for its end, and recalibrated
by the fleet's failed units."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from condmon.forecast.calibration import MIN_PEERS, MIN_PITS, calibrate, life_of, path_pits
from condmon.forecast.measured import coverage_note, forecast_by, forecast_path
from condmon.forecast.path import PathFit, _draws, fit_path, path_remaining, with_fleet
from condmon.errors import DataError

ROOT = Path(__file__).resolve().parents[1]
DECL = ROOT / "examples" / "batteries" / "li-ion-18650.toml"


def _path(rng: np.random.Generator, n: int = 500) -> np.ndarray:
    """A capacity from 1.9 [Ah] on the model's own family: a rate that wanders
    (geometric random walk), deviations that fade (AR(1))."""
    rate = -rng.uniform(0.003, 0.008)
    phi, sd, walk = rng.uniform(0.3, 0.9), rng.uniform(0.002, 0.01), rng.uniform(0.0, 0.002)
    w = np.cumsum(rng.normal(0.0, np.sqrt(walk), n))
    level = 1.9 + np.cumsum(rate * np.exp(w))
    e = np.zeros(n)
    for k in range(1, n):
        e[k] = phi * e[k - 1] + rng.normal(0.0, sd * np.sqrt(1.0 - phi * phi))
    return level + e


def test_its_90_percent_interval_covers_at_its_level_on_its_own_model() -> None:
    """100 simulated paths, each seen from 30 % of its life on: the 90 %
    interval of the cycle a reading first falls below 1.4 holds the truth in
    80-97 % of them (the study in condmon/forecast/path.py: 89 % of 150)."""
    rng = np.random.default_rng(11)
    hits = []
    for i in range(100):
        y = _path(rng)
        first = int(np.argmax(y < 1.4))
        if first < 20:
            continue
        seen = int(rng.integers(int(0.3 * first), first))
        change = 100.0 * (y[:seen + 1] - 1.9) / 1.9
        f = forecast_path(np.arange(seen + 1.0), change, np.zeros(seen + 1), 0.5,
                          100.0 * (1.4 - 1.9) / 1.9, seed=i)
        r = f.remaining
        hits.append(r is not None and r[1] <= first - seen <= r[2])
    assert len(hits) >= 90
    assert 0.80 <= np.mean(hits) <= 0.97, np.mean(hits)


def test_paths_carried_on_only_while_running_each_keep_their_own_crossing() -> None:
    """:func:`path_remaining` carries on only the paths that have not crossed,
    packing its arrays as they cross. Known truth: a line whose rate is
    uncertain (−0.05 ± 0.01 a check) and whose level, walk and deviations
    are nil, from 1.0 down to 0.0. Each drawn path crosses at the first whole
    check past ``1/|rate|``; its own rate is the one drawn first (the same
    seed), so a path given another's state after a packing shows."""
    grid = ((1.0, 1.0, -0.05, 1e-12, 0.0, 1e4, 1e-5),)
    fit = PathFit((1.0, -0.05), ((0.0, 0.0), (0.0, 1e-4)), 0.0, grid, 1000, 0.0, 0.0,
                  10.0, 10.0, 1.0, 12)
    left, step = path_remaining(fit, 0.0, seed=3, horizon=100.0, draws=2000)
    level, rate, *_ = _draws(fit, np.random.default_rng(3), 2000)
    assert step == 1.0 and np.all(rate < 0)
    truth = np.ceil(level / -rate)
    assert np.ptp(truth) >= 10               # paths cross over many checks: packed often
    assert np.mean(left == truth) >= 0.99, np.mean(left == truth)


def test_a_steady_fade_is_forecast_where_it_ends() -> None:
    """−0.3 % a cycle with small scatter, 50 cycles seen: −30 % at cycle 100."""
    rng = np.random.default_rng(2)
    x = np.arange(1.0, 51.0)
    f = forecast_path(x, -0.3 * x + 0.2 * rng.standard_normal(50), np.zeros(50), 0.5, -30.0)
    assert f.model == "path" and f.remaining is not None
    med, lo, hi = f.remaining
    assert abs(med - 50.0) <= 5.0 and lo <= 50.0 <= hi
    mid, low, high = f.band(np.array([0.0, 50.0]))
    assert low[1] < -30.0 < high[1] and abs(mid[1] + 30.0) < 3.0
    assert high[1] < high[0]   # drawn paths of a fade: the band does not rise


def test_a_series_heading_away_or_past_its_end_is_said_so() -> None:
    x = np.arange(1.0, 31.0)
    away = forecast_path(x, 0.2 * x, np.zeros(30), 0.5, -30.0)
    assert away.model == "no trend" and away.remaining is None
    assert "no steady move" in away.notes[-1]
    past = forecast_path(x, -1.1 * x, np.zeros(30), 0.5, -30.0)
    assert past.at_nogo and past.remaining == (0.0, 0.0, 0.0)


def test_a_short_series_is_forecast_as_a_trend_and_says_so() -> None:
    x = np.arange(1.0, 5.0)
    f = forecast_path(x, -2.0 * x, np.full(4, 0.5), 0.5, -30.0)
    assert f.model in ("linear", "exponential") and "too few for a degradation path" in f.notes[0]
    # what such an interval held on real measured series is said with it
    assert "in 23 % of 62 forecasts on NASA's Li-ion cells" in f.notes[-1], f.notes
    with pytest.raises(DataError, match="methods are trend, path"):
        forecast_by("kalman", x, -2.0 * x, np.full(4, 0.5), 0.5, -30.0)
    with pytest.raises(DataError, match="x must increase"):
        fit_path([1.0, 2.0, 2.0, 3.0, 4.0, 5.0], np.zeros(6))


def test_the_fleet_s_failed_units_recalibrate_the_levels() -> None:
    """PITs bunched in the middle (intervals too wide) narrow the interval; a
    fleet too small to tell changes nothing: too few forecasts, or forecasts
    along fewer than three peers (one life's shape, not a fleet's spread)."""
    assert calibrate([0.5] * (MIN_PITS - 1), 3) is None
    assert calibrate(np.linspace(0.35, 0.65, 40), MIN_PEERS - 1) is None
    c = calibrate(np.linspace(0.35, 0.65, 40), MIN_PEERS)
    assert c is not None and 0.35 <= c.low < c.median < c.high <= 0.65
    x = np.arange(1.0, 61.0)
    y = -0.3 * x + 0.5 * np.sin(x / 3.0)
    plain = forecast_path(x, y, np.zeros(60), 0.5, -30.0)
    narrow = forecast_path(x, y, np.zeros(60), 0.5, -30.0, calibration=c)
    assert plain.remaining is not None and narrow.remaining is not None
    assert narrow.remaining[2] - narrow.remaining[1] < plain.remaining[2] - plain.remaining[1]
    assert any(n.startswith("recalibrated on 40 forecasts along 3 failed peer") for n in
               narrow.notes)
    assert "each recalibrated on the other three" in coverage_note("path", True)
    peer = 2.0 - 0.01 * x + 0.004 * np.sin(x)
    assert len(path_pits(x, peer, 1.5)) == 20
    assert path_pits(x, peer, 1.0) == []   # never reaches its end: no life to learn


def test_failed_peers_whole_lives_pool_the_rate_s_wander() -> None:
    """Known truth: three peers fading steadily at −0.3 %/cycle with fading
    deviations and no wander, each to −30 % at cycle 100; a unit on the same
    line seen to cycle 30. Its own quarters give the walk three changes'
    worth of evidence; the peers' whole lives add theirs, weighted by
    degrees of freedom. Pooled, the interval narrows and still holds the
    true 70 cycles left."""
    rng = np.random.default_rng(3)

    def fade(n: int) -> np.ndarray:
        e = np.zeros(n)
        for k in range(1, n):
            e[k] = 0.6 * e[k - 1] + rng.normal(0.0, 0.3)
        return -0.3 * np.arange(1.0, n + 1) + e

    x = np.arange(1.0, 121.0)
    lives = [life_of(x, fade(120), -30.0) for _ in range(3)]
    assert all(w is not None and w.walk[2] == 3 for w in lives)
    own = fit_path(x[:30], fade(30))
    pooled = with_fleet(own, [w for w in lives if w is not None])
    raws = [own.walk_moments[0]] + [w.walk[0] for w in lives if w is not None]
    assert pooled.walk_moments[2] == 12
    assert pooled.walk_moments[0] == pytest.approx(np.mean(raws))
    assert with_fleet(own, []) is own
    c = calibrate(np.linspace(0.025, 0.975, 40), MIN_PEERS, [w for w in lives if w is not None])
    assert c is not None and len(c.lives) == 3
    y = fade(30)
    plain = forecast_path(x[:30], y, np.zeros(30), 0.5, -30.0, seed=1,
                          calibration=dataclasses.replace(c, lives=()))
    lent = forecast_path(x[:30], y, np.zeros(30), 0.5, -30.0, seed=1, calibration=c)
    assert plain.remaining is not None and lent.remaining is not None
    assert lent.remaining[2] - lent.remaining[1] < plain.remaining[2] - plain.remaining[1]
    assert lent.remaining[1] <= 70.0 <= lent.remaining[2], lent.remaining
    assert any("3 of their whole lives its prior" in n for n in lent.notes), lent.notes


def test_failed_peers_mean_rates_are_the_prior_of_a_poorly_told_rate() -> None:
    """Known truth: peers fading at −0.25, −0.3 and −0.35 %/cycle; 20 units
    fading at −0.3 %/cycle, each seen for 15 cycles under recoveries of
    0.5 %, too short to tell its own rate. With the peers' lives as the
    prior, the median remaining life is nearer the truth (85 cycles); and a
    unit whose own rate is well told, −0.6 %/cycle over 60 cycles, keeps it
    against the same peers (its end at −60 %: 40 cycles left, within 20 %)."""
    rng = np.random.default_rng(8)

    def fade(n: int, rate: float, sd: float) -> np.ndarray:
        e = np.zeros(n)
        for k in range(1, n):
            e[k] = 0.7 * e[k - 1] + rng.normal(0.0, sd)
        return rate * np.arange(1.0, n + 1) + e

    x = np.arange(1.0, 161.0)
    lives = [life_of(x, fade(160, r, 0.2), -30.0) for r in (-0.25, -0.3, -0.35)]
    assert all(life is not None for life in lives)
    c = calibrate(np.linspace(0.025, 0.975, 40), MIN_PEERS,
                  [life for life in lives if life is not None])
    assert c is not None and [round(life.rate, 2) for life in c.lives] == [-0.25, -0.3, -0.35]
    alone, lent = [], []
    for i in range(20):
        y = fade(15, -0.3, 0.5)
        a = forecast_path(x[:15], y, np.zeros(15), 0.5, -30.0, seed=i,
                          calibration=dataclasses.replace(c, lives=()))
        b = forecast_path(x[:15], y, np.zeros(15), 0.5, -30.0, seed=i, calibration=c)
        if a.remaining and b.remaining:   # (a short series may show no steady trend)
            alone.append(abs(np.log(a.remaining[0] / 85.0)))
            lent.append(abs(np.log(b.remaining[0] / 85.0)))
    assert len(lent) >= 15
    assert np.median(lent) < 0.75 * np.median(alone), (np.median(lent), np.median(alone))
    y = fade(60, -0.6, 0.2)
    own = forecast_path(x[:60], y, np.zeros(60), 0.5, -60.0, seed=1, calibration=c)
    # 40 cycles left at its own rate; the peers' would say 140
    assert own.remaining is not None and 32.0 <= own.remaining[0] <= 48.0, own.remaining
    said = [n for n in own.notes if "with the fleet's prior" in n]
    assert said and "its own series alone" in said[0], own.notes


def test_peers_lend_the_rate_they_went_on_at_from_as_near_their_end() -> None:
    """Known truth: wear that speeds up with damage, ``y = −(e^(x/τ) − 1)``
    [%], ends at −30 % (x = τ·ln 31). Peers with τ = 36, 40 and 44 cycles
    went on from −20 % to their end at 10/(τ·ln(31/21)) %/cycle: 0.71,
    0.64 and 0.58, above their lines' mean rates over their lives (about
    0.4). A unit with τ = 40 seen up to −20 % (x = 40·ln 21, 122 cycles) has
    15.6 cycles left; its own line through the whole series says far more.
    The peers' rates from its distance are its prior; their mean rates
    over their lives would put it late. (The rates lent are read from the
    peers' trends as their own forecasts read them then, as the unit's is:
    a line through a bending series lags its end, so they are faster still
    than the curve's own from −20 %.)"""
    rng = np.random.default_rng(3)

    def wear(tau: float, n: int) -> tuple[np.ndarray, np.ndarray]:
        x = np.arange(1.0, n + 1.0)
        return x, -(np.exp(x / tau) - 1.0) + rng.normal(0.0, 0.05, n)

    lives = [life_of(*wear(tau, int(tau * np.log(31.0)) + 2), -30.0) for tau in (36.0, 40.0, 44.0)]
    assert all(life is not None and life.track for life in lives)
    known = [life for life in lives if life is not None]
    rates = [-10.0 / (tau * np.log(31.0 / 21.0)) for tau in (36.0, 40.0, 44.0)]
    lent = [life.rate_from(-10.0) for life in known]
    assert lent[0] < lent[1] < lent[2] and all(a < r for a, r in zip(lent, rates)), (lent, rates)
    assert all(life.rate > 0.5 * a for life, a in zip(known, lent))   # (whole lives: slower)
    c = calibrate(np.linspace(0.025, 0.975, 40), MIN_PEERS, known)
    assert c is not None
    bare = dataclasses.replace(c, lives=tuple(dataclasses.replace(life, track=())
                                              for life in known))
    truth = 40.0 * np.log(31.0) - 40.0 * np.log(21.0)
    near, far = [], []
    for i in range(8):
        x, y = wear(40.0, 122)
        a = forecast_path(x, y, np.zeros(x.size), 0.05, -30.0, seed=i, calibration=c)
        b = forecast_path(x, y, np.zeros(x.size), 0.05, -30.0, seed=i, calibration=bare)
        assert a.remaining is not None and b.remaining is not None
        near.append(abs(np.log(a.remaining[0] / truth)))
        far.append(abs(np.log(b.remaining[0] / truth)))
    assert np.median(near) < 0.5 * np.median(far), (near, far)
    assert np.median(near) < np.log(1.3), near


def test_a_peer_s_rate_is_read_where_its_trend_still_headed_for_its_end() -> None:
    """A peer's track matched on the change still to make: the first point
    as near; the first point when the unit is farther from its end than the
    peer ever was; its last point heading for its end when the unit is
    nearer; a point where the peer's trend had passed its end (a recovery
    held its readings up) tells no rate; no track: its mean rate."""
    from condmon.forecast.path import Life

    track = ((-4.0, 80.0), (-2.0, 40.0), (-1.0, 25.0), (0.5, 4.0))   # falling to its end
    peer = Life((0.0, 0.0, 0), -0.05, track)
    assert peer.rate_from(-1.5) == -1.0 / 25.0
    assert peer.rate_from(-9.0) == -4.0 / 80.0
    assert peer.rate_from(-0.2) == -1.0 / 25.0          # not +0.5 / 4: past its end there
    assert Life((0.0, 0.0, 0), -0.05).rate_from(-1.5) == -0.05
    rising = Life((0.0, 0.0, 0), 0.05, tuple((-g, x) for g, x in track))
    assert rising.rate_from(1.5) == 1.0 / 25.0


def test_a_life_past_its_forecasts_95_percent_point_is_read_there() -> None:
    """Known truth: a peer fading at −0.5 %/cycle to −20 %, then at −0.05
    %/cycle to its end at −30 % (cycle 240). Its early forecasts expect the
    end some 20 cycles on; the truth came about 200 on, past nearly every
    draw, so those PITs read above 0.99 (the draws stop at the 95 % point
    only once past the truth). A fleet whose lives came late reads the
    unit's interval above the draws' 95 % point, and its end is still a
    number of cycles, not "never"."""
    rng = np.random.default_rng(4)
    x = np.arange(1.0, 261.0)
    y = np.where(x <= 40, -0.5 * x, -20.0 - 0.05 * (x - 40)) + rng.normal(0.0, 0.05, 260)
    assert max(path_pits(x, y, -30.0)) > 0.99
    c = calibrate(np.linspace(0.5, 1.0, 41), MIN_PEERS)
    assert c is not None and c.high > 0.95
    xs = np.arange(1.0, 61.0)
    ys = -0.3 * xs + 0.5 * np.sin(xs / 3.0)
    plain = forecast_path(xs, ys, np.zeros(60), 0.5, -30.0)
    late = forecast_path(xs, ys, np.zeros(60), 0.5, -30.0, calibration=c)
    assert plain.remaining is not None and late.remaining is not None
    assert np.isfinite(late.remaining[2]) and late.remaining[2] > plain.remaining[2]


def test_a_fleet_whose_lives_end_before_every_draw_is_not_read() -> None:
    """Peers that failed suddenly: 10 % of their forecasts saw the life end
    before every draw (PIT 0). Reading the fleet's levels there would put the
    interval's low end, and here its median, at the first draw ("1 (1-1)");
    the forecast is given unrecalibrated instead, and says why."""
    pits = np.concatenate([np.zeros(6), np.linspace(0.0, 0.05, 54)])
    c = calibrate(pits, MIN_PEERS, names=("A", "B", "C"))
    assert c is not None and c.refused.startswith("not recalibrated: in 7 of 60 forecasts")
    assert "ended before every draw" in c.refused
    assert calibrate(np.linspace(0.0, 1.0, 60), MIN_PEERS).refused == ""   # one at 0, one at 1
    x = np.arange(1.0, 61.0)
    y = -0.3 * x + 0.5 * np.sin(x / 3.0)
    plain = forecast_path(x, y, np.zeros(60), 0.5, -30.0)
    given = forecast_path(x, y, np.zeros(60), 0.5, -30.0, calibration=c)
    assert given.remaining == plain.remaining
    assert given.notes[1] == c.refused
    assert not any("failed peer(s) (A, B, C)" in n for n in given.notes)
    assert not any("the levels their lives call for" in n for n in given.notes), given.notes


def test_the_chance_within_a_horizon_is_read_on_the_fleet_as_the_interval_is() -> None:
    """Peers whose lives all ended early in their forecasts (PITs 0..0.2): the
    recalibrated median comes early, and the chance of no-go by that median
    is about a half (it was the draws' own share, about 0.1, beside it)."""
    x = np.arange(1.0, 61.0)
    y = -0.3 * x + 0.5 * np.sin(x / 3.0)
    c = calibrate(np.linspace(0.0, 0.2, 41), MIN_PEERS)
    assert c is not None
    med = forecast_path(x, y, np.zeros(60), 0.5, -30.0, calibration=c).remaining
    assert med is not None
    at = forecast_path(x, y, np.zeros(60), 0.5, -30.0, horizon=med[0], calibration=c)
    raw = forecast_path(x, y, np.zeros(60), 0.5, -30.0, horizon=med[0])
    assert at.p_within is not None and raw.p_within is not None
    assert 0.4 <= at.p_within <= 0.7 and raw.p_within < 0.25
    assert "not on units like this one" in coverage_note("path")


def test_imported_peers_recalibrate_a_unit_s_forecast(tmp_path: Path) -> None:
    """Three cells of the declaration run to their end of life, a fourth at
    cycle 40: its forecast is read at the levels where theirs fell."""
    from condmon.store import open_store
    from condmon.workflows.forecasting import forecast_unit
    from condmon.workflows.imports import import_table

    rng = np.random.default_rng(5)
    with open_store("sqlite://") as store:
        for i, rate in enumerate((0.005, 0.006, 0.007, 0.006)):
            n = 120 if i < 3 else 40
            cap = 1.9 - rate * np.arange(1, n + 1) + 0.004 * rng.standard_normal(n)
            table = tmp_path / f"c{i}.csv"
            table.write_text("cycle,capacity\n" + "".join(
                f"{k},{v:.5f}\n" for k, v in enumerate(cap, 1)))
            import_table(store, table, DECL, unit=f"C{i}")
        f = forecast_unit(store, "C3").parameters[0].forecast
        assert any("3 failed peer(s) (C0, C1, C2)" in n and "3 of their whole lives" in n
                   for n in f.notes), f.notes
        assert f.remaining is not None
        truth = (1.9 - 1.4) / 0.006 - 40
        assert f.remaining[1] <= truth <= f.remaining[2]
    with open_store("sqlite://") as store:   # one failed peer: not recalibrated
        for i in (0, 3):
            import_table(store, tmp_path / f"c{i}.csv", DECL, unit=f"C{i}")
        f = forecast_unit(store, "C3").parameters[0].forecast
        assert not any("failed peer(s)" in n for n in f.notes), f.notes


def test_peers_counted_in_hours_lend_no_life_to_a_unit_counted_in_cycles(tmp_path: Path) -> None:
    """Two failed cells counted in cycles and two in hours, a fifth at cycle
    40 counted in cycles: all four recalibrate it (a PIT is free of the
    axis), but a rate per hour is no rate per cycle, and two lives are too
    few for a prior: the note names the four and says why none is its prior."""
    from condmon.store import open_store
    from condmon.workflows.forecasting import forecast_unit
    from condmon.workflows.imports import import_table

    rng = np.random.default_rng(6)
    with open_store("sqlite://") as store:
        for i, (rate, axis) in enumerate(((0.005, "cycle"), (0.006, "cycle"),
                                          (0.007, "hours"), (0.006, "hours"), (0.006, "cycle"))):
            n = 120 if i < 4 else 40
            cap = 1.9 - rate * np.arange(1, n + 1) + 0.004 * rng.standard_normal(n)
            table = tmp_path / f"c{i}.csv"
            table.write_text(f"{axis},capacity\n" + "".join(
                f"{2.5 * k if axis == 'hours' else k},{v:.5f}\n" for k, v in enumerate(cap, 1)))
            import_table(store, table, DECL, unit=f"C{i}")
        f = forecast_unit(store, "C4").parameters[0].forecast
        said = [n for n in f.notes if "failed peer(s)" in n]
        assert said and "4 failed peer(s) (C0, C1, C2, C3)" in said[0], f.notes
        assert "whole lives its prior" not in said[0]
        assert "2 of them count their lives otherwise than it does (not its prior: 3 that " \
               "count as it does are needed)" in said[0]


def test_a_unit_imported_twice_is_one_peer_and_no_prior_of_itself(tmp_path: Path) -> None:
    """Three failed cells, one of them imported again under a second name, and
    a fourth cell at cycle 40 whose whole life was also imported as a failed
    'peer': the copies are left out and named, so the prior is the three
    cells' lives and the recalibration theirs, as without the copies."""
    from condmon.store import open_store
    from condmon.workflows.forecasting import forecast_unit
    from condmon.workflows.imports import import_table

    rng = np.random.default_rng(7)
    tables = {}
    for i, rate in enumerate((0.005, 0.006, 0.007, 0.006)):
        cap = 1.9 - rate * np.arange(1, 121) + 0.004 * rng.standard_normal(120)
        for name, n in ((f"c{i}", 120 if i < 3 else 40), (f"w{i}", 120)):
            tables[name] = tmp_path / f"{name}.csv"
            tables[name].write_text("cycle,capacity\n" + "".join(
                f"{k},{v:.5f}\n" for k, v in enumerate(cap[:n], 1)))
    with open_store("sqlite://") as store:
        for i in range(4):
            import_table(store, tables[f"c{i}"], DECL, unit=f"C{i}")
        plain = forecast_unit(store, "C3").parameters[0].forecast
        import_table(store, tables["c1"], DECL, unit="C1-again")
        import_table(store, tables["w3"], DECL, unit="C3-whole")
        f = forecast_unit(store, "C3").parameters[0].forecast
    said = [n for n in f.notes if "failed peer(s)" in n]
    assert said and "3 failed peer(s) (C0, C1, C2)" in said[0], f.notes
    assert "C1-again, C3-whole left out: the same series" in said[0]
    assert f.remaining == plain.remaining


def test_an_indicator_unit_with_too_few_checks_for_a_path_is_not_forecast(
        tmp_path: Path) -> None:
    """A cell five checks past its baseline, falling steadily: a trend would
    give a tight interval (on NASA's cells such intervals held the truth in 23 %
    of forecasts), so no forecast is given, and the reason says so; a sixth
    check gives a path forecast."""
    from condmon.errors import DataError
    from condmon.store import open_store
    from condmon.store.forecasts import try_forecast
    from condmon.workflows.forecasting import forecast_unit
    from condmon.workflows.imports import import_table

    cap = [2.0] * 5 + [1.95, 1.90, 1.85, 1.80, 1.75, 1.70]
    for n, path in ((10, False), (11, True)):
        table = tmp_path / f"t{n}.csv"
        table.write_text("cycle,capacity\n" + "".join(
            f"{k},{v:.5f}\n" for k, v in enumerate(cap[:n], 1)))
        with open_store("sqlite://") as store:
            import_table(store, table, DECL, unit="T")
            if path:
                f = forecast_unit(store, "T").parameters[0].forecast
                assert f.model == "path" and f.remaining is not None
                continue
            with pytest.raises(DataError, match="has 5 check.s. since its baseline, a "
                               "measured degradation path needs 6 .a trend instead: its 90 % "
                               "interval held the true remaining life in only 23 %"):
                forecast_unit(store, "T")
            res, why = try_forecast(store, "T")
            assert res is None and why is not None and "needs 6" in why
