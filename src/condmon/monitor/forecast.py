"""When will it turn no-go? A degradation model of one parameter's change series.

The series is a parameter's change against its unit's baseline, test after test
[%]. Each test is weighted by its own uncertainty and the baseline's spread
(``w = 1 / (se² + sd²)``, both in % of the baseline mean): a test whose estimate
is poor, or a parameter whose healthy scatter is wide, counts less.

Two degradation models are fitted by weighted least squares and chosen by
evidence (Akaike's criterion on the same weighted residuals):

- **linear**: ``change = a + b·x``;
- **exponential**: ``|change| = exp(a + b·x)`` (linear in log-change; only
  where the series keeps one sign, as a wear that feeds itself).

``x`` is the test number (or the days since the first test, or operating
hours). The forecast is the crossing of the no-go change (``r2`` of the
parameter's breakpoints, in the trend's direction): its predictive distribution
comes from the fitted coefficients' covariance (4,000 draws, a fixed seed),
given as a median and a 90 % interval of the tests (or days) left, and the
probability of crossing within a horizon. A slope whose 90 % interval holds 0,
or points away from the threshold, is "no trend": then no number of tests is
given.

Why by hand: a weighted two-model fit with a crossing distribution is a few
lines of numpy, and the prognostics libraries (ProgPy, the Predictive
Maintenance Toolbox) fit their own degradation shapes to run-to-failure
ensembles, not a change series with its own per-test uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import DataError

__all__ = ["Forecast", "forecast_series", "MIN_TESTS"]

FloatArray = NDArray[np.float64]

#: Fewest checks since the baseline that a forecast needs.
MIN_TESTS = 3
_DRAWS = 4000
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
        The chosen model's fitted coefficients ``(a, b)``: ``change = a + b·x``
        (linear) or ``|change| = exp(a + b·x)`` (exponential; the linear fit's
        for "no trend"). [%, % per x (linear); -, 1 per x (exponential)]
    cov : tuple of float
        Their covariance ``(var a, cov ab, var b)``.
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
    coef: tuple[float, float] = (math.nan, math.nan)
    cov: tuple[float, float, float] = (math.nan, math.nan, math.nan)
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
        x = self.last + np.asarray(ahead, dtype=np.float64)
        a, b = self.coef
        var_a, cov_ab, var_b = self.cov
        mid = a + b * x
        half = _Z90 * np.sqrt(np.maximum(var_a + 2.0 * x * cov_ab + x * x * var_b, 0.0))
        if self.model != "exponential":
            return mid, mid - half, mid + half
        sign = 1.0 if self.threshold > 0 else -1.0
        ends = sign * np.exp(mid - half), sign * np.exp(mid + half)
        return sign * np.exp(mid), np.minimum(*ends), np.maximum(*ends)

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


def forecast_series(x: ArrayLike, change: ArrayLike, se: ArrayLike,
                    spread: float, threshold: float, horizon: float | None = None,
                    seed: int = 0) -> Forecast:
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
    """
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
    if horizon is not None and not horizon > 0:
        raise DataError(f"horizon must be > 0, not {horizon:g}")
    if threshold == 0:
        raise DataError("forecast: the no-go threshold is 0 %")
    w = 1.0 / (sa ** 2 + spread ** 2 + 1e-12)
    sign = 1.0 if threshold > 0 else -1.0
    fits: dict[str, tuple[FloatArray, FloatArray, float]] = {"linear": _wls(xa, ya, w)}
    notes: list[str] = []
    toward = sign * ya
    if np.all(toward > 0):
        # log-change: the weight of log|y| is y² w (delta method)
        coef, cov, _ = _wls(xa, np.log(toward), w * toward ** 2)
        resid = (toward - np.exp(coef[0] + coef[1] * xa)) * np.sqrt(w)
        fits["exponential"] = (coef, cov, float(resid @ resid))
    n = len(xa)
    aic = {k: n * math.log(max(v[2], 1e-300) / n) + 4.0 for k, v in fits.items()}
    model = min(aic, key=lambda k: aic[k])
    if len(fits) > 1:
        notes.append(f"{model} chosen by evidence (AIC {aic['linear']:.1f} linear, "
                     f"{aic['exponential']:.1f} exponential)")
    coef, cov, _ = fits[model]
    last = float(xa[-1])
    fit = (float(coef[0]), float(coef[1]))
    fit_cov = (float(cov[0, 0]), float(cov[0, 1]), float(cov[1, 1]))
    sd_b = math.sqrt(max(cov[1, 1], 0.0))
    if model == "linear":
        slope, slope_sd = float(coef[1]), sd_b
    else:  # d|y|/dx at the last test
        level = math.exp(coef[0] + coef[1] * last)
        slope, slope_sd = sign * coef[1] * level, abs(level) * sd_b
    interval = (slope - _Z90 * slope_sd, slope + _Z90 * slope_sd)
    towards = interval[0] > 0 if sign > 0 else interval[1] < 0
    if not towards:   # 0, or the wrong direction, inside the interval
        notes.append(f"the slope's 90 % interval [{interval[0]:.3g}, {interval[1]:.3g}] "
                     "holds no steady move towards the threshold")
        return Forecast("no trend", threshold, slope, interval, None,
                        0.0 if horizon is not None else None, n, tuple(notes), fit, fit_cov,
                        last)
    draws = np.random.default_rng(seed).multivariate_normal(coef, cov, size=_DRAWS,
                                                            method="cholesky")
    a, b = draws[:, 0], draws[:, 1]
    with np.errstate(all="ignore"):
        if model == "linear":
            cross = (threshold - a) / b
            ok = sign * b > 0
        else:
            cross = (math.log(abs(threshold)) - a) / b
            ok = b > 0
    left = np.where(ok, np.maximum(cross - last, 0.0), np.inf)
    # the order statistics themselves: a draw that never crosses is inf, not interpolated
    med, lo, hi = (float(v) for v in np.quantile(left, [0.5, 0.05, 0.95], method="inverted_cdf"))
    p = float(np.mean(left <= horizon)) if horizon is not None else None
    return Forecast(model, threshold, slope, interval, (med, lo, hi), p, n, tuple(notes),
                    fit, fit_cov, last)
