"""An imported indicator's value judged against its unit's baseline and its end of life.

A check of an indicator (:mod:`condmon.models.indicators`) is judged as a
check of an estimated parameter is, with two differences that follow from
what an indicator is:

- **detected**: its change from the baseline mean is a symptom, with the
  breakpoints generic monitoring takes from the baseline's spread
  (``r1 = 4 s``, :func:`~condmon.monitor.generic.spread_breakpoints`,
  ``condmon/data/generic-monitor.toml``), up to the end of life; a change
  past ``r1`` the way the end of life lies is an advisory;
- **no-go** exactly when the value is past its end of life (``capacity <
  1.4 Ah``): an end of life is a definition, not a degree of belief.

The false-alarm rate of the advisory is that of generic monitoring: a
healthy value past 4 s of a normal spread (widened for a short baseline)
about 6 times in 100,000 checks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from condmon.models.indicators import Indicator, IndicatorModel
from condmon.monitor.baseline import Baseline
from condmon.monitor.fuzzy import MonitorConfig, compute_symptoms
from condmon.monitor.generic import indicator_r2, load_generic_settings, spread_breakpoints

__all__ = ["IndicatorFault", "IndicatorJudgement", "judge_indicators"]


@dataclass(frozen=True)
class IndicatorFault:
    """An indicator at its end of life (the store's fault row)."""

    name: str
    degree: float
    severity: str
    advice: str


@dataclass(frozen=True)
class IndicatorJudgement:
    """One check of imported indicators against a baseline.

    Attributes
    ----------
    status : {"go", "advisory", "no-go"}
    condition : float
        1 at end of life, the largest symptom degree towards it otherwise. [-]
    summary : str
    symptoms : dict
        ``{indicator: {"percent_change", "high", "low"}}``. [%, -, -]
    faults : tuple of IndicatorFault
    """

    status: str
    condition: float
    summary: str
    symptoms: dict[str, dict[str, float]]
    faults: tuple[IndicatorFault, ...]


def judge_indicators(values: dict[str, float], std_errors: dict[str, float],
                     indicators: tuple[Indicator, ...], baseline: Baseline
                     ) -> IndicatorJudgement:
    """Judge one check's indicator values (see the module).

    Parameters
    ----------
    values, std_errors : dict of str to float
        The check's values and their standard errors (0: none given).
        [indicator units]
    indicators : tuple of Indicator
        The declaration's indicators, with the unit's end of life.
    baseline : Baseline
        The unit's baseline of the same indicators.

    Example
    -------
    >>> from condmon.models.indicators import parse_end_of_life
    >>> cap = Indicator("capacity", "Ah", parse_end_of_life("< 1.4", "capacity", "Ah"),
    ...                 fault="capacity fade")
    >>> b = Baseline(("capacity",), (1.85,), (0.01,), 5)
    >>> [judge_indicators({"capacity": v}, {}, (cap,), b).status for v in (1.85, 1.6, 1.39)]
    ['go', 'advisory', 'no-go']
    """
    settings = load_generic_settings()
    r1, _ = spread_breakpoints(baseline, settings)
    names = [i.name for i in indicators if i.name in baseline.parameters and i.name in values]
    reaches = indicator_r2(IndicatorModel("", indicators), baseline, r1)
    symptoms: dict[str, dict[str, float]] = {}
    faults: list[IndicatorFault] = []
    advisories: list[str] = []
    condition = 0.0
    for ind in indicators:
        if ind.name not in names:
            continue
        mean = float(baseline.mean[baseline.parameters.index(ind.name)])
        eol = ind.end_of_life
        reach = reaches[ind.name]
        one = Baseline((ind.name,), (mean,), (baseline.std[baseline.parameters.index(ind.name)],),
                       baseline.n)
        sym = compute_symptoms(np.array([[values[ind.name]]]), one,
                               MonitorConfig({ind.name: r1[ind.name]}, {ind.name: reach},
                                             settings.k),
                               np.array([[std_errors.get(ind.name, 0.0)]]))
        symptoms[ind.name] = sym.row(0)[ind.name]
        change, high, low = (symptoms[ind.name][k] for k in ("percent_change", "high", "low"))
        level = eol.level(mean, ind.rated)
        towards = low if eol.below else high
        if eol.reached(values[ind.name], mean, ind.rated):
            faults.append(IndicatorFault(ind.fault, 1.0, "major", ind.advice or (
                f"{ind.name} is past its end of life ({eol.text})")))
            condition = 1.0
        elif (change <= -r1[ind.name]) if eol.below else (change >= r1[ind.name]):
            advisories.append(f"{ind.name} {change:+.1f} % from its baseline, towards its end "
                              f"of life at {level:.4g} {ind.unit}")
            # (the declaration's advice is for the end of life itself)
            faults.append(IndicatorFault(ind.fault, float(towards), "minor", (
                f"{ind.name} has moved past its detection limit towards its end of life "
                f"({eol.text}): follow its forecast (condmon forecast)")))
            condition = max(condition, float(towards))
        else:
            condition = max(condition, float(towards))
    if condition >= 1.0 and any(f.severity == "major" for f in faults):
        ended = [f for f in faults if f.severity == "major"]
        return IndicatorJudgement("no-go", 1.0, "end of life: " + ", ".join(
            f.name for f in ended), symptoms, tuple(ended))
    if advisories:
        return IndicatorJudgement("advisory", condition, "; ".join(advisories), symptoms,
                                  tuple(faults))
    return IndicatorJudgement("go", condition, "no significant change", symptoms, ())
