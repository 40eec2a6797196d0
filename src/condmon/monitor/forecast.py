"""When will it turn no-go? A degradation model of one parameter's change series.

The series is a parameter's change against its unit's baseline, test after test
[%]. Each test is weighted by its own uncertainty and the baseline's spread
(``w = 1 / (se² + sd²)``, both in % of the baseline mean): a test whose estimate
is poor, or a parameter whose healthy scatter is wide, counts less.

Two degradation models are fitted by weighted least squares and chosen by
evidence (Akaike's criterion, small-sample corrected, on the same weighted residuals):

- **linear**: ``change = a + b·x``;
- **exponential**: ``|change| = φ + c·exp(b·x)`` (a wear that feeds itself;
  the offset φ as in Gebraeel's model, so a series that starts from the
  healthy 0 % and crosses it in noise is held; from 5 tests). It is fitted
  as ``α + β·(exp(b·t) − 1)/b`` from the last test, so a rate b near 0 is
  the line, not a draw that never crosses.

When both models fit, the forecast's draws come from each in proportion to
its evidence (Akaike weights): a series that cannot yet tell a line from a
curve gets the interval of both.

``x`` is the test number (or the days since the first test, or operating
hours). The forecast is the crossing of the no-go change (``r2`` of the
parameter's breakpoints, in the trend's direction): its predictive distribution
comes from the fitted coefficients' covariance (4,000 draws, a fixed seed),
given as a median and a 90 % interval of the tests (days, hours) left, and the
probability of crossing within a horizon. A slope whose 90 % interval holds 0,
or points away from the threshold, is "no trend": then no number of tests is
given.

A **fleet prior** (:class:`RatePrior`, built by :func:`fleet_prior` from units
of the same model that have already degraded) is combined with the unit's own
tests by Bayesian updating of the slope ``b`` (normal prior, the weighted
least-squares likelihood, a flat prior on the intercept: Gebraeel 2006, and the
degradation models of MATLAB's Predictive Maintenance Toolbox): after a few
tests the fleet's rate carries the forecast; after many, the unit's own. With
no fleet history the prior is vague, the forecast the unit's own, and a note
says so.

Why by hand: a weighted two-model fit with a crossing distribution is a few
lines of numpy, and the prognostics libraries (ProgPy, the Predictive
Maintenance Toolbox) fit their own degradation shapes to run-to-failure
ensembles, not a change series with its own per-test uncertainty.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import DataError
from condmon.monitor.bounded import bounded_minimum

__all__ = ["Forecast", "forecast_series", "MIN_TESTS", "checked_horizon", "RatePrior", "fleet_prior", "unit_rate",
           "prior_from_rates"]

FloatArray = NDArray[np.float64]

#: Fewest checks since the baseline that a forecast needs.
MIN_TESTS = 3
_DRAWS = 4000
_BAND_DRAWS = 1000
_Z90 = 1.6448536269514722


@dataclass(frozen=True)
class Forecast:
    """The forecast of one parameter's change series.

    Attributes
    ----------
    model : {"linear", "exponential", "no trend"}
    threshold : float
        The change at which a check turns no-go, signed. [%]
    slope : float
        The trend at the last test: change per unit of ``x``. [% per test (or day)]
    slope_interval : tuple of float
        Its 90 % interval. [% per test (or day)]
    remaining : tuple of float or None
        Tests (or days) from the last one to the crossing: median, then the
        90 % interval (5 % and 95 % points; inf: not within any horizon).
        None for "no trend". [tests (or days)]
    p_within : float or None
        Probability of crossing within the horizon (None: no horizon given). [-]
    n : int
        Tests used.
    notes : tuple of str
    coef : tuple of float
        The chosen model's fitted coefficients: ``(a, b)`` of ``change = a +
        b·x`` (linear; also for "no trend"), or ``(α, β, r)`` of ``|change| =
        α + β·(exp(r·t) − 1)/r`` with ``t = x − last`` (exponential). [%, % per
        x (linear); %, % per x, 1 per x (exponential)]
    cov : tuple of tuple of float
        Their covariance matrix.
    last : float
        ``x`` of the last test. [test (or d, h)]
    """

    model: str
    threshold: float
    slope: float
    slope_interval: tuple[float, float]
    remaining: tuple[float, float, float] | None
    p_within: float | None
    n: int
    notes: tuple[str, ...] = ()
    coef: tuple[float, ...] = ()
    cov: tuple[tuple[float, ...], ...] = ()
    last: float = math.nan

    @property
    def trend(self) -> bool:
        """Whether a trend towards the threshold was found."""
        return self.model != "no trend"

    def band(self, ahead: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The fitted trend continued past the last test, with its 90 % band.

        Pointwise quantiles of the chosen model's fitted change under the
        coefficients' covariance (the distribution the crossing is drawn
        from: the band's edges meet the threshold at the 5 % and 95 % points
        of ``remaining``).

        Parameters
        ----------
        ahead : array_like
            Tests (or days, hours) after the last one. [test (or d, h)]

        Returns
        -------
        median, low, high : ndarray
            The fitted change and its 90 % interval at each point. [%]

        Example
        -------
        >>> x = np.arange(1.0, 16.0)
        >>> f = forecast_series(x, 4.0 * x, np.full(15, 1.0), 2.0, threshold=100.0)
        >>> med, lo, hi = f.band([0.0, 10.0])
        >>> [round(float(v)) for v in med], bool(lo[1] < 100.0 < hi[1])
        ([60, 100], True)
        """
        t = np.asarray(ahead, dtype=np.float64)
        coef = np.asarray(self.coef, dtype=np.float64)
        cov = np.asarray(self.cov, dtype=np.float64)
        if self.model != "exponential":
            x = self.last + t
            a, b = coef
            mid = a + b * x
            half = _Z90 * np.sqrt(np.maximum(cov[0, 0] + 2.0 * x * cov[0, 1]
                                             + x * x * cov[1, 1], 0.0))
            return mid, mid - half, mid + half
        # the exponential is not linear in its rate: pointwise quantiles of drawn paths
        sign = 1.0 if self.threshold > 0 else -1.0
        draws = np.random.default_rng(0).multivariate_normal(coef, cov, size=_BAND_DRAWS,
                                                             method="eigh")
        paths = np.array([lv + sl * _growth(float(r), t) for lv, sl, r in draws])
        lo, hi = np.quantile(paths, [0.05, 0.95], axis=0)
        path = coef[0] + coef[1] * _growth(float(coef[2]), t)
        ends = sign * lo, sign * hi
        return sign * path, np.minimum(*ends), np.maximum(*ends)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (inf as None)."""
        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {"model": self.model, "threshold_percent": self.threshold,
                "slope": float(self.slope), "slope_interval": [num(v) for v in self.slope_interval],
                "remaining": None if self.remaining is None else {
                    "median": num(self.remaining[0]), "low": num(self.remaining[1]),
                    "high": num(self.remaining[2])},
                "p_within_horizon": self.p_within, "tests": self.n, "notes": list(self.notes)}


@dataclass(frozen=True)
class RatePrior:
    """The fleet's prior on the degradation rate of one model.

    Attributes
    ----------
    model : {"linear", "exponential"}
        The degradation model whose slope ``b`` it is about.
    mean : float
        The rate: for "linear" the change per test (or day) [% per test (or day)];
        for "exponential" the rate ``b`` of its growing part [1 per test (or day)].
    sd : float
        Its standard deviation for a new unit (inf: vague). [as ``mean``]
    units : int
        How many units it came from (0: no fleet history).
    per : str
        What ``x`` counts, for the description ("test", "day", "h").
    """

    model: str
    mean: float
    sd: float
    units: int
    per: str = "test"

    def __post_init__(self) -> None:
        if self.model not in _MODELS:
            raise DataError(f"unknown degradation model {self.model!r}: "
                            f"use one of {', '.join(_MODELS)}")
        if not (math.isfinite(self.mean) and self.sd > 0):
            raise DataError(f"a rate prior needs a finite mean and an sd > 0, "
                            f"not {self.mean:g} ± {self.sd:g}")

    @classmethod
    def vague(cls, model: str = "linear", per: str = "test") -> RatePrior:
        """The prior with no fleet history: the unit's own tests decide."""
        return cls(model, 0.0, math.inf, 0, per)

    @property
    def informative(self) -> bool:
        """Whether it carries any fleet knowledge."""
        return math.isfinite(self.sd)

    def describe(self) -> str:
        """One line: where the prior comes from and what it says."""
        if not self.informative:
            return "no fleet history: vague prior"
        if self.model == "linear":
            what = f"slope {self.mean:.3g} ± {self.sd:.2g} %/{self.per}"
        else:
            what = f"growth rate {self.mean:.3g} ± {self.sd:.2g} /{self.per}"
        return f"fleet prior ({self.model}) from {self.units} units: {what}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (a vague sd as None)."""
        return {"model": self.model, "mean": self.mean,
                "sd": self.sd if self.informative else None, "units": self.units,
                "per": self.per}


_MODELS = ("linear", "exponential")
#: Fewest tests for the exponential (three coefficients, and a residual to judge them by).
_EXP_MIN_TESTS = 5


def _wls(x: FloatArray, y: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray, float]:
    """Weighted straight line: coefficients (a, b), their covariance, weighted RSS."""
    X = np.column_stack([np.ones_like(x), x])
    sw = np.sqrt(w)
    coef, *_ = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)
    r = (y - X @ coef) * sw
    rss = float(r @ r)
    dof = max(len(x) - 2, 1)
    # the weights give the relative scale; the residuals the absolute one (at
    # least the weights' own: a series smoother than its stated noise is not
    # taken as more certain than that)
    scale = max(rss / dof, 1.0)
    cov = np.asarray(np.linalg.pinv((X * w[:, None]).T @ X) * scale, dtype=np.float64)
    return np.asarray(coef, dtype=np.float64), cov, rss


def _updated(fit: tuple[FloatArray, FloatArray, float],
             prior: RatePrior) -> tuple[FloatArray, FloatArray, float]:
    """The fit's coefficients updated by a normal prior on the slope (flat on
    the others), in the gain form ``θ + k (m − b)``, ``C − k C_b`` with
    ``k = C_·b / (C_bb + s²)``: the same as adding precisions, and sound for
    a prior as tight as the fit is loose (no inverse of a near-singular sum)."""
    coef, cov, rss = fit
    if not prior.informative:
        return fit
    gain = cov[:, -1] / (cov[-1, -1] + prior.sd ** 2)   # the slope is the last coefficient
    post_coef = coef + gain * (prior.mean - coef[-1])
    post_cov = cov - np.outer(gain, cov[-1, :])
    return (np.asarray(post_coef, dtype=np.float64),
            np.asarray((post_cov + post_cov.T) / 2.0, dtype=np.float64), rss)


def checked_horizon(horizon: float | None) -> None:
    """Refuse a horizon that is not a finite number > 0 (None: no horizon). [tests (or d, h)]"""
    if horizon is not None and not (horizon > 0 and math.isfinite(horizon)):
        raise DataError(f"--horizon must be a finite number > 0 (tests, days or hours "
                        f"ahead), not {horizon:g}")


def _fitted(fit: tuple[FloatArray, FloatArray, float]
            ) -> tuple[tuple[float, ...], tuple[tuple[float, ...], ...]]:
    """A fit's coefficients and covariance as plain tuples (for :class:`Forecast`)."""
    return (tuple(float(v) for v in fit[0]),
            tuple(tuple(float(v) for v in row) for row in fit[1]))


def _growth(b: float, t: FloatArray) -> FloatArray:
    """``(exp(b·t) − 1) / b``: ``t`` itself as ``b`` → 0."""
    return np.asarray(t if b == 0 else np.expm1(b * t) / b, dtype=np.float64)


def _expfit(x: FloatArray, y: FloatArray,
            w: FloatArray) -> tuple[FloatArray, FloatArray, float] | None:
    """Weighted exponential with an offset, written from the last test
    (``t = x − x_last``) as ``y = α + β·(exp(b·t) − 1)/b``: the level α and
    slope β at the last test and the growth rate b (a line as b → 0).
    Coefficients (α, β, b), their covariance (Gauss-Newton), weighted RSS;
    None where no growing exponential (b above the flat end) fits better."""
    t = x - x[-1]
    span = float(x[-1] - x[0])
    sw = np.sqrt(w)

    def profile(b: float) -> tuple[float, FloatArray]:
        # for a given rate the model is linear in (α, β)
        X = np.column_stack([np.ones_like(t), _growth(b, t)])
        coef, *_ = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)
        r = (y - X @ coef) * sw
        return float(r @ r), np.asarray(coef, dtype=np.float64)

    grid = np.geomspace(0.01, 30.0, 64) / span
    rss = [profile(float(b))[0] for b in grid]
    i = int(np.argmin(rss))
    if i == 0:                     # flattest rate best: a line, not an exponential
        return None
    b = bounded_minimum(lambda rate: profile(float(rate))[0], float(grid[i - 1]),
                        float(grid[min(i + 1, len(grid) - 1)]))
    best, (level, slope) = profile(b)
    g = _growth(b, t)
    J = np.column_stack([np.ones_like(t), g, slope * (t * np.exp(b * t) - g) / b])
    scale = max(best / max(len(x) - 3, 1), 1.0)
    cov = np.asarray(np.linalg.pinv((J * w[:, None]).T @ J) * scale, dtype=np.float64)
    return np.array([level, slope, b]), cov, best


def _fits(xa: FloatArray, ya: FloatArray, sa: FloatArray, spread: float,
          sign: float) -> dict[str, tuple[FloatArray, FloatArray, float]]:
    """Both degradation models' weighted fits, the change taken towards the
    threshold (the exponential from :data:`_EXP_MIN_TESTS` tests, where it
    grows). The slope ``b`` is each model's last coefficient."""
    w = 1.0 / (sa ** 2 + spread ** 2 + 1e-12)
    fits: dict[str, tuple[FloatArray, FloatArray, float]] = {"linear": _wls(xa, ya, w)}
    if len(xa) >= _EXP_MIN_TESTS:
        exp = _expfit(xa, sign * ya, w)
        if exp is not None:
            fits["exponential"] = exp
    return fits


def fleet_prior(series: Sequence[tuple[ArrayLike, ArrayLike, ArrayLike, float]],
                model: str = "linear", per: str = "test") -> RatePrior:
    """The prior on the degradation rate from units that have already degraded.

    Each unit's own rate is its weighted fit of ``model`` (as in
    :func:`forecast_series`); the prior is their mean, with the between-unit
    standard deviation widened for a new unit (``sd·√(1 + 1/n)``, the
    predictive spread of one more draw).

    Parameters
    ----------
    series : sequence of (x, change, se, spread)
        Each unit's series, the leading arguments of :func:`forecast_series`:
        the tests' times [test (or d, h)], changes [%], standard errors and
        baseline spread [% of the baseline mean].
    model : {"linear", "exponential"}
        The model whose slope is wanted. A unit that no growing exponential
        fits has no exponential rate and is left out.
    per : str
        What ``x`` counts ("test", "day", "h"), for the description.

    Returns
    -------
    RatePrior
        Vague (``units=0``, sd inf) when fewer than 2 units give a rate.

    Raises
    ------
    DataError
        An unknown model; a series that :func:`forecast_series` would refuse.

    References
    ----------
    N. Gebraeel, "Sensory-updated residual life distributions for components
    with exponential degradation patterns", IEEE Trans. Automation Science
    and Engineering 3(4), 2006.

    Example
    -------
    >>> x = np.arange(1.0, 21.0)                  # three worn units: +1.8, +2.0, +2.2 % a test
    >>> fleet = [(x, r * x, np.ones(20), 1.0, ) for r in (1.8, 2.0, 2.2)]
    >>> p = fleet_prior(fleet)
    >>> p.describe()
    'fleet prior (linear) from 3 units: slope 2 ± 0.23 %/test'
    >>> fleet_prior(fleet[:1]).describe()
    'no fleet history: vague prior'
    """
    if model not in _MODELS:
        raise DataError(f"unknown degradation model {model!r}: use one of {', '.join(_MODELS)}")
    rates = [found for x, change, se, spread in series
             if (found := unit_rate(x, change, se, spread, model)) is not None]
    return prior_from_rates(rates, model, per)


def unit_rate(x: ArrayLike, change: ArrayLike, se: ArrayLike, spread: float,
              model: str = "linear") -> tuple[float, float] | None:
    """One unit's degradation rate under ``model`` and its variance (None: no
    growing exponential fits the series), as :func:`fleet_prior` reads it.
    [% per x (linear), 1 per x (exponential); squared]"""
    xa, ya, sa = _checked(x, change, se, spread)
    tail = float(np.mean(ya[-MIN_TESTS:]))
    fit = _fits(xa, ya, sa, spread, 1.0 if tail >= 0 else -1.0).get(model)
    return None if fit is None else (float(fit[0][-1]), float(fit[1][-1, -1]))


def prior_from_rates(rates: Sequence[tuple[float, float]], model: str = "linear",
                     per: str = "test") -> RatePrior:
    """The prior from units' rates and their variances (:func:`unit_rate`):
    their mean, and their spread for a new unit (``sd·√(1 + 1/n)``), never
    less than the rates' own estimation error; vague with fewer than 2."""
    if len(rates) < 2:
        return RatePrior.vague(model, per)
    r = np.asarray([v for v, _ in rates])
    # the units' rates scatter by their own estimation error too: never less than that
    var = max(float(np.var(r, ddof=1)), float(np.mean([e for _, e in rates])))
    sd = math.sqrt(var * (1.0 + 1.0 / len(r)))
    return RatePrior(model, float(np.mean(r)), max(sd, 1e-12 * max(1.0, abs(float(np.mean(r))))),
                     len(r), per)


def _checked(x: ArrayLike, change: ArrayLike, se: ArrayLike,
             spread: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """One series as arrays, refused as :func:`forecast_series` says."""
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


def _left(model: str, fit: tuple[FloatArray, FloatArray, float], n: int, var1: float,
          threshold: float, last: float, rng: np.random.Generator, size: int) -> FloatArray:
    """Draws of the tests (days, hours) left until a check measures ``threshold``:
    the path's crossing, less that check's own scatter (the fit's residual
    scale at a typical weight, ``var1`` the typical ``1/w``); inf: never."""
    coef, cov, rss = fit
    sign = 1.0 if threshold > 0 else -1.0
    scale = max(rss / max(n - len(coef), 1), 1.0)
    if size == 0:
        return np.empty(0)
    draws = rng.multivariate_normal(coef, cov, size=size, method="eigh")
    reach = abs(threshold) - rng.normal(0.0, math.sqrt(scale * var1), size)
    with np.errstate(all="ignore"):
        if model == "linear":
            a, b = draws[:, 0], draws[:, 1]
            cross = (sign * reach - a) / b
            ok = sign * b > 0
        else:   # from the last test: (exp(b·t) − 1)/b = q, t = q·ln(1 + b·q)/(b·q)
            level, slope, b = draws[:, 0], draws[:, 1], draws[:, 2]
            q = (reach - level) / slope
            z = b * q
            factor = np.where(np.abs(z) < 1e-9, 1.0, np.log1p(np.maximum(z, -1.0)) / z)
            cross = last + np.where(level >= reach, 0.0, q * factor)
            ok = (level >= reach) | ((slope > 0) & (z > -1.0))
    return np.asarray(np.where(ok, np.maximum(cross - last, 0.0), np.inf), dtype=np.float64)


def forecast_series(x: ArrayLike, change: ArrayLike, se: ArrayLike,
                    spread: float, threshold: float, horizon: float | None = None,
                    seed: int = 0, *, prior: RatePrior | None = None) -> Forecast:
    """Forecast when a change series crosses ``threshold``.

    Parameters
    ----------
    x : array_like
        Test number, days or hours of each test, increasing. [test (or d, h)]
    change : array_like
        The parameter's change against the baseline at each test. [%]
    se : array_like
        Each test's standard error. [% of the baseline mean]
    spread : float
        The baseline's standard deviation. [% of the baseline mean]
    threshold : float
        The change at which a check turns no-go, signed (+r2 for a rise,
        -r2 for a fall). [%]
    horizon : float, optional
        For the probability of crossing within it. [tests (or d, h)]
    seed : int
        Seed of the predictive draws.
    prior : RatePrior, optional
        The fleet's prior on the slope (:func:`fleet_prior`), in the units of
        ``x``. Its model's slope is updated by the unit's tests (the models
        still weighted by the unit's evidence); a note names it. None: the
        unit's own tests alone, no note.

    Raises
    ------
    DataError
        Fewer than :data:`MIN_TESTS` tests, non-finite values, ``x`` not
        increasing, a horizon <= 0.

    Example
    -------
    >>> x = np.arange(1.0, 16.0)                      # 15 checks, friction +4 % a test
    >>> f = forecast_series(x, 4.0 * x, np.full(15, 1.0), 2.0, threshold=100.0)
    >>> f.model, round(f.remaining[0], 1)             # 100 % at test 25: 10 tests left
    ('linear', 10.0)

    Four tests of a unit whose fleet wore +4.0 ± 0.2 % a test:

    >>> f = forecast_series(x[:4], 4.0 * x[:4] + [2.0, -2.0, 2.0, -2.0], np.full(4, 1.0), 2.0,
    ...                     threshold=100.0, prior=RatePrior("linear", 4.0, 0.2, 12))
    >>> round(f.remaining[0]), f.notes[-1]
    (21, 'fleet prior (linear) from 12 units: slope 4 ± 0.2 %/test')
    """
    xa, ya, sa = _checked(x, change, se, spread)
    checked_horizon(horizon)
    if threshold == 0:
        raise DataError("forecast: the no-go threshold is 0 %")
    sign = 1.0 if threshold > 0 else -1.0
    fits = _fits(xa, ya, sa, spread, sign)
    notes: list[str] = []
    n = len(xa)
    weight = {"linear": 1.0}
    if len(fits) > 1:   # small-sample Akaike (AICc) on the same weighted residuals
        aic = {k: n * math.log(max(v[2], 1e-300) / n) + 2 * len(v[0])
               + 2 * len(v[0]) * (len(v[0]) + 1) / (n - len(v[0]) - 1) for k, v in fits.items()}
        best = min(aic.values())
        weight = {k: math.exp(-0.5 * (v - best)) for k, v in aic.items()}
        weight = {k: v / sum(weight.values()) for k, v in weight.items()}
    model = max(weight, key=lambda k: weight[k])
    if len(fits) > 1:
        notes.append(f"{model} chosen by evidence (AICc {aic['linear']:.1f} linear, "
                     f"{aic['exponential']:.1f} exponential); the forecast averages both, "
                     f"weighted {weight['linear']:.2f} and {weight['exponential']:.2f}")
    if prior is not None:
        if prior.model in fits or not prior.informative:
            if prior.model in fits:
                fits[prior.model] = _updated(fits[prior.model], prior)
            notes.append(prior.describe())
        else:
            notes.append(f"{prior.describe()} not used: no growing {prior.model} "
                         "fits the series")
    coef, cov, _ = fits[model]
    last = float(xa[-1])
    if model == "linear":
        slope, slope_sd = float(coef[1]), math.sqrt(max(cov[1, 1], 0.0))
    else:  # d|y|/dx at the last test: β, towards the threshold
        slope, slope_sd = sign * float(coef[1]), math.sqrt(max(cov[1, 1], 0.0))
    interval = (slope - _Z90 * slope_sd, slope + _Z90 * slope_sd)
    towards = interval[0] > 0 if sign > 0 else interval[1] < 0
    if not towards:   # 0, or the wrong direction, inside the interval
        notes.append(f"the slope's 90 % interval [{interval[0]:.3g}, {interval[1]:.3g}] "
                     "holds no steady move towards the threshold")
        return Forecast("no trend", threshold, slope, interval, None,
                        0.0 if horizon is not None else None, n, tuple(notes),
                        *_fitted(fits["linear"]), last)
    # each model's draws in proportion to its evidence weight (model averaging)
    rng = np.random.default_rng(seed)
    w = 1.0 / (sa ** 2 + spread ** 2 + 1e-12)
    lefts = [_left(m, fits[m], n, float(np.median(1.0 / w)), threshold, last, rng,
                   round(_DRAWS * weight[m])) for m in sorted(weight)]
    left = np.concatenate(lefts)
    # the order statistics themselves: a draw that never crosses is inf, not interpolated
    med, lo, hi = (float(v) for v in np.quantile(left, [0.5, 0.05, 0.95], method="inverted_cdf"))
    p = float(np.mean(left <= horizon)) if horizon is not None else None
    return Forecast(model, threshold, slope, interval, (med, lo, hi), p, n, tuple(notes),
                    *_fitted(fits[model]), last)
