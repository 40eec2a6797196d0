"""The fleet prior on the degradation rate (and shape) against known truth: a tight correct
prior sharpens an early forecast, a vague one leaves it alone, the fleet's rate
and spread are recovered, and the refusals."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from condmon.errors import DataError
from condmon.forecast.series import (
    FleetPrior, RatePrior, fleet_prior, fleet_wear_prior, forecast_series, prior_from_wear,
    unit_wear,
)

# the truth: +2 % a test, no-go at +60 %: crossed at test 30
RATE, THRESHOLD, NOISE = 2.0, 60.0, 3.0


def _early(seed: int, tests: int = 4) -> tuple[np.ndarray, np.ndarray]:
    x = np.arange(1.0, tests + 1.0)
    return x, RATE * x + np.random.default_rng(seed).normal(0.0, NOISE, tests)


def test_a_tight_correct_prior_sharpens_an_early_forecast() -> None:
    """Six tests of a unit that wears as its fleet did: once its own checks
    move, the fleet's rate narrows and steadies the forecast; the tests where
    its own checks do not move yet are "no trend" with the prior too (the
    fleet's wear is not a trend of a unit's own)."""
    truth = THRESHOLD / RATE - 6.0
    tight = RatePrior("linear", RATE, 0.1, 20)
    err_own, err_prior, width_own, width_prior = [], [], [], []
    for seed in range(40):
        x, y = _early(seed, tests=6)
        own = forecast_series(x, y, np.full(6, NOISE), 1.0, THRESHOLD)
        post = forecast_series(x, y, np.full(6, NOISE), 1.0, THRESHOLD, prior=tight)
        assert (post.remaining is None) == (own.remaining is None)
        if own.remaining is None:       # no trend seen in 6 tests: no number at all
            continue
        assert post.model == "linear"
        err_prior.append(abs(post.remaining[0] - truth))
        width_prior.append(post.remaining[2] - post.remaining[1])
        err_own.append(abs(own.remaining[0] - truth))
        width_own.append(own.remaining[2] - own.remaining[1])
    assert len(err_own) >= 30
    assert np.median(err_prior) < 0.5 * np.median(err_own)
    assert np.median(err_prior) / truth < 0.1
    assert np.median(width_prior) < 0.5 * np.median(width_own)


def test_a_healthy_unit_is_not_forecast_to_wear_as_its_peers_did() -> None:
    """Peers that wore -5 %/day give a tight prior; a unit whose checks stay
    flat (±2 %) is "no trend"; mostly because its own checks do not move
    where the prior alone would have made a trend of them."""
    x = np.arange(1.0, 11.0)
    peers = RatePrior("linear", -5.0, 0.2, 3)
    own = 0
    for seed in range(20):
        y = np.random.default_rng(seed).normal(0.0, 1.0, 10)
        f = forecast_series(x, y, np.full(10, 1.0), 1.0, -40.0, prior=peers)
        assert not f.trend and f.remaining is None, (seed, f)
        assert "no steady move" in f.notes[-1]
        own += "own checks hold no steady move" in f.notes[-1]
    assert own >= 10, own


def test_a_wrong_but_vague_prior_does_not_move_the_forecast() -> None:
    x, y = _early(3, tests=12)
    own = forecast_series(x, y, np.full(12, NOISE), 1.0, THRESHOLD)
    wide = forecast_series(x, y, np.full(12, NOISE), 1.0, THRESHOLD,
                           prior=RatePrior("linear", -10.0, 1e4, 3))
    assert own.remaining is not None and wide.remaining is not None
    assert wide.remaining[0] == pytest.approx(own.remaining[0], rel=0.01)
    assert wide.slope == pytest.approx(own.slope, rel=0.01)


def test_no_fleet_history_is_a_vague_prior_and_said() -> None:
    x, y = _early(5, tests=10)
    alone = fleet_prior([(x, y, np.full(10, NOISE), 1.0)])
    assert alone.units == 0 and not alone.informative
    own = forecast_series(x, y, np.full(10, NOISE), 1.0, THRESHOLD)
    vague = forecast_series(x, y, np.full(10, NOISE), 1.0, THRESHOLD, prior=alone)
    assert vague.remaining == own.remaining and vague.model == own.model
    assert vague.notes[-1] == "no fleet history: vague prior"
    assert not any("prior" in n for n in own.notes)      # no prior asked: nothing said


def test_the_fleet_rate_and_spread_are_recovered() -> None:
    rng = np.random.default_rng(11)
    rates = rng.normal(2.0, 0.3, 40)
    x = np.arange(1.0, 26.0)
    fleet = [(x, r * x + rng.normal(0.0, 1.0, 25), np.ones(25), 0.5) for r in rates]
    p = fleet_prior(fleet)
    assert p.model == "linear" and p.units == 40
    assert p.mean == pytest.approx(rates.mean(), abs=0.05)
    assert p.sd == pytest.approx(rates.std(ddof=1), rel=0.15)
    assert p.describe() == f"fleet prior (linear) from 40 units: slope {p.mean:.3g} ± {p.sd:.2g} %/test"


def test_an_exponential_fleet_gives_its_growth_rate() -> None:
    rng = np.random.default_rng(2)
    x = np.arange(1.0, 21.0)
    rates = rng.normal(0.15, 0.02, 10)
    fleet = [(x, 5.0 * np.exp(r * x) * (1.0 + rng.normal(0.0, 0.02, 20)), np.full(20, 0.5), 0.5)
             for r in rates]
    p = fleet_prior(fleet, model="exponential")
    assert p.units == 10 and p.mean == pytest.approx(rates.mean(), abs=0.01)
    # a unit's first tests with its fleet's growth rate: the exponential, updated
    y = fleet[0][1][:8]
    own = forecast_series(x[:8], y, np.full(8, 0.5), 0.5, threshold=200.0)
    f = forecast_series(x[:8], y, np.full(8, 0.5), 0.5, threshold=200.0, prior=p)
    assert f.notes[-1] == p.describe()
    truth = math.log(200.0 / 5.0) / rates[0] - 8.0
    assert f.remaining is not None and own.remaining is not None
    assert f.remaining[1] <= truth <= f.remaining[2]
    assert f.remaining[2] - f.remaining[1] < own.remaining[2] - own.remaining[1]


def test_a_prior_whose_model_cannot_be_fitted_is_not_used() -> None:
    x = np.arange(1.0, 7.0)
    y = np.array([0.0, 4.0, 6.0, 7.0, 7.5, 7.8])             # slowing down: no exponential
    p = RatePrior("exponential", 0.2, 0.01, 8)
    f = forecast_series(x, y, np.full(6, 0.1), 0.1, threshold=40.0, prior=p)
    assert f.model == "linear" and f.notes[-1].endswith("not used: no growing exponential "
                                                         "fits the series")


@pytest.mark.parametrize("args,message", [
    (("quadratic", 1.0, 1.0, 3), "unknown degradation model 'quadratic'"),
    (("linear", 1.0, 0.0, 3), "an sd > 0"),
    (("linear", math.nan, 1.0, 3), "a finite mean"),
])
def test_bad_priors_are_refused(args: tuple[str, float, float, int], message: str) -> None:
    with pytest.raises(DataError, match=message):
        RatePrior(*args)


def test_fleet_prior_refusals() -> None:
    x = np.arange(1.0, 5.0)
    with pytest.raises(DataError, match="unknown degradation model 'cubic'"):
        fleet_prior([(x, x, np.ones(4), 1.0)] * 2, model="cubic")
    with pytest.raises(DataError, match="not enough tests to forecast"):
        fleet_prior([(x[:2], x[:2], np.ones(2), 1.0)] * 2)


def test_a_prior_as_tight_as_can_be_is_the_rate() -> None:
    """A prior far tighter than the fit (two identical fleet units) fixes the
    rate without a near-singular inverse: 600 % from +420 % at 115 %/day is
    1.6 days, not 10^8."""
    x = np.array([1.0, 2.0, 3.0, 4.0])
    f = forecast_series(x, [100.0, 210.0, 290.0, 420.0], np.full(4, 5.0), 10.0, 600.0,
                        prior=RatePrior("linear", 115.0, 1e-12, 2, "day"))
    assert f.slope == pytest.approx(115.0) and f.remaining is not None
    assert 1.2 < f.remaining[1] <= f.remaining[0] <= f.remaining[2] < 2.0


def _exp_unit(rate: float, seed: int, tests: int) -> tuple[np.ndarray, np.ndarray]:
    """A unit that wears exponentially: +10·(e^(r·k) − 1) %, ±2 % per test."""
    x = np.arange(1.0, tests + 1.0)
    return x, 10.0 * np.expm1(rate * x) + np.random.default_rng(seed).normal(0.0, 2.0, tests)


def test_peers_that_wore_exponentially_make_a_new_unit_exponential() -> None:
    """Half-way to no-go (+300 %) a unit's own 11 tests barely pin the curve;
    a fleet that wore exponentially at a like rate makes its forecast
    exponential and on time (the truth inside the 90 % interval), closer than
    its own evidence alone."""
    rng = np.random.default_rng(4)
    fleet = [(*_exp_unit(r, 100 + i, 30), np.full(30, 2.0), 1.0)
             for i, r in enumerate(rng.normal(0.15, 0.015, 8))]
    prior = fleet_wear_prior(fleet)
    assert prior.exponential.units == 8 and prior.p_exponential == pytest.approx(0.9)
    assert prior.exponential.mean == pytest.approx(0.15, abs=0.015)
    own_hits = shaped = 0
    err_own, err_prior = [], []
    for seed in range(10):
        x, y = _exp_unit(0.15, seed, 11)
        truth = math.log(31.0) / 0.15 - 11.0            # 10·(e^(0.15·k) − 1) = 300
        own = forecast_series(x, y, np.full(11, 2.0), 1.0, 300.0)
        f = forecast_series(x, y, np.full(11, 2.0), 1.0, 300.0, prior=prior)
        assert f.remaining is not None and own.remaining is not None
        assert f.model == "exponential" and f.notes[-1] == prior.describe()
        assert f.remaining[1] <= truth <= f.remaining[2]
        shaped += abs(f.remaining[0] - truth) <= 0.2 * truth
        own_hits += abs(own.remaining[0] - truth) <= 0.2 * truth
        err_own.append(abs(own.remaining[0] - truth))
        err_prior.append(abs(f.remaining[0] - truth))
    # own evidence: 7 of 10 within ±20 %, a median error of 1.2 tests; the fleet's: 10, 0.2
    assert shaped >= 9 and shaped > own_hits
    assert np.median(err_prior) < 0.5 * np.median(err_own)


def test_a_linear_fleet_keeps_a_linear_unit_linear() -> None:
    """Peers that wore linearly give the slope and no curve: a unit on their
    path is forecast by the line, on time."""
    rng = np.random.default_rng(8)
    x = np.arange(1.0, 31.0)
    fleet = [(x, r * x + rng.normal(0.0, NOISE, 30), np.full(30, NOISE), 1.0)
             for r in rng.normal(RATE, 0.2, 8)]
    prior = fleet_wear_prior(fleet)
    # (noise curves 2 of the 8 a little, b·span ≈ 0.5: the odds stay with the line)
    assert prior.p_exponential < 0.5 and prior.linear.units >= 6
    assert prior.linear.mean == pytest.approx(RATE, abs=0.2)
    x, y = _early(7, tests=10)
    f = forecast_series(x, y, np.full(10, NOISE), 1.0, THRESHOLD, prior=prior)
    assert f.model == "linear" and f.remaining is not None
    assert f.remaining[0] == pytest.approx(THRESHOLD / RATE - 10.0, rel=0.2)


def test_a_shape_prior_without_peers_is_vague_and_said() -> None:
    x, y = _early(5, tests=10)
    own = forecast_series(x, y, np.full(10, NOISE), 1.0, THRESHOLD)
    f = forecast_series(x, y, np.full(10, NOISE), 1.0, THRESHOLD, prior=fleet_wear_prior([]))
    assert f.remaining == own.remaining and f.notes[-1] == "no fleet history: vague prior"
    with pytest.raises(DataError, match=r"in \(0, 1\)"):
        FleetPrior(1.0, RatePrior.vague(), RatePrior.vague("exponential"), 3)


def _mixed_fleet() -> FleetPrior:
    """8 units that wore exponentially (+10·(e^(b·k) − 1) %, b ≈ 0.15) and 8
    that wore linearly (≈ +13 %/test: the same life to +300 %), 30 tests each."""
    rng = np.random.default_rng(5)
    x = np.arange(1.0, 31.0)
    fleet = [(*_exp_unit(r, 100 + i, 30), np.full(30, 2.0), 1.0)
             for i, r in enumerate(rng.normal(0.15, 0.015, 8))]
    fleet += [(x, s * x + rng.normal(0.0, 2.0, 30), np.full(30, 2.0), 1.0)
              for s in rng.normal(13.0, 2.0, 8)]
    return fleet_wear_prior(fleet)


def test_the_fleets_amplitude_pins_a_curve_that_still_looks_straight() -> None:
    """Six tests into a life of 23, an exponential unit has risen +8 %, far
    slower than the fleet's lines (+13 %/test) and not yet visibly bent. With
    the fleet's amplitude and slope priors the Bayes factor weighs the
    fleet's line against the fleet's curve, and the forecast is the curve's,
    on time and tight; with the rate prior alone (the line's slope flat) the
    intervals run to 5-9 times the truth."""
    prior = _mixed_fleet()
    assert prior.exponential.units == 8 and prior.linear.units == 8
    assert prior.amplitude is not None and prior.amplitude.mean == pytest.approx(10.0, rel=0.1)
    assert "amplitude 9.9" in prior.describe() and prior.to_dict()["amplitude"]["units"] == 8
    rate_only = dataclasses.replace(prior, amplitude=None)
    truth = math.log(31.0) / 0.15 - 6.0
    for seed in range(10):
        x, y = _exp_unit(0.15, seed, 6)
        f = forecast_series(x, y, np.full(6, 2.0), 1.0, 300.0, prior=prior)
        old = forecast_series(x, y, np.full(6, 2.0), 1.0, 300.0, prior=rate_only)
        assert f.remaining is not None and old.remaining is not None
        assert f.model == "exponential" and "against the fleet's line" in f.notes[0]
        assert abs(f.remaining[0] - truth) <= 0.2 * truth
        assert f.remaining[1] <= truth <= f.remaining[2] < 1.5 * truth
        assert old.remaining[2] > 5.0 * truth


def test_a_barely_bent_peer_teaches_its_slope() -> None:
    """A peer whose fitted curve's slope grew less than e-fold over its series
    (b·span < 1) wore as a line: it teaches its slope, not a near-flat rate
    with an amplitude of thousands of %; a clearly bent one teaches its curve."""
    x = np.arange(1.0, 21.0)
    gentle = unit_wear(x, 2000.0 * np.expm1(0.02 * x), np.full(20, 1.0), 1.0)
    assert gentle.exponential is not None and gentle.exponential_weight > 0.5
    assert gentle.exponential[0] * (gentle.span or 0.0) < 1.0 and gentle.shape == "linear"
    bent = unit_wear(x, 10.0 * np.expm1(0.2 * x), np.full(20, 1.0), 1.0)
    assert bent.shape == "exponential" and bent.amplitude is not None
    assert bent.amplitude[0] == pytest.approx(10.0, rel=0.02)
    assert bent.exponential is not None and bent.exponential[0] == pytest.approx(0.2, rel=0.01)
    prior = prior_from_wear([gentle, gentle, bent])
    assert prior.linear.units == 2 and prior.p_exponential == pytest.approx(2.0 / 5.0)


def test_the_evidence_is_the_integral_it_stands_for() -> None:
    """The closed-form marginal likelihood of ``y = c + k·g`` (c flat, k
    normal) and its posterior mean of k, against numerical integration."""
    from scipy.integrate import dblquad

    from condmon.forecast.degradation import _normal_evidence

    x = np.arange(1.0, 7.0)
    y = np.array([1.0, 3.5, 4.0, 7.5, 8.0, 11.0])
    w = np.array([1.0, 0.5, 1.0, 2.0, 1.0, 0.8])
    g = np.expm1(0.2 * x)
    mean, sd, scale = 5.0, 2.0, 1.3
    log_e, ck, _, _ = _normal_evidence(g[None, :], y, w, mean, sd, scale)

    def joint(k: float, c: float) -> float:
        r = y - c - k * g
        return math.exp(-0.5 * float(w @ r ** 2) / scale) * math.exp(
            -0.5 * ((k - mean) / sd) ** 2) / (sd * math.sqrt(2.0 * math.pi))

    total, _ = dblquad(joint, -20.0, 20.0, 0.0, 10.0, epsabs=1e-14)
    first, _ = dblquad(lambda k, c: k * joint(k, c), -20.0, 20.0, 0.0, 10.0, epsabs=1e-14)
    # the shared ½·ln(2πσ²/Σw) of the flat level is left out of the closed form
    shared = 0.5 * math.log(2.0 * math.pi * scale / float(w.sum()))
    assert float(log_e[0]) + shared == pytest.approx(math.log(total), abs=1e-6)
    assert float(ck[0, 1]) == pytest.approx(first / total, rel=1e-6)


def _bent_unit(slope: float, bend: float, seed: int, tests: int) -> tuple[np.ndarray, np.ndarray]:
    """A line that bends up a little: +slope·(e^(b·k) − 1)/b %, ±2 % per test."""
    x = np.arange(1.0, tests + 1.0)
    return x, slope * np.expm1(bend * x) / bend + np.random.default_rng(seed).normal(
        0.0, 2.0, tests)


def test_a_fleet_whose_lines_bent_teaches_the_bend() -> None:
    """Lines that bent a little (b·span 0.9: slope +5 %/test rising to +12),
    beside peers that wore exponentially: the fleet's bend is recovered, and a
    unit on the lines' path is forecast on time (within 1.5 tests), where
    the fleet's line taken straight is 3.5-7 tests late."""
    rng = np.random.default_rng(11)
    x = np.arange(1.0, 31.0)
    fleet = [(*_bent_unit(s, 0.03, 100 + i, 30), np.full(30, 2.0), 1.0)
             for i, s in enumerate(rng.normal(5.0, 0.5, 8))]
    fleet += [(x, 10.0 * np.expm1(r * x) + rng.normal(0.0, 2.0, 30), np.full(30, 2.0), 1.0)
              for r in rng.normal(0.12, 0.01, 8)]
    prior = fleet_wear_prior(fleet)
    assert prior.bend is not None and prior.bend.mean == pytest.approx(0.03, abs=0.003)
    assert "the lines' bend 0.03" in prior.describe()
    straight = dataclasses.replace(prior, bend=None)
    life = math.log1p(200.0 * 0.03 / 5.0) / 0.03          # +200 % at test 26.3
    for tests in (12, 18):
        truth = life - tests
        for seed in range(10):
            xs, y = _bent_unit(5.0, 0.03, seed, tests)
            f = forecast_series(xs, y, np.full(tests, 2.0), 1.0, 200.0, prior=prior)
            line = forecast_series(xs, y, np.full(tests, 2.0), 1.0, 200.0, prior=straight)
            assert f.remaining is not None and line.remaining is not None
            assert f.model == "linear" and len(f.coef) == 3      # drawn bent
            assert abs(f.remaining[0] - truth) < 1.5
            assert line.remaining[0] - truth > 3.0
            mid, lo, hi = f.band([0.0, f.remaining[0]])
            assert lo[1] < 200.0 < hi[1]                          # the band meets no-go


def test_the_bent_line_is_recovered_both_ways() -> None:
    """The bent line's slope at the origin and its bend, up and down, and a
    straight line's bend of 0 within its error."""
    from condmon.forecast.degradation import bent_fit

    x = np.arange(1.0, 21.0)
    for b in (-0.04, 0.0, 0.05):
        y = 3.0 + (4.0 * (np.expm1(b * x) / b if b else x))
        coef, cov, _ = bent_fit(x, y + np.random.default_rng(1).normal(0.0, 0.1, 20),
                                np.full(20, 100.0))
        assert coef[1] == pytest.approx(4.0, rel=0.02)
        assert abs(coef[2] - b) < 3.0 * math.sqrt(cov[2, 2]) + 1e-3
