"""Whether a baseline can be trusted: robust outliers, and a trend in time order
(a warm-up, a drift) with what to do about it; the record-to-record scatter noted.

A baseline's tests should be one stationary sample of the healthy unit: the
same condition, scattering from test to test. Two things break that and are
flagged (:func:`assess_baseline`): a test far from the others (a robust
outlier), and a mean that moves with time (:func:`baseline_trends`). A
scatter wider than the estimates' standard errors breaks nothing: real
machines scatter by several times that from test to test, and the baseline's
sample standard deviation, which holds it, is the yardstick a check is
measured against; :func:`baseline_scatter` notes it as information.

The trend's t distribution is :func:`condmon.monitor.distributions.t_cdf`
(scipy's ``stdtr`` to 1e-13) rather than ``scipy.stats.t``: a check that
saves its unit's first baseline version runs this test, and a check loads no
scipy (about 0.35 s of imports).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import ConfigError
from condmon.monitor.distributions import t_cdf
from condmon.monitor.statistics import _serial

__all__ = ["MIN_BASELINE_TESTS", "INFO_KINDS", "is_warning", "BaselineChecks", "Trend",
           "baseline_trends", "assess_baseline", "baseline_scatter"]

FloatArray = NDArray[np.float64]

#: Fewest accepted healthy tests a baseline is computed from.
MIN_BASELINE_TESTS = 3

#: Kinds of baseline entries that inform and do not warn: ``scatter`` (the
#: record-to-record scatter against the estimates' standard errors) and
#: ``spread``, the same ratio as older versions stored it among the flags.
INFO_KINDS = frozenset({"scatter", "spread"})


def is_warning(entry: Mapping[str, Any]) -> bool:
    """Whether a baseline entry says the baseline may not be trusted (not a note).

    Example
    -------
    >>> is_warning({"kind": "trend"}), is_warning({"kind": "scatter"})
    (True, False)
    """
    return entry.get("kind") not in INFO_KINDS


@dataclass(frozen=True)
class BaselineChecks:
    """When a baseline is flagged, and when its scatter is noted (the
    ``[baseline]`` table of a monitor file).

    Attributes
    ----------
    outlier_z : float
        Robust z-score (``0.6745 |x - median| / MAD``) above which a test is an
        outlier ... [-]
    outlier_se : float
        ... provided it is also this many of its own standard errors from the
        median (so a tiny MAD among a few tests raises no false flag) ... [-]
    outlier_alpha : float
        ... and, when the tests scatter more than ``spread_ratio`` times their
        standard errors (so that these say nothing of the scatter), provided
        it also stands out of the others' scatter: Rosner's generalized ESD
        test at this false-alarm probability over all the parameters, in
        (0, 0.5). [-]
    spread_ratio : float
        A parameter's record-to-record sample standard deviation over the RMS
        of the tests' own standard errors above which the scatter is noted
        (:func:`baseline_scatter`): information, not a warning, since a
        check's yardstick is that scatter. [-]
    trend_alpha : float
        False-alarm probability of the trend test of a stationary baseline
        (:func:`baseline_trends`), over all its parameters, in (0, 0.5). [-]

    Raises
    ------
    ConfigError
        ``trend_alpha`` or ``outlier_alpha`` outside (0, 0.5).

    Example
    -------
    >>> BaselineChecks(trend_alpha=0.05).trend_alpha
    0.05
    """

    outlier_z: float = 3.5
    outlier_se: float = 4.0
    spread_ratio: float = 3.0
    trend_alpha: float = 0.01
    outlier_alpha: float = 0.01

    def __post_init__(self) -> None:
        for key in ("trend_alpha", "outlier_alpha"):
            value = getattr(self, key)
            if not 0.0 < value < 0.5:
                raise ConfigError(f"[baseline] {key} must be a false-alarm probability in "
                                  f"(0, 0.5), not {value!r}")


@dataclass(frozen=True)
class Trend:
    """The least-squares trend of one parameter over a baseline's tests in time order.

    Attributes
    ----------
    parameter : str
    slope : float
        Change from one test to the next. [parameter units / test]
    slope_percent : float
        ``slope`` in % of the parameter's mean over the tests. [% / test]
    se : float
        Standard error of ``slope`` from the residuals of all the tests, its
        variance widened by ``(1 + ρ)/(1 - ρ)``. [parameter units / test]
    p : float
        Two-sided p value of the slope, this parameter alone: the smaller of
        its two t tests (see :func:`baseline_trends`), doubled. [-]
    p_family : float
        ``p`` with Šidák's correction over the parameters tested
        (``1 - (1 - p)^P``): the trend is significant when it is below the
        false-alarm rate. [-]
    rho : float
        Lag-one autocorrelation of the later half's residuals about their own
        line (bias added back, clipped to [0, 0.95]; 0 with fewer than 6
        tests in that half). [-]
    n : int
        Tests that have the parameter.
    significant : bool
        ``p_family`` below the false-alarm rate asked for.
    """

    parameter: str
    slope: float
    slope_percent: float
    se: float
    p: float
    p_family: float
    rho: float
    n: int
    significant: bool


def _fit(x: FloatArray, y: FloatArray) -> tuple[float, FloatArray, float]:
    """Slope, residuals and ``Sxx`` of the least-squares line of ``y`` on ``x``."""
    xc = x - x.mean()
    sxx = float(xc @ xc)
    slope = float(xc @ (y - y.mean())) / sxx
    return slope, y - y.mean() - slope * xc, sxx


def _two_sided(slope: float, var: float, dof: float) -> float:
    """Two-sided p value of ``slope`` with variance ``var`` on ``dof`` degrees of freedom."""
    if var <= 0:
        return 0.0 if slope != 0 else 1.0
    return min(1.0, 2.0 * t_cdf(dof, -abs(slope) / math.sqrt(var)))


def _line(x: FloatArray, y: FloatArray) -> tuple[float, float, float, float]:
    """Slope, its standard error (all residuals), p (the two t tests') and ρ
    of the least-squares line of ``y`` on ``x`` (3 points or more)."""
    m = len(y)
    if float(np.ptp(y)) <= 1e-12 * float(np.max(np.abs(y))):  # constant: no trend
        return 0.0, 0.0, 1.0, 0.0
    slope, resid, sxx = _fit(x, y)
    later = m // 2
    k = m - later
    late = _fit(x[later:], y[later:])[1] if k >= 3 else np.zeros(0)
    # serially correlated tests (one session's warm-up) hold fewer independent
    # ones: the slope's variance is (1 + ρ)/(1 - ρ) times the white-noise one
    # (ρ from the later half: about one line through all the tests, a leading
    # warm-up's misfit looks like serial correlation and would hide itself)
    widen = 1.0
    if k >= 3:
        rho = _serial(late)
        widen = (1.0 + rho) / (1.0 - rho)
    else:
        rho = 0.0
    var = float(resid @ resid) / (m - 2) / sxx * widen
    p = _two_sided(slope, var, m - 2.0)
    if k >= 3:  # the later half's scatter: no warm-up's misfit in it
        p = min(1.0, 2.0 * min(p, _two_sided(slope, float(late @ late) / (k - 2) / sxx * widen,
                                             k - 2.0)))
    return slope, math.sqrt(var), p, rho


def _distinct(x: FloatArray, cols: Sequence[int]) -> int:
    """Columns that are not exact multiples of another (``Ke`` and ``Kt`` count once)."""
    groups: list[int] = []
    for j in cols:
        for g in groups:
            both = np.isfinite(x[:, j]) & np.isfinite(x[:, g])
            a, b = x[both, j], x[both, g]
            if both.sum() >= 3 and np.ptp(a) > 0 and np.ptp(b) > 0 and abs(
                    float(np.corrcoef(a, b)[0, 1])) > 1.0 - 1e-8:
                break
        else:
            groups.append(j)
    return len(groups)


def baseline_trends(values: ArrayLike, parameters: Sequence[str], alpha: float = 0.01
                    ) -> tuple[Trend, ...]:
    """Test each parameter of a baseline for a trend over its tests in time order.

    A warm-up or a drift makes a baseline's mean depend on when its tests
    were taken. Each parameter's values are fitted with a least-squares line
    against the tests' order (0, 1, 2, ... over the baseline's tests; a test
    lacking the parameter keeps its place), and the slope is tested against
    two estimates of its noise, each an exact t test of a stationary
    baseline: the residuals of all ``n`` tests (``t(n - 2)``; the most
    power against a steady drift), and the residuals of the later ``k =
    ⌈n/2⌉`` tests about their own line (``t(k - 2)``; independent of the
    slope, and untouched by a leading warm-up, whose misfit inflates the
    first). The smaller p, doubled (Bonferroni), is the parameter's. At
    0.2 % (1 % over 5 parameters), of 3000 draws of 20 tests, a warm-up of
    the first 4 at 15, 11, 8 and 6 standard deviations was found in 52 % by
    the first test, 99.8 % by the second and 99.6 % by both; a drift of a
    quarter standard deviation per test in 96 %, 85 % and 94 %.
    Tests of one session wander together, so the slope's variance is widened
    by ``(1 + ρ)/(1 - ρ)``, ``ρ`` the lag-one autocorrelation of the later
    half's residuals as the drift test of :mod:`condmon.monitor.statistics`
    takes it (small-sample bias added back, clipped to [0, 0.95], 0 from
    fewer than 6 residuals); about one line through all the tests a
    warm-up's misfit would pass for serial correlation and hide itself (the
    warm-up above was found in none of the 3000 draws so). A trend is
    significant when its p value, with Šidák's correction over the distinct
    parameters tested (``Ke`` and ``Kt`` in SI units count once), is below
    ``alpha``: a stationary baseline of independent tests is flagged with
    probability at most ``alpha``. Serially correlated tests are flagged
    more often: ``ρ`` estimated from 10 tests falls short of the truth.

    Parameters
    ----------
    values : array_like, shape (N, P)
        Estimates, one row per test in time order (NaN: the test lacks the
        parameter). [parameter units]
    parameters : sequence of str
    alpha : float
        False-alarm probability over the parameters. [-]

    Returns
    -------
    tuple of Trend
        One per parameter with at least 3 tests.

    Example
    -------
    >>> ramp = [[1.0 + 0.01 * i + 0.002 * (-1) ** i] for i in range(10)]
    >>> flat = [[1.0 + 0.002 * (-1) ** i] for i in range(10)]
    >>> [t.significant for t in baseline_trends(ramp, ["R"]) + baseline_trends(flat, ["R"])]
    [True, False]
    >>> round(baseline_trends(ramp, ["R"])[0].slope_percent, 2)
    0.95
    """
    x = np.atleast_2d(np.asarray(values, dtype=np.float64))
    names = list(parameters)
    cols = [j for j in range(len(names)) if np.isfinite(x[:, j]).sum() >= MIN_BASELINE_TESTS]
    if not cols:
        return ()
    family = _distinct(x, cols)
    out = []
    for j in cols:
        have = np.isfinite(x[:, j])
        y = x[have, j]
        slope, se, p, rho = _line(np.flatnonzero(have).astype(np.float64), y)
        p_family = float(min(1.0, -math.expm1(family * math.log1p(-min(p, 1.0 - 1e-16)))))
        scale = abs(float(np.mean(y))) or 1.0
        out.append(Trend(names[j], slope, 100.0 * slope / scale, se, p, p_family, rho,
                         int(have.sum()), p_family < alpha))
    return tuple(out)


def _outliers(col: FloatArray, s: FloatArray, cfg: BaselineChecks, family: int = 1
              ) -> tuple[NDArray[np.bool_], float, FloatArray]:
    """Which values are outliers, the median and each value's distance from it.

    An outlier's median/MAD z-score exceeds ``outlier_z`` and it lies more
    than ``outlier_se`` of its own standard errors from the median. When the
    values scatter more than ``spread_ratio`` times their standard errors
    (sample standard deviation against the RMS standard error), the
    standard errors guard nothing and a few tests' MAD is a poor scale
    (healthy 6-parameter baselines of 5 to 20 tests with a 2 % scatter and
    0.2 % standard errors: a z above 3.5 in 59 % to 34 % of them): it must
    then also be one of the generalized ESD test's outliers (:func:`_esd`)
    at ``outlier_alpha`` over the ``family`` parameters. So must it with
    :data:`_ESD_TESTS` tests or more, whatever the standard errors: a MAD of
    ten tests is still a noisy scale (healthy 5-parameter baselines of 10
    tests scattering 2 % with standard errors of 1 %: 7 of 30 flagged by the
    z and SE rule alone).
    """
    med = float(np.median(col))
    dev = np.abs(col - med)
    mad = float(np.median(dev))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(mad > 0, 0.6745 * dev / mad, np.where(dev > 0, np.inf, 0.0))
        in_se = np.where(np.isfinite(s) & (s > 0), dev / s, np.inf)
    off = (z > cfg.outlier_z) & (in_se > cfg.outlier_se)
    good = np.isfinite(s) & (s > 0)
    rms_se = float(np.sqrt(np.mean(s[good] ** 2))) if good.any() else 0.0
    if off.any() and (float(np.std(col, ddof=1)) > cfg.spread_ratio * rms_se
                      or len(col) >= _ESD_TESTS):
        level = -math.expm1(math.log1p(-cfg.outlier_alpha) / max(family, 1))
        off &= _esd(col, level)
    return off, med, dev


#: Tests from which an outlier must also pass the calibrated ESD test (below it the
#: ESD test has little power, and the z and standard-error rule stands alone).
_ESD_TESTS = 6


def _esd(col: FloatArray, alpha: float) -> NDArray[np.bool_]:
    """Rosner's (1983) generalized ESD test: the outliers among ``col``, up to
    ``⌊(n - 1)/2⌋`` of them, with false-alarm probability about ``alpha``.

    The most extreme value (``R = max |x - mean| / sd``) is taken out, again
    and again; the outliers are those taken out up to the last step whose
    ``R`` exceeds its critical value, found from ``t(m - 2)`` at
    ``1 - alpha / (2m)`` (``m`` the values left): one outlier masking
    another is still found.
    """
    n = len(col)
    left = list(range(n))
    taken: list[int] = []
    found = 0
    for step in range(1, (n - 1) // 2 + 1):
        vals = col[left]
        m = len(vals)
        sd = float(np.std(vals, ddof=1))
        if m < 3 or sd <= 0:
            break
        k = int(np.argmax(np.abs(vals - vals.mean())))
        r2 = float((vals[k] - vals.mean()) / sd) ** 2
        room = (m - 1.0) ** 2 - m * r2  # R = λ(t) solved for t
        t = math.inf if room <= 0 else math.sqrt(m * (m - 2.0) * r2 / room)
        if 2.0 * m * t_cdf(m - 2.0, -t) < alpha:
            found = step
        taken.append(left.pop(k))
    out = np.zeros(n, dtype=bool)
    out[taken[:found]] = True
    return out


def _remnant(rest: FloatArray, hits: Sequence[Trend], columns: Sequence[int],
             alpha: float) -> bool:
    """Whether the first test of ``rest`` is still off the others the way the
    leading tests were (a warm-up's last test): its prediction ``t`` against
    the later tests' mean and standard deviation, one-sided (the leading
    tests lie where the slope came from), Šidák over the trending parameters."""
    worst = 1.0
    for trend, j in zip(hits, columns):
        have = np.flatnonzero(np.isfinite(rest[:, j]))
        if len(have) < MIN_BASELINE_TESTS:
            continue
        first, later = rest[have[0], j], rest[have[1:], j]
        sd = float(np.std(later, ddof=1))
        off = -math.copysign(1.0, trend.slope) * (first - float(np.mean(later)))
        if sd <= 0:
            p = 0.0 if off > 0 else 1.0
        else:
            p = t_cdf(len(later) - 1.0, -off / (sd * math.sqrt(1.0 + 1.0 / len(later))))
        worst = min(worst, p)
    return -math.expm1(len(hits) * math.log1p(-min(worst, 1.0 - 1e-16))) < alpha


def _stopped(full: Trend, rest: Trend, alpha: float) -> bool:
    """Whether the rest's slope is below the whole baseline's, one-sided at
    ``alpha``: the trend has stopped, not gone on unseen among fewer tests."""
    drop = math.copysign(1.0, full.slope) * (full.slope - rest.slope)
    if rest.se <= 0:
        return drop > 0
    return t_cdf(rest.n - 2.0, -drop / rest.se) < alpha


def _leading_cut(x: FloatArray, parameters: Sequence[str], hits: Sequence[Trend],
                 alpha: float) -> tuple[int | None, int]:
    """The fewest leading tests whose removal leaves tests without a trend, and
    the fewest tests that must be left.

    Without them no parameter trends among the rest; each trending
    parameter's slope among the rest is significantly below its slope over
    all the tests (a drift that goes on would pass the trend test of fewer
    tests only for want of power); and the first test kept is not off the
    others as the leading tests were (:func:`_remnant`: a one-test remnant
    of a warm-up leaves no significant slope but is still off). Each at
    ``alpha``. At least ``max(3, ⌈N/2⌉)`` tests must be left: a "warm-up"
    longer than what follows it is a drift. None when no such number exists.
    """
    n = x.shape[0]
    least = max(MIN_BASELINE_TESTS, (n + 1) // 2)
    cols = [list(parameters).index(t.parameter) for t in hits]
    for k in range(1, n - least + 1):
        rest = x[k:]
        trends = {t.parameter: t for t in baseline_trends(rest, parameters, alpha)}
        if any(t.significant for t in trends.values()):
            continue
        if not all(t.parameter in trends and _stopped(t, trends[t.parameter], alpha)
                   for t in hits):
            continue
        if _remnant(rest, hits, cols, alpha):
            continue
        return k, least
    return None, least


def _trend_flag(trend: Trend, cut: int | None, least: int, ids: Sequence[int],
                alpha: float, family: int) -> dict[str, Any]:
    """The flag of one trending parameter, with what to do about it."""
    n = len(ids)
    text = (f"{trend.parameter}: the baseline's tests trend in time order, "
            f"{trend.slope_percent:+.3g} % of the mean per test (p = {trend.p_family:.1g} "
            f"< {alpha:g}, over {family} parameter{'s' if family != 1 else ''})")
    if cut is not None:
        leave, keep = list(ids[:cut]), list(ids[cut:])
        text += (f"; leave out the first {cut} test{'s' if cut != 1 else ''} "
                 f"({', '.join(f'#{i}' for i in leave)}), a warm-up: the other "
                 f"{len(keep)} show no trend")
        more = None
    else:
        leave, keep, more = list(ids), [], n
        text += (f"; the unit still drifts: no leading tests can be left out that leave "
                 f"{least} or more without a trend. Take more records until the trend test "
                 f"passes, at least {n} more (as many again: a test of the newest {n} alone "
                 "is as sensitive as this one), and build the baseline from them")
    return {"kind": "trend", "parameter": trend.parameter, "tests": leave, "message": text,
            "slope_percent": trend.slope_percent, "p_value": trend.p_family, "keep": keep,
            "more_records": more}


def assess_baseline(values: ArrayLike, std_errors: ArrayLike, test_ids: Sequence[int],
                    parameters: Sequence[str], checks: BaselineChecks | None = None
                    ) -> tuple[dict[str, Any], ...]:
    """Flags of a baseline that should not be trusted as it is.

    Two tests of the *form* of the tests' scatter, not of its size: a robust
    outlier test per parameter (median and MAD, which one bad test cannot
    drag; when the tests scatter beyond their standard errors, also Rosner's
    generalized ESD test at ``outlier_alpha``: see :func:`_outliers`), and a
    trend test in time order (:func:`baseline_trends`: a warm-up
    or a drift), with the remedy: the leading tests to leave out (the fewest
    whose removal leaves no trend), or, when none do, how many more records
    to take. A record-to-record scatter wider than the estimates' standard
    errors is no flag: real machines scatter so from test to test, and that
    scatter is what a check is measured against (:func:`baseline_scatter`
    notes it).

    Parameters
    ----------
    values, std_errors : array_like, shape (N, P)
        Estimates and their standard errors, one row per test in time
        (test) order. [parameter units]
    test_ids : sequence of int
        The tests' ids, in the rows' order, for the messages.
    parameters : sequence of str
    checks : BaselineChecks, optional

    Returns
    -------
    tuple of dict
        ``{"kind": "outlier" | "trend", "parameter", "tests", "message"}``
        (``tests``: those to look at; a trend's are the leading tests to
        leave out, or all when the unit still drifts), a trend's also with
        ``slope_percent`` [% / test], ``p_value`` (over the parameters),
        ``keep`` (the tests to build the baseline from, empty when the unit
        still drifts) and ``more_records`` (None, or how many more to take);
        empty when nothing is suspicious.

    Example
    -------
    >>> vals = [[1.00], [1.02], [0.98], [1.01], [7.0]]
    >>> ses = [[0.02]] * 5
    >>> [f["kind"] for f in assess_baseline(vals, ses, [1, 2, 3, 4, 5], ["D"])]
    ['outlier']
    >>> warm = [[1.3], [1.2], [1.1], [1.01], [0.99], [1.0], [1.02], [0.98], [1.0], [1.01]]
    >>> flag = assess_baseline(warm, [[0.005]] * 10, range(1, 11), ["D"])[-1]
    >>> flag["kind"], flag["tests"]
    ('trend', [1, 2, 3])
    """
    cfg = checks or BaselineChecks()
    x = np.atleast_2d(np.asarray(values, dtype=np.float64))
    se = np.atleast_2d(np.asarray(std_errors, dtype=np.float64))
    all_ids = [int(i) for i in test_ids]
    flags: list[dict[str, Any]] = []
    if x.shape[0] < MIN_BASELINE_TESTS:
        return ()
    names = list(parameters)
    tested = [j for j in range(len(names)) if np.isfinite(x[:, j]).sum() >= MIN_BASELINE_TESTS]
    family = _distinct(x, tested) if tested else 1
    for j in tested:
        p = names[j]
        have = np.isfinite(x[:, j])  # a test of another regime lacks the parameter
        col = x[have, j]
        ids = [i for i, h in zip(all_ids, have) if h]
        off, med, dev = _outliers(col, se[have, j], cfg, family)
        out = [ids[i] for i in np.flatnonzero(off)]
        if out:
            scale = abs(med) if med != 0 else 1.0
            worst = int(np.argmax(dev))
            flags.append({"kind": "outlier", "parameter": p, "tests": out,
                          "message": f"{p}: test(s) {', '.join(f'#{i}' for i in out)} far from "
                                     f"the others (#{ids[worst]} at "
                                     f"{100 * (col[worst] - med) / scale:+.0f} % of the median)"})
    trends = baseline_trends(x, names, cfg.trend_alpha)
    hits = [t for t in trends if t.significant]
    if hits:
        cut, least = _leading_cut(x, names, hits, cfg.trend_alpha)
        family = _distinct(x, [names.index(t.parameter) for t in trends])
        flags.extend(_trend_flag(t, cut, least, all_ids, cfg.trend_alpha, family) for t in hits)
    return tuple(flags)


def baseline_scatter(values: ArrayLike, std_errors: ArrayLike, parameters: Sequence[str],
                     checks: BaselineChecks | None = None) -> tuple[dict[str, Any], ...]:
    """Notes of the parameters whose tests scatter more than their estimates'
    standard errors say: information, not a warning.

    A machine's parameters move from test to test (temperature, supply,
    lubrication) by several times what one estimate's standard error
    allows; the baseline's sample standard deviation holds that scatter, and
    a check is measured against the larger of it and the check's own
    standard error. Noted when the ratio to the RMS of the standard errors
    exceeds ``spread_ratio``.

    Parameters
    ----------
    values, std_errors : array_like, shape (N, P)
        Estimates and their standard errors, one row per test. [parameter units]
    parameters : sequence of str
    checks : BaselineChecks, optional

    Returns
    -------
    tuple of dict
        ``{"kind": "scatter", "parameter", "ratio", "tests": [], "message"}``.

    Example
    -------
    >>> vals = [[1.00], [1.02], [0.98], [1.01]]
    >>> [n["message"] for n in baseline_scatter(vals, [[0.002]] * 4, ["D"])]
    ["record-to-record scatter of D is 8.5× its estimates' standard errors: the scatter, not the standard error, is the yardstick of a check"]
    """
    cfg = checks or BaselineChecks()
    x = np.atleast_2d(np.asarray(values, dtype=np.float64))
    se = np.atleast_2d(np.asarray(std_errors, dtype=np.float64))
    notes: list[dict[str, Any]] = []
    for j, p in enumerate(parameters):
        have = np.isfinite(x[:, j])
        s = se[have, j]
        good = np.isfinite(s) & (s > 0)
        if have.sum() < MIN_BASELINE_TESTS or good.sum() < 2:
            continue
        rms_se = float(np.sqrt(np.mean(s[good] ** 2)))
        ratio = float(np.std(x[have, j], ddof=1)) / rms_se
        if ratio > cfg.spread_ratio:
            notes.append({"kind": "scatter", "parameter": p, "ratio": ratio, "tests": [],
                          "message": f"record-to-record scatter of {p} is {ratio:.1f}× its "
                                     "estimates' standard errors: the scatter, not the "
                                     "standard error, is the yardstick of a check"})
    return tuple(notes)
