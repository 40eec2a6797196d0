"""Remaining life of a degradation series modelled as a Wiener process with drift.

A health indicator that wanders about its trend (a battery's capacity with its
recoveries after rests, a friction that moves with the oil's temperature) is
not a line with independent scatter: each step adds to the next. The Wiener
process with drift is the usual model of such a path (Si, Wang, Hu and Zhou,
"Remaining useful life estimation – a review on the statistical data driven
approaches", Eur. J. Oper. Res. 213 (2011), section 3.1; Whitmore 1995):

    y(t) = y(t₀) + μ (t − t₀) + σ B(t − t₀)

Its first passage of a level ``w`` at distance ``d`` ahead has a known law:
the inverse Gaussian with mean ``d/μ`` and shape ``d²/σ²`` (a drift away from
the level crosses with probability ``exp(−2|μ|d/σ²)``, or never). Readings scatter about the path too (a measurement error
σε): it makes neighbouring increments anti-correlated, which tells it from
the diffusion (Ye, Wang, Tsui and Pecht, "Degradation data analysis using
Wiener processes with measurement errors", IEEE Trans. Reliab. 62 (2013)).
The drift, diffusion and error come from the path's own increments (by
moments), the level now from the Kalman filter of the path, and their
uncertainty is carried into the forecast by drawing them (μ normal about its
estimate, σ² scaled inverse χ², the level about its filtered value) before
each first passage is drawn: a short series gives a wide interval, never a
confident wrong one.

Nothing is fitted to a data set: the model has no setting.

Why by hand: scipy has the inverse Gaussian (and numpy its ``wald`` draws),
but no library fits a Wiener degradation path and forecasts its first
passage; this is that, in a few lines over them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from condmon.errors import DataError

__all__ = ["WienerForecast", "wiener_forecast"]

#: Draws of the parameters and first passages.
DRAWS = 4000


@dataclass(frozen=True)
class WienerForecast:
    """The first passage of a level by a Wiener path with drift.

    Attributes
    ----------
    drift : float
        Estimated drift μ. [indicator units per x]
    diffusion : float
        Estimated diffusion σ (the increments' spread per √x). [indicator units per √x]
    noise : float
        Estimated measurement error σε (a reading's scatter about the path). [indicator units]
    remaining : tuple of float
        From the last point to the first passage: median, then the 90 %
        interval (5 % and 95 % points; inf where a draw never crosses). [x]
    p_never : float
        Share of the draws that never cross (a drift away from the level). [-]
    n : int
        Points used.
    """

    drift: float
    diffusion: float
    noise: float
    remaining: tuple[float, float, float]
    p_never: float
    n: int


def wiener_forecast(x: ArrayLike, y: ArrayLike, level: float, seed: int = 0
                    ) -> WienerForecast:
    """Forecast when the series ``y`` (at ``x``) first passes ``level``.

    Parameters
    ----------
    x : array_like
        Time, cycle or test of each point, increasing. [x]
    y : array_like
        The indicator at each point. [indicator units]
    level : float
        The end-of-life level (below the last point for a fall, above it for
        a rise). [indicator units]
    seed : int
        Seed of the draws.

    Returns
    -------
    WienerForecast

    Raises
    ------
    DataError
        Fewer than 4 points, non-finite values, ``x`` not increasing, or the
        last point at or past the level.

    Example
    -------
    A capacity falling 0.005 Ah a cycle with a random walk of 0.01 Ah a cycle,
    from 1.85 Ah, 30 cycles in; the level 1.4 Ah lies about 60 cycles ahead:

    >>> rng = np.random.default_rng(1)
    >>> x = np.arange(31.0)
    >>> y = 1.85 - 0.005 * x + np.concatenate([[0.0], np.cumsum(rng.normal(0, 0.01, 30))])
    >>> f = wiener_forecast(x, y, 1.4)
    >>> 40 < f.remaining[0] < 110, f.remaining[1] < f.remaining[0] < f.remaining[2]
    (True, True)
    """
    xa = np.asarray(x, dtype=np.float64).ravel()
    ya = np.asarray(y, dtype=np.float64).ravel()
    if xa.size != ya.size or xa.size < 4:
        raise DataError(f"forecast: a Wiener path needs 4 points or more of x and y, "
                        f"got {xa.size} and {ya.size}")
    if not (np.all(np.isfinite(xa)) and np.all(np.isfinite(ya)) and np.isfinite(level)):
        raise DataError("forecast: the series or the level is not finite")
    dt = np.diff(xa)
    if np.any(dt <= 0):
        raise DataError("forecast: x must increase")
    sign = 1.0 if level > ya[0] else -1.0
    if sign * (level - ya[-1]) <= 0:
        raise DataError("forecast: the last point is at or past the level")
    dy = np.diff(ya)
    span = xa[-1] - xa[0]
    mu = (ya[-1] - ya[0]) / span                         # the drift, unbiased
    r = dy - mu * dt
    m = r.size
    # The diffusion is the increments' long-run variance (Newey-West, Bartlett
    # kernel, the usual bandwidth 4(m/100)^(2/9)): what no longer cancels over
    # many steps. Readings that scatter about the path, or recover for a few
    # steps and fall back, add to each increment's variance but cancel in the
    # long run; that short-run excess is their error, σε² = (γ0 - LRV)/2, with
    # white measurement error the one-lag case of Ye, Wang, Tsui and Pecht (2013).
    gamma0 = float(np.mean(r ** 2))
    lags = int(np.floor(4.0 * (m / 100.0) ** (2.0 / 9.0)))
    lrv = gamma0 + 2.0 * sum((1.0 - j / (lags + 1)) * float(np.mean(r[:-j] * r[j:]))
                             for j in range(1, min(lags, m - 1) + 1))
    lrv = max(lrv, 1e-12 * gamma0 + 1e-300)
    noise2 = max(0.0, (gamma0 - lrv) / 2.0)
    s2 = lrv / float(np.mean(dt))
    level_now, level_var = _filtered_level(xa, ya, mu, s2, noise2)
    rng = np.random.default_rng(seed)
    # the parameters' uncertainty: σ² ~ (m-1)·s²/χ²(m-1), μ ~ N(μ̂, its variance)
    sig2 = (m - 1) * s2 / rng.chisquare(max(m - 1, 1), DRAWS)
    drift = sign * rng.normal(mu, np.sqrt((sig2 * span + 2.0 * noise2) / span ** 2))
    start = rng.normal(level_now, np.sqrt(level_var), DRAWS)   # where the path is now
    distance_d = np.maximum(sign * (level - start), 0.0)
    towards = np.abs(drift)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        crosses = (drift > 0) | (rng.random(DRAWS) < np.exp(-2.0 * towards * distance_d / sig2))
        mean = np.where(distance_d > 0, distance_d / np.maximum(towards, 1e-300), 1.0)
        shape = np.where(distance_d > 0, distance_d ** 2 / sig2, 1.0)
    passage = np.where(distance_d <= 0, 0.0,
                       np.where(crosses, rng.wald(np.minimum(mean, 1e300), shape), np.inf))
    # quantiles of the draws themselves (no interpolation towards a never: inf)
    q = [float(np.quantile(passage, p, method="inverted_cdf")) for p in (0.5, 0.05, 0.95)]
    return WienerForecast(float(mu), float(np.sqrt(s2)), float(np.sqrt(noise2)),
                          (q[0], q[1], q[2]), float(np.mean(~crosses)), int(xa.size))


def _filtered_level(x: np.ndarray, y: np.ndarray, mu: float, s2: float, noise2: float
                    ) -> tuple[float, float]:
    """The path's level at the last point and its variance, by the Kalman filter
    of the local level with drift (random-walk state, white measurement error):
    a last point lifted by a recovery is not taken for the path."""
    mean, var = y[0], noise2
    for k in range(1, y.size):
        mean, var = mean + mu * (x[k] - x[k - 1]), var + s2 * (x[k] - x[k - 1])
        if noise2 > 0:
            gain = var / (var + noise2)
            mean, var = mean + gain * (y[k] - mean), (1.0 - gain) * var
        else:
            mean, var = y[k], 0.0
    return float(mean), float(max(var, 0.0))
