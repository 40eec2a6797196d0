"""The fleet's remaining lives beside the path forecast, weighed by how each
scored along the failed peers' own series (stacking)."""

from __future__ import annotations

import math

import numpy as np

from condmon.forecast.calibration import MIN_PEERS, calibrate, life_of, path_scores, stacked
from condmon.forecast.measured import forecast_path
from condmon.forecast.path import Life
from condmon.forecast.similar import fleet_left, mixed, path_log_density


def test_the_weight_is_the_one_whose_mixture_scored_best() -> None:
    """Known truth: where the fleet's density at the true lives is e² times
    the path's, the fleet takes the whole weight; where it is e⁻² times, none;
    where the two tie on half the forecasts each way, a weight between.
    The mixture's PITs are the weighted PITs, the path's where no fleet was."""
    n = 40
    rows = np.column_stack([np.full(n, 0.2), np.zeros(n), np.full(n, 0.6), np.full(n, 2.0)])
    w, pits = stacked(rows)
    assert w == 1.0 and np.allclose(pits, 0.6)
    rows[:, 3] = -2.0
    w, pits = stacked(rows)
    assert w == 0.0 and np.allclose(pits, 0.2)
    rows[: n // 2, 3] = 2.0
    w, pits = stacked(rows)
    assert 0.0 < w < 1.0 and np.allclose(pits, 0.2 + w * 0.4)
    rows[:5, 2:] = np.nan   # no fleet there: the path's PIT
    w, pits = stacked(rows)
    assert np.allclose(pits[:5], 0.2)
    # too few peers for a prior: no fleet in the forecast, the path's PITs read
    c = calibrate(rows, MIN_PEERS - 1)
    assert c is None
    lives = [Life((0.0, 0.0, 0), -0.1)] * MIN_PEERS
    c = calibrate(rows, MIN_PEERS, lives)
    assert c is not None and c.weight == w


def test_the_fleet_s_lives_left_and_a_path_s_density() -> None:
    """The fleet's predictive centres on the peers' matched lives left (their
    geometric mean); a path whose draws sit at the truth has a higher density
    there than one whose draws are far from it; a share of draws mixed in."""
    lives = [Life((0.0, 0.0, 0), -0.1, ((-4.0, 4 * t), (-2.0, 2 * t))) for t in (8, 10, 12)]
    loc, scale, df = fleet_left(lives, -2.0)
    assert math.isclose(math.exp(loc), (16 * 20 * 24) ** (1 / 3)) and df == 2.0 and scale > 0
    assert fleet_left(lives[:1], -2.0) is None
    near = path_log_density(np.full(1000, 20.0), 20.0, 1.0)
    far = path_log_density(np.full(1000, 200.0), 20.0, 1.0)
    assert near > far + 5.0
    mix = mixed(np.full(1000, 200.0), (loc, scale, df), 0.25, 1.0, seed=3)
    assert 245 <= int(np.sum(mix != 200.0)) <= 250   # (a fleet draw may land on 200)
    assert np.median(mix[mix != 200.0]) < 40.0


def test_a_knee_the_unit_has_not_reached_is_seen_in_its_failed_peers() -> None:
    """Known truth: wear that bends into a knee, a slow fade of 0.02 %/cycle
    turning into a fast one around cycle 100 ± 10, its end at −20 %. A unit
    seen up to cycle 70, before its knee, has its own series' slow rate well
    told: the path alone says hundreds of cycles. Its four failed peers say
    about 50 (their knees), and along their own series the fleet's lives
    scored better than the path, so they take the weight: the median is
    within 30 % of the truth and the interval holds it."""
    rng = np.random.default_rng(11)

    def cell(knee: float) -> tuple[np.ndarray, np.ndarray]:
        x = np.arange(1.0, 200.0)
        y = -0.02 * x - 0.6 * 10.0 * np.logaddexp(0.0, (x - knee) / 10.0)
        y = y + rng.normal(0.0, 0.1, x.size)
        end = int(np.argmax(y < -20.0))
        return x[:end + 5], y[:end + 5]

    peers = [cell(k) for k in (92.0, 97.0, 103.0, 108.0)]
    lives = [life_of(x, y, -20.0) for x, y in peers]
    assert all(life is not None for life in lives)
    known = [life for life in lives if life is not None]
    rows = []
    for i, (x, y) in enumerate(peers):
        others = [life for j, life in enumerate(known) if j != i]
        rows += path_scores(x, y, -20.0, seed=10 * i, lives=others)
    c = calibrate(rows, len(peers), known)
    assert c is not None and not c.refused and c.weight >= 0.5, c
    x, y = cell(100.0)
    truth = float(x[int(np.argmax(y < -20.0))]) - 70.0
    alone = forecast_path(x[:70], y[:70], np.zeros(70), 0.1, -20.0, seed=1)
    lent = forecast_path(x[:70], y[:70], np.zeros(70), 0.1, -20.0, seed=1, calibration=c)
    assert alone.remaining is not None and alone.remaining[0] > 2.0 * truth, alone.remaining
    assert lent.remaining is not None, lent.notes
    med, lo, hi = lent.remaining
    assert abs(math.log(med / truth)) < math.log(1.3) and lo <= truth <= hi, (lent.remaining, truth)
    assert any("of its draws from the lives they had left" in n for n in lent.notes)
