"""The fleet's prior on a unit's degradation: its shape and its rate.

Units of the same model that have already degraded teach a new unit how it
will wear (Gebraeel 2006, and the degradation models of MATLAB's Predictive
Maintenance Toolbox, fit their priors on such an ensemble):

- :class:`RatePrior`: a normal prior on one model's rate (the linear slope,
  or the exponential's growth rate ``b``), the peers' rates' mean and their
  spread for one more unit;
- :class:`FleetPrior`: the shape as well: how likely the unit is to wear
  exponentially (the share of peers whose own evidence chose the
  exponential, by Laplace's rule: ``(k + 1) / (n + 2)``; a curve whose slope
  grew less than e-fold over its series counts as a line), the slope prior
  of the peers that wore linearly, and the growth-rate and amplitude priors
  of those that wore exponentially (Gebraeel's two priors). A unit whose
  peers wore exponentially is forecast with that shape, rate and amplitude
  (:func:`condmon.forecast.series.forecast_series` weighs the models by
  that prior and the unit's own evidence).

:func:`unit_wear` reads one peer's series once; :func:`prior_from_wear`
builds the prior from the peers' readings (so a store reads each peer once
for many forecasts); :func:`fleet_prior` and :func:`fleet_wear_prior` do
both from the series.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from condmon.errors import DataError
from condmon.forecast.degradation import (
    MIN_TESTS, Z90, Fit, FloatArray, aicc_weights, bent_fit, checked_series, fits, weights,
)

__all__ = ["RatePrior", "FleetPrior", "UnitWear", "fleet_prior", "fleet_wear_prior", "unit_rate",
           "unit_wear", "prior_from_rates", "prior_from_wear", "updated", "Prior"]

_MODELS = ("linear", "exponential")


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
        return f"fleet prior ({self.model}) from {_count(self.units)}: {what}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (a vague sd as None)."""
        return {"model": self.model, "mean": self.mean,
                "sd": self.sd if self.informative else None, "units": self.units,
                "per": self.per}


def fleet_prior(series: Sequence[tuple[ArrayLike, ArrayLike, ArrayLike, float]],
                model: str = "linear", per: str = "test") -> RatePrior:
    """The prior on the degradation rate from units that have already degraded.

    Each unit's own rate is its weighted fit of ``model`` (as in
    :func:`~condmon.forecast.series.forecast_series`); the prior is their
    mean, with the spread of a new unit's true rate about it
    (:func:`prior_from_rates`: the units' differences, their estimation error
    taken out, plus the mean's own error).

    Parameters
    ----------
    series : sequence of (x, change, se, spread)
        Each unit's series, the leading arguments of
        :func:`~condmon.forecast.series.forecast_series`: the tests' times [test (or d, h)], changes [%], standard errors and
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
        An unknown model; a series that
        :func:`~condmon.forecast.series.forecast_series` would refuse.

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
    xa, ya, sa = checked_series(x, change, se, spread)
    tail = float(np.mean(ya[-MIN_TESTS:]))
    fit = fits(xa, ya, sa, spread, 1.0 if tail >= 0 else -1.0).get(model)
    return None if fit is None else (float(fit[0][-1]), float(fit[1][-1, -1]))


def _count(n: int) -> str:
    return f"{n} unit{'s' * (n != 1)}"


def prior_from_rates(rates: Sequence[tuple[float, float]], model: str = "linear",
                     per: str = "test") -> RatePrior:
    """The prior from units' rates and their variances (:func:`unit_rate`):
    their mean, and the spread of a new unit's true rate about it: the
    units' own differences (the rates' variance less their mean estimation
    variance, at least 0) plus the mean's error (``τ² + (τ² + ē)/n``); vague
    with fewer than 2."""
    if len(rates) < 2:
        return RatePrior.vague(model, per)
    r = np.asarray([v for v, _ in rates])
    # the rates scatter by the units' differences and by their own estimation
    # error: the units' differences are what is left of the one after the other
    # (the moment estimate of a random-effects spread, DerSimonian and Laird);
    # a new unit's true rate then spreads by them and by the mean's own error
    error = float(np.mean([e for _, e in rates]))
    between = max(float(np.var(r, ddof=1)) - error, 0.0)
    sd = math.sqrt(between + (between + error) / len(r))
    return RatePrior(model, float(np.mean(r)), max(sd, 1e-12 * max(1.0, abs(float(np.mean(r))))),
                     len(r), per)


def updated(fit: Fit, prior: RatePrior) -> Fit:
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


@dataclass(frozen=True)
class UnitWear:
    """How one unit wore, as its whole series since its baseline tells.

    Attributes
    ----------
    exponential_weight : float
        The exponential's Akaike weight against the line (0 where no growing
        exponential fits). [-]
    linear : tuple of float
        The linear slope and its variance. [% per x; squared]
    exponential : tuple of float or None
        The exponential's growth rate and its variance (None: none fits). [1 per x; squared]
    amplitude : tuple of float or None
        The exponential's amplitude ``A`` of ``c + A·(exp(b·x) − 1)`` from the
        series' origin, and its variance (None: none fits, or kept before it
        was). [%; %²]
    start, bend : tuple of float or None
        The series as a bent line ``c + s·(exp(b·x) − 1)/b``, towards the side
        it moved to: its slope ``s`` at the origin [% per x] and its bend
        ``b`` [1 per x], signed (a line that bows down bends below 0), each
        with its variance (:func:`~condmon.forecast.degradation.bent_fit`;
        None: it did not move).
    span : float or None
        ``x`` of the last test less that of the first. [test (or d, h)]
    direction : float
        The way it wore: +1.0 a rise, -1.0 a fall (the line's 90 % slope
        interval on that side of 0), 0.0 neither (a peer that degraded on
        another parameter). [-]
    """

    exponential_weight: float
    linear: tuple[float, float]
    exponential: tuple[float, float] | None
    amplitude: tuple[float, float] | None = None
    start: tuple[float, float] | None = None
    bend: tuple[float, float] | None = None
    span: float | None = None
    direction: float = 0.0

    @property
    def shape(self) -> str:
        """The model its own evidence chose: "exponential" or "linear" (a
        curve whose slope grew less than e-fold over the series, ``b·span <
        1``, wore as a line: its slope, not its barely bent curve, is what a
        new unit learns from it)."""
        bent = self.exponential is None or self.span is None or \
            self.exponential[0] * self.span >= 1.0
        return "exponential" if self.exponential_weight > 0.5 and bent else "linear"


def unit_wear(x: ArrayLike, change: ArrayLike, se: ArrayLike, spread: float) -> UnitWear:
    """One unit's wear (:class:`UnitWear`): both models fitted to its series
    towards the side it moved to, and the evidence between them.

    Raises
    ------
    DataError
        A series :func:`~condmon.forecast.series.forecast_series` would refuse.
    """
    xa, ya, sa = checked_series(x, change, se, spread)
    sign = 1.0 if float(np.mean(ya[-MIN_TESTS:])) >= 0 else -1.0
    found = fits(xa, ya, sa, spread, sign)
    lin = found["linear"]
    exp = found.get("exponential")
    weight = aicc_weights(found, len(xa))[1].get("exponential", 0.0)
    start, bend = _bent_line(xa, sign * ya, weights(sa, spread))
    slope, var = _rate_of(lin)
    half = Z90 * math.sqrt(max(var, 0.0))
    way = 1.0 if slope - half > 0 else -1.0 if slope + half < 0 else 0.0
    return UnitWear(weight, (slope, var), None if exp is None else _rate_of(exp),
                    None if exp is None else _amplitude_of(exp, float(xa[-1])), start, bend,
                    float(xa[-1] - xa[0]), way)


def _bent_line(x: FloatArray, y: FloatArray, w: FloatArray
               ) -> tuple[tuple[float, float] | None, tuple[float, float] | None]:
    """The slope at the origin and the bend of the bent line
    (:func:`~condmon.forecast.degradation.bent_fit`), each with its variance;
    None for both where the series has fewer than 4 tests or does not rise
    (its slope not above its own error)."""
    if len(x) < 4:
        return None, None
    coef, cov, _ = bent_fit(x, y, w)
    if not coef[1] > math.sqrt(max(float(cov[1, 1]), 0.0)):
        return None, None
    return (float(coef[1]), float(cov[1, 1])), (float(coef[2]), float(cov[2, 2]))



def _rate_of(fit: Fit) -> tuple[float, float]:
    return float(fit[0][-1]), float(fit[1][-1, -1])


def _amplitude_of(fit: Fit, last: float) -> tuple[float, float]:
    """The exponential's amplitude at the origin, ``A = β·exp(−b·x_last)/b``
    from its (α, β, b) at the last test, and its variance (delta method)."""
    (_, beta, b), cov = fit[0], fit[1]
    amp = beta * math.exp(-b * last) / b
    grad = np.array([0.0, math.exp(-b * last) / b, -amp * (last + 1.0 / b)])
    return float(amp), float(grad @ cov @ grad)


@dataclass(frozen=True)
class FleetPrior:
    """The fleet's prior on a unit's degradation: its shape and each shape's rate.

    Attributes
    ----------
    p_exponential : float
        The prior probability that the unit wears exponentially: the share of
        peers whose evidence chose the exponential (:attr:`UnitWear.shape`),
        ``(k + 1) / (n + 2)`` (Laplace's rule; 0.5 with no peers). [-]
    linear : RatePrior
        The slope, from the peers that wore linearly. [% per x]
    exponential : RatePrior
        The growth rate ``b``, from the peers that wore exponentially. [1 per x]
    units : int
        How many peers it came from (0: no fleet history).
    amplitude : RatePrior or None
        The exponential's amplitude ``A`` (:class:`UnitWear`), from the peers
        that wore exponentially (its ``mean`` and ``sd`` in %; None: not
        known). [%]
    bend, start : RatePrior or None
        How the peers that wore linearly bent: the bend ``b`` of their line
        ``c + s·(exp(b·x) − 1)/b`` (:class:`UnitWear`) [1 per x], and its
        slope ``s`` at the origin [% per x], towards the threshold (None: not
        known).
    why : str
        Why a vague prior learnt nothing from peers that exist ("": there
        are none: no fleet history).
    """

    p_exponential: float
    linear: RatePrior
    exponential: RatePrior
    units: int
    amplitude: RatePrior | None = None
    bend: RatePrior | None = None
    start: RatePrior | None = None
    why: str = ""

    def __post_init__(self) -> None:
        if not 0.0 < self.p_exponential < 1.0:
            raise DataError(f"a shape prior's probability of the exponential must be in (0, 1), "
                            f"not {self.p_exponential:g}")

    @classmethod
    def vague(cls, per: str = "test", why: str = "") -> FleetPrior:
        """The prior with no fleet history (or none that teaches: ``why``):
        the unit's own tests decide."""
        return cls(0.5, RatePrior.vague("linear", per), RatePrior.vague("exponential", per), 0,
                   why=why)

    @property
    def informative(self) -> bool:
        """Whether it carries any fleet knowledge."""
        return self.units > 0

    def describe(self) -> str:
        """One line: where the prior comes from and what it says."""
        if not self.informative:
            return f"{self.why}: vague prior" if self.why else RatePrior.vague().describe()
        what = [f"P(exponential) {self.p_exponential:.2f}"]
        for p in (self.linear, self.exponential):
            if p.informative:
                what.append(p.describe().split(": ", 1)[1])
        for label, q, unit in (("amplitude", self.amplitude, " %"),
                               ("the lines' bend", self.bend, f" /{self.linear.per}")):
            if q is not None and q.informative:
                what.append(f"{label} {q.mean:.3g} ± {q.sd:.2g}{unit}")
        k = self.exponential.units
        return (f"fleet prior from {_count(self.units)} ({k} wore exponentially): "
                + "; ".join(what) + (f" ({self.why})" if self.why else ""))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        def plain(p: RatePrior | None) -> dict[str, Any] | None:
            return None if p is None else {"mean": p.mean, "sd": p.sd if p.informative else None,
                                           "units": p.units}

        return {"p_exponential": self.p_exponential, "units": self.units,
                "linear": self.linear.to_dict(), "exponential": self.exponential.to_dict(),
                "amplitude": plain(self.amplitude), "bend": plain(self.bend),
                "start": plain(self.start)}


#: A prior :func:`~condmon.forecast.series.forecast_series` takes.
Prior = RatePrior | FleetPrior


def prior_from_wear(wears: Sequence[UnitWear], per: str = "test",
                    direction: float | None = None) -> FleetPrior:
    """The fleet's prior (:class:`FleetPrior`) from its units' wear
    (:func:`unit_wear`): the shape by the share that wore exponentially, the
    slope and bend from those that wore linearly, the growth rate and
    amplitude from the others (each vague from fewer than 2 units that give
    it); vague with no units. With a ``direction`` (+1.0 a rise, -1.0 a
    fall), only the units that wore that way: a peer that degraded on
    another parameter, or whose parameter went the other way, teaches
    nothing of this one's wear."""
    if direction is not None and wears:
        n = len(wears)
        wears = [w for w in wears if w.direction == direction]
        if not wears:
            return FleetPrior.vague(per, f"none of {n} degraded peer(s) wore this way "
                                         f"({'a rise' if direction > 0 else 'a fall'})")
    if not wears:
        return FleetPrior.vague(per)
    curved = [w for w in wears if w.shape == "exponential" and w.exponential]
    straight = [w for w in wears if not (w.shape == "exponential" and w.exponential)]

    def among(values: list[tuple[float, float] | None], model: str) -> RatePrior:
        # a peer without one (a bend of a line that did not rise) leaves it to the others
        return prior_from_rates([v for v in values if v is not None], model, per)

    return FleetPrior(
        (len(curved) + 1.0) / (len(wears) + 2.0),
        prior_from_rates([w.linear for w in straight], "linear", per),
        among([w.exponential for w in curved], "exponential"),
        len(wears), among([w.amplitude for w in curved], "exponential"),
        among([w.bend for w in straight], "exponential"),
        among([w.start for w in straight], "linear"))


def fleet_wear_prior(series: Sequence[tuple[ArrayLike, ArrayLike, ArrayLike, float]],
                     per: str = "test", direction: float | None = None) -> FleetPrior:
    """The fleet's prior on shape and rate from units that have already degraded.

    Parameters
    ----------
    series : sequence of (x, change, se, spread)
        Each unit's series, as :func:`fleet_prior` takes them.
    per : str
        What ``x`` counts ("test", "day", "h"), for the description.
    direction : float, optional
        Only the units that wore this way (+1.0 a rise, -1.0 a fall).

    Example
    -------
    >>> x = np.arange(1.0, 21.0)                  # three units that wore exponentially
    >>> fleet = [(x, 5.0 * np.expm1(r * x), np.full(20, 0.5), 0.5) for r in (0.14, 0.15, 0.16)]
    >>> p = fleet_wear_prior(fleet)
    >>> round(p.p_exponential, 2), round(p.exponential.mean, 2), p.linear.informative
    (0.8, 0.15, False)
    """
    return prior_from_wear([unit_wear(*s) for s in series], per, direction)
