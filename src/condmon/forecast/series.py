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
probability of crossing within a horizon. Counted in tests (``step``), the
forecast is of the first future check whose *measured* change passes the
threshold: each drawn path is read at the checks to come, each check with its
own scatter, so the answer is a whole number of checks, as the no-go itself
is (a check turns no-go, not the time between two). Its 90 % interval then
ends at the mid-p quantiles (a check at an end counts half), which hold close
to 90 % on average: the 5 % and 95 % points of a few whole checks hold 97-98 %.
The fits' residuals give their scale, with the tests' stated variance as a
prior worth two tests (:func:`~condmon.forecast.degradation.residual_scale`);
a trend must stand out of the stated variance at least, and of checks that
drift together (:func:`~condmon.forecast.degradation.serial_factor`). A slope whose 90 % interval holds 0,
or points away from the threshold, is "no trend": then no number of tests is
given.

A **fleet prior**, built from units of the same model that have already
degraded (:mod:`condmon.forecast.prior`), is combined with the unit's own
tests by Bayesian updating (Gebraeel 2006, and the degradation models of
MATLAB's Predictive Maintenance Toolbox, fit such priors on a fleet):

- :class:`RatePrior` (:func:`fleet_prior`): a normal prior on one model's
  rate, updated with the weighted least-squares likelihood (a flat prior on
  the other coefficients);
- :class:`FleetPrior` (:func:`fleet_wear_prior`, what ``condmon forecast``
  uses): the shape as well. The exponential's growth rate ``b`` and
  amplitude ``A`` (of ``c + A·(exp(b·x) − 1)``, Gebraeel's two priors), and
  the line's slope ``s`` and bend ``b`` (of ``c + s·(exp(b·x) − 1)/b``, ``b``
  near 0: the fleet's lines may bend a little) by their exact posteriors,
  ``b`` on a grid (:func:`~condmon.forecast.degradation.fleet_posteriors`:
  for a given ``b`` each shape is linear, so the level and ``A`` or ``s``
  are integrated out in closed form), and the two shapes weighted by the
  fleet's odds of the exponential times the Bayes factor of the unit's
  tests, in place of Akaike's weights. Both carry the fleet's proper priors,
  so the factor weighs the fleet's line against the fleet's curve: a unit
  whose first half looks straight, but far slower than its peers' lines, is
  forecast with their curve before its own tests could show it. Without the
  line's bend or the curve's amplitude (fewer than 2 peers give them), the
  line's slope is updated alone and the exponential's rate is weighed
  against a line with a flat slope
  (:func:`~condmon.forecast.degradation.rate_posterior`).

After a few tests the fleet carries the forecast; after many, the unit's own
tests. With no fleet history the prior is vague, the forecast the unit's
own, and a note says so.

Why by hand: a weighted two-model fit with a crossing distribution is a few
lines of numpy, and the prognostics libraries (ProgPy, the Predictive
Maintenance Toolbox) fit their own degradation shapes to run-to-failure
ensembles, not a change series with its own per-test uncertainty.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import DataError
from condmon.forecast.degradation import (
    MIN_TESTS, Z90, Fit, RatePosterior, aicc_weights, checked_series, fleet_posteriors, growth,
    rate_posterior, residual_scale, trend_sd, weights,
)
from condmon.forecast.degradation import fits as degradation_fits
from condmon.forecast.path import path_band
from condmon.forecast.prior import (
    FleetPrior, Prior, RatePrior, fleet_prior, fleet_wear_prior, prior_from_rates,
    prior_from_wear, unit_rate, unit_wear, updated,
)

__all__ = ["Forecast", "forecast_series", "MIN_TESTS", "checked_horizon", "median_interval", "RatePrior",
           "fleet_prior", "unit_rate", "prior_from_rates", "FleetPrior", "fleet_wear_prior",
           "prior_from_wear", "unit_wear", "Prior"]

FloatArray = NDArray[np.float64]

_DRAWS = 4000
_BAND_DRAWS = 1000


@dataclass(frozen=True)
class Forecast:
    """The forecast of one parameter's change series.

    Attributes
    ----------
    model : {"linear", "exponential", "path", "no trend"}
        "path": a measured degradation path (:mod:`condmon.forecast.path`).
    threshold : float
        The change at which a check turns no-go, signed. [%]
    slope : float
        The trend at the last test: change per unit of ``x``. [% per test (or day)]
    slope_interval : tuple of float
        Its 90 % interval. [% per test (or day)]
    remaining : tuple of float or None
        Tests (or days) from the last one to the crossing: median, then the
        90 % interval (5 % and 95 % points; inf: not within any horizon).
        Whole checks when forecast with a ``step``, the interval's ends then
        the mid-p quantiles. None for "no trend".
        [tests (or days)]
    p_within : float or None
        Probability of crossing within the horizon (None: no horizon given). [-]
    n : int
        Tests used.
    notes : tuple of str
    coef : tuple of float
        The chosen model's fitted coefficients: ``(a, b)`` of ``change = a +
        b·x`` (linear; also for "no trend"), or ``(α, β, r)`` of ``|change| =
        α + β·(exp(r·t) − 1)/r`` with ``t = x − last`` (exponential, and a
        line bent as its fleet's lines were), or ``(a, b, φ, walk, deviation,
        scatter, step, span)`` of a path (:meth:`~condmon.forecast.path.PathFit.summary`).
        [%, % per x (linear); %, % per x, 1 per x (exponential)]
    cov : tuple of tuple of float
        Their covariance matrix.
    last : float
        ``x`` of the last test. [test (or d, h)]
    unreachable : str
        Why no check can turn no-go this way ("": it can), for a "no trend".
    at_nogo : bool
        The last check measured past the threshold: at no-go now (the
        remaining (0, 0, 0)). A trend whose path is past the threshold while
        the last check was not gives 0 too, without it: due now.
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
    unreachable: str = ""
    at_nogo: bool = False

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
        if self.model == "path":
            return path_band(coef, cov, t)
        if len(coef) == 2:   # the straight line (a line bent as its fleet's has three)
            x = self.last + t
            a, b = coef
            mid = a + b * x
            half = Z90 * np.sqrt(np.maximum(cov[0, 0] + 2.0 * x * cov[0, 1]
                                             + x * x * cov[1, 1], 0.0))
            return mid, mid - half, mid + half
        # the exponential is not linear in its rate: pointwise quantiles of drawn paths
        sign = 1.0 if self.threshold > 0 else -1.0
        draws = np.random.default_rng(0).multivariate_normal(coef, cov, size=_BAND_DRAWS,
                                                             method="eigh")
        paths = _level("exponential", draws, t.reshape(-1), self.last, sign)
        lo, hi = (q.reshape(t.shape) for q in np.quantile(paths, [0.05, 0.95], axis=0))
        path = coef[0] + coef[1] * growth(float(coef[2]), t)
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
                "p_within_horizon": self.p_within, "tests": self.n, "notes": list(self.notes),
                "unreachable": self.unreachable or None, "at_no_go": self.at_nogo}


def checked_horizon(horizon: float | None) -> None:
    """Refuse a horizon that is not a finite number > 0 (None: no horizon). [tests (or d, h)]"""
    if horizon is not None and not (horizon > 0 and math.isfinite(horizon)):
        raise DataError(f"--horizon must be a finite number > 0 (tests, days or hours "
                        f"ahead), not {horizon:g}")


def _fitted(fit: tuple[FloatArray, FloatArray] | Fit
            ) -> tuple[tuple[float, ...], tuple[tuple[float, ...], ...]]:
    """A fit's coefficients and covariance as plain tuples (for :class:`Forecast`)."""
    return (tuple(float(v) for v in fit[0]),
            tuple(tuple(float(v) for v in row) for row in fit[1]))


def _normal_draws(fit: Fit) -> Callable[[np.random.Generator, int], FloatArray]:
    return lambda rng, size: rng.multivariate_normal(fit[0], fit[1], size=size, method="eigh")


def _level(model: str, draws: FloatArray, t: FloatArray, last: float, sign: float) -> FloatArray:
    """The drawn paths' change towards the threshold at ``t`` after the last
    test (rows: draws; columns: ``t``, one row of times for all, or one a draw). [%]"""
    tt = np.asarray(t, dtype=np.float64)
    tt = tt[None, :] if tt.ndim == 1 else tt
    if model == "linear":
        return np.asarray(sign * (draws[:, :1] + draws[:, 1:2] * (last + tt)), dtype=np.float64)
    b = draws[:, 2:3]
    with np.errstate(all="ignore"):   # a fast draw overflows to inf: past the threshold
        g = np.where(np.abs(b) < 1e-12, tt, np.expm1(b * tt) / np.where(b == 0, 1.0, b))
        return np.asarray(draws[:, :1] + draws[:, 1:2] * g, dtype=np.float64)


def _crossing(model: str, draws: FloatArray, reach: FloatArray | float, sign: float,
              last: float) -> FloatArray:
    """Where each drawn path reaches ``reach`` (towards the threshold), after
    the last test; inf: never. [test (or d, h)]"""
    with np.errstate(all="ignore"):
        if model == "linear":
            a, b = draws[:, 0], draws[:, 1]
            cross = (sign * reach - a) / b - last
            ok = sign * b > 0
        else:   # from the last test: (exp(b·t) − 1)/b = q, t = q·ln(1 + b·q)/(b·q)
            level, slope, b = draws[:, 0], draws[:, 1], draws[:, 2]
            q = (reach - level) / slope
            z = b * q
            factor = np.where(np.abs(z) < 1e-9, 1.0, np.log1p(np.maximum(z, -1.0)) / z)
            cross = np.where(level >= reach, 0.0, q * factor)
            ok = (level >= reach) | ((slope > 0) & (z > -1.0))
    return np.asarray(np.where(ok, np.maximum(cross, 0.0), np.inf), dtype=np.float64)


_BLOCK = 32           # future checks looked at a time
_MAX_BLOCKS = 64      # past this many blocks, the first check after the path's crossing
_FAR = 8.0            # a check whose path is this many of its sd short cannot pass (P < 1e-15)


def _left(model: str, draw: Callable[[np.random.Generator, int], FloatArray], scale: float,
          var1: float, threshold: float, last: float, rng: np.random.Generator,
          size: int, step: float | None = None) -> FloatArray:
    """Draws of the tests (days, hours) left until a check measures ``threshold``;
    inf: never.

    With ``step`` (the spacing of future checks), the first future check
    whose measured change passes the threshold: the drawn path at each
    check plus that check's own scatter (the fit's residual scale at a
    typical weight, ``var1`` the typical ``1/w``), so a whole number of
    steps. Without it, the path's crossing less one check's scatter."""
    sign = 1.0 if threshold > 0 else -1.0
    if size == 0:
        return np.empty(0)
    draws = draw(rng, size)
    sd = math.sqrt(scale * var1)
    if step is None:
        return _crossing(model, draws, abs(threshold) - rng.normal(0.0, sd, size), sign, last)
    cross = _crossing(model, draws, abs(threshold), sign, last)
    out = np.full(size, np.inf)
    todo = np.flatnonzero(np.isfinite(cross))
    if todo.size == 0:
        return out
    # each path only rises towards the threshold: a check cannot pass while the path
    # is _FAR of its scatter short, so each draw's search starts where it comes near
    near = _crossing(model, draws[todo], abs(threshold) - _FAR * sd, sign, last)
    first = np.maximum(np.ceil(np.where(np.isfinite(near), near, 0.0) / step), 1.0)
    ahead = np.arange(_BLOCK, dtype=np.float64)
    for block in range(_MAX_BLOCKS):
        if todo.size == 0:
            break
        k = first[:, None] + (block * _BLOCK + ahead)[None, :]
        seen = _level(model, draws[todo], k * step, last, sign) + rng.normal(
            0.0, sd, (todo.size, _BLOCK))
        hit = seen >= abs(threshold)
        at = np.argmax(hit, axis=1)
        got = hit[np.arange(todo.size), at]
        out[todo[got]] = k[np.arange(todo.size), at][got] * step
        todo, first = todo[~got], first[~got]
    # past the limit: the first check at or after the path's crossing
    out[todo] = np.ceil(cross[todo] / step) * step
    return out


def median_interval(left: FloatArray, whole: bool) -> tuple[float, float, float]:
    """The median and the 90 % interval of drawn tests (days, hours) left.

    The order statistics themselves: a draw that never crosses is inf, not
    interpolated. In whole checks (``whole``) the interval's ends are the
    mid-p quantiles (Lancaster's mid-p: a value counts half towards the tail
    it ends): the 5 % and 95 % quantiles of a few whole checks hold far more
    than 90 % (97-98 % with 3-7 checks left), a mid-p interval holds close to
    90 % on average, more or less for one forecast."""
    med = float(np.quantile(left, 0.5, method="inverted_cdf"))
    if not whole:
        lo, hi = np.quantile(left, [0.05, 0.95], method="inverted_cdf")
        return med, float(lo), float(hi)
    values, counts = np.unique(left, return_counts=True)
    p = counts / left.size
    below = np.cumsum(p) - 0.5 * p             # P(K < v) + P(K = v) / 2
    above = 1.0 - np.cumsum(p) + 0.5 * p       # P(K > v) + P(K = v) / 2
    # (both at least 0.5 at the far end: an end is always found)
    lo = values[int(np.searchsorted(below, 0.05))]
    hi = values[int(np.flatnonzero(above >= 0.05)[-1])]
    return med, float(lo), float(hi)


def _slope(fit: Fit, kind: str, scale: float, xa: FloatArray, ya: FloatArray, w: FloatArray,
           sign: float) -> tuple[float, tuple[float, float]]:
    """A fit's slope at the last test, towards the threshold for the
    exponential's, and its 90 % interval as a trend test takes it
    (:func:`~condmon.forecast.degradation.trend_sd`). [% per x]"""
    coef, cov, _ = fit
    slope = float(coef[1])
    if kind == "exponential":   # β at the last test, towards the threshold
        slope *= sign
    last = float(xa[-1])
    fitted = _level(kind, np.asarray(coef, dtype=np.float64)[None, :], xa - last, last, sign)[0]
    sd = trend_sd(math.sqrt(max(cov[1, 1], 0.0)), (sign * ya - fitted) * np.sqrt(w), scale)
    return slope, (slope - Z90 * sd, slope + Z90 * sd)


def _scale(fit: Fit, n: int) -> float:
    """A fit's residual variance factor (:func:`residual_scale`)."""
    return residual_scale(fit[2], max(n - len(fit[0]), 1))


def _with_shape(prior: FleetPrior, found: dict[str, Fit], xa: FloatArray, ya: FloatArray,
                w: FloatArray, weight: dict[str, float]
                ) -> tuple[dict[str, float], dict[str, RatePosterior], str]:
    """The models' weights under the fleet's shape prior, the posteriors the
    forecast draws from in place of a model's normal fit (none: no rate
    prior), and the note on how they were weighed.

    With the fleet's priors on every coefficient of both shapes (the line's
    slope and bend, the exponential's rate and amplitude), the exponential's
    weight is its posterior probability: the fleet's odds times the Bayes
    factor of the unit's tests between the fleet's line and the fleet's
    curve (:func:`~condmon.forecast.degradation.fleet_posteriors`), and both
    are drawn from their posteriors: a unit whose start looks straight but
    far slower than the peers' lines is weighed against their curve too.
    With the growth rate alone, the factor is against the line with a flat
    slope (:func:`~condmon.forecast.degradation.rate_posterior`). Without it,
    the Akaike weights times the fleet's odds (Burnham and Anderson's prior
    model probabilities)."""
    p = prior.p_exponential
    if prior.exponential.informative:
        pieces = (prior.bend, prior.start, prior.amplitude)
        known = [q for q in pieces if q is not None and q.informative]
        if prior.linear.informative and len(known) == len(pieces):
            bend, start, amp = known
            both = fleet_posteriors(xa, ya, w, (bend.mean, bend.sd), (start.mean, start.sd),
                                    (prior.exponential.mean, prior.exponential.sd),
                                    (amp.mean, amp.sd))
            posts = {"linear": both.linear, "exponential": both.exponential}
            against = " against the fleet's line"
        else:
            posts = {"exponential": rate_posterior(xa, ya, w, prior.exponential.mean,
                                                   prior.exponential.sd)}
            against = ""
        log_bayes = posts["exponential"].log_bayes
        odds = math.log(p / (1.0 - p)) + log_bayes
        w_exp = 1.0 / (1.0 + math.exp(-odds)) if odds > -700 else 0.0
        return ({"linear": 1.0 - w_exp, "exponential": w_exp}, posts,
                f"Bayes factor {math.exp(min(log_bayes, 700.0)):.3g} of the unit's tests"
                + against)
    if "exponential" not in found:
        return weight, {}, "no growing exponential fits the unit's tests"
    raw = {"linear": (1.0 - p) * weight["linear"], "exponential": p * weight["exponential"]}
    return ({k: v / sum(raw.values()) for k, v in raw.items()}, {},
            "Akaike weights of the unit's tests")


def forecast_series(x: ArrayLike, change: ArrayLike, se: ArrayLike,
                    spread: float, threshold: float, horizon: float | None = None,
                    seed: int = 0, *, prior: Prior | None = None,
                    step: float | None = None, unreachable: str | None = None) -> Forecast:
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
    step : float, optional
        The spacing of the checks to come: the forecast is then of the first
        check that measures past the threshold (its own scatter drawn), a
        whole number of steps. None: the path's crossing, less one check's
        scatter. [test (or d, h)]
    prior : RatePrior or FleetPrior, optional
        The fleet's prior, in the units of ``x``. A :class:`RatePrior`
        (:func:`fleet_prior`): its model's rate is updated by the unit's tests
        (the models still weighted by the unit's evidence). A
        :class:`FleetPrior` (:func:`fleet_wear_prior`): the shape as well:
        each model's rate updated by the unit's tests (the exponential's
        growth rate by its exact posterior on a grid), and the models weighted
        by the fleet's odds times the unit's evidence. A note names it. None:
        the unit's own tests alone, no note.
    unreachable : str, optional
        Why a check cannot turn no-go this way (a fall past the parameter's
        plausible values; no rule names the symptom alone): a series that
        moves towards the threshold is then "no trend", with it as a note.

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
    >>> f = forecast_series(x, 4.0 * x, np.full(15, 1.0), 2.0, threshold=98.0, step=1.0)
    >>> f.remaining                 # 98 % at test 24.5: the check of test 25 turns no-go
    (10.0, 10.0, 10.0)

    Four tests of a unit whose fleet wore +4.0 ± 0.2 % a test:

    >>> f = forecast_series(x[:4], 4.0 * x[:4] + [2.0, -2.0, 2.0, -2.0], np.full(4, 1.0), 2.0,
    ...                     threshold=100.0, prior=RatePrior("linear", 4.0, 0.2, 12))
    >>> round(f.remaining[0]), f.notes[-1]
    (21, 'fleet prior (linear) from 12 units: slope 4 ± 0.2 %/test')
    """
    xa, ya, sa = checked_series(x, change, se, spread)
    checked_horizon(horizon)
    if threshold == 0:
        raise DataError("forecast: the no-go threshold is 0 %")
    sign = 1.0 if threshold > 0 else -1.0
    shaped = isinstance(prior, FleetPrior) and prior.informative
    # with the fleet's growth rate the exponential is its exact posterior, not the fit alone
    fits = degradation_fits(xa, ya, sa, spread, sign, exponential=not (
        shaped and isinstance(prior, FleetPrior) and prior.exponential.informative))
    notes: list[str] = []
    n = len(xa)
    w = weights(sa, spread)
    aic, weight = aicc_weights(fits, n) if len(fits) > 1 else ({}, {"linear": 1.0})
    own, own_model = dict(fits), max(weight, key=lambda k: weight[k])   # the unit's alone
    posts: dict[str, RatePosterior] = {}
    straight: Fit | None = None   # the line's own fit, for "no trend", when a posterior bends it
    if shaped and isinstance(prior, FleetPrior):
        weight, posts, how = _with_shape(prior, fits, xa, sign * ya, w, weight)
        if prior.linear.informative:
            fits["linear"] = updated(fits["linear"], prior.linear)
        straight = fits["linear"]
        for m, post in posts.items():   # (α, β, b) from the last test, towards the threshold
            fits[m] = (*post.moments(), 0.0)
        model = max(weight, key=lambda k: weight[k])
        if len(weight) > 1:
            notes.append(f"{model} chosen by the fleet's shape and the unit's evidence "
                         f"(P(exponential) {prior.p_exponential:.2f} from the fleet, "
                         f"{weight['exponential']:.2f} with the {how}); the forecast "
                         f"averages both, weighted {weight['linear']:.2f} and "
                         f"{weight['exponential']:.2f}")
        notes.append(prior.describe())
    else:
        model = max(weight, key=lambda k: weight[k])
        if len(fits) > 1:
            notes.append(f"{model} chosen by evidence (AICc {aic['linear']:.1f} linear, "
                         f"{aic['exponential']:.1f} exponential); the forecast averages both, "
                         f"weighted {weight['linear']:.2f} and {weight['exponential']:.2f}")
        if isinstance(prior, RatePrior):
            if prior.model in fits or not prior.informative:
                if prior.model in fits:
                    fits[prior.model] = updated(fits[prior.model], prior)
                notes.append(prior.describe())
            else:
                notes.append(f"{prior.describe()} not used: no growing {prior.model} "
                             "fits the series")
        elif prior is not None:
            notes.append(prior.describe())
    last = float(xa[-1])
    def kind(m: str) -> str:        # a posterior's (α, β, b) are drawn as the exponential's
        return "exponential" if m in posts else m

    def scale(m: str) -> float:
        return posts[m].scale if m in posts else _scale(fits[m], n)

    def heads(iv: tuple[float, float]) -> bool:   # clear of 0, on the threshold's side
        return iv[0] > 0 if sign > 0 else iv[1] < 0

    slope, interval = _slope(fits[model], kind(model), scale(model), xa, ya, w, sign)
    towards = heads(interval)
    # the fleet's wear is a unit's only once its own checks move: peers that
    # degraded do not make a healthy unit's trend
    mine = (_slope(own[own_model], own_model, _scale(own[own_model], n), xa, ya, w, sign)[1]
            if own[own_model] is not fits[own_model] or model in posts else interval)
    if not towards or not heads(mine):
        notes.append(f"the slope's 90 % interval [{interval[0]:.3g}, {interval[1]:.3g}] "
                     "holds no steady move towards the threshold" if not towards else
                     f"the unit's own checks hold no steady move towards the threshold "
                     f"(their slope's 90 % interval [{mine[0]:.3g}, {mine[1]:.3g}]): the "
                     "fleet's wear is not taken as a trend of this unit's")
        towards = False
        unreachable = None   # no move: which way it cannot come is noise
    elif unreachable:   # a move towards a no-go that cannot come
        notes.append(unreachable)
    if unreachable or not towards:
        return Forecast("no trend", threshold, slope, interval, None,
                        0.0 if horizon is not None else None, n, tuple(notes),
                        *_fitted(straight or fits["linear"]), last, unreachable or "")
    if sign * ya[-1] >= abs(threshold):   # already there: no draw of when
        notes.append("the last check measured past the no-go change: at no-go now")
        return Forecast(model, threshold, slope, interval, (0.0, 0.0, 0.0),
                        1.0 if horizon is not None else None, n, tuple(notes),
                        *_fitted(fits[model]), last, at_nogo=True)
    # each model's draws in proportion to its evidence weight (model averaging);
    # a posterior's draws are (α, β, b) from the last test, drawn as the exponential's
    rng = np.random.default_rng(seed)
    lefts = [_left(kind(m), posts[m].draws if m in posts else _normal_draws(fits[m]), scale(m),
                   float(np.median(1.0 / w)), threshold, last, rng, round(_DRAWS * weight[m]),
                   step)
             for m in sorted(weight)]
    left = np.concatenate(lefts)
    med, lo, hi = median_interval(left, whole=step is not None)
    p = float(np.mean(left <= horizon)) if horizon is not None else None
    return Forecast(model, threshold, slope, interval, (med, lo, hi), p, n, tuple(notes),
                    *_fitted(fits[model]), last)
