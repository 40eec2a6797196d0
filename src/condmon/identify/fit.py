"""Model assessment: coefficient of determination R_T² on the simulation residual."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from condmon.identify.defaults import DEFAULT_FIT_THRESHOLD
from condmon.models.transfer import DiscreteTF

__all__ = ["FitCheck", "fit_check", "DEFAULT_FIT_THRESHOLD", "ResidualFigures",
           "residual_figures"]


@dataclass(frozen=True)
class FitCheck:
    """Goodness of fit of a model to one record.

    Attributes
    ----------
    r2 : dict of str to float
        R_T² = 1 - var(e)/var(y) per output, e = y - model simulated from the
        measured input (output error). [-]
    fit_percent : float
        Mean of ``r2`` over outputs x 100. [%]
    threshold : float
        Acceptance threshold. [%]
    accepted : bool
        ``fit_percent >= threshold``.
    """

    r2: dict[str, float]
    fit_percent: float
    threshold: float
    accepted: bool

    @property
    def fits_percent(self) -> dict[str, float]:
        """R_T² per output x 100. [%]"""
        return {k: 100.0 * v for k, v in self.r2.items()}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {"fit_percent": self.fit_percent, "fits": self.fits_percent,
                "threshold": self.threshold, "accepted": self.accepted}


def fit_check(model: DiscreteTF, u: ArrayLike, y: ArrayLike,
              threshold: float = DEFAULT_FIT_THRESHOLD, skip: int = 0) -> FitCheck:
    """Coefficient of determination of each output (SPEC A4) and the accept test.

    Parameters
    ----------
    model : DiscreteTF
        Estimated model.
    u : array_like, shape (N,)
        Measured input. [input unit]
    y : array_like, shape (N, m)
        Measured outputs, in the order of ``model.outputs``.
    threshold : float
        Reject below this percentage fit. [%]
    skip : int
        Initial samples left out (initial-condition transient).

    Returns
    -------
    FitCheck
        An unstable or diverging model gets R_T² = -inf and is rejected, never NaN.

    Example
    -------
    >>> g = DiscreteTF(np.array([1.0, -0.5]), np.array([[0.0, 1.0]]), 1e-3, ("y",))
    >>> u = np.random.default_rng(0).standard_normal(500)
    >>> fit_check(g, u, g.simulate(u)).fit_percent
    100.0
    """
    u_a = np.asarray(u, dtype=np.float64)
    y_a = np.asarray(y, dtype=np.float64)
    if y_a.ndim == 1:
        y_a = y_a[:, None]
    if np.any(np.abs(model.poles()) >= 1.0):
        r2 = {name: float("-inf") for name in model.outputs}
    else:
        with np.errstate(all="ignore"):
            e = (y_a - model.simulate(u_a))[skip:]
            var_y = np.var(y_a[skip:], axis=0)
            var_e = np.var(e, axis=0)
        r2 = {}
        for j, name in enumerate(model.outputs):
            if not np.isfinite(var_e[j]):
                r2[name] = float("-inf")
            elif var_y[j] == 0.0:
                r2[name] = 1.0 if var_e[j] == 0.0 else float("-inf")
            else:
                r2[name] = float(1.0 - var_e[j] / var_y[j])
    fit = 100.0 * float(np.mean(list(r2.values())))
    return FitCheck(r2, fit, float(threshold), bool(fit >= threshold))


@dataclass(frozen=True)
class ResidualFigures:
    """Figures of one signal's residual.

    Attributes
    ----------
    r2 : float
        ``1 - var(e)/var(measured)`` (-inf when the measured signal is constant). [-]
    nrmse : float
        RMS of the error / RMS of the measured signal (inf when that is 0). [-]
    whiteness : float
        Largest normalised autocorrelation of the error at lags 1..20
        (0 for white noise, near 1 for a slowly varying misfit). [-]
    """

    r2: float
    nrmse: float
    whiteness: float


def residual_figures(measured: ArrayLike, error: ArrayLike, lags: int = 20) -> ResidualFigures:
    """R_T², normalised RMS error and residual whiteness of one signal.

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> y = np.sin(np.linspace(0, 20, 2000))
    >>> f = residual_figures(y, 0.01 * rng.standard_normal(2000))
    >>> round(f.r2, 3), f.whiteness < 0.1
    (1.0, True)
    """
    y = np.asarray(measured, dtype=np.float64)
    e = np.asarray(error, dtype=np.float64)
    if not y.size:
        return ResidualFigures(float("-inf"), float("inf"), 0.0)
    # the variances and mean squares as dot products of the centred signals
    # (np.var's two passes, without its per-call cost: this runs per estimate)
    size = y.size
    yc = y - float(np.sum(y)) / size
    c = e - float(np.sum(e)) / size
    denom = float(c @ c)
    var_y = float(yc @ yc) / size
    r2 = 1.0 - denom / size / var_y if var_y > 0 else float("-inf")
    rms = math.sqrt(float(y @ y) / size)
    nrmse = math.sqrt(float(e @ e) / size) / rms if rms > 0 else float("inf")
    white = 0.0
    if denom > 0 and c.size > lags:
        # Σ_t c[t] c[t-k], k = 1..lags: the rows t - k < N - lags in one
        # correlation, the last lags rows' few terms in another
        n = c.size
        r = np.correlate(c, c[: n - lags], "valid")[1:]
        r[:-1] += np.correlate(c[n - lags:], c[n - lags:], "full")[lags: 2 * lags - 1]
        white = float(np.max(np.abs(r))) / denom
    return ResidualFigures(r2, nrmse, white)
