"""Operating conditions as covariates: a healthy value predicted from the conditions it was measured in.

A machine's friction depends on its oil's temperature, a pump's efficiency
on its speed: a change of conditions moves a healthy unit's parameters and
features as surely as wear does. A declaration names its conditions in a
``[conditions]`` table (:mod:`condmon.models.features`); each record's are
stored beside its estimates. Against a baseline:

- each parameter's (or feature's) healthy value is fitted against the
  conditions of the baseline's tests by ordinary least squares, ``y = a +
  bᵀ(c - c̄)``, with the conditions of its own regime (``oil@forward`` for
  ``Tc@forward``) and the regime-free ones (a metadata field);
- the check is judged on its departure from the prediction at its own
  conditions: the baseline the monitor sees has the prediction as its mean
  and the prediction's spread for a new healthy test, ``s·sqrt(1 + h₀)``
  (``h₀ = x₀ᵀ(XᵀX)⁻¹x₀`` the check's leverage), as its standard deviation,
  over ``n - q`` tests (``q`` conditions: the t quantile that widens a
  spread of few tests takes the regression's degrees of freedom);
- a check whose conditions lie outside the range the baseline's tests span
  is **not judged**: nothing says how a healthy unit behaves there. It is
  stored with the reason, shown, and never trended as a change.

Without enough baseline tests to fit (fewer than ``q + 3``), a parameter is
judged against its mean, and the note says so.

Why by hand: ``numpy.linalg.lstsq`` does the fit; the prediction interval
of a new observation (the leverage term) is two lines that statsmodels
would bring a dependency for.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from condmon.monitor.baseline import Baseline
from condmon.models.regimes import split_key

if TYPE_CHECKING:
    from condmon.identify.result import EstimateResult
    from condmon.models.features import ConditionSpec

__all__ = ["Conditioned", "condition_keys", "conditioned_baseline", "NotJudged", "NOT_JUDGED",
           "explained", "departures", "session_elapsed", "with_session_time"]

FloatArray = NDArray[np.float64]

#: The status of a check whose conditions the baseline does not span.
NOT_JUDGED = "not judged"


@dataclass(frozen=True)
class NotJudged:
    """The diagnosis of a check that is not judged (stored like one: a
    status, a condition index, a summary and no faults).

    Attributes
    ----------
    reason : str
        Which condition, its value and the baseline's range.
    """

    reason: str
    status: str = NOT_JUDGED
    condition: float = 0.0
    faults: tuple[Any, ...] = ()

    @property
    def summary(self) -> str:
        """``not judged: <reason>``."""
        return f"{NOT_JUDGED}: {self.reason}"


@dataclass(frozen=True)
class Conditioned:
    """A baseline turned into the prediction at a check's conditions.

    Attributes
    ----------
    baseline : Baseline
        Mean: each parameter's predicted healthy value [parameter units];
        std: the spread of a new healthy test about it [parameter units].
    not_judged : str or None
        Why the check is not judged (a condition outside the baseline's range).
    fitted : dict of str to tuple of str
        The conditions each parameter was fitted against.
    notes : tuple of str
    """

    baseline: Baseline
    not_judged: str | None
    fitted: dict[str, tuple[str, ...]]
    notes: tuple[str, ...] = ()


def session_elapsed(at: float, others: Sequence[float], gap: float) -> float:
    """The time since the session that holds ``at`` started: since the first
    of the unit's records (``others`` and ``at`` itself) that follow each
    other with no pause longer than ``gap``. [s]

    Parameters
    ----------
    at : float
        The record's start time (seconds since any fixed epoch). [s]
    others : sequence of float
        The unit's other records' start times, in any order. [s]
    gap : float
        The longest pause within one session. [s]

    Example
    -------
    Cycles every 12 s from 8:00, a lunch break, cycles again from 13:00:

    >>> day = [8 * 3600 + 12.0 * k for k in range(50)] + [13 * 3600 + 12.0 * k for k in range(9)]
    >>> session_elapsed(13 * 3600 + 96.0, day, 1800.0), session_elapsed(8 * 3600 + 24.0, day, 1800.0)
    (96.0, 24.0)
    """
    before = np.unique(np.asarray([t for t in others if t < at], dtype=np.float64))
    times = np.append(before, at)
    pauses = np.flatnonzero(np.diff(times) > gap)
    start = float(times[pauses[-1] + 1]) if pauses.size else float(times[0])
    return float(at - start)


def with_session_time(res: EstimateResult, conditions: Sequence[ConditionSpec],
                      when: datetime | None, others: Sequence[float]) -> EstimateResult:
    """``res`` with its session conditions (``since = "session start"``) set
    from its start time ``when`` and the unit's other records' start times
    ``others`` (POSIX seconds, :func:`session_elapsed`); a record without a
    start time gets a note that says how to give one. ``res`` itself when
    the machine declares no such condition."""
    sessions = [c for c in conditions if c.session_gap is not None]
    if not sessions:
        return res
    if when is None:
        return dataclasses.replace(res, notes=(*res.notes, *(
            f"condition {c.name} not known: the record has no start time (give the test's "
            "date, or the time its file names hold with [record] name_time)"
            for c in sessions)))
    at = when.timestamp()
    return dataclasses.replace(res, conditions={**res.conditions, **{
        c.name: (session_elapsed(at, others, float(c.session_gap or 0.0)), 0.0)
        for c in sessions}})


def condition_keys(parameter: str, available: Sequence[str]) -> list[str]:
    """The conditions that apply to ``parameter``: its own regime's
    (``oil@forward`` for ``Tc@forward``) and the regime-free ones.

    Example
    -------
    >>> condition_keys("Tc@forward", ["oil@forward", "oil@reverse", "load"])
    ['oil@forward', 'load']
    """
    regime = split_key(parameter)[1]
    return [c for c in available if split_key(c)[1] in ("", regime)
            and (split_key(c)[1] == regime or "@" not in c)]


def _fmt(x: float) -> str:
    return f"{x:.5g}"


def conditioned_baseline(baseline: Baseline, values: Mapping[str, FloatArray],
                         conditions: Mapping[str, FloatArray], now: Mapping[str, float],
                         units: Mapping[str, str] | None = None,
                         errors: Mapping[str, float] | None = None) -> Conditioned:
    """The baseline a check at conditions ``now`` is judged against.

    Parameters
    ----------
    baseline : Baseline
        The baseline (its mean and spread, unconditioned).
    values : mapping of str to ndarray
        Each parameter's values over the baseline's tests (NaN where a test
        lacks it). [parameter units]
    conditions : mapping of str to ndarray
        Each condition's values over the same tests. [condition units]
    now : mapping of str to float
        The check's conditions. [condition units]
    units : mapping of str to str, optional
        Each condition's unit (by name), for messages.
    errors : mapping of str to float, optional
        The standard errors of the check's conditions: a condition is outside
        the baseline's range only when it is further out than twice its
        standard error (a constant condition measured with noise is not
        "outside" its own scatter). [condition units]

    Returns
    -------
    Conditioned

    Example
    -------
    Friction falls 0.1 N m per degree; the baseline spans 30-40 °C:

    >>> t = np.linspace(30.0, 40.0, 12)
    >>> tc = 50.0 - 0.1 * t + np.random.default_rng(0).normal(0.0, 0.05, 12)
    >>> b = Baseline(("Tc",), (float(tc.mean()),), (float(tc.std(ddof=1)),), 12)
    >>> c = conditioned_baseline(b, {"Tc": tc}, {"oil": t}, {"oil": 38.0})
    >>> round(c.baseline.mean[0], 1), c.baseline.std[0] < 0.1, c.not_judged
    (46.2, True, None)
    >>> print(conditioned_baseline(b, {"Tc": tc}, {"oil": t}, {"oil": 45.0}).not_judged)
    oil = 45 outside the baseline's 30 .. 40
    """
    unit_of = dict(units or {})
    means, stds, counts = list(baseline.mean), list(baseline.std), list(baseline.count_array)
    fitted: dict[str, tuple[str, ...]] = {}
    notes: list[str] = []
    outside: list[str] = []
    seen: set[str] = set()
    for j, key in enumerate(baseline.parameters):
        keys = [c for c in condition_keys(key, list(conditions))
                if c in now and math.isfinite(now[c])]
        if not keys or key not in values:
            continue
        y = np.asarray(values[key], dtype=np.float64)
        C = np.column_stack([np.asarray(conditions[c], dtype=np.float64) for c in keys])
        ok = np.isfinite(y) & np.isfinite(C).all(axis=1)
        y, C = y[ok], C[ok]
        if y.size == 0:
            continue
        for i, c in enumerate(keys):
            lo, hi = float(C[:, i].min()), float(C[:, i].max())
            tol = 2.0 * float((errors or {}).get(c, 0.0))
            tol = tol if math.isfinite(tol) else 0.0
            if c not in seen and not lo - tol <= now[c] <= hi + tol:
                unit = unit_of.get(split_key(c)[0], "")
                outside.append(f"{c} = {_fmt(now[c])}{' ' + unit if unit else ''} outside "
                               f"the baseline's {_fmt(lo)} .. {_fmt(hi)}")
            seen.add(c)
        q = len(keys)
        if y.size < q + 3:
            notes.append(f"{key}: {y.size} baseline test(s) cannot fit it against "
                         f"{', '.join(keys)} (needs {q + 3}): judged against its mean")
            continue
        center = C.mean(axis=0)
        X = np.column_stack([np.ones(y.size), C - center])
        beta, *_ = np.linalg.lstsq(X, y, rcond=None)
        dof = y.size - q - 1
        s2 = float(np.sum((y - X @ beta) ** 2)) / dof
        x0 = np.concatenate([[1.0], np.array([now[c] for c in keys]) - center])
        h0 = float(x0 @ np.linalg.pinv(X.T @ X) @ x0)
        means[j] = float(x0 @ beta)
        # the spread of a new healthy test about the prediction, stated as a
        # baseline spread of n - q tests (the monitor adds the mean's own 1/n)
        stds[j] = math.sqrt(s2 * (1.0 + h0) / (1.0 + 1.0 / (y.size - q)))
        counts[j] = y.size - q
        fitted[key] = tuple(keys)
    out = Baseline(baseline.parameters, tuple(means), tuple(stds), baseline.n,
                   tuple(int(c) for c in counts))
    return Conditioned(out, "; ".join(outside) or None, fitted, tuple(notes))


def explained(values: FloatArray, parameters: Sequence[str],
              conditions: Mapping[str, FloatArray]) -> FloatArray:
    """The baseline's values with what its conditions explain taken out: each
    parameter's mean plus its residual from the fit against its conditions
    (:func:`condition_keys`), so that a warm-up the oil's temperature
    explains is no trend of the baseline. A parameter with too few tests to
    fit (fewer than ``q + 3``) is left as it is. [parameter units]

    Parameters
    ----------
    values : ndarray, shape (n, p)
        The baseline's tests, in the order of ``parameters``. [parameter units]
    parameters : sequence of str
    conditions : mapping of str to ndarray
        Each condition over the same ``n`` tests. [condition units]

    Example
    -------
    >>> t = np.linspace(30.0, 40.0, 8)
    >>> out = explained((50.0 - 0.5 * t)[:, None], ["Tc"], {"oil": t})
    >>> bool(np.ptp(out[:, 0]) < 1e-9), round(float(out[0, 0]), 2)
    (True, 32.5)
    """
    out = np.array(values, dtype=np.float64, copy=True)
    for j, key in enumerate(parameters):
        keys = condition_keys(key, list(conditions))
        if not keys:
            continue
        C = np.column_stack([np.asarray(conditions[c], dtype=np.float64) for c in keys])
        y = out[:, j]
        ok = np.isfinite(y) & np.isfinite(C).all(axis=1)
        if np.count_nonzero(ok) < len(keys) + 3:
            continue
        X = np.column_stack([np.ones(int(ok.sum())), C[ok] - C[ok].mean(axis=0)])
        beta, *_ = np.linalg.lstsq(X, y[ok], rcond=None)
        y[ok] = beta[0] + (y[ok] - X @ beta)
    return out


def departures(values: FloatArray, parameters: Sequence[str],
               conditions: Mapping[str, FloatArray], later: FloatArray,
               later_conditions: Mapping[str, FloatArray]) -> FloatArray:
    """Later tests' values with what their conditions explain taken out, by the
    baseline's fit: each later value minus its prediction at its own
    conditions, plus the baseline's mean (as :func:`explained` does for the
    baseline's own tests). A parameter the baseline cannot fit is left as it
    is. [parameter units]

    Parameters
    ----------
    values : ndarray, shape (n, p)
        The baseline's tests. [parameter units]
    parameters : sequence of str
    conditions : mapping of str to ndarray
        Each condition over the baseline's ``n`` tests.
    later : ndarray, shape (m, p)
        The later tests (checks). [parameter units]
    later_conditions : mapping of str to ndarray
        Each condition over the ``m`` later tests.

    Example
    -------
    >>> t = np.linspace(30.0, 40.0, 8)
    >>> out = departures((50.0 - 0.5 * t)[:, None], ["Tc"], {"oil": t},
    ...                  np.array([[29.0], [26.5]]), {"oil": np.array([42.0, 47.0])})
    >>> out[:, 0].round(2).tolist()      # both on the baseline's line: its mean, 32.5
    [32.5, 32.5]
    """
    out = np.array(later, dtype=np.float64, copy=True)
    for j, key in enumerate(parameters):
        keys = [c for c in condition_keys(key, list(conditions)) if c in later_conditions]
        if not keys:
            continue
        C = np.column_stack([np.asarray(conditions[c], dtype=np.float64) for c in keys])
        y = np.asarray(values, dtype=np.float64)[:, j]
        ok = np.isfinite(y) & np.isfinite(C).all(axis=1)
        if np.count_nonzero(ok) < len(keys) + 3:
            continue
        center = C[ok].mean(axis=0)
        X = np.column_stack([np.ones(int(ok.sum())), C[ok] - center])
        beta, *_ = np.linalg.lstsq(X, y[ok], rcond=None)
        L = np.column_stack([np.asarray(later_conditions[c], dtype=np.float64) for c in keys])
        fit = beta[0] + (L - center) @ beta[1:]
        have = np.isfinite(fit)
        out[have, j] = beta[0] + (out[have, j] - fit[have])
    return out
