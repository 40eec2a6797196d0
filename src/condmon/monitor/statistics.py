"""Calibrated detection: a check's change, and a unit's drift, with a stated false-alarm rate.

The fuzzy monitor (:mod:`condmon.monitor.fuzzy`) says *which* fault and how far
it has gone, on breakpoints of a reference rig; it states no false-alarm rate.
Beside it, each check gets two tests with one:

**Change (level).** The test's change vector ``d`` [% of the baseline mean]
against the baseline's ``n`` tests is a new draw from the baseline's
distribution when the unit is healthy, so with the baseline's sample
covariance ``S`` (which holds each test's estimation noise and the unit's
test-to-test scatter alike)

    T² = dᵀ [S (1 + 1/n) + E]⁻¹ d,      F = T² (n - r) / (r (n - 1)) ~ F(r, n - r)

(Hotelling's prediction test; ``r`` the rank of ``S``: parameters that are
functions of the same estimated coefficient, as ``Ke`` and ``Kt`` in SI
units, count once). With several directions T² spreads its power over all of
them: with 9 parameters (signal features beside the physical ones) and 15
tests, one parameter 6 scatters out gave p 0.05. So each parameter's ``t``
(below) is tested beside it, and the check's ``p`` is the two tests'
combination by Simes (``min(2 min(p₁, p₂), max(p₁, p₂))``, valid as both
grow with the change), so that ``alpha`` stays the false-alarm probability. ``E`` is the test's own estimation variance beyond the
worst of the baseline tests' (``diag(max(0, se² - max se_b²))``): a test that
estimated its parameters worse than any baseline test is not taken as a
change for that (beyond the baseline's worst, so that the ordinary
test-to-test scatter of the standard errors leaves the rate as stated).
The alarm is ``p < alpha``, so that ``alpha`` *is* the false-alarm probability of
one check of a healthy unit. A rank its ``n`` tests could show by
themselves (``r >= n - 1``) says nothing of the parameters' structure: then
each parameter's ``t = d / sqrt(s²(1 + 1/n) + e)`` (``t(n - 1)``) is tested
with Šidák's correction over the distinct parameters (``max-t``;
conservative when parameters correlate).

**Drift.** A slow wear moves each check a little: too little for either test
above until late. The drift test is the likelihood-ratio (GLR) test of a
straight-line trend in the ``m >= 3`` checks since the baseline, level free:
the slope vector ``b`` [% per check] of the checks against their order, whose
covariance under no drift is ``Σ / Sxx``; ``Σ`` is pooled from the baseline's
scatter and the checks' own residuals about the line (``ν = n + m - 3``
degrees of freedom), so

    T²_drift = Sxx bᵀ Σ̂⁻¹ b,      F = T²_drift (ν - r + 1) / (r ν) ~ F(r, ν - r + 1).

Its alarm, ``p < drift_alpha``, has false-alarm probability ``drift_alpha`` at
each check. The slope does not depend on the baseline's mean, so an unlucky
baseline (its mean off by its own noise) raises no drift alarm, which a CUSUM
on the changes would. Checks that wander from test to test (a machine's
warm-up) are serially correlated and hold fewer independent checks: the
slope's variance is taken ``(1 + ρ)/(1 - ρ)`` times larger, ``ρ`` the lag-one
autocorrelation of the residuals with its small-sample bias added back
(Kendall's ``(1 + 3ρ)/m``), clipped to [0, 0.95] (6 checks or more).

**Calibration.** Both rates hold when the baseline's tests span the unit's
healthy scatter. From 5 earlier checks on, their variance (half the mean
squared successive difference: blind to a drift or one step) is compared with
the baseline's per parameter (``F(2(k-1)/3, n-1)``, 1 % over the parameters);
too large a ratio sets ``calibrated`` false and the line says so.

Both are exact for normal estimates; the benchmark
(``benchmarks/bench_prognostics.py``) measures the rates on simulated checks.

How they combine with the fuzzy status: the change test governs it
(:func:`governed_status`): a check whose change test does not alarm is
``go``, so that its stated false-alarm probability bounds the rate at which
a healthy unit's checks are flagged; with an alarm the fuzzy diagnoser's
status stands and names the fault (an alarm under ``go`` is a change beyond
the healthy scatter, below the fault breakpoints: said beside it, a reason
to look, not to stop). The drift test is shown beside the status.

Why by hand: scipy has the F and t distributions but no Hotelling prediction
or drift test with a rank-deficient covariance, and the change-detection
libraries (ruptures, the CUSUM of statsmodels) work on one raw signal, not a
parameter vector against a baseline of its own scatter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import DataError
from condmon.monitor.distributions import f_sf, t_cdf, t_ppf

__all__ = ["StatisticsConfig", "CheckStatistics", "check_statistics", "checked_alpha",
           "governed_status", "can_govern", "NOGO_SCATTERS"]

FloatArray = NDArray[np.float64]

#: Fewest checks since the baseline the drift test needs.
MIN_DRIFT_CHECKS = 3
_RANK_TOL = 1e-8
#: Earlier checks needed, and the level, to say the baseline's scatter is too narrow.
_SCATTER_CHECKS = 5
_SCATTER_LEVEL = 0.01
#: Checks needed before their serial correlation is estimated.
_SERIAL_CHECKS = 6


def checked_alpha(value: Any, what: str = "alpha") -> float:
    """``value`` as a false-alarm probability in (0, 0.5), else a DataError naming it.

    Example
    -------
    >>> checked_alpha("0.01")
    0.01
    """
    try:
        if isinstance(value, bool):
            raise TypeError
        a = float(value)
    except (TypeError, ValueError):
        raise DataError(f"{what} must be a number in (0, 0.5), not {value!r}") from None
    if not 0.0 < a < 0.5:
        raise DataError(f"{what} must be a false-alarm probability in (0, 0.5), not {a:g}")
    return a


@dataclass(frozen=True)
class StatisticsConfig:
    """False-alarm probabilities of the statistical detectors (the monitor file's
    ``[statistics]`` table).

    Attributes
    ----------
    alpha : float
        Of one check's change test. [-]
    drift_alpha : float
        Of the drift test at one check. [-]
    """

    alpha: float = 0.01
    drift_alpha: float = 0.01


@dataclass(frozen=True)
class CheckStatistics:
    """The calibrated tests of one check.

    Attributes
    ----------
    statistic : float
        Hotelling's T² of the change vector (``max-t``: the largest |t|). [-]
    p_value : float
        Its probability under no change. [-]
    alpha : float
        The false-alarm probability it is tested at. [-]
    alarm : bool
        ``p_value < alpha``.
    method : {"hotelling", "max-t"}
        The test whose p was the smaller (with two directions or more both
        run, ``p_value`` their Simes combination).
    parameters : tuple of str
        The parameters tested (a regime's as ``Tc@forward``).
    rank : int
        Independent directions among them. [-]
    tests : int
        Baseline tests the scatter comes from. [-]
    drift_statistic, drift_p_value : float or None
        The drift test's T² (or largest |t|) and probability under no drift;
        None with fewer than 3 checks since the baseline. [-]
    drift_alpha : float
        Its false-alarm probability per check. [-]
    drift_alarm : bool or None
    drift_slope : dict of str to float
        The fitted slope of each parameter's change. [% per check]
    checks : int
        Checks since the baseline, this one included. [-]
    scatter_ratio : dict of str to float
        The checks' own test-to-test variance (half the mean squared
        difference of successive checks before this one: blind to a slow
        drift or a step) over the baseline's, per parameter; empty with fewer
        than 5 earlier checks. [-]
    calibrated : bool
        False when that ratio is too large to be chance (1 % over all the
        parameters): the baseline's tests do not span this unit's healthy
        scatter, so the alarms are not at the stated rates.
    largest : str
        ``max-t``: the parameter of the largest |t| (its change over its own
        scatter, not the largest change in %). "" for ``hotelling``.
    """

    statistic: float
    p_value: float
    alpha: float
    alarm: bool
    method: str
    parameters: tuple[str, ...]
    rank: int
    tests: int
    drift_statistic: float | None
    drift_p_value: float | None
    drift_alpha: float
    drift_alarm: bool | None
    drift_slope: dict[str, float]
    checks: int
    scatter_ratio: dict[str, float] = field(default_factory=dict)
    calibrated: bool = True
    largest: str = ""

    @property
    def any_alarm(self) -> bool:
        """Either test alarms."""
        return self.alarm or bool(self.drift_alarm)

    def describe(self, status: str | None = None) -> str:
        """One line for a person: both tests, and what an alarm under ``go`` means."""
        level = (f"change T² {self.statistic:.3g}, p {self.p_value:.2g}"
                 if self.method == "hotelling" else
                 f"change max |t| {self.statistic:.3g}"
                 + (f" ({self.largest})" if self.largest else "")
                 + f", p {self.p_value:.2g}")
        drift = ("drift: fewer than 3 checks since the baseline" if self.drift_p_value is None
                 else f"drift p {self.drift_p_value:.2g}")
        alarms = [n for n, a in (("change", self.alarm), ("drift", self.drift_alarm)) if a]
        verdict = (f"ALARM ({' and '.join(alarms)})" if alarms else "no alarm")
        line = (f"statistics: {verdict}; {level} (α {self.alpha:g}); {drift} "
                f"(α {self.drift_alpha:g})")
        if alarms and status == "go":
            line += ("; statistical alarm under go: a change beyond the healthy scatter, "
                     "below the fault breakpoints")
        if not self.calibrated:
            wide = sorted(self.scatter_ratio, key=lambda k: -self.scatter_ratio[k])[:2]
            scatter = ("this unit's checks scatter "
                       + ", ".join(f"{self.scatter_ratio[k]:.2g}x" + f" ({k})" for k in wide)
                       + " the variance of its baseline's tests")
            # a change under way (a fault, a drift alarm) scatters the checks too:
            # rebuilding the baseline from them would bury it
            line += (f"; {scatter}: a diagnosed fault's own change may do that, the rates "
                     "are stated for a healthy unit" if status in ("advisory", "no-go") else
                     f"; {scatter}: the change the alarm shows may do that; do not rebuild "
                     "the baseline from these checks" if alarms else
                     f"; NOT at the stated rates: {scatter}: rebuild the baseline from tests "
                     "that span its operating conditions (sessions, temperatures)")
        return line

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (the ``statistics`` of ``condmon check --json``)."""
        return {"statistic": self.statistic, "p_value": self.p_value, "alpha": self.alpha,
                "alarm": self.alarm, "method": self.method, "parameters": list(self.parameters),
                "rank": self.rank, "baseline_tests": self.tests,
                "drift_statistic": self.drift_statistic, "drift_p_value": self.drift_p_value,
                "drift_alpha": self.drift_alpha, "drift_alarm": self.drift_alarm,
                "drift_slope_percent_per_check": self.drift_slope, "checks": self.checks,
                "scatter_ratio": self.scatter_ratio, "calibrated": self.calibrated,
                "largest_t": self.largest or None}


def _distinct(S: FloatArray) -> int:
    """Parameters that are not exact multiples of another (``Ke`` and ``Kt`` count once)."""
    scale = np.sqrt(np.clip(np.diag(S), 1e-300, None))
    R = np.abs(S / np.outer(scale, scale))
    seen: set[int] = set()
    groups = 0
    for i in range(len(R)):
        if i not in seen:
            groups += 1
            seen.update(int(j) for j in np.flatnonzero(R[i] > 1.0 - _RANK_TOL))
    return groups


def _test(z: FloatArray, scatter: FloatArray, factor: float, extra: FloatArray, dof: float,
          distinct: int, *, both: bool = False) -> tuple[float, float, str, int, int]:
    """Statistic, p, method and rank of ``z`` against ``scatter`` (estimated on
    ``dof`` degrees of freedom) times ``factor``, plus ``extra``.

    Hotelling's T² in the directions the scatter spans when its rank is the
    parameters' own (below ``dof``: a rank ``dof`` tests could show by
    themselves says nothing of the structure); else the largest |t| with
    Šidák's correction over the ``distinct`` parameters. ``both``: with two
    directions or more, both tests, their p combined by Simes, the method and
    statistic those of the smaller p. Last, the index of the largest |t|.
    """
    scale = np.sqrt(np.clip(np.diag(scatter), 1e-300, None))
    w, V = np.linalg.eigh(scatter / np.outer(scale, scale))
    keep = w > _RANK_TOL * max(float(w[-1]), 1e-300)
    r = int(np.count_nonzero(keep))
    t = z / np.sqrt(np.clip(np.diag(scatter) * factor + np.diag(extra), 1e-300, None))
    top = int(np.argmax(np.abs(t)))
    big = float(abs(t[top]))
    p1 = min(2.0 * t_cdf(dof, -big), 1.0 - 1e-16)
    p_max = float(min(1.0, -math.expm1(distinct * math.log1p(-p1))))
    if 1 <= r < dof:
        W = V[:, keep] / scale[:, None]
        zw = W.T @ z
        t2 = float(zw @ np.linalg.solve(W.T @ (scatter * factor + extra) @ W, zw))
        p_t2 = float(f_sf(r, dof - r + 1, t2 * (dof - r + 1) / (r * dof)))
        if not both or r < 2:
            return t2, p_t2, "hotelling", r, top
        p = min(1.0, 2.0 * min(p_t2, p_max), max(p_t2, p_max))
        return (t2, p, "hotelling", r, top) if p_t2 <= p_max else (big, p, "max-t", r, top)
    return big, p_max, "max-t", distinct, top


def check_statistics(parameters: tuple[str, ...], change: ArrayLike, se: ArrayLike,
                     baseline_changes: ArrayLike, baseline_se: ArrayLike,
                     series: ArrayLike, config: StatisticsConfig = StatisticsConfig()
                     ) -> CheckStatistics:
    """The change and drift tests of one check.

    Parameters
    ----------
    parameters : tuple of str
        Names of the columns below.
    change : array_like, shape (p,)
        The check's change against the baseline mean. [%]
    se : array_like, shape (p,)
        The check's standard errors. [% of the baseline mean]
    baseline_changes : array_like, shape (n, p)
        Each baseline test's change against the baseline mean. [%]
    baseline_se : array_like, shape (n, p)
        Their standard errors. [% of the baseline mean]
    series : array_like, shape (m, p)
        The checks since the baseline, in order, this one last. [%]
    config : StatisticsConfig

    Raises
    ------
    DataError
        Fewer than 3 baseline tests, shapes that differ, a non-finite value.

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> base = rng.normal(0.0, 1.0, (20, 2))
    >>> s = check_statistics(("R", "D"), [0.5, -0.3], [1.0, 1.0], base, np.ones((20, 2)),
    ...                      [[0.1, 0.2], [-0.4, 0.0], [0.5, -0.3]])
    >>> s.method, s.alarm, s.drift_alarm
    ('hotelling', False, False)
    >>> check_statistics(("R", "D"), [9.0, 0.0], [1.0, 1.0], base, np.ones((20, 2)),
    ...                  [[0.0, 0.0]]).alarm          # 9 baseline spreads
    True
    """
    d = np.asarray(change, dtype=np.float64).reshape(-1)
    e = np.asarray(se, dtype=np.float64).reshape(-1)
    B = np.asarray(baseline_changes, dtype=np.float64)
    Bse = np.asarray(baseline_se, dtype=np.float64)
    Y = np.asarray(series, dtype=np.float64)
    Y = Y.reshape(1, -1) if Y.ndim == 1 else Y
    p, n = d.size, B.shape[0] if B.ndim == 2 else 0
    if p == 0 or len(parameters) != p or B.shape != (n, p) or Bse.shape != (n, p) \
            or e.size != p or Y.ndim != 2 or Y.shape[1] != p:
        raise DataError("statistics: the change, its errors and the baseline differ in shape")
    if n < 3:
        raise DataError(f"statistics: the baseline has {n} complete test(s), need 3")
    if not all(np.all(np.isfinite(a)) for a in (d, e, B, Bse, Y)):
        raise DataError("statistics: a change or standard error is not finite")
    S = np.cov(B, rowvar=False, ddof=1).reshape(p, p)
    distinct = _distinct(S)
    # a test estimated worse than every baseline test: its excess noise is no change
    extra = np.diag(np.clip(e ** 2 - np.max(Bse ** 2, axis=0), 0.0, None))
    stat, pv, method, r, top = _test(d, S, 1.0 + 1.0 / n, extra, n - 1, distinct, both=True)
    # which parameter the largest |t| is: a small change of a quiet parameter may
    # be it, not the largest change in %
    largest = parameters[top] if method == "max-t" else ""
    m = Y.shape[0]
    dstat = dp = None
    slope = np.full(p, np.nan)
    if m >= MIN_DRIFT_CHECKS:
        x = np.arange(m, dtype=np.float64)
        x -= x.mean()
        sxx = float(x @ x)
        slope = (x @ (Y - Y.mean(axis=0))) / sxx
        resid = Y - Y.mean(axis=0) - np.outer(x, slope)
        nu = n + m - 3
        pooled = (S * (n - 1) + resid.T @ resid) / nu
        rho = _serial(resid)
        # a serially correlated series (a warm-up within each session) holds
        # fewer independent checks: the slope's variance grows by (1+ρ)/(1-ρ)
        dstat, dp, _, _, _ = _test(slope * math.sqrt(sxx), pooled, (1.0 + rho) / (1.0 - rho),
                                np.zeros((p, p)), nu, distinct)
    ratio, calibrated = _scatter_check(Y[:-1], S, n, distinct)
    return CheckStatistics(stat, pv, config.alpha, pv < config.alpha, method, tuple(parameters),
                           r, n, dstat, dp, config.drift_alpha,
                           None if dp is None else dp < config.drift_alpha,
                           {k: float(v) for k, v in zip(parameters, slope)
                            if math.isfinite(v)}, m,
                           {k: float(v) for k, v in zip(parameters, ratio)}, calibrated,
                           largest)


def _serial(resid: FloatArray) -> float:
    """Lag-one autocorrelation of the checks' residuals about their line, over
    the parameters, with the short-series bias of its estimate added back
    (Kendall's ``(1 + 3ρ)/m``), clipped to [0, 0.95] (0 with fewer than 6 checks)."""
    m = resid.shape[0]
    den = float(np.sum(resid ** 2))
    if m < _SERIAL_CHECKS or den <= 0:
        return 0.0
    rho = float(np.sum(resid[1:] * resid[:-1])) / den
    return float(np.clip(rho + (1.0 + 3.0 * rho) / m, 0.0, 0.95))


def _scatter_check(earlier: FloatArray, S: FloatArray, n: int, distinct: int
                   ) -> tuple[FloatArray, bool]:
    """The earlier checks' variance over the baseline's, per parameter, and
    whether it can be chance.

    The checks' variance is half their mean squared successive difference (von
    Neumann's): a slow drift or one step barely moves it. Its ratio to the
    baseline's variance is read as ``F(ν, n - 1)`` with ``ν = 2(k - 1)/3`` (the
    successive differences' efficiency), at 1 % over the ``distinct``
    parameters (Bonferroni).
    """
    k = earlier.shape[0]
    if k < _SCATTER_CHECKS:
        return np.zeros(0), True
    q = np.mean(np.diff(earlier, axis=0) ** 2, axis=0) / 2.0
    ratio = q / np.clip(np.diag(S), 1e-300, None)
    nu = 2.0 * (k - 1) / 3.0
    p = f_sf(nu, n - 1, ratio)
    return ratio, bool(np.min(p) >= _SCATTER_LEVEL / max(distinct, 1))


#: Where the generic monitor's symptom reaches the no-go degree, in scatters of
#: the baseline (r1 - k + 0.727 (k + r2 - r1) with r1, r2, k = 4, 8, 2; see
#: condmon.forecast.unit.NoGo): the change a governing test must be able to confirm.
NOGO_SCATTERS = 6.36


def can_govern(stats: CheckStatistics) -> bool:
    """Whether the change test of a baseline of ``stats.tests`` tests can
    confirm a change the fuzzy monitor calls no-go: its critical ``|t|``
    (Šidák over the parameters, the mean's own error in) no larger than the
    no-go point of a scatter of that many tests (:data:`NOGO_SCATTERS`, the
    scatter widened by ``t(n-1, 0.975)/z`` as the breakpoints are). With few
    tests the test's heavy tails make it blind to any change: it cannot
    govern then.

    Example
    -------
    >>> mk = lambda n: CheckStatistics(0.0, 1.0, 0.01, False, "max-t", ("R", "L", "D"), 1, n,
    ...                                None, None, 0.01, None, {}, 1)
    >>> can_govern(mk(3)), can_govern(mk(10))
    (False, True)
    """
    n = stats.tests
    if n < 3:
        return False
    k = max(len(stats.parameters), 1)
    crit = t_ppf(float(n - 1), 1.0 - stats.alpha / (2.0 * k)) * math.sqrt(1.0 + 1.0 / n)
    return crit <= NOGO_SCATTERS * t_ppf(float(n - 1), 0.975) / 1.959963984540054


def governed_status(status: str, stats: CheckStatistics, changes: dict[str, float],
                    scatter: dict[str, float]) -> tuple[str, str]:
    """The status a check takes once its calibrated change test governs it, and why.

    The change test's false-alarm probability ``alpha`` is the one stated for
    a check of a healthy unit, so it decides whether the check shows a
    change at all: with no alarm (``p >= alpha``) the check is ``go``
    whatever the fuzzy monitor's breakpoints say, its change being within
    the healthy scatter. With an alarm the fuzzy status stands: it says
    whether the change matters (a change beyond the scatter but below the
    fault breakpoints stays ``go``, the alarm said beside it) and which fault.
    A baseline of too few tests for the test to confirm a no-go
    (:func:`can_govern`) leaves the fuzzy status as it is.

    Parameters
    ----------
    status : str
        The fuzzy diagnoser's.
    stats : CheckStatistics
    changes : dict of str to float
        The check's change per parameter. [%]
    scatter : dict of str to float
        Each parameter's baseline scatter. [% of the mean]

    Returns
    -------
    status : str
    why : str
        "" when the fuzzy status stands.

    Example
    -------
    >>> s = CheckStatistics(3.0, 0.2, 0.01, False, "max-t", ("R",), 1, 10, None, None,
    ...                     0.01, None, {}, 1)
    >>> governed_status("advisory", s, {"R": 9.0}, {"R": 3.0})[0]
    'go'
    >>> a = CheckStatistics(9.0, 1e-6, 0.01, True, "max-t", ("R",), 1, 10, None, None,
    ...                     0.01, None, {}, 1)
    >>> governed_status("no-go", a, {"R": 60.0}, {"R": 2.0})
    ('no-go', '')
    """
    if not stats.alarm and status in ("advisory", "no-go") and can_govern(stats):
        z = {k: abs(v) / scatter[k] for k, v in changes.items()
             if k in scatter and scatter[k] > 0 and math.isfinite(v)}
        top = max(z, key=lambda k: z[k]) if z else None
        what = (f" (largest: {top} {changes[top]:+.1f} %, {z[top]:.1f} scatters)"
                if top is not None else "")
        return "go", (f"not shown beyond the healthy scatter{what}: the change test's p "
                      f"{stats.p_value:.2g} >= α {stats.alpha:g}, so the fuzzy monitor's "
                      f"{status} is not taken")
    return status, ""
