"""Monitoring any declared machine: breakpoints from the baseline's spread, generic rules.

A declaration without a ``[monitor]`` table says nothing of how much change
matters or what it means. condmon then takes both from the data:

- **Breakpoints** (:func:`spread_breakpoints`): a parameter's symptom starts
  at ``r1 = r1_sigma · s`` and is full at ``r2 = r2_sigma · s``, with ``s``
  the relative spread of the baseline the test is compared with (its sample
  standard deviation over its mean, widened for few tests by the ratio of
  Student's t to the normal quantile, floored at ``min_relative_spread``).
- **Rules** (:func:`condmon.diagnose.rules.generic_rules`): ``<parameter>
  increase`` if high, ``<parameter> decrease`` if low, named by the
  parameter's description.

The same breakpoints judge a unit against a group of its peers
(:mod:`condmon.monitor.group`). The numbers are data
(``condmon/data/generic-monitor.toml``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from condmon.errors import ConfigError
from condmon.io.config import load_default
from condmon.models.machine import Machine
from condmon.models.regimes import split_key
from condmon.monitor.baseline import Baseline, BaselineChecks
from condmon.monitor.fuzzy import MonitorConfig, load_statistics
from condmon.monitor.statistics import StatisticsConfig

__all__ = ["GenericSettings", "load_generic_settings", "spread_breakpoints", "generic_config",
           "indicator_r2", "describe_generic", "StatusPoints", "machine_monitor", "peer_monitor",
           "yardstick", "judged_config", "with_scatter", "typical_systematic", "peer_spread",
           "peer_sigmas"]

#: Membership functions of the status (go, advisory, no-go) on [0, 1]: 3 or 4 points each.
StatusPoints = tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]


@dataclass(frozen=True)
class GenericSettings:
    """The numbers of generic monitoring (``generic-monitor.toml``).

    Attributes
    ----------
    r1_sigma, r2_sigma : float
        Breakpoints in relative spreads of the baseline. [-]
    min_relative_spread : float
        Floor of the relative spread. [%]
    k : float
        Symptom half-width in spreads. [-]
    severity : str
        Of the generic faults ("major" or "minor").
    status : tuple of three tuples of float
        The go, advisory and no-go membership functions of the generic rules.
    baseline : BaselineChecks
    group_min_units : int
        Fewest units with a baseline a group baseline is made of.
    group_flag_z : float
        A unit's own baseline further than this many between-unit standard
        deviations from its peers' is flagged. [-]
    statistics : StatisticsConfig
        False-alarm probabilities of the statistical tests (``[statistics]``).
    """

    r1_sigma: float = 4.0
    r2_sigma: float = 8.0
    min_relative_spread: float = 1.0
    k: float = 2.0
    severity: str = "major"
    status: StatusPoints = ((0.0, 0.0, 0.25, 0.5), (0.25, 0.5, 0.75), (0.5, 0.75, 1.0, 1.0))
    baseline: BaselineChecks = BaselineChecks()
    group_min_units: int = 3
    group_flag_z: float = 3.0
    statistics: StatisticsConfig = StatisticsConfig()


def load_generic_settings() -> GenericSettings:
    """The shipped settings (``condmon/data/generic-monitor.toml``).

    Example
    -------
    >>> s = load_generic_settings()
    >>> s.r1_sigma, s.r2_sigma
    (4.0, 8.0)
    """
    raw = load_default("generic-monitor.toml")
    st = raw.get("status", {})
    try:
        go, adv, nogo = (tuple(float(v) for v in st[k]) for k in ("go", "advisory", "no_go"))
        status: StatusPoints = (go, adv, nogo)
        group = dict(raw.get("group", {}))
        out = GenericSettings(float(raw["r1_sigma"]), float(raw["r2_sigma"]),
                              float(raw["min_relative_spread"]), float(raw["k"]),
                              str(raw["severity"]), status,
                              BaselineChecks(**{k: float(v) for k, v in
                                                dict(raw.get("baseline", {})).items()}),
                              int(group.get("min_units", 3)), float(group.get("flag_z", 3.0)),
                              load_statistics(raw.get("statistics", {}),
                                              "condmon/data/generic-monitor.toml"))
    except (KeyError, TypeError, ValueError) as err:
        raise ConfigError(f"condmon/data/generic-monitor.toml: {err}") from None
    if not 0 < out.r1_sigma < out.r2_sigma or out.severity not in ("major", "minor"):
        raise ConfigError("condmon/data/generic-monitor.toml: needs 0 < r1_sigma < r2_sigma "
                          "and severity major or minor")
    return out


def _t_ratio(n: int) -> float:
    """``t(n-1, 0.975) / z(0.975)``: how much wider a spread of ``n`` tests is read."""
    if n < 2:
        return math.inf
    from condmon.monitor.distributions import t_ppf   # plain Python: a check loads no scipy

    return t_ppf(float(n - 1), 0.975) / 1.959963984540054


def spread_breakpoints(baseline: Baseline, settings: GenericSettings | None = None
                       ) -> tuple[dict[str, float], dict[str, float]]:
    """``r1`` and ``r2`` of each of the baseline's parameters from its spread. [%]

    Example
    -------
    >>> b = Baseline(("R",), (1.0,), (0.02,), 10)
    >>> r1, r2 = spread_breakpoints(b)
    >>> round(r1["R"], 2), round(r2["R"], 2)     # 4 and 8 x 2 %, widened for 10 tests
    (9.23, 18.47)
    """
    cfg = settings or load_generic_settings()
    r1, r2 = {}, {}
    for name, mean, std, n in zip(baseline.parameters, baseline.mean, baseline.std,
                                  baseline.count_array):
        s = max(100.0 * std / abs(mean) * _t_ratio(int(n)), cfg.min_relative_spread)
        r1[name], r2[name] = cfg.r1_sigma * s, cfg.r2_sigma * s
    return r1, r2


#: The source of the breakpoints :func:`generic_config` makes: nobody declared
#: them, so a check's own yardstick replaces them (:func:`judged_config`).
GENERIC_SOURCE = "generic monitoring (condmon/data/generic-monitor.toml)"


def generic_config(baseline: Baseline, settings: GenericSettings | None = None
                   ) -> MonitorConfig:
    """The monitor configuration of a machine without ``[monitor]``, for checks
    against ``baseline``."""
    cfg = settings or load_generic_settings()
    r1, r2 = spread_breakpoints(baseline, cfg)
    return MonitorConfig(r1, r2, cfg.k, GENERIC_SOURCE, cfg.baseline, cfg.statistics)


def machine_monitor(machine: Machine, baseline: Baseline | None = None) -> MonitorConfig:
    """The monitor configuration of a machine: its ``[monitor]`` breakpoints, or
    generic ones from ``baseline``'s spread when it declares none (without a
    baseline: the generic settings' floor). Declared breakpoints come as
    declared: a check raises those inside the healthy scatter
    (:func:`judged_config`); :func:`with_scatter` gives the ones a check
    against a baseline is judged with, to draw or forecast with.

    Example
    -------
    >>> from condmon.models.registry import get_model
    >>> machine_monitor(get_model("dc-motor")).r1["R"]
    20.0
    """
    from condmon.monitor.fuzzy import load_monitor_config

    if machine.breakpoints is not None:
        declared = load_monitor_config(machine.breakpoints)
        declared.check_parameters(machine.monitored, machine.name)   # a misspelt name
        return declared
    cfg = load_generic_settings()
    if machine.indicators is not None and baseline is not None:
        # an imported indicator: detected past r1, no-go at its end of life
        g = generic_config(baseline, cfg)
        return dataclasses.replace(g, r2={**g.r2, **indicator_r2(machine.indicators, baseline,
                                                                  g.r1)},
                                   source="generic monitoring to each indicator's end of life")
    if baseline is None:
        floor = {p: cfg.min_relative_spread for p in machine.monitored}
        return MonitorConfig({p: cfg.r1_sigma * v for p, v in floor.items()},
                             {p: cfg.r2_sigma * v for p, v in floor.items()}, cfg.k,
                             "generic monitoring (no baseline yet)", cfg.baseline, cfg.statistics)
    return generic_config(baseline, cfg)


def indicator_r2(indicators: Any, baseline: Baseline, r1: Mapping[str, float]
                 ) -> dict[str, float]:
    """Each imported indicator's ``r2``: the size of its end of life's change
    from ``baseline`` (:class:`~condmon.models.indicators.IndicatorModel`),
    beyond ``r1`` at least. [%]

    Example
    -------
    >>> from condmon.models.indicators import Indicator, IndicatorModel, parse_end_of_life
    >>> m = IndicatorModel("cell", (Indicator("capacity", "Ah",
    ...                     parse_end_of_life("< 1.4", "capacity", "Ah")),))
    >>> round(indicator_r2(m, Baseline(("capacity",), (2.0,), (0.01,), 5), {"capacity": 4.0})
    ...       ["capacity"], 6)
    30.0
    """
    out = {}
    for ind in indicators.indicators:
        if ind.name not in baseline.parameters or ind.name not in r1:
            continue
        mean = float(baseline.mean[baseline.parameters.index(ind.name)])
        end = ind.end_of_life.change(mean, ind.rated)
        out[ind.name] = (max(abs(end), r1[ind.name] * 1.000001) if math.isfinite(end)
                         else 2.0 * r1[ind.name])
    return out


def peer_sigmas(alpha: float, parameters: int) -> tuple[float, float]:
    """The breakpoints of a check against peers, in the peers' spreads: ``z``
    and ``2 z``, ``z`` the two-sided normal quantile a healthy unit's
    difference from its peers exceeds in one of ``parameters`` parameters
    with probability ``alpha`` (Šidák: each at ``1 - (1 - alpha)^(1/m)``).

    Against its own baseline a unit is judged by the calibrated change test
    at ``alpha`` beside breakpoints at 4 and 8 scatters; against peers no
    test of the unit's own history exists, so the stated false-alarm
    probability sets the breakpoints themselves: with the symptom's blur
    (``k = 2`` spreads) a check turns advisory about ``z`` spreads out, and a
    healthy unit is flagged on about ``alpha`` of its checks. [-]

    Example
    -------
    >>> [round(x, 2) for x in peer_sigmas(0.01, 5)]
    [3.09, 6.18]
    """
    from statistics import NormalDist

    m = max(int(parameters), 1)
    z = NormalDist().inv_cdf(1.0 - (1.0 - (1.0 - alpha) ** (1.0 / m)) / 2.0)
    return z, 2.0 * z


def peer_monitor(machine: Machine, reference: Baseline) -> MonitorConfig:
    """Breakpoints of a check against a group's (or another unit's) baseline:
    the spread-based ones at the peers' false-alarm probability
    (:func:`peer_sigmas`, the monitor file's ``[statistics] alpha``), capped
    at the machine's own when it declares them. Against peers, a deviation
    beyond what the peers show is a symptom even below the change the
    machine's breakpoints call a fault over a unit's own life; a change those
    call a fault is one against peers too.

    Example
    -------
    >>> from condmon.models.registry import get_model
    >>> ref = Baseline(("R", "D"), (1.0, 1e-4), (0.03, 1e-5), 20)
    >>> cfg = peer_monitor(get_model("dc-motor"), ref)
    >>> round(cfg.r1["R"], 1), round(cfg.r1["D"], 1)     # 2.81 x 3 % x 1.07; 2.81 x 10 % x 1.07
    (9.0, 30.0)
    """
    settings = load_generic_settings()
    own = machine_monitor(machine, reference)
    sigmas = peer_sigmas(own.statistics.alpha, len(reference.parameters))
    r1, r2 = spread_breakpoints(reference, dataclasses.replace(
        settings, r1_sigma=sigmas[0], r2_sigma=sigmas[1]))
    if machine.breakpoints is not None:
        mine = with_scatter(own, reference).arrays(reference.parameters)
        for i, key in enumerate(reference.parameters):
            r1[key] = min(r1[key], float(mine[0][i]))
            r2[key] = max(min(r2[key], float(mine[1][i])), r1[key] * (1 + 1e-9) + 1e-12)
    return MonitorConfig(r1, r2, own.k, f"peer comparison ({own.source}, capped at "
                         f"{sigmas[0]:.3g}/{sigmas[1]:.3g} spreads: α {own.statistics.alpha:g} "
                         f"over {len(reference.parameters)} parameters)", own.baseline,
                         own.statistics, sigmas=sigmas)


def yardstick(baseline: Baseline) -> dict[str, float]:
    """The relative record-to-record scatter a change is judged against, per parameter. [%]

    ``s = σ/|θ̄| · t(n-1, 0.975)/z(0.975) · 100``: the baseline's sample
    standard deviation, widened for few tests as in
    :func:`spread_breakpoints`, floored at the generic settings'
    ``min_relative_spread``. The estimate's own standard error is not part of
    it: on real machines it is several times smaller than the scatter.

    Example
    -------
    >>> b = Baseline(("Tc",), (40.0,), (0.4,), 30)
    >>> round(yardstick(b)["Tc"], 2)
    1.04
    """
    cfg = load_generic_settings()
    out = {}
    for name, mean, std, n in zip(baseline.parameters, baseline.mean, baseline.std,
                                  baseline.count_array):
        scale = 100.0 / abs(mean) if mean != 0 else math.inf
        s = std * scale * _t_ratio(int(n))
        out[name] = max(s, cfg.min_relative_spread) if math.isfinite(s) else math.inf
    return out


def judged_config(config: MonitorConfig, baseline: Baseline,
                  systematic: Mapping[str, float] | None = None
                  ) -> tuple[MonitorConfig, tuple[str, ...]]:
    """The breakpoints a check against ``baseline`` is judged with, and what was raised.

    Each parameter's ``r1`` and ``r2`` are at least ``b + r1_sigma · s`` and
    ``b + r2_sigma · s``: ``s`` its :func:`yardstick` (the healthy scatter;
    the generic settings' 4 and 8 times it), ``b`` the bound the sensors'
    stated accuracy sets on a change they could make by drifting
    (:attr:`condmon.identify.EstimateResult.systematic`, in % of the
    baseline mean). A bounded error is added to the random one's limit, as
    a guard band is (ISO 14253-1): a change inside the sensors' accuracy is
    no change of the machine, whatever the scatter. A declared breakpoint
    below that floor would call the unit's ordinary variation a fault, so the
    floor wins, and the note says so, unless the monitor file insists
    (``insist = true``). A parameter the file has no breakpoints for (a
    signal feature) takes the floor, and so does every parameter when nobody
    declared breakpoints (:data:`GENERIC_SOURCE`): a baseline judged at its
    operating conditions has a smaller scatter than its raw spread, and its
    breakpoints come down with it.

    Returns
    -------
    config : MonitorConfig
        Keyed by the baseline's parameters.
    raised : tuple of str
        One note per declared breakpoint the floor raised.

    Example
    -------
    >>> b = Baseline(("Tc@forward", "vib@forward"), (40.0, 5.0), (0.4, 1.0), 30)
    >>> cfg, raised = judged_config(MonitorConfig({"Tc": 15.0}, {"Tc": 30.0}), b, {"Tc@forward": 6.0})
    >>> round(cfg.r1["Tc@forward"], 1), round(cfg.r1["vib@forward"], 1)
    (19.2, 83.5)
    >>> raised[0][:60]
    'Tc@forward: the declared r1 15 % lies inside the healthy sca'
    """
    settings = load_generic_settings()
    s = yardstick(baseline)
    known = config.keyed(baseline.parameters)
    sys_ = systematic or {}
    r1_sigma, r2_sigma = config.sigmas or (settings.r1_sigma, settings.r2_sigma)
    r1, r2, raised = {}, {}, []
    for name, mean in zip(baseline.parameters, baseline.mean):
        b = sys_.get(name, 0.0)
        b = 100.0 * b / abs(mean) if math.isfinite(b) and mean != 0 else 0.0
        floor1, floor2 = b + r1_sigma * s[name], b + r2_sigma * s[name]
        if name not in known.r1 or config.source == GENERIC_SOURCE:
            r1[name], r2[name] = floor1, floor2
            continue
        d1, d2 = known.r1[name], known.r2[name]
        if split_key(name)[0] in config.insist or name in config.insist or d1 >= floor1:
            r1[name], r2[name] = d1, d2
            continue
        r1[name], r2[name] = floor1, max(d2, floor2)
        if config.source.startswith("peer comparison"):
            continue   # the peers' own spread, not a declared breakpoint: nothing to say
        accuracy = f" plus the sensors' accuracy {b:.3g} %" if b else ""
        within = " and the sensors' accuracy" if b else ""
        raised.append(f"{name}: the declared r1 {d1:.3g} % lies inside the healthy scatter"
                      f"{within} ({r1_sigma:g} × {s[name]:.3g} %{accuracy} = "
                      f"{floor1:.3g} %): that is used (insist = true in [breakpoints] keeps "
                      "the declared)")
    return dataclasses.replace(config, r1=r1, r2=r2), tuple(raised)


def peer_spread(reference: Baseline, config: MonitorConfig
                ) -> tuple[Baseline, tuple[str, ...]]:
    """Another unit's baseline as a check of this unit is judged against it.

    One peer's record-to-record scatter says nothing of how far two healthy
    units of the model differ (their sensors, their assembly, their load's
    own friction). Its standard deviation is widened by the spread between
    units the monitor file states (``[between_units]``, one standard
    deviation in % of the mean), and by the checked unit's own
    record-to-record scatter (one test of it is compared with the peer's
    mean; unknown, it is taken as the peer's): ``sqrt(2σ² + (τ·|θ̄|)²)``, so
    the answer is as wide as two units may honestly differ. A parameter with
    none stated is judged on the two units' scatter alone, and the note says
    so. A spread stated of the logarithm (``{ log = τ }``: healthy units
    differ by ratios) enters as the spread in % whose ``z`` multiples reach
    the rise ``z`` such spreads of the logarithm reach,
    ``(exp(z τ) - 1) / z``, ``z`` the peers' breakpoint (:func:`peer_sigmas`):
    changes are judged in percent, and a rise is what a level's rules read.

    Returns
    -------
    baseline : Baseline
    notes : tuple of str

    Example
    -------
    >>> ref = Baseline(("Tc@forward", "vib1@forward"), (40.0, 5.0), (0.4, 0.5), 50)
    >>> b, notes = peer_spread(ref, MonitorConfig({}, {}, between_units={"Tc": 10.0}))
    >>> round(b.std[0], 3), round(b.std[1], 3), notes[0][:40]
    (4.04, 0.707, 'vib1@forward: no spread between units is')
    """
    stds, notes = [], []
    z = peer_sigmas(config.statistics.alpha, len(reference.parameters))[0]
    for name, mean, std in zip(reference.parameters, reference.mean, reference.std):
        tau = config.between_units.get(name, config.between_units.get(split_key(name)[0]))
        if tau is not None and (name in config.between_log
                                or split_key(name)[0] in config.between_log):
            tau = 100.0 * math.expm1(z * tau / 100.0) / z
        if tau is None:
            stds.append(math.sqrt(2.0) * std)
            notes.append(f"{name}: no spread between units is stated ([between_units] of "
                         f"{config.source}): a difference is judged against the two units' "
                         "scatter and their sensors' stated accuracy alone")
            continue
        stds.append(math.hypot(math.sqrt(2.0) * std, tau / 100.0 * abs(mean)))
    return dataclasses.replace(reference, std=tuple(stds)), tuple(notes)


def typical_systematic(history: Any) -> dict[str, float]:
    """The median systematic part of each parameter over a history's rows
    (its ``P_sys`` columns; empty when it has none). [parameter units]

    Example
    -------
    >>> import pandas as pd
    >>> typical_systematic(pd.DataFrame({"Tc": [40.0, 41.0], "Tc_sys": [6.0, 6.2]}))
    {'Tc': 6.1}
    """
    import numpy as np

    cols = [c for c in getattr(history, "columns", ()) if str(c).endswith("_sys")]
    out = {}
    for c in cols:
        values = np.asarray(history[c], dtype=np.float64)
        values = values[np.isfinite(values)]
        if values.size:   # an all-NaN median warns on older numpy
            out[str(c)[: -len("_sys")]] = float(np.median(values))
    return out


def with_scatter(config: MonitorConfig, baseline: Baseline,
                 systematic: Mapping[str, float] | None = None) -> MonitorConfig:
    """``config`` with the breakpoints a check against ``baseline`` is judged
    with (:func:`judged_config`, with a typical ``systematic`` part, e.g.
    :func:`typical_systematic`) under the baseline's names, its own kept under
    theirs (``Tc`` beside ``Tc@forward``): what a figure draws and a forecast
    aims at.

    Example
    -------
    >>> b = Baseline(("Tc@forward",), (40.0,), (2.0,), 30)
    >>> cfg = with_scatter(MonitorConfig({"Tc": 15.0}, {"Tc": 30.0}), b)
    >>> cfg.r1["Tc"], round(cfg.r1["Tc@forward"], 1)
    (15.0, 20.9)
    """
    judged = judged_config(config, baseline, systematic)[0]
    return dataclasses.replace(judged, r1={**config.r1, **judged.r1},
                               r2={**config.r2, **judged.r2})


def describe_generic(settings: GenericSettings | None = None, *, rules: bool = False,
                     breakpoints: bool = False) -> str:
    """One sentence saying how a machine is monitored whose ``[monitor]`` table
    is missing or declares only ``rules`` or only ``breakpoints``.

    Example
    -------
    >>> describe_generic(rules=True).split(":")[0]
    '[monitor] declares rules but no breakpoints'
    """
    cfg = settings or load_generic_settings()
    points = (f"each parameter's symptom from {cfg.r1_sigma:g} to {cfg.r2_sigma:g} times the "
              f"baseline's relative spread (at least {cfg.min_relative_spread:g} %)")
    generic_rules = "rules '<parameter> increase' and '<parameter> decrease'"
    if rules and not breakpoints:
        return f"[monitor] declares rules but no breakpoints: {points}; the declared rules"
    if breakpoints and not rules:
        return f"[monitor] declares breakpoints but no rules: {generic_rules}"
    return f"no [monitor] table: generic monitoring, {points}, {generic_rules}"
