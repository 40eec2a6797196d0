"""Degradation models of one change series, fitted test by test.

The fits :mod:`condmon.forecast.series` and :mod:`condmon.forecast.prior`
share: the weighted straight line, the exponential with an offset written from
the last test (``|change| = α + β·(exp(b·t) − 1)/b``, ``t = x − x_last``), the
small-sample Akaike weights that compare them, and the exponential's posterior
over its growth rate ``b`` under a prior on it (:func:`rate_posterior`).

The posterior is exact for this model, not a normal approximation: for a given
``b`` the model is linear in (α, β), so with a flat prior on them the
posterior of ``b`` is its prior times ``|XᵀWX|^(−1/2)·exp(−RSS(b)/2σ²)`` (the
profile likelihood with its Laplace volume), taken on a grid of rates, and
(α, β) given ``b`` are normal. The straight line is the same model at
``b = 0`` with the same (α, β), so the ratio of the two marginal likelihoods
is a Bayes factor with no arbitrary constant: the evidence for the curve that
a rate prior makes proper (Gebraeel 2006 fits such priors on a fleet).

With the fleet's priors on the line's slope and the exponential's amplitude
and the bend of its lines as well (:func:`fleet_posteriors`), both models
are written from the series' origin and carry proper priors on all but the
shared level, so the Bayes factor weighs the fleet's line against the
fleet's curve.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import DataError

__all__ = ["MIN_TESTS", "EXP_MIN_TESTS", "Fit", "wls", "growth", "exp_fit", "fits",
           "checked_series", "aicc_weights", "weights", "RatePosterior", "rate_posterior",
           "ShapePosteriors", "fleet_posteriors", "bent_fit", "Z90",
           "SCALE_PRIOR_TESTS", "residual_scale", "steady_direction",
           "serial_factor", "SERIAL_MIN_TESTS", "trend_sd"]

FloatArray = NDArray[np.float64]
#: A weighted fit: coefficients, their covariance, the weighted residual sum of squares.
Fit = tuple[FloatArray, FloatArray, float]

#: The standard normal's 95 % point: a 90 % interval is ± this many sd. [-]
Z90 = 1.6448536269514722
#: Fewest checks since the baseline that a forecast needs.
MIN_TESTS = 3
#: Fewest tests for the exponential with no prior on its rate (three
#: coefficients, and a residual to judge them by).
EXP_MIN_TESTS = 5
#: Rates the exponential is fitted over, times the series' span: from barely
#: curved to a factor e^30 over the span. [-]
_RATE_SPAN = (0.01, 30.0)

#: How many tests' worth the weights' stated variance counts as, beside a
#: fit's residuals (:func:`residual_scale`). [tests]
SCALE_PRIOR_TESTS = 2.0

#: Fewest residuals whose autocorrelation :func:`serial_factor` reads. [tests]
SERIAL_MIN_TESTS = 6

def residual_scale(rss: float, dof: int) -> float:
    """A fit's residual variance factor against its weights' stated variance.

    The weights' variance ``se² + sd²`` counts a check's estimation error
    twice when the baseline spread ``sd`` already holds it, so a series
    scatters less than stated (the residuals of simulated fleets: 0.3-1.7,
    median 0.67, of it). The factor is read from the residuals, with the
    stated variance as a prior worth :data:`SCALE_PRIOR_TESTS` tests (a
    scaled inverse-χ² prior): a few tests cannot claim a scale from one
    residual, many are read from their own. [-]

    Example
    -------
    >>> residual_scale(4.0, 8), residual_scale(0.0, 1)
    (0.6, 0.6666666666666666)
    """
    return (rss + SCALE_PRIOR_TESTS) / (dof + SCALE_PRIOR_TESTS)


def wls(x: FloatArray, y: FloatArray, w: FloatArray) -> Fit:
    """Weighted straight line: coefficients (a, b), their covariance, weighted RSS."""
    X = np.column_stack([np.ones_like(x), x])
    sw = np.sqrt(w)
    coef, *_ = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)
    r = (y - X @ coef) * sw
    rss = float(r @ r)
    dof = max(len(x) - 2, 1)
    # the weights give the relative scale; the residuals the absolute one
    scale = residual_scale(rss, dof)
    cov = np.asarray(np.linalg.pinv((X * w[:, None]).T @ X) * scale, dtype=np.float64)
    return np.asarray(coef, dtype=np.float64), cov, rss


def growth(b: float, t: FloatArray) -> FloatArray:
    """``(exp(b·t) − 1) / b``: ``t`` itself as ``b`` → 0."""
    return np.asarray(t if b == 0 else np.expm1(b * t) / b, dtype=np.float64)


def _rate_fit(t: FloatArray, y: FloatArray, w: FloatArray, grid: FloatArray,
              flat_is_line: bool, xatol: float) -> Fit | None:
    """``y = level + slope·growth(b, t)`` weighted: for a given rate the model
    is linear in (level, slope), so the rate is taken on ``grid`` and refined
    between its neighbours. Coefficients (level, slope, b), their covariance
    (Gauss-Newton), weighted RSS; None where ``flat_is_line`` and the grid's
    first (flattest) rate fits best. ``xatol``: the rate's tolerance. [1 per x]"""
    sw = np.sqrt(w)

    def profile(b: float) -> tuple[float, FloatArray]:
        X = np.column_stack([np.ones_like(t), growth(b, t)])
        coef, *_ = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)
        r = (y - X @ coef) * sw
        return float(r @ r), np.asarray(coef, dtype=np.float64)

    flat = grid == 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        shapes = np.where(flat[:, None], t[None, :],
                          np.expm1(np.outer(grid, t)) / np.where(flat, 1.0, grid)[:, None])
    rss = _line_fits(shapes, y, w)[-1]   # each rate's free fit
    i = int(np.argmin(np.where(np.isfinite(rss), rss, np.inf)))
    if flat_is_line and i == 0:    # flattest rate best: a line, not an exponential
        return None
    from condmon.monitor.bounded import bounded_minimum  # scipy's bounded steps, no scipy import

    b = bounded_minimum(lambda rate: profile(float(rate))[0], float(grid[max(i - 1, 0)]),
                        float(grid[min(i + 1, len(grid) - 1)]), xatol=xatol)
    best, (level, slope) = profile(b)
    g = growth(b, t)
    dg = t * t / 2.0 if b == 0.0 else (t * np.exp(b * t) - g) / b
    J = np.column_stack([np.ones_like(t), g, slope * dg])
    scale = residual_scale(best, max(len(t) - 3, 1))
    cov = np.asarray(np.linalg.pinv((J * w[:, None]).T @ J) * scale, dtype=np.float64)
    return np.array([level, slope, b]), cov, best


def exp_fit(x: FloatArray, y: FloatArray,
            w: FloatArray) -> Fit | None:
    """Weighted exponential with an offset, written from the last test
    (``t = x − x_last``) as ``y = α + β·(exp(b·t) − 1)/b``: the level α and
    slope β at the last test and the growth rate b (a line as b → 0).
    Coefficients (α, β, b), their covariance (Gauss-Newton), weighted RSS;
    None where no growing exponential (b above the flat end) fits better."""
    return _rate_fit(x - x[-1], y, w, np.geomspace(*_RATE_SPAN, 64) / float(x[-1] - x[0]),
                     True, 1e-5)


def bent_fit(x: FloatArray, y: FloatArray, w: FloatArray) -> Fit:
    """Weighted bent line ``y = c + s·(exp(b·x) − 1)/b`` from the series'
    origin: its level c and slope s at ``x = 0`` and its bend b, signed (below
    0 a line that bows down; a straight line at 0), taken within a slope that
    grows or falls e^3-fold over the span. Coefficients (c, s, b), their
    covariance (Gauss-Newton), weighted RSS."""
    span = float(x[-1] - x[0])
    # never None: the flattest bend is kept like any other
    return cast(Fit, _rate_fit(x, y, w, np.linspace(-3.0, 3.0, 121) / span, False, 1e-6 / span))


def fits(xa: FloatArray, ya: FloatArray, sa: FloatArray, spread: float,
          sign: float, exponential: bool = True) -> dict[str, Fit]:
    """Both degradation models' weighted fits, the change taken towards the
    threshold (the exponential from :data:`EXP_MIN_TESTS` tests, where it
    grows; not at all when ``exponential`` is false). The slope ``b`` is
    each model's last coefficient."""
    w = weights(sa, spread)
    fits: dict[str, Fit] = {"linear": wls(xa, ya, w)}
    if exponential and len(xa) >= EXP_MIN_TESTS:
        exp = exp_fit(xa, sign * ya, w)
        if exp is not None:
            fits["exponential"] = exp
    return fits


def checked_series(x: ArrayLike, change: ArrayLike, se: ArrayLike,
             spread: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """One series as arrays, refused as :func:`~condmon.forecast.series.forecast_series` says."""
    xa, ya, sa = (np.asarray(v, dtype=np.float64) for v in (x, change, se))
    if not (len(xa) == len(ya) == len(sa)):
        raise DataError("forecast: x, change and se differ in length")
    if len(xa) < MIN_TESTS:
        raise DataError(f"not enough tests to forecast: {len(xa)} check(s) since the baseline, "
                        f"need {MIN_TESTS}")
    if not (np.all(np.isfinite(xa)) and np.all(np.isfinite(ya)) and np.all(np.isfinite(sa))
            and math.isfinite(spread)):
        raise DataError("forecast: the series holds a non-finite value")
    if np.any(np.diff(xa) <= 0):
        raise DataError("forecast: the tests' times do not increase")
    return xa, ya, sa


def weights(se: FloatArray, spread: float) -> FloatArray:
    """Each test's weight ``1 / (se² + sd²)`` from its standard error and the
    baseline's spread. [1 / %²]"""
    return np.asarray(1.0 / (se ** 2 + spread ** 2 + 1e-12), dtype=np.float64)


def serial_factor(r: FloatArray) -> float:
    """How much a slope's variance grows when a series' checks drift together:
    ``(1 + ρ) / (1 − ρ)`` of its weighted residuals' lag-1 autocorrelation
    ``ρ`` (an AR(1) series' effective number of tests, as trend tests of
    climate series take it: Santer et al. 2000), ``ρ`` held to [0, 0.8]; 1
    for fewer than :data:`SERIAL_MIN_TESTS` residuals. Real records drift
    together (a day's temperature, a season): the actuators' Coulomb
    friction shows ρ 0.3-0.6, where a slope read as independent tests
    would be a trend by chance. [-]

    Example
    -------
    >>> serial_factor(np.array([1.0, -1.0] * 5)), round(serial_factor(np.repeat([1.0, -1.0], 5)), 2)
    (1.0, 5.67)
    """
    if len(r) < SERIAL_MIN_TESTS:
        return 1.0
    rc = r - r.mean()
    denom = float(rc @ rc)
    # residuals far inside their stated scatter (in sd) carry no drift to read
    rho = float(rc[:-1] @ rc[1:]) / denom if denom > 1e-9 * len(r) else 0.0
    rho = min(max(rho, 0.0), 0.8)
    return (1.0 + rho) / (1.0 - rho)


def trend_sd(sd: float, residuals: FloatArray, scale: float) -> float:
    """A slope's standard deviation as a trend test takes it: at the tests'
    stated variance at least (a series that happens to scatter less than
    stated, ``scale`` < 1, does not make a stable unit's drift), and widened
    by :func:`serial_factor` of its weighted ``residuals`` (checks that drift
    together). [% per x]

    Example
    -------
    >>> trend_sd(1.0, np.zeros(3), 0.25)        # a quarter of the stated variance: taken at 1
    2.0
    """
    return sd * math.sqrt(serial_factor(residuals) / min(scale, 1.0))


def steady_direction(x: FloatArray, y: FloatArray, se: FloatArray, spread: float) -> float:
    """The sign of a series' steady move: +1.0 or -1.0 when its weighted
    line's slope has a 90 % interval clear of 0 (at the tests' stated
    variance at least, and widened by :func:`serial_factor`, as a
    forecast's trend), 0.0 when it holds 0.

    Example
    -------
    >>> x = np.arange(1.0, 11.0)
    >>> steady_direction(x, 0.5 * x, np.ones(10), 1.0), steady_direction(x, 0 * x, np.ones(10), 1.0)
    (1.0, 0.0)
    """
    w = weights(se, spread)
    coef, cov, rss = wls(x, y, w)
    sd = trend_sd(math.sqrt(max(cov[1, 1], 0.0)), (y - coef[0] - coef[1] * x) * np.sqrt(w),
                  residual_scale(rss, max(len(x) - 2, 1)))
    if abs(coef[1]) > Z90 * sd:
        return float(np.sign(coef[1]))
    return 0.0


def aicc_weights(found: dict[str, Fit], n: int) -> tuple[dict[str, float], dict[str, float]]:
    """Each fit's small-sample Akaike criterion (AICc, on its weighted
    residuals) and its Akaike weight (Burnham and Anderson): the models'
    relative evidence, summing to 1."""
    aic = {k: n * math.log(max(v[2], 1e-300) / n) + 2 * len(v[0])
           + 2 * len(v[0]) * (len(v[0]) + 1) / max(n - len(v[0]) - 1, 1) for k, v in found.items()}
    best = min(aic.values())
    w = {k: math.exp(-0.5 * (v - best)) for k, v in aic.items()}
    return aic, {k: v / sum(w.values()) for k, v in w.items()}


@dataclass(frozen=True)
class RatePosterior:
    """The exponential's posterior over its growth rate, on a grid.

    Attributes
    ----------
    rates : ndarray
        The grid of rates ``b``. [1 per x]
    prob : ndarray
        Each rate's posterior probability (summing to 1). [-]
    coef : ndarray
        (α, β) at each rate: level and slope at the last test. [%, % per x]
    cov : ndarray
        Their covariance at each rate, shape (grid, 2, 2).
    log_bayes : float
        ln of the marginal likelihood over that of the other shape: the
        straight line (``b = 0``) with the same flat prior on (α, β)
        (:func:`rate_posterior`), or the fleet's line (:func:`fleet_posteriors`). [-]
    scale : float
        The residual variance factor ``σ²`` the likelihood is taken at
        (:func:`residual_scale`). [-]
    """

    rates: FloatArray
    prob: FloatArray
    coef: FloatArray
    cov: FloatArray
    log_bayes: float
    scale: float

    def draws(self, rng: np.random.Generator, size: int) -> FloatArray:
        """Draws of (α, β, b) from the posterior, shape (size, 3)."""
        pick = rng.choice(len(self.prob), size=size, p=self.prob)
        vals, vecs = np.linalg.eigh(self.cov[pick])     # each draw's (α, β) | b
        root = vecs * np.sqrt(np.maximum(vals, 0.0))[:, None, :]
        ab = self.coef[pick] + np.einsum("sij,sj->si", root, rng.standard_normal((size, 2)))
        return np.column_stack([ab, self.rates[pick]])

    def moments(self) -> tuple[FloatArray, FloatArray]:
        """The posterior mean of (α, β, b) and its covariance (within and between rates)."""
        theta = np.column_stack([self.coef, self.rates])
        mean = self.prob @ theta
        d = theta - mean
        cov = np.einsum("j,jk,jl->kl", self.prob, d, d)
        cov[:2, :2] += np.einsum("j,jkl->kl", self.prob, self.cov)
        return np.asarray(mean, dtype=np.float64), np.asarray(cov, dtype=np.float64)


def rate_posterior(x: FloatArray, y: FloatArray, w: FloatArray, mean: float, sd: float,
                   grid: int = 200) -> RatePosterior:
    """The exponential's posterior over its rate under a normal prior on it.

    Parameters
    ----------
    x : ndarray
        The tests' times, increasing. [test (or d, h)]
    y : ndarray
        The change towards the threshold (``|change|``'s sign taken). [%]
    w : ndarray
        Each test's weight (:func:`weights`). [1 / %²]
    mean, sd : float
        The normal prior on the rate ``b`` (truncated to the growing rates
        of the grid). [1 per x]
    grid : int
        Rates on the grid (log-spaced over 0.01–30 per the series' span).

    Returns
    -------
    RatePosterior
        With the Bayes factor over the straight line. ``σ²`` is the residual
        variance of the best rate on the grid or the line (the most flexible
        fit's, as Mallows's Cp takes it; :func:`residual_scale`).
    """
    t = x - x[-1]
    span = float(x[-1] - x[0])
    rates = np.geomspace(*_RATE_SPAN, grid) / span
    g = np.vstack([t, np.expm1(np.outer(rates, t)) / rates[:, None]])   # b = 0: the line
    X = np.stack([np.ones_like(g), g], axis=-1)                           # (rate, test, 2)
    info = np.einsum("gni,n,gnj->gij", X, w, X)
    coef = np.linalg.solve(info, np.einsum("gni,n->gi", X, w * y)[..., None])[..., 0]
    r = y - np.einsum("gni,gi->gn", X, coef)
    rss = np.einsum("gn,n,gn->g", r, w, r)
    scale = residual_scale(float(rss.min()), max(len(x) - 3, 1))
    logdet = np.linalg.slogdet(info)[1]
    loglik = -0.5 * (rss - rss[0]) / scale - 0.5 * (logdet - logdet[0])
    # the prior's mass in each cell of the grid (its density times the cell's
    # width), truncated to the grid: the rates it can hold
    logprior = -0.5 * ((rates - mean) / sd) ** 2 + np.log(np.gradient(rates))
    logprior -= float(logprior.max()) + math.log(float(np.exp(logprior - logprior.max()).sum()))
    log_post = loglik[1:] + logprior
    top = float(log_post.max())
    prob = np.exp(log_post - top)
    cov = np.asarray(np.linalg.inv(info[1:]) * scale, dtype=np.float64)
    return RatePosterior(rates, prob / prob.sum(), coef[1:], cov,
                         top + math.log(float(prob.sum())), scale)


def _line_fits(g: FloatArray, y: FloatArray, w: FloatArray
               ) -> tuple[float, float, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The weighted straight fit ``y = c + k·g`` for each row of ``g``, in
    centred sums: Σw, the weighted means of y and of each row, each row's
    centred Σw·g², its slope k and its weighted residual sum of squares."""
    W = float(w.sum())
    ybar = float(w @ y) / W
    gbar = g @ w / W
    dg = g - gbar[:, None]
    sgg = np.maximum(np.einsum("gn,n,gn->g", dg, w, dg), 1e-300)
    sgy = dg @ (w * (y - ybar))
    k_hat = sgy / sgg
    rss = np.maximum(float(w @ (y - ybar) ** 2) - sgy * k_hat, 0.0)
    return W, ybar, gbar, sgg, k_hat, rss


def _normal_evidence(g: FloatArray, y: FloatArray, w: FloatArray, mean: float, sd: float,
                     scale: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """``y = c + k·g`` with c flat and ``k ~ N(mean, sd²)``, for each row of
    ``g`` (one shape a row): ln of the marginal likelihood (less the shared
    ``½·ln(2πσ²/Σw)`` of c), and the posterior mean and covariance of (c, k),
    as (log evidence, mean (rows, 2), covariance (rows, 2, 2), weighted residual
    sum of squares of the free fit)."""
    W, ybar, gbar, sgg, k_hat, rss = _line_fits(g, y, w)
    like_var = scale / sgg                     # k's variance from the tests alone
    pred_var = sd ** 2 + like_var
    log_e = (-0.5 * rss / scale + 0.5 * np.log(2.0 * math.pi * like_var)
             - 0.5 * (k_hat - mean) ** 2 / pred_var - 0.5 * np.log(2.0 * math.pi * pred_var))
    var_k = 1.0 / (1.0 / like_var + 1.0 / sd ** 2)
    k = var_k * (k_hat / like_var + mean / sd ** 2)
    c = ybar - k * gbar
    cov = np.empty((len(g), 2, 2))
    cov[:, 0, 0] = scale / W + gbar ** 2 * var_k
    cov[:, 0, 1] = cov[:, 1, 0] = -gbar * var_k
    cov[:, 1, 1] = var_k
    return log_e, np.column_stack([c, k]), cov, rss


@dataclass(frozen=True)
class ShapePosteriors:
    """Both shapes' posteriors under the fleet's priors (:func:`fleet_posteriors`).

    Attributes
    ----------
    linear : RatePosterior
        The line, bent as the fleet's lines were (``c + s·(exp(b·x) − 1)/b``:
        ``s`` its slope at the origin, ``b`` near 0 its bend).
    exponential : RatePosterior
        The exponential ``c + A·(exp(b·x) − 1)``.
    log_bayes : float
        ln of the exponential's marginal likelihood over the line's. [-]
    """

    linear: RatePosterior
    exponential: RatePosterior
    log_bayes: float


def _curve(x: FloatArray, y: FloatArray, w: FloatArray, rates: FloatArray,
           rate: tuple[float, float], coef: tuple[float, float], amplitude: bool,
           scale: float) -> RatePosterior:
    """One shape's posterior on a grid of ``rates``: ``y = c + k·g_b(x)`` with
    ``g_b = exp(b·x) − 1`` (``k`` the amplitude) or ``(exp(b·x) − 1)/b``
    (``k`` the slope at the origin; ``x`` itself at ``b = 0``), c flat, ``k``
    and ``b`` normal; ``log_bayes`` its log marginal likelihood (less the
    level's shared term)."""
    with np.errstate(over="ignore"):
        e = np.expm1(np.outer(rates, x))
    flat = rates == 0.0
    g = e if amplitude else np.where(flat[:, None], x[None, :],
                                     e / np.where(flat, 1.0, rates)[:, None])
    ok = np.all(np.isfinite(g), axis=1)
    rates, g = rates[ok], g[ok]
    log_e, ck, ck_cov, _ = _normal_evidence(g, y, w, coef[0], coef[1], scale)
    width = np.gradient(rates) if len(rates) > 1 else np.ones(1)
    logprior = -0.5 * ((rates - rate[0]) / rate[1]) ** 2 + np.log(width)
    logprior -= float(logprior.max()) + math.log(float(np.exp(logprior - logprior.max()).sum()))
    log_post = log_e + logprior
    top = float(log_post.max())
    prob = np.exp(log_post - top)
    # (c, k) at the origin to (α, β) at the last test: α = c + k·g(x_last), β = k·g'(x_last)
    J = np.zeros((len(rates), 2, 2))
    J[:, 0, 0] = 1.0
    J[:, 0, 1] = g[:, -1]
    J[:, 1, 1] = (rates if amplitude else 1.0) * np.exp(rates * x[-1])
    mean = np.einsum("gij,gj->gi", J, ck)
    cov = np.einsum("gij,gjk,glk->gil", J, ck_cov, J)
    return RatePosterior(rates, prob / prob.sum(), mean, (cov + cov.transpose(0, 2, 1)) / 2.0,
                         top + math.log(float(prob.sum())), scale)


def fleet_posteriors(x: FloatArray, y: FloatArray, w: FloatArray,
                     bend: tuple[float, float], slope: tuple[float, float],
                     rate: tuple[float, float], amplitude: tuple[float, float],
                     grid: int = 200) -> ShapePosteriors:
    """Both shapes' posteriors under the fleet's priors, and the Bayes factor
    between them.

    Both shapes are written from the series' origin (``x = 0``: the baseline
    when tests are counted, the first check when days or hours are):

    - the **line** as its peers wore it, ``y = c + s·(exp(b·x) − 1)/b``: the
      slope ``s`` at the origin and a bend ``b`` near 0 (a straight line as
      ``b`` → 0), so a fleet whose measured wear curves up a little teaches
      that too;
    - the **exponential**, ``y = c + A·(exp(b·x) − 1)``: Gebraeel (2006) puts
      his fleet's priors on the same amplitude ``A`` and rate ``b``.

    The level c has the same flat prior in both, so it cancels from the
    Bayes factor; every other coefficient has the fleet's normal prior, so
    both marginal likelihoods are proper and their ratio weighs the fleet's
    line against the fleet's curve: a unit whose start looks straight but far
    slower than the peers' lines is weighed against their curve too. For a
    given ``b`` each shape is linear in (c, s) or (c, A), integrated in closed
    form; ``b`` is taken on a grid.

    Parameters
    ----------
    x, y, w : ndarray
        The tests' times [test (or d, h)], the change towards the threshold
        [%] and each test's weight [1 / %²] (:func:`weights`).
    bend, slope : tuple of float
        The fleet's (mean, sd) of the line's bend ``b`` (signed: below 0 a
        line that bows down) [1 per x] and its slope at the origin ``s`` [%
        per x].
    rate, amplitude : tuple of float
        The fleet's (mean, sd) of the exponential's rate ``b`` [1 per x] and
        amplitude ``A`` [%].
    grid : int
        Rates on each grid: the exponential's log-spaced over 0.01–30 per
        the series' span, the line's bends evenly over the fleet's ± 6 sd.

    Returns
    -------
    ShapePosteriors
        Each posterior's ``log_bayes`` is over the other shape; ``σ²`` is the
        most flexible free fit's residual variance (:func:`residual_scale`),
        for both.

    Example
    -------
    >>> x = np.arange(1.0, 9.0)                     # a curve whose start looks straight
    >>> y = 10.0 * np.expm1(0.25 * x)
    >>> p = fleet_posteriors(x, y, np.ones(8), (0.01, 0.01), (40.0, 10.0), (0.25, 0.05),
    ...                      (10.0, 2.0))
    >>> p.log_bayes > 5, abs(float(p.exponential.prob @ p.exponential.rates) - 0.25) < 0.01
    (True, True)
    """
    span = float(x[-1] - x[0])
    with np.errstate(over="ignore"):
        g = np.expm1(np.outer(np.geomspace(*_RATE_SPAN, grid) / span, x))
    g = g[np.all(np.isfinite(g), axis=1)]
    # the scale: the most flexible free fit's residual variance
    free = _line_fits(np.vstack([x, g]), y, w)[-1]
    scale = residual_scale(float(free.min()), max(len(x) - 3, 1))
    # the bend's grid: the fleet's bends ± 6 sd, within a slope that grows or
    # falls e^3-fold over the span, evenly spaced (it crosses 0: a straight line)
    half = max(6.0 * bend[1], 0.01 / span)
    bends = np.linspace(max(bend[0] - half, -3.0 / span), min(bend[0] + half, 3.0 / span), grid)
    line = _curve(x, y, w, bends, bend, slope, False, scale)
    curve = _curve(x, y, w, np.geomspace(*_RATE_SPAN, grid) / span, rate, amplitude, True, scale)
    log_bayes = curve.log_bayes - line.log_bayes
    return ShapePosteriors(replace(line, log_bayes=-log_bayes),
                           replace(curve, log_bayes=log_bayes), log_bayes)
