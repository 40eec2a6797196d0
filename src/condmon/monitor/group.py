"""Peer baselines: a group of units judged together, within- and between-unit spread apart.

Units of one type (one model, one load) differ from each other by their
manufacture and installation, and each scatters from test to test around
its own level. Pooling their tests into one baseline mixes the two spreads:
a new unit is then judged too harshly (its own level is not known) or its
later tests too leniently. The group baseline keeps them apart, as a one-way
random-effects model of each parameter over the units' baselines:

    θ_ij = μ + u_i + e_ij,   u_i ~ N(0, τ²)  (between units),
                             e_ij ~ N(0, σ_w²) (within a unit)

- ``σ_w²``: the units' sample variances pooled by their degrees of freedom;
- ``τ²``: the DerSimonian-Laird moment estimate from the spread of the unit
  means beyond what ``σ_w²/n_i`` explains (0 when there is none);
- ``μ``: the mean of the unit means, each weighted by ``1/(τ² + σ_w²/n_i)``.

A unit without a baseline of its own is judged against the spread a new
unit's test has, ``sqrt(τ² + σ_w² + var μ)`` (:meth:`GroupBaseline.predictive`);
once it has its own baseline, its tests are judged against that (its own
spread). :func:`unlike_group` says when a unit's own baseline lies outside its
peers' between-unit spread (each unit against the others: leave one out).

Written for condmon: a few lines of the standard moment estimators
(DerSimonian and Laird 1986), on the store's baselines.

References
----------
.. [1] R. DerSimonian, N. Laird, "Meta-analysis in clinical trials",
   Controlled Clinical Trials 7(3), 1986.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from condmon.errors import DataError
from condmon.monitor.baseline import Baseline

__all__ = ["GroupBaseline", "group_baseline", "unlike_group", "MIN_GROUP_UNITS"]

#: Fewest units with a baseline of their own a group baseline is made of.
MIN_GROUP_UNITS = 3


@dataclass(frozen=True)
class GroupBaseline:
    """A group's baseline of each parameter, from its units' baselines.

    Attributes
    ----------
    group : str
    parameters : tuple of str
    mean : tuple of float
        ``μ``: the weighted mean of the unit means. [parameter units]
    between : tuple of float
        ``τ``: the standard deviation of the units' own levels. [parameter units]
    within : tuple of float
        ``σ_w``: the pooled test-to-test standard deviation within a unit.
        [parameter units]
    mean_se : tuple of float
        Standard error of ``μ``. [parameter units]
    units : tuple of str
        The units it is made of.
    counts : tuple of int
        Units behind each parameter.

    Example
    -------
    >>> b = {u: Baseline(("R",), (m,), (0.01,), 5) for u, m in
    ...      (("A", 1.00), ("B", 1.04), ("C", 0.96), ("D", 1.02))}
    >>> g = group_baseline("line", b)
    >>> round(g.mean[0], 3), round(g.between[0], 3), round(g.within[0], 3)
    (1.005, 0.034, 0.01)
    """

    group: str
    parameters: tuple[str, ...]
    mean: tuple[float, ...]
    between: tuple[float, ...]
    within: tuple[float, ...]
    mean_se: tuple[float, ...]
    units: tuple[str, ...]
    counts: tuple[int, ...]

    def predictive(self) -> Baseline:
        """The baseline a unit with none of its own is judged against: ``μ``
        and the spread of a new unit's test, ``sqrt(τ² + σ_w² + se(μ)²)``,
        over the group's units (``n`` and ``counts``: units)."""
        std = tuple(math.sqrt(b * b + w * w + s * s)
                    for b, w, s in zip(self.between, self.within, self.mean_se))
        n = len(self.units)
        return Baseline(self.parameters, self.mean, std, n,
                        None if all(c == n for c in self.counts) else self.counts)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"group": self.group, "units": list(self.units),
                "mean": dict(zip(self.parameters, self.mean)),
                "between_std": dict(zip(self.parameters, self.between)),
                "within_std": dict(zip(self.parameters, self.within)),
                "mean_se": dict(zip(self.parameters, self.mean_se)),
                "units_per_parameter": dict(zip(self.parameters, self.counts))}


def _random_effects(means: np.ndarray[Any, np.dtype[np.float64]],
                    stds: np.ndarray[Any, np.dtype[np.float64]],
                    ns: np.ndarray[Any, np.dtype[np.float64]]) -> tuple[float, float, float, float]:
    """``(μ, τ, σ_w, se(μ))`` of one parameter from the unit means, spreads and sizes."""
    dof = ns - 1.0
    within2 = float(np.sum(dof * stds ** 2) / np.sum(dof)) if np.sum(dof) > 0 else 0.0
    v = np.maximum(within2 / ns, 1e-300)  # variance of each unit's mean
    w = 1.0 / v
    mu_w = float(np.sum(w * means) / np.sum(w))
    q = float(np.sum(w * (means - mu_w) ** 2))
    k = means.size
    denom = float(np.sum(w) - np.sum(w ** 2) / np.sum(w))
    tau2 = max(0.0, (q - (k - 1)) / denom) if denom > 0 else float(np.var(means, ddof=1))
    ws = 1.0 / (tau2 + v)
    mu = float(np.sum(ws * means) / np.sum(ws))
    return mu, math.sqrt(tau2), math.sqrt(within2), math.sqrt(1.0 / float(np.sum(ws)))


def group_baseline(group: str, baselines: Mapping[str, Baseline],
                   min_units: int = MIN_GROUP_UNITS) -> GroupBaseline:
    """The group baseline of some units' own baselines (see the module's description).

    Parameters
    ----------
    group : str
        Its name, for messages.
    baselines : mapping of str to Baseline
        Each unit's own baseline.
    min_units : int
        Fewest units a parameter needs; parameters with fewer are left out.

    Returns
    -------
    GroupBaseline

    Raises
    ------
    DataError
        No parameter has ``min_units`` units with a baseline.
    """
    keys = list(dict.fromkeys(k for b in baselines.values() for k in b.parameters))
    params, mean, between, within, se, counts = [], [], [], [], [], []
    for key in keys:
        have = [(b.value(key), b.std[b.parameters.index(key)],
                 int(b.count_array[b.parameters.index(key)]))
                for b in baselines.values() if key in b.parameters]
        if len(have) < min_units:
            continue
        m, s, n = (np.array([h[i] for h in have], dtype=np.float64) for i in range(3))
        mu, tau, sw, mse = _random_effects(m, s, n)
        if mu == 0 or not all(map(math.isfinite, (mu, tau, sw, mse))):
            continue
        params.append(key)
        mean.append(mu)
        between.append(tau)
        within.append(sw)
        se.append(mse)
        counts.append(len(have))
    if not params:
        units = ", ".join(sorted(baselines)) or "none"
        raise DataError(f"group {group!r} has {len(baselines)} unit(s) with a baseline of "
                        f"their own ({units}); a group baseline needs at least {min_units}")
    return GroupBaseline(group, tuple(params), tuple(mean), tuple(between), tuple(within),
                         tuple(se), tuple(sorted(baselines)), tuple(counts))


def unlike_group(unit: str, own: Baseline, peers: Mapping[str, Baseline], z_limit: float,
                 min_units: int = MIN_GROUP_UNITS) -> list[dict[str, Any]]:
    """Where a unit's own baseline lies outside its peers' between-unit spread.

    Each parameter's ``z = (m - μ) / sqrt(τ² + σ_w²/n + se(μ)²)`` against the
    group baseline of the *other* units (``peers``, without ``unit``): ``m``
    and ``n`` the unit's own mean and number of tests, ``σ_w`` the peers'
    pooled within-unit spread (better known than the unit's own few tests').

    Returns
    -------
    list of dict
        ``{"parameter", "change_percent", "z", "message"}`` for each parameter
        with ``|z| > z_limit``; empty when the unit is like its peers (or too
        few peers).

    Example
    -------
    >>> peers = {u: Baseline(("R",), (m,), (0.01,), 5) for u, m in
    ...          (("A", 1.00), ("B", 1.03), ("C", 0.97), ("D", 1.01), ("E", 0.99))}
    >>> odd = Baseline(("R",), (1.20,), (0.01,), 5)
    >>> [round(f["z"], 1) for f in unlike_group("F", odd, peers, 3.0)]
    [8.2]
    """
    others = {u: b for u, b in peers.items() if u != unit}
    try:
        g = group_baseline("peers", others, min_units)
    except DataError:
        return []
    flags = []
    for i, key in enumerate(g.parameters):
        if key not in own.parameters:
            continue
        j = own.parameters.index(key)
        m, n = own.mean[j], int(own.count_array[j])
        scale = math.sqrt(g.between[i] ** 2 + g.within[i] ** 2 / max(n, 1) + g.mean_se[i] ** 2)
        if scale <= 0:
            continue
        z = (m - g.mean[i]) / scale
        if abs(z) > z_limit:
            change = 100.0 * (m - g.mean[i]) / abs(g.mean[i])
            flags.append({"parameter": key, "change_percent": change, "z": z,
                          "message": f"{key} {change:+.1f} % from the group's mean, "
                                     f"{abs(z):.1f} between-unit σ (limit {z_limit:g})"})
    return flags


def units_of(baselines: Sequence[str]) -> str:
    """``A, B and 3 more`` for messages."""
    names = list(baselines)
    return ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
