"""Fuzzy significant-change detection: the parameter monitor (SPEC A6.3-5).

For each parameter, HIGH rises linearly from 0 at ``r1`` to 1 at ``r2`` on the
percent change r; LOW mirrors it. The measured change is blurred into a
triangular symptom set S centred on r with half-width ``w = k σ/θ̄ × 100``
(the true change may differ from the measured one), and

    SymH = sup_x min(μ_S(x), μ_HIGH(x)),   SymL likewise with LOW

(max-min composition): a worst-case degree of "high"/"low" in [0, 1].

Choice made here: σ in the width is the larger of the baseline's sample standard
deviation and the new estimate's own standard error. With few baseline tests
(3 to 5) the sample standard deviation often underestimates the estimation
noise, and the width is there to cover how far the true change may be from the
measured one, which is at least the new estimate's uncertainty.

For a triangle and a monotone ramp the supremum has a closed form, used here
because it is exact and vectorises over parameters and tests:
the right flank of S meets the ramp at height ``(r + w - r1) / (w + r2 - r1)``,
clipped to [0, 1]. The tests check it against a grid max-min composition
built from scikit-fuzzy membership functions.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import CondmonError, ConfigError
from condmon.io.config import load_default, load_toml
from condmon.models.regimes import split_key
from condmon.monitor.baseline import Baseline, BaselineChecks, percent_change
from condmon.monitor.statistics import StatisticsConfig, checked_alpha

__all__ = ["MonitorConfig", "load_monitor_config", "load_statistics", "symptom_degree", "symptom_width",
           "Symptoms", "compute_symptoms"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MonitorConfig:
    """Breakpoints and confidence factor of the parameter monitor.

    Attributes
    ----------
    r1, r2 : dict of str to float
        Per parameter: change where HIGH starts rising and where it reaches 1. [%]
    k : float
        Symptom half-width in baseline standard deviations. [-]
    source : str
        File the configuration came from.
    baseline : BaselineChecks
        When a baseline is flagged as implausible (optional ``[baseline]`` table).
    statistics : StatisticsConfig
        False-alarm probabilities of the statistical tests beside the fuzzy
        status (optional ``[statistics]`` table; :mod:`condmon.monitor.statistics`).
    insist : frozenset of str
        Parameters whose declared breakpoints hold even inside the healthy
        scatter (``insist = true`` in their ``[breakpoints]`` entry); the
        others' are raised to the scatter's
        (:func:`condmon.monitor.generic.judged_config`).
    between_units : dict of str to float
        The stated spread of a parameter between healthy units of the model
        (one standard deviation, in % of the mean; the ``[between_units]``
        table): a comparison with fewer than three peers adds it to the
        peer's scatter (:func:`condmon.monitor.generic.peer_spread`). [%]
    between_log : frozenset of str
        The names whose stated spread is of the logarithm (``{ log = 25.0 }``:
        one standard deviation of ``ln x``, in %): a spread by ratios, as
        vibration levels spread. [-]
    sigmas : (float, float) or None
        The multiples of the yardstick the floors of ``r1`` and ``r2`` lie at
        (:func:`condmon.monitor.generic.judged_config`); None: the generic
        settings' 4 and 8. A check against peers sets them from its false-alarm
        probability (:func:`condmon.monitor.generic.peer_monitor`). [-]
    """

    r1: dict[str, float]
    r2: dict[str, float]
    k: float = 2.0
    source: str = "condmon/data/monitor.toml"
    baseline: BaselineChecks = BaselineChecks()
    statistics: StatisticsConfig = StatisticsConfig()
    insist: frozenset[str] = frozenset()
    between_units: dict[str, float] = dataclasses.field(default_factory=dict)
    sigmas: tuple[float, float] | None = None
    between_log: frozenset[str] = frozenset()

    def check_parameters(self, available: Sequence[str], model: str = "") -> None:
        """Refuse breakpoints or a between-unit spread of a name the model
        does not monitor: a misspelt one (``d`` for ``D``) would be ignored,
        its parameter judged by the scatter's default instead.

        Raises
        ------
        ConfigError
            Naming the file, the unknown names and the allowed ones.
        """
        unknown = sorted({split_key(p)[0] for p in (*self.r1, *self.between_units)}
                         - set(available))
        if unknown:
            of = f" of model {model!r}" if model else ""
            raise ConfigError(f"{self.source}: breakpoints or spreads name unknown "
                              f"parameter(s) {unknown}; the parameters{of} are "
                              f"{', '.join(available)}")

    def arrays(self, parameters: Sequence[str]) -> tuple[FloatArray, FloatArray]:
        """``r1`` and ``r2`` in the order of ``parameters``; a regime's parameter
        (``Tc@forward``) takes its own breakpoints if configured, else its
        parameter's (``Tc``)."""
        def key(p: str) -> str:
            return p if p in self.r1 else split_key(p)[0]

        missing = [p for p in parameters if key(p) not in self.r1]
        if missing:
            raise ConfigError(f"{self.source}: no breakpoints for {missing}; "
                              f"configured: {sorted(self.r1)}")
        return (np.array([self.r1[key(p)] for p in parameters]),
                np.array([self.r2[key(p)] for p in parameters]))


    def keyed(self, names: Sequence[str]) -> MonitorConfig:
        """The breakpoints of ``names`` that it knows, under those names (a
        regime's parameter, ``Tc@forward``, takes ``Tc``'s), in their order.

        Example
        -------
        >>> cfg = MonitorConfig({"Tc": 15.0}, {"Tc": 30.0})
        >>> cfg.keyed(["Tc@forward", "J", "Tc@reverse"]).r1
        {'Tc@forward': 15.0, 'Tc@reverse': 15.0}
        """
        known = [n for n in names if n in self.r1 or split_key(n)[0] in self.r1]
        if not known:
            return dataclasses.replace(self, r1={}, r2={})
        r1, r2 = self.arrays(known)
        return dataclasses.replace(self, r1=dict(zip(known, map(float, r1))),
                                   r2=dict(zip(known, map(float, r2))))


def load_monitor_config(path: str | Path | None = None, k: float | None = None) -> MonitorConfig:
    """Monitor configuration: shipped defaults (the reference rig's Table 1) or a file.

    Example
    -------
    >>> cfg = load_monitor_config()
    >>> cfg.r1["D"], cfg.r2["D"], cfg.k
    (300.0, 600.0, 2.0)
    """
    src = str(path) if path is not None else "condmon/data/monitor.toml"
    raw = load_toml(path) if path is not None else load_default("monitor.toml")
    try:
        bp = raw["breakpoints"]
        r1 = {p: float(v["r1"]) for p, v in bp.items()}
        r2 = {p: float(v["r2"]) for p, v in bp.items()}
        insist = frozenset(p for p, v in bp.items() if v.get("insist", False) is True)
        kk = float(raw.get("k", 2.0)) if k is None else float(k)
        table = dict(raw.get("baseline", {}))
        unknown = sorted(set(table) - {"outlier_z", "outlier_se", "spread_ratio",
                                       "trend_alpha", "outlier_alpha"})
        if unknown:
            raise KeyError(f"unknown [baseline] key(s) {unknown}; allowed: outlier_z, "
                           "outlier_se, spread_ratio, trend_alpha, outlier_alpha")
        checks = BaselineChecks(**{key: float(v) for key, v in table.items()})
        stated = dict(raw.get("between_units", {}))
    except (KeyError, TypeError, ValueError) as err:
        raise ConfigError(f"{src}: expected [breakpoints] P = {{ r1 = .., r2 = .. }}, "
                          f"k = number and an optional [baseline] table ({err})") from None
    between, logs = _between_units(stated, src)
    stats = load_statistics(raw.get("statistics", {}), src)
    if not all(np.isfinite(v) and v > 0 for v in (checks.outlier_z, checks.outlier_se,
                                                   checks.spread_ratio)):
        raise ConfigError(f"{src}: [baseline] values must be positive numbers")
    for p in r1:
        if not 0 <= r1[p] < r2[p]:
            raise ConfigError(f"{src}: breakpoints of {p} must satisfy 0 <= r1 < r2, "
                              f"got r1={r1[p]}, r2={r2[p]}")
    if kk < 0:
        raise ConfigError(f"{src}: k must be >= 0, got {kk}")
    return MonitorConfig(r1, r2, kk, src, checks, stats, insist, between, between_log=logs)


def _between_units(stated: dict[str, Any], src: str) -> tuple[dict[str, float], frozenset[str]]:
    """``[between_units]``: each a spread > 0 in % of the mean, or ``{ log = s }``
    (one standard deviation of the logarithm, in %); the spreads and the names
    stated of the logarithm.

    Raises
    ------
    ConfigError
        Naming the file, the entry and the forms allowed.
    """
    out, logs = {}, set()
    for p, v in stated.items():
        form = "a spread > 0 [% of the mean] or { log = s } [% of ln x], s > 0"
        if isinstance(v, dict):
            if set(v) != {"log"}:
                raise ConfigError(f"{src}: [between_units] {p} must be {form}, got {v!r}")
            v, unit = v["log"], "% of ln x"
            logs.add(str(p))
        else:
            unit = "% of the mean"
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                math.isfinite(v) and v > 0):
            raise ConfigError(f"{src}: [between_units] {p} must be {form}, got {v!r}"
                              + (f" [{unit}]" if isinstance(v, (int, float)) else ""))
        out[str(p)] = float(v)
    return out, frozenset(logs)


def load_statistics(table: Any, source: str) -> StatisticsConfig:
    """The ``[statistics]`` table of a monitor file (``alpha``, ``drift_alpha``),
    defaults for what it leaves out.

    Raises
    ------
    ConfigError
        Not a table, an unknown key, or a value outside (0, 0.5), naming ``source``.

    Example
    -------
    >>> load_statistics({"alpha": 0.05}, "m.toml")
    StatisticsConfig(alpha=0.05, drift_alpha=0.01)
    """
    allowed = ("alpha", "drift_alpha")
    if not isinstance(table, dict):
        raise ConfigError(f"{source}: [statistics] must be a table ({', '.join(allowed)})")
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise ConfigError(f"{source}: unknown [statistics] key(s) {unknown}; allowed: "
                          f"{', '.join(allowed)}")
    try:
        values = {k: checked_alpha(v, f"[statistics] {k}") for k, v in table.items()}
    except CondmonError as err:
        raise ConfigError(f"{source}: {err}") from None
    return StatisticsConfig(**values)


def symptom_degree(r: ArrayLike, width: ArrayLike, r1: ArrayLike, r2: ArrayLike
                   ) -> tuple[FloatArray, FloatArray]:
    """SymH and SymL of percent changes ``r`` with symptom half-widths ``width``.

    Parameters
    ----------
    r : array_like
        Percent change. [%]
    width : array_like
        Half-width of the triangular symptom set (0: a crisp change). [%]
    r1, r2 : array_like
        Breakpoints of HIGH (LOW uses -r1, -r2). [%]

    Returns
    -------
    high, low : ndarray
        Degrees in [0, 1], broadcast shape of the inputs. Where the band
        ``r ± width`` reaches both ``r1`` and ``-r1`` the direction is not
        measured, and both are 0; so ``high > 0`` implies ``r > 0`` and
        ``low > 0`` implies ``r < 0``.

    Example
    -------
    >>> h, l = symptom_degree([0.0, 30.0, 45.0], 2.0, 20.0, 40.0)
    >>> h.round(4), l
    (array([0.    , 0.5455, 1.    ]), array([0., 0., 0.]))
    >>> symptom_degree(7.0, 40.0, 15.0, 30.0)    # the band spans both ways
    (array(0.), array(0.))
    """
    r_a = np.asarray(r, dtype=np.float64)
    w = np.asarray(width, dtype=np.float64)
    a = np.asarray(r1, dtype=np.float64)
    d = np.asarray(r2, dtype=np.float64) - a
    # Rounded to 12 decimals so that a change landing on a breakpoint up to
    # floating-point error (1.4/1.0 - 1 = 0.39999999999999991) reads as exactly 1.
    with np.errstate(invalid="ignore"):
        high = np.round(np.clip((r_a + w - a) / (w + d), 0.0, 1.0), 12).astype(np.float64)
        low = np.round(np.clip((-r_a + w - a) / (w + d), 0.0, 1.0), 12).astype(np.float64)
    # a parameter the test does not have (another regime's) is no symptom
    high, low = np.nan_to_num(high, nan=0.0), np.nan_to_num(low, nan=0.0)
    # A band that reaches both +r1 and -r1 cannot say which way the parameter
    # went: neither symptom is evidence (a fault read from it would contradict
    # the measured change's sign). With both kept, a +7 % change with a wide
    # band read "high" and "low" at once and named a decrease.
    both = (high > 0) & (low > 0)
    return np.where(both, 0.0, high), np.where(both, 0.0, low)


def symptom_width(mean: ArrayLike, std: ArrayLike, std_error: ArrayLike | None,
                  k: float) -> FloatArray:
    """Half-width of the symptom set, ``k·max(σ, SE)/|θ̄|·100``.

    The one definition of the band around a measured change: the monitor
    blurs the change by it, and every error bar of the reports and the fleet
    page is drawn with it, so a parameter's symptom is above 0 exactly when
    its bar reaches ``±r1``.

    Parameters
    ----------
    mean : array_like
        Baseline mean θ̄ (0: no width, NaN). [parameter units]
    std : array_like
        Baseline sample standard deviation σ. [parameter units]
    std_error : array_like or None
        The estimate's standard error SE (NaN or None: σ alone). [parameter units]
    k : float
        Width in standard deviations. [-]

    Returns
    -------
    ndarray
        Half-width, broadcast shape of the inputs. [%]

    Example
    -------
    >>> symptom_width(2.0, 0.01, [0.005, 0.04, float("nan")], 2.0)
    array([1., 4., 1.])
    """
    m = np.abs(np.asarray(mean, dtype=np.float64))
    sigma = np.asarray(std, dtype=np.float64)
    if std_error is not None:
        se = np.asarray(std_error, dtype=np.float64)
        sigma = np.maximum(sigma, np.where(np.isfinite(se), se, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        width = np.where(m > 0, k * 100.0 * sigma / m, np.nan)
    return np.asarray(width, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Symptoms:
    """Percent changes and fuzzy symptoms of one or more tests.

    Attributes
    ----------
    parameters : tuple of str
        Column order.
    percent_change : ndarray, shape (n_tests, n_params)
        Change against the baseline mean. [%]
    width : ndarray, shape (n_params,) or (n_tests, n_params)
        Symptom-set half-width ``k·max(σ, SE)/|θ̄|·100`` (:func:`symptom_width`). [%]
    high, low : ndarray, shape (n_tests, n_params)
        SymH and SymL in [0, 1].
    """

    parameters: tuple[str, ...]
    percent_change: FloatArray
    width: FloatArray
    high: FloatArray
    low: FloatArray

    def row(self, i: int = 0) -> dict[str, dict[str, float]]:
        """``{param: {"high": .., "low": .., "percent_change": ..}}`` of test ``i``."""
        return {p: {"high": float(self.high[i, j]), "low": float(self.low[i, j]),
                    "percent_change": float(self.percent_change[i, j])}
                for j, p in enumerate(self.parameters)}

    def to_dict(self, i: int = 0) -> dict[str, Any]:
        """JSON-ready symptoms of test ``i``."""
        return {p: {"high": v["high"], "low": v["low"]} for p, v in self.row(i).items()}


def compute_symptoms(values: ArrayLike, baseline: Baseline,
                     config: MonitorConfig | None = None,
                     std_errors: ArrayLike | None = None) -> Symptoms:
    """Symptoms of tests against a baseline, vectorised over tests and parameters.

    Parameters
    ----------
    values : array_like, shape (n_tests, n_params) or (n_params,)
        Estimates in the order of ``baseline.parameters``.
    baseline : Baseline
    config : MonitorConfig, optional
        Breakpoints and k (shipped defaults if omitted).
    std_errors : array_like, optional
        Standard errors of ``values`` (same shape); σ of the width is then
        ``max(baseline std, standard error)``. [parameter units]

    Returns
    -------
    Symptoms

    Example
    -------
    >>> b = Baseline(("R", "L"), (1.0, 1e-3), (0.005, 1e-5), 5)
    >>> s = compute_symptoms([1.4, 1.0e-3], b)
    >>> s.to_dict()["R"]
    {'high': 1.0, 'low': 0.0}
    """
    cfg = config if config is not None else load_monitor_config()
    v = np.atleast_2d(np.asarray(values, dtype=np.float64))
    r = percent_change(v, baseline)
    r1, r2 = cfg.arrays(baseline.parameters)
    se = None if std_errors is None else np.atleast_2d(np.asarray(std_errors, dtype=np.float64))
    width = symptom_width(baseline.mean_array, baseline.std_array, se, cfg.k)
    high, low = symptom_degree(r, width, r1, r2)
    return Symptoms(baseline.parameters, r, width, high, low)
