"""Healthy baseline of each parameter and percent change against it (SPEC A6.1-2).

Whether a baseline can be trusted (outliers, a trend in time order) is
:mod:`condmon.monitor.baseline_checks`; its names are importable from here too.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import DataError
from condmon.monitor.baseline_checks import (  # kept importable from here
    INFO_KINDS, MIN_BASELINE_TESTS, BaselineChecks, Trend, assess_baseline, baseline_scatter,
    baseline_trends, is_warning,
)

__all__ = ["Baseline", "make_baseline", "percent_change", "MIN_BASELINE_TESTS",
           "BaselineChecks", "assess_baseline", "missing_regimes", "Trend", "baseline_trends",
           "baseline_scatter", "is_warning", "INFO_KINDS"]

FloatArray = NDArray[np.float64]

@dataclass(frozen=True)
class Baseline:
    """Mean and spread of each parameter over healthy tests.

    Attributes
    ----------
    parameters : tuple of str
        Parameter names, in column order (a regime's parameters as
        ``Tc@forward``, see :func:`condmon.models.regimes.regime_key`).
    mean : tuple of float
        Sample mean of each parameter. [parameter units]
    std : tuple of float
        Sample standard deviation (ddof = 1). [parameter units]
    n : int
        Number of tests.
    counts : tuple of int or None
        Tests behind each parameter, when fewer than ``n`` (a regime's
        parameters are in its tests only); None: ``n`` for every one.
    """

    parameters: tuple[str, ...]
    mean: tuple[float, ...]
    std: tuple[float, ...]
    n: int
    counts: tuple[int, ...] | None = None

    @property
    def count_array(self) -> NDArray[np.int64]:
        """Tests behind each parameter."""
        return np.asarray(self.counts if self.counts is not None
                          else (self.n,) * len(self.parameters), dtype=np.int64)

    def value(self, name: str) -> float | None:
        """The mean of ``name``, None when the baseline lacks it. [unit]"""
        return self.mean[self.parameters.index(name)] if name in self.parameters else None

    @property
    def mean_array(self) -> FloatArray:
        """Means as an array. [parameter units]"""
        return np.asarray(self.mean, dtype=np.float64)

    @property
    def std_array(self) -> FloatArray:
        """Standard deviations as an array. [parameter units]"""
        return np.asarray(self.std, dtype=np.float64)

    @property
    def relative_std_percent(self) -> FloatArray:
        """``std / |mean| * 100`` per parameter. [%]"""
        return 100.0 * self.std_array / np.abs(self.mean_array)

    def regime_counts(self) -> dict[str, int]:
        """Tests the baseline holds per operating regime (``{}`` without regimes).

        A regime's count is that of its best-covered parameter.

        Example
        -------
        >>> Baseline(("Tc@forward", "Tc@reverse"), (39.5, 39.5), (0.2, 0.4), 10,
        ...          (5, 4)).regime_counts()
        {'forward': 5, 'reverse': 4}
        """
        from condmon.models.regimes import split_key

        counts: dict[str, int] = {}
        for key, n in zip(self.parameters, self.count_array):
            regime = split_key(key)[1]
            if regime:
                counts[regime] = max(counts.get(regime, 0), int(n))
        return counts

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``counts`` per parameter when they differ from ``n``)."""
        doc: dict[str, Any] = {"n": self.n, "mean": dict(zip(self.parameters, self.mean)),
                               "std": dict(zip(self.parameters, self.std))}
        if self.counts is not None:
            doc["counts"] = dict(zip(self.parameters, map(int, self.counts)))
        return doc


def make_baseline(values: ArrayLike | Sequence[Mapping[str, float]],
                  parameters: Sequence[str] | None = None) -> Baseline:
    """Baseline from the parameter estimates of N accepted healthy tests.

    A test may lack some parameters (NaN, or a key missing from its mapping):
    those of an operating regime it was not run in, or ones it did not
    identify. Each parameter's mean and spread are over the tests that have
    it; a parameter that fewer than 3 tests have is left out (its regime
    has no baseline yet).

    Parameters
    ----------
    values : array_like, shape (N, P), or sequence of {name: value}
        One row per test.
    parameters : sequence of str, optional
        Column names (taken from the mappings when rows are mappings).

    Returns
    -------
    Baseline

    Raises
    ------
    DataError
        Fewer than 3 tests of any parameter, an infinite value, or a zero mean.

    Example
    -------
    >>> b = make_baseline([{"R": 1.0}, {"R": 1.1}, {"R": 0.9}])
    >>> b.mean, round(b.std[0], 3), b.n
    ((1.0,), 0.1, 3)
    >>> b = make_baseline([[1.0, np.nan], [1.2, 2.0], [1.1, 2.2], [0.9, 2.1]], ["Tc@f", "Tc@r"])
    >>> b.parameters, b.counts
    (('Tc@f', 'Tc@r'), (4, 3))
    """
    rows: Any = list(values) if not isinstance(values, np.ndarray) else values  # type: ignore[arg-type]
    if len(rows) and isinstance(rows[0], Mapping):
        names = tuple(parameters) if parameters is not None else tuple(
            dict.fromkeys(k for r in rows for k in r))
        arr = np.array([[float(r.get(k, np.nan)) for k in names] for r in rows])
    else:
        arr = np.atleast_2d(np.asarray(rows, dtype=np.float64))
        if parameters is None:
            raise DataError("parameter names are needed for an array of estimates")
        names = tuple(parameters)
    n = arr.shape[0] if arr.size else 0
    if n < MIN_BASELINE_TESTS:
        raise DataError(f"a baseline needs at least {MIN_BASELINE_TESTS} accepted healthy "
                        f"tests, got {n}; add more with `condmon baseline add`")
    if arr.shape[1] != len(names):
        raise DataError(f"{arr.shape[1]} columns for {len(names)} parameter names")
    if np.any(np.isinf(arr)):
        raise DataError("baseline estimates contain inf")
    counts = np.sum(np.isfinite(arr), axis=0)
    keep = [j for j in range(len(names)) if counts[j] >= MIN_BASELINE_TESTS]
    if not keep:
        raise DataError(f"no parameter has {MIN_BASELINE_TESTS} accepted healthy tests yet "
                        f"({', '.join(f'{k}: {c}' for k, c in zip(names, counts))}); add more "
                        "with `condmon baseline add`")
    arr = arr[:, keep]
    names = tuple(names[j] for j in keep)
    counts = counts[keep]
    mean = np.nanmean(arr, axis=0)
    if np.any(mean == 0):
        bad = [k for k, m in zip(names, mean) if m == 0]
        raise DataError(f"baseline mean of {bad} is zero: percent change is undefined")
    std = np.nanstd(arr, axis=0, ddof=1)
    full = bool(np.all(counts == n))
    return Baseline(names, tuple(map(float, mean)), tuple(map(float, std)), int(n),
                    None if full else tuple(int(c) for c in counts))


def missing_regimes(keys: Sequence[str], baseline: Baseline) -> list[str]:
    """The keys (``Tc@forward``) a baseline has no value for: their regime has
    no baseline yet.

    Example
    -------
    >>> b = Baseline(("Tc@forward",), (40.0,), (0.5,), 5)
    >>> missing_regimes(["Tc@forward", "Tc@reverse"], b)
    ['Tc@reverse']
    """
    return [k for k in keys if k not in baseline.parameters]


def percent_change(values: ArrayLike, baseline: Baseline) -> FloatArray:
    """``(θ - θ̄) / |θ̄| * 100`` per parameter, shape like ``values``. [%]

    Example
    -------
    >>> b = Baseline(("R",), (1.0,), (0.01,), 5)
    >>> percent_change([[1.4]], b)
    array([[40.]])
    """
    v = np.asarray(values, dtype=np.float64)
    return np.asarray(100.0 * (v - baseline.mean_array) / np.abs(baseline.mean_array),
                      dtype=np.float64)
