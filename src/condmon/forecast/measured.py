"""A change series forecast as a measured degradation path, and what each
forecast method's interval covered on data with known ends.

:func:`forecast_path` is :func:`~condmon.forecast.series.forecast_series`'s
counterpart for the "path" method (:mod:`condmon.forecast.path`): the same
arguments, the same :class:`~condmon.forecast.series.Forecast`, the same
"no trend" and "at no-go now" answers, so a unit's forecast, its page and
``condmon forecast`` read either alike. :func:`coverage_note` states, with
every forecast, how often its method's 90 % interval held the truth where
the truth is known (``data/coverage.toml``: real run-to-failure series and
simulated fleets, each with its source).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from functools import cache
from importlib import resources
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from condmon.errors import DataError
from condmon.forecast.calibration import MIN_PEERS, Calibration
from condmon.forecast.path import (
    PATH_MIN_TESTS, Z90, drawn_rate, fit_path, path_remaining, with_fleet,
)
from condmon.forecast.series import (
    Forecast, Prior, checked_horizon, forecast_series, median_interval,
)
from condmon.forecast.similar import fleet_left, lives_left, mixed

__all__ = ["METHODS", "forecast_path", "forecast_by", "coverage_note", "measured_coverage",
           "real_coverage"]

#: The forecast methods: "trend" (a line or an exponential, chosen by
#: evidence, with the fleet's priors) and "path" (a measured degradation path).
METHODS = ("trend", "path")


@cache
def measured_coverage() -> dict[str, Any]:
    """``data/coverage.toml``: each method's measured 90 % interval coverage.

    Example
    -------
    >>> sorted(measured_coverage())
    ['path', 'trend']
    """
    text = resources.files("condmon.data").joinpath("coverage.toml").read_text("utf-8")
    return tomllib.loads(text)


def coverage_note(method: str, recalibrated: bool = False, caveat: bool = True) -> str:
    """How often ``method``'s 90 % interval held the truth, where measured
    (``recalibrated``: read at its fleet's levels; ``caveat``: say that a
    fleet of failed units would be read, when it is not).

    Example
    -------
    >>> coverage_note("path").startswith("its 90 % interval held the true remaining life")
    True
    """
    found = measured_coverage().get(method, {})
    parts = [f"{100 * v['coverage']:.0f} % of {v['forecasts']} forecasts on {v['data']}"
             for v in found.values() if bool(v.get("recalibrated", False)) == recalibrated]
    if not parts:
        return ""
    # measured on one fleet: a unit of another kind may wear otherwise
    said = ("" if recalibrated or method != "path" or not caveat else
            f"; measured there, not on units like this one: with {MIN_PEERS} failed units "
            "of this model or more in the history, the forecast is read at the levels "
            "their lives call for")
    return "its 90 % interval held the true remaining life in " + "; ".join(parts) + said


def real_coverage(method: str) -> str:
    """How often ``method``'s 90 % interval held the truth on real data
    (``real = true`` in ``data/coverage.toml``), in a few words; empty:
    not measured there.

    Example
    -------
    >>> real_coverage("trend")
    "23 % of 62 forecasts on NASA's Li-ion cells"
    """
    real = [v for v in measured_coverage().get(method, {}).values()
            if v.get("real") and not v.get("recalibrated", False)]
    return "" if not real else (f"{100 * real[0]['coverage']:.0f} % of {real[0]['forecasts']} "
                                f"forecasts on {str(real[0]['data']).split(' (')[0]}")


def forecast_path(x: ArrayLike, change: ArrayLike, se: ArrayLike, spread: float,
                  threshold: float, horizon: float | None = None, seed: int = 0, *,
                  prior: Prior | None = None, step: float | None = None,
                  unreachable: str | None = None,
                  calibration: Calibration | None = None, per: str = "x") -> Forecast:
    """Forecast when a change series crosses ``threshold``, as a measured path.

    The arguments are :func:`~condmon.forecast.series.forecast_series`'s.
    The path's deviations and wandering rate come from the series itself,
    so ``se`` and ``spread`` serve only a series too short for a path
    (fewer than :data:`~condmon.forecast.path.PATH_MIN_TESTS` points: the
    trend method, with a note), and ``step`` is the series' usual spacing
    (the remaining life is the first check at that spacing to measure past
    the threshold). A fleet ``prior`` is not used by this method (a note
    says so). With a ``calibration`` from the fleet's failed units
    (:mod:`condmon.forecast.calibration`) the draws are read at its levels.

    Raises
    ------
    DataError
        Non-finite values, ``x`` not increasing, a horizon <= 0, a 0 threshold.

    Example
    -------
    A capacity's change falling 0.3 % a cycle, with recoveries, 60 cycles in;
    the no-go at −30 % lies about 40 cycles ahead:

    >>> x = np.arange(1.0, 61.0)
    >>> y = -0.3 * x + 0.5 * np.sin(x / 3.0)
    >>> f = forecast_path(x, y, np.zeros(60), 0.5, -30.0)
    >>> f.model, 30 < f.remaining[0] < 50, f.remaining[1] < f.remaining[0] < f.remaining[2]
    ('path', True, True)
    """
    xa = np.asarray(x, dtype=np.float64).ravel()
    ya = np.asarray(change, dtype=np.float64).ravel()
    checked_horizon(horizon)
    if threshold == 0:
        raise DataError("forecast: the no-go threshold is 0 %")
    if xa.size < PATH_MIN_TESTS:
        f = forecast_series(x, change, se, spread, threshold, horizon, seed, prior=prior,
                            step=step, unreachable=unreachable)
        note = (f"{xa.size} checks: too few for a degradation path (it needs "
                f"{PATH_MIN_TESTS}), forecast as a trend")
        said = coverage_note("trend")   # what that interval is worth on measured series
        return dataclasses.replace(f, notes=(note, *f.notes, *([said] if said else [])))
    own = fit_path(xa, ya)
    refused = calibration.refused if calibration is not None else ""
    if refused:
        calibration = None
    fit = own if calibration is None else with_fleet(own, calibration.lives, threshold)
    sign = 1.0 if threshold > 0 else -1.0
    slope = fit.coef[1]
    sd = math.sqrt(max(fit.cov[1][1], 0.0))
    interval = (slope - Z90 * sd, slope + Z90 * sd)
    notes = [f"degradation path: mean rate {slope:.3g} %/{per} over the series (90 % "
             f"interval [{interval[0]:.3g}, {interval[1]:.3g}]; the rate now is drawn about "
             f"it), recoveries fading at φ = "
             f"{fit.phi:.2f} a check, " + (
                 f"the rate wandering {100 * math.sqrt(fit.walk):.2g} % per √{per}"
                 if fit.walk > 0 else "the quarters' rates within their own error (their "
                 "wander drawn from it)")]
    if refused:
        notes.append(refused)
    if prior is not None:
        notes.append("the fleet's prior is not used by the path method")
    towards = interval[0] > 0 if sign > 0 else interval[1] < 0
    coef, cov = fit.summary, fit.cov
    last = float(xa[-1])
    if not towards:
        notes.append(f"the slope's 90 % interval [{interval[0]:.3g}, {interval[1]:.3g}] "
                     "holds no steady move towards the threshold")
        return Forecast("no trend", threshold, slope, interval, None,
                        0.0 if horizon is not None else None, fit.n, tuple(notes),
                        coef, cov, last)
    if unreachable:
        notes.append(unreachable)
        return Forecast("no trend", threshold, slope, interval, None,
                        0.0 if horizon is not None else None, fit.n, tuple(notes),
                        coef, cov, last, unreachable)
    if sign * ya[-1] >= abs(threshold):
        notes.append("the last check measured past the no-go change: at no-go now")
        return Forecast("path", threshold, slope, interval, (0.0, 0.0, 0.0),
                        1.0 if horizon is not None else None, fit.n, tuple(notes),
                        coef, cov, last, at_nogo=True)
    left, step_x = path_remaining(fit, threshold, seed, horizon,
                                  upto=0.95 if calibration is None else max(0.95, calibration.high))
    if calibration is not None and calibration.weight > 0:   # the stacked mixture
        gap = threshold - fit.coef[0]
        left = mixed(left, fleet_left(calibration.lives, gap), calibration.weight, step_x, seed)
        had = sorted(lives_left(calibration.lives, gap))
        notes.append("the failed peers' remaining lives from as near their ends as it is: "
                     + ", ".join(f"{v:.4g}" for v in had)
                     + f" [{per}] ({100 * calibration.weight:.0f} % of its draws)")
    if calibration is None:
        med, lo, hi = median_interval(left, whole=True)
    else:
        med, lo, hi = (float(np.quantile(left, q, method="inverted_cdf")) for q in (
            calibration.median, calibration.low, calibration.high))
        notes.append(calibration.describe())
        if fit.fleet:   # what the fleet's lives changed
            notes.append(f"with the fleet's prior (its peers went on from as near their ends "
                         f"at " + ", ".join(f"{r:.3g}" for r in fit.fleet) + f" %/{per}), the "
                         f"rate now drawn at {drawn_rate(fit, seed):.3g} %/{per} and the rate "
                         f"wandering {100 * math.sqrt(fit.walk):.2g} % per √{per} (from its "
                         f"own series alone: {drawn_rate(own, seed):.3g} and "
                         f"{100 * math.sqrt(own.walk):.2g} %)")
    said = coverage_note("path", calibration is not None, caveat=not refused)
    if said:
        notes.append(said)
    p = float(np.mean(left <= horizon)) if horizon is not None else None
    if p is not None and calibration is not None:   # read on the fleet, as the interval is
        p = calibration.probability(p)
    return Forecast("path", threshold, slope, interval, (med, lo, hi), p, fit.n,
                    tuple(notes), coef, cov, last)


def forecast_by(method: str, x: ArrayLike, change: ArrayLike, se: ArrayLike, spread: float,
                threshold: float, horizon: float | None = None, seed: int = 0, *,
                prior: Prior | None = None, step: float | None = None,
                unreachable: str | None = None,
                calibration: Calibration | None = None, per: str = "x") -> Forecast:
    """:func:`forecast_path` or :func:`~condmon.forecast.series.forecast_series`
    by ``method`` (one of :data:`METHODS`); ``per`` names a unit of ``x``
    in the path's notes ("cycle").

    Raises
    ------
    DataError
        An unknown method, and as the method does.
    """
    if method == "path":
        return forecast_path(x, change, se, spread, threshold, horizon, seed, prior=prior,
                             step=step, unreachable=unreachable, calibration=calibration,
                             per=per)
    if method != "trend":
        raise DataError(f"forecast method {method!r}: the methods are {', '.join(METHODS)}")
    f = forecast_series(x, change, se, spread, threshold, horizon, seed, prior=prior, step=step,
                        unreachable=unreachable)
    said = coverage_note("trend") if f.remaining is not None and not f.at_nogo else ""
    return dataclasses.replace(f, notes=(*f.notes, said)) if said else f
