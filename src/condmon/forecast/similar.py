"""The remaining life a unit's failed peers had from as near their ends.

A unit's own series tells how it has worn so far; it cannot show a knee
ahead of it. Its failed peers of the same model can: each one's track
(:attr:`~condmon.forecast.path.Life.track`) says how many cycles it had
left once its trend was as near its end of life as the unit's is now
(similarity-based prognostics: Wang, Yu, Siegel and Lee, "A similarity-based
prognostics approach for remaining useful life estimation of engineered
systems", PHM 2008). Their logs, under the normal model of lives between
units with its mean and spread unknown, give a Student t on n − 1 degrees of
freedom about their mean, scale their sd times ``sqrt(1 + 1/n)``: the
fleet's predictive of the unit's remaining life.

How much that weighs beside the unit's own path forecast is read from the
fleet too (:func:`condmon.forecast.calibration.calibrate`): along each
peer's series, both are scored at the life it really had (the log score),
and the weight that scores best is kept (stacking of predictive
distributions: Yao, Vehtari, Simpson and Gelman, "Using stacking to average
Bayesian predictive distributions", Bayesian Analysis 2018).

Why by hand: no library matches a unit's damage to its fleet's; numpy
draws the Student t, and its log density is one line here, so that the
forecast (which ``condmon check`` imports) keeps scipy out of its import.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from condmon.forecast.path import Life, between_units

__all__ = ["FleetLeft", "lives_left", "fleet_left", "fleet_draws", "fleet_score", "pit",
           "path_log_density", "mixed"]

FleetLeft = tuple[float, float, float]
"""The fleet's predictive of a unit's remaining life: the location and scale
of its log [log x] and the degrees of freedom of its Student t."""


def lives_left(lives: Sequence[Life], gap: float) -> list[float]:
    """The ``x`` each peer had left from the first point its trend was as
    near its end as ``gap`` [y] (:meth:`~condmon.forecast.path.Life.matched`);
    peers without a track heading for their end left out. [x]"""
    return [m[1] for life in lives if (m := life.matched(gap)) is not None]


def pit(left: NDArray[np.float64], truth: float) -> float:
    """The share of the draws ``left`` below ``truth``, ties counted half. [-]"""
    return float(np.mean(left < truth) + 0.5 * np.mean(left == truth))


def fleet_left(lives: Sequence[Life], gap: float) -> FleetLeft | None:
    """The fleet's predictive of the remaining life of a unit whose trend has
    ``gap`` still to go to its end [y]; None without two peers' tracks whose
    lives left differ.

    Example
    -------
    >>> a = Life((0.0, 0.0, 0), -0.1, ((-4.0, 40.0), (-2.0, 20.0)))
    >>> b = Life((0.0, 0.0, 0), -0.1, ((-4.0, 60.0), (-2.0, 30.0)))
    >>> loc, scale, df = fleet_left([a, b], -2.0)
    >>> round(math.exp(loc), 1), df
    (24.5, 1.0)
    """
    return between_units(np.log(lives_left(lives, gap)))


def fleet_draws(fleet: FleetLeft, step: float, size: int, seed: int) -> NDArray[np.float64]:
    """``size`` draws of the remaining life from the fleet's predictive, in
    whole steps (at least one), as the path's draws count it. [x]"""
    loc, scale, df = fleet
    t = loc + scale * np.random.default_rng(seed).standard_t(df, size)
    out: NDArray[np.float64] = np.maximum(np.ceil(np.exp(np.minimum(t, 700.0)) / step),
                                          1.0) * step
    return out


def fleet_score(fleet: FleetLeft, truth: float, step: float, seed: int, size: int
                ) -> tuple[float, float]:
    """Where ``truth`` fell in the fleet's predictive (its PIT, from ``size``
    draws counted as :func:`fleet_draws` counts them) and its log density
    there, on the log of the remaining life. [-, -]"""
    loc, scale, df = fleet
    z = (math.log(truth) - loc) / scale
    log_density = (math.lgamma((df + 1.0) / 2.0) - math.lgamma(df / 2.0)
                   - 0.5 * math.log(df * math.pi) - math.log(scale)
                   - 0.5 * (df + 1.0) * math.log1p(z * z / df))
    return pit(fleet_draws(fleet, step, size, seed), truth), log_density


def path_log_density(left: NDArray[np.float64], truth: float, step: float) -> float:
    """The path draws' density at ``truth``, on the log of the remaining
    life: the share of the draws within a window about it (Silverman's
    bandwidth on their logs, at least half a step), counting half a draw
    when none is in it (fewer than one in the sample). [-]"""
    finite = left[np.isfinite(left)]
    logs = np.log(np.maximum(finite, step))
    h = 1.06 * float(logs.std()) * max(logs.size, 1) ** -0.2 if logs.size > 1 else 0.0
    h = max(h, 0.5 * math.log1p(step / truth))
    near = np.count_nonzero(np.abs(logs - math.log(truth)) <= h)
    return math.log((near + 0.5) / (left.size * 2.0 * h))


def mixed(left: NDArray[np.float64], fleet: FleetLeft | None, weight: float, step: float,
          seed: int) -> NDArray[np.float64]:
    """The path's draws with a share ``weight`` of them replaced by the
    fleet's (the stacked mixture); unchanged without a fleet or a weight. [x]

    Example
    -------
    >>> left = np.full(1000, 50.0)
    >>> mix = mixed(left, (math.log(20.0), 0.1, 5.0), 0.3, 1.0, seed=0)
    >>> int(np.sum(mix < 40.0))
    300
    """
    if fleet is None or weight <= 0.0:
        return left
    k = int(round(weight * left.size))
    out = left.copy()
    rng = np.random.default_rng(seed + 1)
    out[rng.permutation(left.size)[:k]] = fleet_draws(fleet, step, k, seed)
    return out
