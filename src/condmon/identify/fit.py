"""Model assessment: coefficient of determination R_T² on the simulation residual."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.models.transfer import DiscreteTF

__all__ = ["FitCheck", "fit_check", "DEFAULT_FIT_THRESHOLD"]

DEFAULT_FIT_THRESHOLD = 90.0
"""Default acceptance threshold on the percentage fit. [%]"""


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
