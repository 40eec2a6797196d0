"""A path forecast read at the levels its fleet's failed units call for.

A unit's failed peers of the same model are run-to-failure data of the kind
the unit's own forecast needs: along each peer's series, the forecast it
would have been given at each check can be scored against the life it
really had. Where each true life fell in its forecast's distribution (the
probability integral transform, PIT) tells how the method's levels read on
this fleet: intervals too wide put the PITs near the middle, forecasts too
early put them high. The unit's forecast is then read at the levels the
PITs give (the recalibration of Kuleshov, Fenner and Ermon, "Accurate
uncertainties for deep learning using calibrated regression", ICML 2018;
Gneiting, Balabdaoui and Raftery, "Probabilistic forecasts, calibration and
sharpness", 2007): its 90 % interval between the PITs' 5 % and 95 % points,
its median at their median.

The same failed peers' whole lives (:func:`life_of`) are the unit's
forecast's prior (:func:`~condmon.forecast.path.with_fleet`): their rates'
wander pooled with its own, and the rates at which they went on to their ends
from as near them as it is now weighed against its own rate now. Each
peer's forecasts behind the PITs take the other peers' lives the same way, so
the levels are read on forecasts made as the unit's is.

Nothing is set by hand: the levels are the PITs' own quantiles, and a fleet
too small to tell them (fewer than :data:`MIN_PITS` forecasts, or fewer than
:data:`MIN_PEERS` failed units) changes nothing. On NASA's cells, each
recalibrated on the other three (leave one out), the 90 % interval's coverage
went from 97 % to 92 %, α-λ from 0.26 to 0.63 and the median width from 3.4
to 0.89 times the true remaining life (``benchmarks/bench_prognostics_real.py``,
the seeds ``condmon forecast`` uses; over five sets of draws: 91-95 %,
0.60-0.63 and 0.87-0.93; the recalibration alone: 82 %, 0.32 and 1.55).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from condmon.errors import CondmonError
from condmon.forecast.path import PATH_MIN_TESTS, Life, fit_path, path_remaining, with_fleet
from condmon.forecast.similar import fleet_left, fleet_score, path_log_density, pit

__all__ = ["MIN_PITS", "MIN_PEERS", "PER_PEER", "TRACK", "WEIGHTS", "Calibration", "life_of",
           "path_pits", "path_scores", "stacked", "calibrate"]

#: Fewest peer forecasts whose PITs may recalibrate a unit's: the 5 % and
#: 95 % points of fewer than 19 cannot be told from the extremes. [-]
MIN_PITS = 19
#: Fewest failed peers that may recalibrate a unit's forecast. The forecasts
#: along one peer's series share its one future, so their PITs are one life's
#: shape, not a fleet's spread: one peer of another wear shape (a linear pad
#: for an accelerating one) narrowed an interval until it left the truth out.
#: Three, the fewest units from which condmon measures a spread between units
#: (:mod:`condmon.monitor.group`). [-]
MIN_PEERS = 3
#: Most forecasts scored along one peer's series (evenly spread). [-]
PER_PEER = 20
#: Most checks along a peer's life at which its trend's distance to its end
#: is read (:attr:`~condmon.forecast.path.Life.track`), evenly spread: a
#: unit's distance is matched to within 1/60 of the peer's life, at a path
#: fit each. [-]
TRACK = 60
#: The weights of the fleet's remaining lives (:mod:`condmon.forecast.similar`)
#: beside the path's that the stacking chooses from, a twentieth apart. [-]
WEIGHTS = np.linspace(0.0, 1.0, 21)
#: Draws of each peer forecast (a PIT to ±1 %). [-]
_PIT_DRAWS = 1000


@dataclass(frozen=True)
class Calibration:
    """The levels a forecast's draws are read at, from its fleet's PITs.

    Attributes
    ----------
    median, low, high : float
        The levels of the median and of the 90 % interval's ends. [-]
    pits : int
        Peer forecasts behind them.
    peers : int
        Failed peers they come from.
    levels : tuple of float
        Those forecasts' PITs, sorted: the map from a draw's level to the
        fleet's (:meth:`probability`). [-]
    lives : tuple of Life
        The whole lives (:func:`life_of`) of the failed peers that count as
        the unit does: its forecast's prior
        (:func:`~condmon.forecast.path.with_fleet`), as the other peers'
        were in the peers' forecasts behind the PITs; none when fewer than
        :data:`MIN_PEERS` count so.
    names : tuple of str
        The failed peers, by name.
    apart : int
        Failed peers whose lives count otherwise than the unit's (hours
        against cycles): not its prior.
    refused : str
        Why the levels cannot be read (the forecast is then not
        recalibrated, and says why); empty: they can.
    same : tuple of str
        Peers left out, by name: their series repeats another peer's, or
        begins with the unit's own (the same unit imported twice).
    weight : float
        The share of the forecast's draws taken from the fleet's remaining
        lives from as near their ends (:mod:`condmon.forecast.similar`), the
        rest the path's: the stacking weight that scored best along the
        peers' series (:func:`calibrate`). [-]
    """

    median: float
    low: float
    high: float
    pits: int
    peers: int
    levels: tuple[float, ...] = ()
    lives: tuple[Life, ...] = ()
    names: tuple[str, ...] = ()
    apart: int = 0
    refused: str = ""
    same: tuple[str, ...] = ()
    weight: float = 0.0

    def probability(self, raw: float) -> float:
        """A probability the draws give (the share of them within a horizon)
        read on the fleet: the share of its PITs at or below it.

        Example
        -------
        >>> c = calibrate(np.linspace(0.0, 0.2, 41), peers=3)   # truths came early
        >>> c.probability(0.1), c.probability(0.5)
        (0.5121951219512195, 1.0)
        """
        if not self.levels:
            return raw
        return float(np.searchsorted(np.asarray(self.levels), raw, side="right")
                     / len(self.levels))

    def describe(self) -> str:
        """One clause for a forecast's notes."""
        named = f" ({', '.join(self.names)})" if self.names else ""
        said = (f"recalibrated on {self.pits} forecasts along {self.peers} failed peer(s)"
                f"{named} (where their true lives fell): the 90 % interval read at the draws' "
                f"{100 * self.low:.0f} % and {100 * self.high:.0f} % points, the median "
                f"at {100 * self.median:.0f} %")
        if self.lives:
            said += (f"; {len(self.lives)} of their whole lives its prior: their rates' "
                     "wander pooled with its own")
        if len(self.lives) > 1:
            said += (", and the rates at which they went on to their ends from as near them "
                     "as it is weighed against its own rate now")
        if self.weight > 0:
            said += (f"; {100 * self.weight:.0f} % of its draws from the lives they had left "
                     "from as near their ends (the weight that scored best at their true "
                     "lives)")
        if self.apart:
            said += (f"; {self.apart} of them count their lives otherwise than it does (not "
                     f"its prior" + ("" if self.lives else
                                    f": {MIN_PEERS} that count as it does are needed") + ")")
        if self.same:
            said += (f"; {', '.join(self.same)} left out: the same series as another peer's or "
                     "as the start of its own (one unit imported twice?)")
        return said


def _end(ya: np.ndarray, threshold: float) -> int | None:
    """The index of the first value past ``threshold`` (a fall when below
    the first value); None when none is, or too early for a path."""
    past = np.flatnonzero(ya < threshold) if threshold < ya[0] else np.flatnonzero(ya > threshold)
    return None if past.size == 0 or past[0] < PATH_MIN_TESTS else int(past[0])


def _along(end: int, most: int) -> np.ndarray:
    """Up to ``most`` checks, evenly spread, from the
    :data:`~condmon.forecast.path.PATH_MIN_TESTS`-th to the one before ``end``."""
    ks = np.arange(PATH_MIN_TESTS - 1, end)
    if ks.size > most:
        ks = ks[np.round(np.linspace(0, ks.size - 1, most)).astype(int)]
    return ks


def life_of(x: ArrayLike, y: ArrayLike, threshold: float) -> Life | None:
    """A failed series' whole life, what it lends a unit's forecast: a path
    fitted to it up to its end of life, and its track (None: it never passed
    ``threshold``).

    The track is read at up to :data:`TRACK` checks along the life: there,
    the change its trend (:func:`~condmon.forecast.path.fit_path` on the
    checks up to it, as its own forecast would have read it) still had to
    make to ``threshold``, and the ``x`` it had left.

    Example
    -------
    >>> x = np.arange(1.0, 61.0)
    >>> life = life_of(x, 2.0 - 0.01 * x + 0.004 * np.sin(x), 1.5)
    >>> life.walk[2], round(life.rate, 3), len(life.track)
    (3, -0.01, 44)
    """
    xa = np.asarray(x, dtype=np.float64)
    ya = np.asarray(y, dtype=np.float64)
    end = _end(ya, threshold)
    if end is None:
        return None
    try:
        fit = fit_path(xa[:end + 1], ya[:end + 1])
        track = tuple((threshold - fit_path(xa[:k + 1], ya[:k + 1]).coef[0],
                       float(xa[end] - xa[k])) for k in _along(end, TRACK))
    except CondmonError:
        return None
    return Life(fit.walk_moments, fit.coef[1], track)


def path_pits(x: ArrayLike, y: ArrayLike, threshold: float, seed: int = 0,
              lives: Sequence[Life] = ()) -> list[float]:
    """The PITs of path forecasts made along one failed series: the first
    column of :func:`path_scores`.

    Example
    -------
    >>> x = np.arange(1.0, 61.0)
    >>> y = 2.0 - 0.01 * x + 0.004 * np.sin(x)
    >>> p = path_pits(x, y, 1.5)
    >>> len(p), all(0.0 <= v <= 1.0 for v in p)
    (20, True)
    """
    return [s[0] for s in path_scores(x, y, threshold, seed, lives)]


def path_scores(x: ArrayLike, y: ArrayLike, threshold: float, seed: int = 0,
                lives: Sequence[Life] = ()) -> list[tuple[float, float, float, float]]:
    """How path forecasts made along one failed series, and the fleet's
    remaining lives beside them, scored at the life it really had.

    Parameters
    ----------
    x, y : array_like
        The peer's checks in order, up to at least the first one past
        ``threshold`` (its end of life). [x, y]
    threshold : float
        Its end of life, in ``y``'s units (a fall when below the first value).
    seed : int
    lives : sequence of Life
        Other failed peers' whole lives, each forecast's prior as they are
        the unit's (:func:`~condmon.forecast.path.with_fleet`), and their
        remaining lives from as near their ends its fleet's
        (:func:`~condmon.forecast.similar.fleet_left`).

    Returns
    -------
    list of (float, float, float, float)
        At up to :data:`PER_PEER` checks from the
        :data:`~condmon.forecast.path.PATH_MIN_TESTS`-th on: the path
        forecast's PIT (the share of its draws below the true remaining
        life, ties counted half) and its log density there, then the same
        two of the fleet's (NaN without two lives to tell it), on the log of
        the remaining life; empty when the series never passes the threshold.

    Example
    -------
    >>> x = np.arange(1.0, 61.0)
    >>> y = 2.0 - 0.01 * x + 0.004 * np.sin(x)
    >>> s = path_scores(x, y, 1.5)
    >>> len(s), all(0.0 <= v[0] <= 1.0 and np.isnan(v[2]) for v in s)
    (20, True)
    """
    xa = np.asarray(x, dtype=np.float64)
    ya = np.asarray(y, dtype=np.float64)
    end = _end(ya, threshold)
    if end is None:
        return []
    out = []
    for k in _along(end, PER_PEER):
        try:
            fit = with_fleet(fit_path(xa[:k + 1], ya[:k + 1]), lives, threshold)
        except CondmonError:
            continue
        truth = xa[end] - xa[k]
        # (drawn on to the truth: a PIT past the 95 % point is read, not capped there)
        left, step = path_remaining(fit, threshold, seed + int(k), truth, draws=_PIT_DRAWS)
        fleet = fleet_left(lives, threshold - fit.coef[0])
        theirs = (math.nan, math.nan) if fleet is None else fleet_score(
            fleet, truth, step, seed + int(k), _PIT_DRAWS)
        out.append((pit(left, truth), path_log_density(left, truth, step), *theirs))
    return out


def stacked(scores: np.ndarray) -> tuple[float, np.ndarray]:
    """The weight of the fleet's remaining lives (of :data:`WEIGHTS`) whose
    mixture with the path's scores best at the true lives (the sum of the
    log densities, over the forecasts that have a fleet), and the mixture's
    PITs (the path's where no fleet was). [-]"""
    path_pit, path_log, fleet_pit, fleet_log = scores.T
    has = np.isfinite(fleet_log)
    if not has.any():
        return 0.0, path_pit
    with np.errstate(divide="ignore"):
        total = [float(np.sum(np.logaddexp(math.log(w) + fleet_log[has],
                                           math.log1p(-w) + path_log[has])))
                 if 0 < w < 1 else float(np.sum((fleet_log if w == 1 else path_log)[has]))
                 for w in WEIGHTS]
    w = float(WEIGHTS[int(np.argmax(total))])
    return w, np.where(has, w * np.nan_to_num(fleet_pit) + (1 - w) * path_pit, path_pit)


def calibrate(pits: ArrayLike, peers: int, lives: Sequence[Life] = (),
              names: Sequence[str] = (), apart: int = 0, same: Sequence[str] = ()
              ) -> Calibration | None:
    """The levels to read a forecast's draws at, from its fleet's PITs (None:
    fewer than :data:`MIN_PITS`, or from fewer than :data:`MIN_PEERS` peers).

    ``pits`` are the path forecasts' PITs, or :func:`path_scores`' rows.
    The peers' ``lives`` are the forecast's prior when :data:`MIN_PEERS` or
    more are given; with rows, the forecast's draws are then a mixture of
    the path's and of the fleet's remaining lives
    (:mod:`condmon.forecast.similar`), the fleet's share the one of
    :data:`WEIGHTS` whose mixture scored best at the peers' true lives
    (:func:`stacked`), and the levels are read on the mixture's PITs.
    Levels are refused (:attr:`Calibration.refused`) when 5 % or more of the
    PITs lie at 0 or at 1: the lives ended before (or after) every draw of
    their forecasts, so an end of the 90 % interval would be read where the
    draws stop, not from them (a fleet that fails suddenly, as the path method
    does not describe).

    Example
    -------
    >>> c = calibrate(np.linspace(0.3, 0.7, 41), peers=3)     # intervals far too wide
    >>> round(c.low, 2), round(c.median, 2), round(c.high, 2)
    (0.32, 0.5, 0.68)
    """
    p = np.asarray(pits, dtype=np.float64)
    weight = 0.0
    if p.ndim == 2:   # path_scores' rows
        p = p[np.isfinite(p[:, 0])]
        weight, mix = stacked(p) if len(lives) >= MIN_PEERS and p.size else (0.0, p[:, 0])
        p = mix
    p = p[np.isfinite(p)]
    if p.size < MIN_PITS or peers < MIN_PEERS:
        return None
    p = np.sort(np.clip(p, 0.0, 1.0))
    lo, med, hi = (float(v) for v in np.quantile(p, [0.05, 0.5, 0.95]))
    early, late = int(np.sum(p <= 0.0)), int(np.sum(p >= 1.0))
    refused = ""
    if max(early, late) >= 0.05 * p.size:
        refused = (f"not recalibrated: in {max(early, late)} of {p.size} forecasts along its "
                   f"{peers} failed peers the life ended {'before' if early >= late else 'after'}"
                   " every draw; the path method does not describe how these units end "
                   "(sudden failures?), so the fleet's levels cannot be read")
    return Calibration(med, lo, hi, int(p.size), int(peers), tuple(float(v) for v in p),
                       tuple(lives) if len(lives) >= MIN_PEERS else (), tuple(names),
                       int(apart), refused, tuple(same), weight)
