"""Remaining life of a measured degradation path: a trend whose rate wanders,
with recoveries that fade back to it.

Real degradation series are not a curve plus independent scatter. A Li-ion
cell's capacity jumps up after a rest and falls back over a few cycles; the
rate of fade itself speeds up and slows down over a life. A forecaster that
picks one curve by its evidence on a short series (the line, or an
exponential) and draws only its coefficients' uncertainty is confidently
wrong whenever the rate changes (on NASA's cells: 23 % coverage of a 90 %
interval). The literature's answer is to treat the rate as a state that moves
(the particle-filter prognostics of Saha and Goebel, 2009, and NASA ProgPy's
Kalman filter carry the degradation rate as a state with process noise;
Gebraeel, 2006, updates it per unit) and to draw the remaining life from the
model's own predictive paths. Those set the rate's process noise by hand.
Here every variance is read from the series itself, so nothing is set to a
data set. The one choice, quarters for the walk, was made by a simulation
study of the model's own family (150 simulated paths: its 90 % interval
held the truth in 89 % of them with quarters, median width 0.98 of the true
remaining life, against 96 % and 1.80 with halves, 91 % and 1.58 with
eighths; ``tests/test_forecast_path.py`` keeps the check), not on real data:

- **Trend**: a straight line through the whole series, by generalised least
  squares under AR(1) deviations (Cochrane-Orcutt/Prais-Winsten
  prewhitening); its coefficients drawn from their normal-inverse-χ²
  posterior.
- **Recoveries**: the deviations from the trend are AR(1), ``e[k] =
  φ^Δx·e[k-1] + w[k]``: a recovery decays back to the trend, and the last
  deviation (a recovery under way) is carried into the future. ``φ`` is drawn
  from its profile likelihood on a grid.
- **A rate that wanders**: the rate is a geometric random walk, ``b(x) =
  b·exp(W(x))``, so it stays a fade (a cell does not heal) while speeding up
  or slowing down by factors, its median the rate now. The walk's variance
  per check is read by moments from the series' four quarters: how much the
  fitted rate changed from one quarter to the next, less what the quarters'
  own estimation error explains (:func:`_walk`). It is drawn, not plugged in
  (a scaled inverse χ² on the quarters' three changes): three changes cannot
  claim a calm rate. Under the walk the rate now differs from the series'
  mean rate by ``W(0) ~ N(0, v·span/3)`` (a Brownian path's end against its
  average).
- **Model form**: a bending trend is a wandering rate, so no evidence weight
  picks one curve: the accelerating and the slowing futures are both drawn.

The remaining life is the first future check (at the series' usual spacing)
whose measured value, trend plus deviation, passes the threshold: the median
and the 5 % and 95 % points of the drawn paths. Its coverage on real
run-to-failure data is measured by ``benchmarks/bench_prognostics_real.py``
and stated with each forecast (``condmon/data/coverage.toml``).

Why by hand: no library forecasts a first passage under this model;
numpy/scipy do the algebra and the draws.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import DataError

#: The standard normal's 95 % point: a 90 % interval is ± this many sd. [-]
Z90 = 1.6448536269514722

__all__ = ["PATH_MIN_TESTS", "PathFit", "Life", "fit_path", "with_fleet", "between_units",
           "drawn_rate",
           "path_remaining", "path_band"]

FloatArray = NDArray[np.float64]

#: Fewest points: two halves of three, each with a rate and a residual.
PATH_MIN_TESTS = 6
#: Autocorrelations the profile likelihood is taken over (0 to 0.98). [-]
_PHI = np.linspace(0.0, 0.98, 50)
#: Blocks the rate's wander is read over (:func:`_walk`).
_BLOCKS = 4
#: Largest exponent of the rate's factor (a draw past it has long crossed). [-]
_EXP_MAX = 50.0
#: Draws of the paths.
_DRAWS = 4000
#: The farthest future looked at, in the series' spans (beyond: never). [-]
_FAR_SPANS = 50.0

@dataclass(frozen=True)
class PathFit:
    """A degradation path fitted to one series (see the module).

    Attributes
    ----------
    coef : tuple of float
        The trend ``(a, b)`` at ``x − last``, at the most likely ``φ``: its
        value at the last point and its rate. [y, y per x]
    cov : tuple of tuple of float
        Their covariance there (at the residuals' scale). [y², y² per x, y² per x²]
    phi : float
        The deviations' most likely lag-one autocorrelation, per check. [-]
    grid : tuple of tuple of float
        Per ``φ`` of the grid: its posterior weight, the line's ``a`` and ``b``
        (per check), the unscaled covariance's three terms, and the
        prewhitened residual sum of squares.
    dof : int
        The residuals' degrees of freedom.
    walk : float
        The rate's relative random walk variance per unit of x. [1 per x]
    walk_moments : tuple of (float, float, int)
        What it is read from (:func:`_walk`): the blocks' mean square change
        of rate and of its estimation error [1 per x], and their count.
    deviation : float
        The last point's deviation from the trend (a recovery under way). [y]
    last, span, step : float
        ``x`` of the last point, the series' span and its usual spacing. [x]
    n : int
        Points used.
    fleet : tuple of float
        Failed peers' rates from as near their ends as this unit is (or
        their mean rates over their lives), the prior of its rate now
        (:func:`with_fleet`); empty: none. [y per x]
    """

    coef: tuple[float, float]
    cov: tuple[tuple[float, float], tuple[float, float]]
    phi: float
    grid: tuple[tuple[float, ...], ...]
    dof: int
    walk: float
    deviation: float
    last: float
    span: float
    step: float
    n: int
    walk_moments: tuple[float, float, int] = (0.0, 0.0, 0)
    fleet: tuple[float, ...] = ()

    @property
    def summary(self) -> tuple[float, ...]:
        """``(a, b, φ, walk, deviation, scatter, step, span)``: what
        :func:`path_band` draws from. [y, y per x, -, 1 per x, y, y, x, x]"""
        return (*self.coef, self.phi, self.walk, self.deviation, self.scatter,
                self.step, self.span)

    @property
    def scatter(self) -> float:
        """The deviations' sd about the trend at the most likely ``φ``. [y]"""
        best = max(self.grid, key=lambda g: g[0])
        return math.sqrt(best[6] / max(self.dof, 1))


def _gls(x: FloatArray, y: FloatArray, phi: float
         ) -> tuple[FloatArray, FloatArray, float, float]:
    """The line at ``x − x[-1]`` under AR(1) deviations: coefficients, their
    unscaled covariance, the residual sum of squares, and the log marginal
    likelihood (flat prior on the line, 1/σ on its scale)."""
    X = np.column_stack([np.ones_like(x), x - x[-1]])
    p = phi ** np.diff(x)
    s = np.sqrt(1.0 - p * p)
    first = math.sqrt(1.0 - phi * phi)
    Xw = np.vstack([X[:1] * first, (X[1:] - p[:, None] * X[:-1]) / s[:, None]])
    yw = np.concatenate([y[:1] * first, (y[1:] - p * y[:-1]) / s])
    coef, *_ = np.linalg.lstsq(Xw, yw, rcond=None)
    r = yw - Xw @ coef
    rss = float(r @ r)
    xtx = Xw.T @ Xw
    # the prewhitening's Jacobian: log|det| of the transform, per point
    jac = math.log(first) - float(np.sum(np.log(s)))
    ll = -0.5 * float(np.linalg.slogdet(xtx)[1]) - 0.5 * (y.size - 2) * math.log(
        max(rss, 1e-300)) + jac
    return coef, np.linalg.inv(xtx), rss, ll


def _rate(x: FloatArray, y: FloatArray) -> float:
    """The least-squares slope of ``y`` on ``x``. [y per x]"""
    xc = x - x.mean()
    return float(xc @ (y - y.mean()) / (xc @ xc))


def _walk(u: FloatArray, y: FloatArray, phi: float, rate: float
          ) -> tuple[float, float, int]:
    """The rate's relative random-walk variance per check, by moments over
    :data:`_BLOCKS` consecutive blocks of the series (fewer when short: 3
    points a block at least). Adjacent blocks' rates (each by GLS at
    ``phi``) differ by ``δ = (b₂ − b₁)/b``; under the walk, the difference of
    two adjacent averages of a Brownian path over ``g`` checks each has
    variance ``2g/3·v``, and the blocks' own estimation error adds
    ``(se₁² + se₂²)/b²``. Returns the mean square of the δ and of their
    estimation error, both per ``2g/3`` [1 per check], and their count (the
    degrees of freedom of the walk's scaled inverse-χ² draws)."""
    if rate == 0:
        return 0.0, 0.0, 0
    k = max(2, min(_BLOCKS, y.size // 3))
    edges = np.linspace(0, y.size, k + 1).round().astype(int)
    parts = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        c, cov, rss, _ = _gls(u[lo:hi], y[lo:hi], phi)
        parts.append((float(c[1]), float(cov[1, 1]) * rss / max(hi - lo - 2, 1),
                      float(u[lo:hi].mean())))
    raw = noise = 0.0
    for (b1, v1, m1), (b2, v2, m2) in zip(parts[:-1], parts[1:]):
        scale = 2.0 * (m2 - m1) / 3.0
        raw += (b2 - b1) ** 2 / rate ** 2 / scale
        noise += (v1 + v2) / rate ** 2 / scale
    return raw / (k - 1), noise / (k - 1), k - 1


def fit_path(x: ArrayLike, y: ArrayLike) -> PathFit:
    """Fit the degradation path of a series (see the module).

    Parameters
    ----------
    x : array_like
        Cycle, check, day or hour of each point, increasing. [x]
    y : array_like
        The measured value (or its change) at each point. [y]

    Returns
    -------
    PathFit

    Raises
    ------
    DataError
        Fewer than :data:`PATH_MIN_TESTS` points, non-finite values, ``x``
        not increasing.

    Example
    -------
    >>> x = np.arange(1.0, 41.0)
    >>> f = fit_path(x, 2.0 - 0.005 * x + 0.002 * np.sin(x))
    >>> round(f.coef[1], 4), f.n
    (-0.005, 40)
    """
    xa = np.asarray(x, dtype=np.float64).ravel()
    ya = np.asarray(y, dtype=np.float64).ravel()
    if xa.size != ya.size or xa.size < PATH_MIN_TESTS:
        raise DataError(f"forecast: a degradation path needs {PATH_MIN_TESTS} points or more, "
                        f"got {min(xa.size, ya.size)}")
    if not (np.all(np.isfinite(xa)) and np.all(np.isfinite(ya))):
        raise DataError("forecast: the series is not finite")
    if np.any(np.diff(xa) <= 0):
        raise DataError("forecast: x must increase")
    # (the spacing in units of the usual one, so φ is per check whatever x counts)
    step = float(np.median(np.diff(xa)))
    u = xa / step
    fits = [_gls(u, ya, float(p)) for p in _PHI]
    ll = np.array([f[3] for f in fits])
    w = np.exp(ll - ll.max())
    w /= w.sum()
    best = int(np.argmax(ll))
    coef, cov, rss, _ = fits[best]
    grid = tuple((float(wi), float(f[0][0]), float(f[0][1]), float(f[1][0, 0]),
                  float(f[1][0, 1]), float(f[1][1, 1]), float(f[2])) for wi, f in zip(w, fits))
    s2 = rss / max(ya.size - 2, 1)
    raw, noise, dof = _walk(u, ya, float(_PHI[best]), float(coef[1]))
    dev = float(ya[-1] - coef[0])
    c = (float(coef[0]), float(coef[1]) / step)
    cv = ((s2 * float(cov[0, 0]), s2 * float(cov[0, 1]) / step),
          (s2 * float(cov[1, 0]) / step, s2 * float(cov[1, 1]) / step ** 2))
    return PathFit(c, cv, float(_PHI[best]), grid, ya.size - 2, max(raw - noise, 0.0) / step,
                   dev, float(xa[-1]), float(xa[-1] - xa[0]), step, int(ya.size),
                   (raw / step, noise / step, dof))


@dataclass(frozen=True)
class Life:
    """What a failed peer's whole life lends a unit's path forecast: a path
    fitted to its series up to its end of life, and where its trend stood
    along the way.

    Attributes
    ----------
    walk : tuple of (float, float, int)
        Its :attr:`PathFit.walk_moments`. [1 per x, 1 per x, -]
    rate : float
        Its mean rate over that life (:attr:`PathFit.coef`'s second). [y per x]
    track : tuple of (float, float)
        At checks along the life, in order: the change its trend had still
        to make to its end of life (the end's level less the trend's value
        there, as its own path forecast read it then) and the ``x`` it had
        left; empty: not known (its mean rate stands for every point). [y, x]
    """

    walk: tuple[float, float, int]
    rate: float
    track: tuple[tuple[float, float], ...] = ()

    def rate_from(self, gap: float) -> float:
        """The rate at which this life went on to its end from the first
        point its trend was within ``gap`` of it (its first tracked point
        when never that far; its last when never that near): the
        change still to make over the ``x`` it had left. Points where its
        trend had already passed its end (a recovery held the readings up)
        tell no rate towards it and are passed over. [y per x]

        Example
        -------
        >>> Life((0.0, 0.0, 0), -0.01, ((-2.0, 100.0), (-1.0, 20.0))).rate_from(-1.5)
        -0.05
        """
        found = self.matched(gap)
        return self.rate if found is None else found[0] / found[1]

    def matched(self, gap: float) -> tuple[float, float] | None:
        """The tracked point :meth:`rate_from` reads: the change still to
        make there and the ``x`` left; None without a track heading for its
        end. [y, x]"""
        towards = [(g, left) for g, left in self.track if g * self.rate > 0]
        if not towards:
            return None
        near = [i for i, (g, _) in enumerate(towards) if abs(g) <= abs(gap)]
        return towards[near[0]] if near else towards[-1]


def with_fleet(fit: PathFit, lives: Sequence[Life], threshold: float | None = None
               ) -> PathFit:
    """``fit`` with failed peers' whole lives as its prior: their rates' wander
    pooled with its own, and the rates at which they went on from as near
    their ends of life as it is now as the prior of its rate now.

    This is the hierarchical reading of a model's wear (Gebraeel, 2006: a
    unit's degradation rate drawn from its fleet's, updated by its own
    series; particle-filter prognostics set the rate's process noise by
    hand instead):

    - **The walk.** A series' own blocks give the walk's variance three
      changes' worth of evidence (:func:`_walk`): a scaled inverse χ² on three
      degrees of freedom is heavy-tailed, and the interval with it. Each
      peer's blocks' moments are pooled with the unit's, weighted by their
      degrees of freedom.
    - **The rate.** A unit's own rate now is poorly told (a flat start, a
      recovery under way, a fade that speeds up towards the end); its
      peers say at what rate a unit of this model went on to its end from
      as near it as this unit is now (:meth:`Life.rate_from`, matched on the
      change still to make, as each one's own path forecast read its trend
      then: wear that speeds up with damage is matched on damage, not on
      age; the similarity-based prognostics of Wang, Yu, Siegel and Lee,
      2008, match a unit's health to its fleet's in the same way). The
      drawn rates now (the trend's rate times the walk's factor now) are
      weighed by the peers' predictive distribution (a Student t on n − 1
      degrees of freedom about their mean, scale their sd times
      ``sqrt(1 + 1/n)``: the normal model of rates between units with its
      mean and variance unknown), so a well-told rate of its own stands and
      a poorly told one is drawn towards the fleet's. Two peers at least.
      Without ``threshold`` (or a peer's track), a peer's mean rate over its
      life stands for it.

    Relative changes make both free of each unit's scale; the peers must
    count the same ``x``, and ``threshold`` is the unit's end of life in its
    ``y``, as each peer's track is to its own.

    Parameters
    ----------
    fit : PathFit
    lives : sequence of Life
    threshold : float, optional
        The unit's end of life. [y]

    Returns
    -------
    PathFit
        ``fit`` unchanged when no peer is given.

    Example
    -------
    >>> x = np.arange(1.0, 41.0)
    >>> f = fit_path(x, 2.0 - 0.005 * x + 0.002 * np.sin(x))
    >>> g = with_fleet(f, [Life((0.01, 0.0, 3), -0.004), Life((0.03, 0.0, 3), -0.006)])
    >>> g.walk_moments[2], g.fleet
    (9, (-0.004, -0.006))
    """
    if not lives:
        return fit
    gap = None if threshold is None else threshold - fit.coef[0]
    fleet = tuple(float(life.rate if gap is None else life.rate_from(gap)) for life in lives)
    moments = [fit.walk_moments, *(life.walk for life in lives)]
    d = sum(dof for _, _, dof in moments)
    if d == 0:   # no block told a wander: the rates alone
        return dataclasses.replace(fit, fleet=fleet)
    raw = sum(r * dof for r, _, dof in moments) / d
    noise = sum(n * dof for _, n, dof in moments) / d
    return dataclasses.replace(fit, walk=max(raw - noise, 0.0), walk_moments=(raw, noise, d),
                               fleet=fleet)


def between_units(values: ArrayLike) -> tuple[float, float, float] | None:
    """A new unit's predictive from its peers' ``values``, under the normal
    model of values between units with its mean and variance unknown: a
    Student t about their mean, scale their sd times ``sqrt(1 + 1/n)``, on
    n − 1 degrees of freedom. None without two values that differ.

    Example
    -------
    >>> loc, scale, df = between_units([1.0, 2.0, 3.0])
    >>> loc, round(scale, 3), df
    (2.0, 1.155, 2.0)
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size < 2:
        return None
    scale = float(v.std(ddof=1)) * math.sqrt(1.0 + 1.0 / v.size)
    if not scale > 0:
        return None
    return float(v.mean()), scale, float(v.size - 1)


def _fleet_weights(fit: PathFit, rate: FloatArray) -> FloatArray | None:
    """The peers' predictive density at each drawn rate now [per check],
    normalised over the draws (:func:`with_fleet`); None without two peers
    whose rates differ.

    Why by hand: a Student t's log density is one line, and the path
    forecast keeps scipy out of its import."""
    fleet = between_units(np.asarray(fit.fleet, dtype=np.float64) * fit.step)  # per check
    if fleet is None:
        return None
    loc, scale, df = fleet
    z = (rate - loc) / scale
    logw = -0.5 * (df + 1.0) * np.log1p(z * z / df)
    w: FloatArray = np.exp(logw - logw.max())
    return w / float(w.sum())


def _draws(fit: PathFit, rng: np.random.Generator, size: int
           ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Drawn (level now, rate, φ, innovation sd, W(0), the walk's variance
    [per x]), per check but the walk: φ from its profile posterior, then the
    scale (inverse χ²) and the line (normal) given it."""
    g = np.array(fit.grid)
    pick = rng.choice(len(g), size=size, p=g[:, 0] / g[:, 0].sum())
    s2 = g[pick, 6] / rng.chisquare(max(fit.dof, 1), size)
    z = rng.standard_normal((size, 2))
    # the 2x2 covariance's Cholesky factor, per draw
    c00, c01, c11 = g[pick, 3], g[pick, 4], g[pick, 5]
    l00 = np.sqrt(c00)
    l10 = c01 / l00
    l11 = np.sqrt(np.maximum(c11 - l10 ** 2, 0.0))
    sd = np.sqrt(s2)
    level = g[pick, 1] + sd * l00 * z[:, 0]
    rate = g[pick, 2] + sd * (l10 * z[:, 0] + l11 * z[:, 1])
    phis = _PHI[pick]
    # s2 is the deviations' variance about the trend: the innovations' is (1 - φ²) of it
    innovation = sd * np.sqrt(1.0 - phis ** 2)
    raw, noise, dof = fit.walk_moments
    # the walk's variance drawn (scaled inverse χ² of the blocks' changes, less
    # their estimation error): a few blocks cannot claim a calm rate
    walk = (np.maximum(raw * dof / rng.chisquare(dof, size) - noise, 0.0) if dof > 0
            else np.zeros(size))
    var0 = walk * fit.span / 3.0
    w0 = rng.normal(0.0, np.sqrt(var0))
    weights = _fleet_weights(fit, rate * np.exp(np.minimum(w0, _EXP_MAX)))   # the rate now
    if weights is None:
        return level, rate, phis, innovation, w0, walk
    # the fleet's prior on the rate, by importance: the draws resampled by it
    pick = rng.choice(size, size=size, p=weights)
    return level[pick], rate[pick], phis[pick], innovation[pick], w0[pick], walk[pick]


def drawn_rate(fit: PathFit, seed: int = 0, draws: int = _DRAWS) -> float:
    """The median of the rates now :func:`path_remaining` draws (the
    trend's rate times the walk's factor now): with the fleet's prior when
    ``fit`` has one (:func:`with_fleet`). [y per x]

    Example
    -------
    >>> x = np.arange(1.0, 41.0)
    >>> f = fit_path(x, 2.0 - 0.005 * x + 0.002 * np.sin(x))
    >>> round(drawn_rate(f), 4)
    -0.005
    """
    _, rate, _, _, w0, _ = _draws(fit, np.random.default_rng(seed), draws)
    return float(np.median(rate * np.exp(np.minimum(w0, _EXP_MAX)))) / fit.step


def path_remaining(fit: PathFit, threshold: float, seed: int = 0,
                   horizon: float | None = None, draws: int = _DRAWS, upto: float = 0.95
                   ) -> tuple[FloatArray, float]:
    """Draws of the ``x`` left until a check measures past ``threshold``
    (inf: not within :data:`_FAR_SPANS` spans, or past both the ``upto``
    point and ``horizon``: the draws stop once fewer than ``1 − upto`` of
    them are left), and the step. [x]

    Example
    -------
    >>> x = np.arange(1.0, 41.0)
    >>> f = fit_path(x, 2.0 - 0.005 * x + 0.002 * np.sin(x))
    >>> left, step = path_remaining(f, 1.6)         # 1.6 at x = 80: 40 to go
    >>> 30 < float(np.median(left)) < 50, step
    (True, 1.0)
    """
    rng = np.random.default_rng(seed)
    level, rate, phis, sd, w, walks = _draws(fit, rng, draws)
    sign = 1.0 if threshold > fit.coef[0] + fit.deviation else -1.0
    dev = np.full(draws, fit.deviation)
    wander = np.sqrt(walks * fit.step)
    left = np.full(draws, np.inf)
    # Only the paths still running are carried on (``slot``: the draw each
    # array element is): a heavy right tail would otherwise cost every draw's
    # random numbers until its last path crosses. The arrays are packed when
    # a quarter of them have crossed, so at most a third more is drawn.
    slot = np.arange(draws)
    alive = np.ones(draws, dtype=bool)
    steps = max(int(math.ceil(_FAR_SPANS * max(fit.span, fit.step) / fit.step)), 1)
    for k in range(1, steps + 1):
        w = w + rng.standard_normal(slot.size) * wander
        level = level + rate * np.exp(np.minimum(w, _EXP_MAX))
        dev = phis * dev + rng.standard_normal(slot.size) * sd
        hit = alive & (sign * (level + dev - threshold) >= 0)
        left[slot[hit]] = k * fit.step
        alive &= ~hit
        running = int(np.count_nonzero(alive))
        if running == 0 or (running < (1.0 - upto) * draws and (
                horizon is None or k * fit.step >= horizon)):
            break
        if running < 0.75 * slot.size:
            slot = slot[alive]
            w, level, rate, dev, phis, sd, wander = (
                a[alive] for a in (w, level, rate, dev, phis, sd, wander))
            alive = np.ones(running, dtype=bool)
    return left, fit.step


def path_band(coef: ArrayLike, cov: ArrayLike, ahead: ArrayLike, seed: int = 0
              ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The drawn paths' median and 90 % band at ``ahead`` after the last point:
    1,000 paths of the trend (its line drawn from ``cov``), its rate wandering
    at the fitted walk and the last deviation fading at ``φ`` with the
    deviations' scatter, read at each point; what a trend figure draws. [y]

    ``coef`` is :meth:`PathFit.summary`'s and ``cov`` the line's covariance.

    Example
    -------
    >>> x = np.arange(1.0, 41.0)
    >>> f = fit_path(x, 2.0 - 0.005 * x + 0.002 * np.sin(x))
    >>> med, lo, hi = path_band(f.summary, f.cov, [0.0, 20.0])
    >>> round(float(med[1]), 2), bool(lo[1] < med[1] < hi[1])
    (1.7, True)
    """
    a, b, phi, walk, dev, scatter, step, span = (float(v) for v in np.asarray(coef).ravel())
    c = np.asarray(cov, dtype=np.float64)
    t = np.asarray(ahead, dtype=np.float64)
    flat = t.reshape(-1)
    steps = int(math.ceil(max(float(flat.max(initial=0.0)), 0.0) / step)) + 1
    rng = np.random.default_rng(seed)
    n = 1000
    line = rng.multivariate_normal([a, b], c, size=n, method="eigh")
    level, rate = line[:, 0], line[:, 1] * step
    w = rng.normal(0.0, math.sqrt(walk * span / 3.0), n)
    e = np.full(n, dev)
    sd = scatter * math.sqrt(max(1.0 - phi * phi, 0.0))
    paths = np.empty((n, steps + 1))
    paths[:, 0] = level + e
    for k in range(1, steps + 1):
        w = w + rng.normal(0.0, math.sqrt(walk * step), n)
        level = level + rate * np.exp(np.minimum(w, _EXP_MAX))
        e = phi * e + rng.normal(0.0, sd, n)
        paths[:, k] = level + e
    grid = np.arange(steps + 1) * step
    q = np.quantile(paths, [0.5, 0.05, 0.95], axis=0)
    med, lo, hi = (np.interp(flat, grid, row).reshape(t.shape) for row in q)
    return med, lo, hi
