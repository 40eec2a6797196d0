"""Healthy baseline of each parameter and percent change against it (SPEC A6.1-2)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import DataError

__all__ = ["Baseline", "make_baseline", "percent_change", "MIN_BASELINE_TESTS"]

FloatArray = NDArray[np.float64]

#: Fewest accepted healthy tests a baseline is computed from.
MIN_BASELINE_TESTS = 3


@dataclass(frozen=True)
class Baseline:
    """Mean and spread of each parameter over healthy tests.

    Attributes
    ----------
    parameters : tuple of str
        Parameter names, in column order.
    mean : tuple of float
        Sample mean of each parameter. [parameter units]
    std : tuple of float
        Sample standard deviation (ddof = 1). [parameter units]
    n : int
        Number of tests.
    """

    parameters: tuple[str, ...]
    mean: tuple[float, ...]
    std: tuple[float, ...]
    n: int

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

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"n": self.n, "mean": dict(zip(self.parameters, self.mean)),
                "std": dict(zip(self.parameters, self.std))}


def make_baseline(values: ArrayLike | Sequence[Mapping[str, float]],
                  parameters: Sequence[str] | None = None) -> Baseline:
    """Baseline from the parameter estimates of N accepted healthy tests.

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
        Fewer than 3 tests, a non-finite value, or a zero mean.

    Example
    -------
    >>> b = make_baseline([{"R": 1.0}, {"R": 1.1}, {"R": 0.9}])
    >>> b.mean, round(b.std[0], 3), b.n
    ((1.0,), 0.1, 3)
    """
    rows: Any = list(values) if not isinstance(values, np.ndarray) else values  # type: ignore[arg-type]
    if len(rows) and isinstance(rows[0], Mapping):
        names = tuple(parameters) if parameters is not None else tuple(rows[0])
        arr = np.array([[float(r[k]) for k in names] for r in rows])
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
    if not np.all(np.isfinite(arr)):
        raise DataError("baseline estimates contain NaN or inf")
    mean = arr.mean(axis=0)
    if np.any(mean == 0):
        bad = [k for k, m in zip(names, mean) if m == 0]
        raise DataError(f"baseline mean of {bad} is zero: percent change is undefined")
    std = arr.std(axis=0, ddof=1)
    return Baseline(names, tuple(map(float, mean)), tuple(map(float, std)), int(n))


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
