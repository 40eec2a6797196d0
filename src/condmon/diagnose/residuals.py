"""Residuals of a declared model run beside the plant, their normalisation and
debounced detection.

r = measured − predicted, the prediction coming from the model simulated from
zero initial conditions (and, for structured residuals, from the sensors used as
inputs). Each residual is smoothed by a trailing moving average of ``window``
seconds and normalised, ``(r̄ − mean)/(z·std)``, with the mean and spread learned
from healthy records (or, lacking those, from the sensors' declared noise). A
residual *fires* when its normalised value stays outside ±1 for ``persistence``
seconds: a single noisy sample never raises an alarm.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from condmon.diagnose.checks import validate_plant_record
from condmon.errors import ConfigError, DataError
from condmon.io.columns import Columns, column_values
from condmon.io.config import load_default, load_toml, merge
from condmon.models.declared import PlantModel
from condmon.simulate.plant import (
    ParameterStep, SimulationLimits, input_signals, integrate, operating_segments,
    sensor_readings,
)

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["DetectionSettings", "Residuals", "Normalisation", "Detection", "load_settings",
           "validate_plant_record", "compute_residuals", "learn_normalisation",
           "noise_normalisation", "detect", "moving_average"]

FloatArray = NDArray[np.float64]
_MIN_SAMPLES = 10  # fewest samples a mean and spread are learned from


def load_settings(path: str | Path | None = None) -> dict[str, Any]:
    """Detection, estimation and isolation settings (shipped ``isolation.toml``,
    overridden key by key by the file ``path``)."""
    base = load_default("isolation.toml")
    return base if path is None else merge(base, load_toml(path), str(path))


@dataclass(frozen=True)
class DetectionSettings:
    """Detection settings (defaults from ``condmon/data/isolation.toml``).

    Attributes
    ----------
    window : float
        Moving-average window of the residuals. [s]
    z : float
        Confidence coefficient: the threshold is z standard deviations. [-]
    persistence : float
        Time a normalised residual must stay outside ±1 to fire. [s]
    startup : float
        Residuals are not judged before this time. [s]
    by_operating_point : bool
        Learn the mean and spread separately at each operating point (level of
        the known inputs) of the healthy records.
    min_point_time : float
        Shortest time at an operating point for figures of its own. [s]
    input_settle : float
        Residuals are not judged this long after a step of a known input (the
        model's transient may differ from the plant's). [s]
    """

    window: float = 0.2
    z: float = 4.0
    persistence: float = 0.5
    startup: float = 1.0
    by_operating_point: bool = True
    min_point_time: float = 2.0
    input_settle: float = 0.0

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any] | None = None) -> DetectionSettings:
        d = (cfg or load_settings())["detection"]
        out = cls(float(d["window"]), float(d["z"]), float(d["persistence"]), float(d["startup"]),
                  bool(d["by_operating_point"]), float(d["min_point_time"]),
                  float(d["input_settle"]))
        bad = [f"{k} = {v:g} (must be {'> 0' if k == 'z' else '>= 0'})"
               for k, v in (("window", out.window), ("z", out.z),
                            ("persistence", out.persistence), ("startup", out.startup),
                            ("input_settle", out.input_settle))
               if not (v > 0 if k == "z" else v >= 0)]
        if bad:
            raise ConfigError(f"[detection] {'; '.join(bad)}")
        return out

    def judged(self, t: FloatArray, inputs: FloatArray) -> NDArray[np.bool_]:
        """Samples whose residuals are judged: after start-up, away from input steps."""
        ok = t >= t[0] + self.startup
        if self.input_settle > 0 and len(t) > 1:
            for i in operating_segments(inputs)[1:]:
                ok &= ~((t >= t[i]) & (t < t[i] + self.input_settle))
        return ok  # type: ignore[no-any-return]


@dataclass(frozen=True)
class Residuals:
    """Residuals on the record's time grid.

    Attributes
    ----------
    t : ndarray
        Time. [s]
    names : tuple of str
        Residual names.
    sensors : tuple of str
        The sensor each residual compares.
    values : ndarray, shape (n, n_residuals)
        Measured − predicted. [sensor unit]
    predicted : ndarray, shape (n, n_residuals)
        The model's prediction. [sensor unit]
    inputs : ndarray, shape (n, n_inputs)
        The known inputs: they define the operating point. [input units]
    states : ndarray, shape (n, n_states), or None
        The model's states when run from the known inputs alone (None when no
        residual did so). [state units]
    """

    t: FloatArray
    names: tuple[str, ...]
    sensors: tuple[str, ...]
    values: FloatArray
    predicted: FloatArray
    inputs: FloatArray
    states: FloatArray | None = None


@dataclass(frozen=True)
class Normalisation:
    """Mean and spread of each smoothed residual on healthy data.

    Attributes
    ----------
    names : tuple of str
    mean, std : ndarray
        Of the smoothed residual. [sensor unit]
    raw_std : ndarray
        Of the unsmoothed residual (the noise of one sample). [sensor unit]
    window : float
        Smoothing window the figures belong to. [s]
    source : str
        "healthy records (N)" or "declared sensor noise".
    points : ndarray, shape (n_points, n_inputs)
        Operating points (levels of the known inputs) with figures of their own;
        a sample at any other operating point gets the pooled ``mean``/``std``.
    point_mean, point_std : ndarray, shape (n_points, n_residuals)
        Mean and spread of the smoothed residuals at each operating point. [sensor unit]
    notes : tuple of str
        What was learned otherwise than asked (e.g. pooled figures for a
        continuously varying input).
    """

    names: tuple[str, ...]
    mean: FloatArray
    std: FloatArray
    raw_std: FloatArray
    window: float
    source: str
    points: FloatArray = field(default_factory=lambda: np.empty((0, 0)))
    point_mean: FloatArray = field(default_factory=lambda: np.empty((0, 0)))
    point_std: FloatArray = field(default_factory=lambda: np.empty((0, 0)))
    notes: tuple[str, ...] = ()

    def figures(self, inputs: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Mean and spread for every sample, by its operating point, shape (n, n_residuals)."""
        n = len(inputs)
        mean = np.tile(self.mean, (n, 1))
        std = np.tile(self.std, (n, 1))
        for k, point in enumerate(self.points):
            at = _near(inputs, point)
            mean[at], std[at] = self.point_mean[k], self.point_std[k]
        return mean, std

    def to_dict(self) -> dict[str, Any]:
        return {"source": self.source, "window": self.window,
                "residuals": {n: {"mean": float(m), "std": float(s), "raw_std": float(r)}
                              for n, m, s, r in zip(self.names, self.mean, self.std, self.raw_std)},
                "operating_points": [{"inputs": p.tolist(), "mean": m.tolist(), "std": sd.tolist()}
                                     for p, m, sd in zip(self.points, self.point_mean,
                                                         self.point_std)],
                "notes": list(self.notes)}


@dataclass(frozen=True)
class Detection:
    """Outcome of the threshold test.

    Attributes
    ----------
    detected : bool
    time : float or None
        When the first residual had stayed outside ±1 for the persistence time. [s]
    onset : float or None
        When that residual left the band. [s]
    fired : tuple of str
        Residuals that fired anywhere in the record.
    normalised : ndarray, shape (n, n_residuals)
        Smoothed, normalised residuals (±1 is the threshold). [-]
    undecidable : str or None
        Why the record could not show a fault had there been one (no judged
        stretch as long as the persistence time), None when it could.
    """

    detected: bool
    time: float | None
    onset: float | None
    fired: tuple[str, ...]
    normalised: FloatArray
    undecidable: str | None = None


def compute_residuals(model: PlantModel, record: pd.DataFrame | Columns, generators: Sequence[Any],
                      steps: Sequence[ParameterStep] = (),
                      params: Mapping[str, float] | None = None,
                      limits: SimulationLimits | None = None, source: str = "record"
                      ) -> Residuals:
    """Run the model beside the record and return every generator's residual.

    Parameters
    ----------
    model : PlantModel
    record : DataFrame
        ``t``, the sensor columns and, optionally, the input columns.
    generators : sequence of ResidualGenerator
        From :func:`condmon.diagnose.structure.residual_generators`.
    steps : sequence of ParameterStep
        Parameter changes applied to the model (a suspect's fault).
    params : mapping, optional
        Parameter values replacing the nominal ones.
    limits : SimulationLimits, optional
        Bounds on each model run (default: the shipped ``[simulation]`` settings).
    source : str
        Name of the record for error messages.

    Raises
    ------
    DataError
        When a residual is not finite (naming ``source`` and the column).
    EstimationError
        When the model cannot be run beside the record (solver failure, limit).

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> from condmon.simulate.plant import simulate_plant
    >>> from condmon.diagnose.structure import residual_generators
    >>> m = load_plant_model("hst")
    >>> r = compute_residuals(m, simulate_plant(m, seed=1), residual_generators(m))
    >>> r.names, round(float(r.values[100:, 0].std()) / 2.5e4, 1)   # noise only
    (('r_Ps', 'r_omega_m'), 1.0)
    """
    compiled = model.compile()
    lim = limits or SimulationLimits.from_config()
    t = column_values(record, "t")
    u = input_signals(model, t, record, params)
    values = np.empty((len(t), len(generators)))
    predicted = np.empty_like(values)
    runs: dict[tuple[tuple[str, ...], tuple[str, ...]], FloatArray] = {}
    full: FloatArray | None = None
    for j, g in enumerate(generators):
        key = (g.integrated, g.inputs)
        if key not in runs:
            measured = {_measured_state(model, s): column_values(record, s)
                        for s in g.inputs}
            x = integrate(compiled, t, u, steps, params, measured, g.integrated, lim)
            runs[key] = sensor_readings(compiled, x, u, steps, t, params)
            if not g.inputs and g.integrated == model.state_names:
                full = x
        k = model.sensor_names.index(g.sensor)
        predicted[:, j] = runs[key][:, k]
        with np.errstate(all="ignore"):
            values[:, j] = column_values(record, g.sensor) - predicted[:, j]
        if not np.all(np.isfinite(values[:, j])):
            k = int(np.flatnonzero(~np.isfinite(values[:, j]))[0])
            raise DataError(f"{source}: residual {g.name!r} of column {g.sensor!r} is not finite "
                            f"at row {k} (t = {t[k]:g} s): the model's prediction overflowed")
    return Residuals(t, tuple(g.name for g in generators), tuple(g.sensor for g in generators),
                     values, predicted, u, full)


def _measured_state(model: PlantModel, sensor: str) -> str:
    return next(s.measures.strip() for s in model.sensors if s.name == sensor)


def _near(inputs: FloatArray, level: FloatArray, rel_tol: float = 0.02) -> NDArray[np.bool_]:
    """Samples whose inputs are within ``rel_tol`` of an operating point's level."""
    return np.all(np.abs(inputs - level) <= rel_tol * np.maximum(np.abs(level), 1e-12),  # type: ignore[no-any-return]
                  axis=1)


def moving_average(values: FloatArray, n: int) -> FloatArray:
    """Trailing moving average over ``n`` samples along axis 0 (shorter at the start).

    Example
    -------
    >>> moving_average(np.array([[1.0], [3.0], [5.0]]), 2).ravel().tolist()
    [1.0, 2.0, 4.0]
    """
    if n <= 1:
        return np.asarray(values, dtype=np.float64)
    with np.errstate(all="ignore"):  # values near the float limit: inf, judged by the caller
        c = np.cumsum(np.vstack([np.zeros((1, values.shape[1])), values]), axis=0)
        k = np.arange(1, len(values) + 1)
        lo = np.maximum(k - n, 0)
        return (c[k] - c[lo]) / (k - lo)[:, None]  # type: ignore[no-any-return]


def _samples(seconds: float, t: FloatArray) -> int:
    return max(1, int(round(seconds / float(t[1] - t[0]))))


def learn_normalisation(residual_sets: Sequence[Residuals], settings: DetectionSettings
                        ) -> Normalisation:
    """Mean and spread of each smoothed residual over healthy records.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> from condmon.simulate.plant import simulate_plant
    >>> from condmon.diagnose.structure import residual_generators
    >>> m = load_plant_model("hst")
    >>> gens = residual_generators(m)
    >>> sets = [compute_residuals(m, simulate_plant(m, seed=s), gens) for s in range(3)]
    >>> norm = learn_normalisation(sets, DetectionSettings())
    >>> round(float(norm.raw_std[0]) / 2.5e4, 1)   # the pressure sensor's noise
    1.0
    """
    if not residual_sets:
        raise DataError("no healthy record to learn the residuals' normalisation from")
    smooth, raw, inputs = [], [], []
    for r in residual_sets:
        keep = settings.judged(r.t, r.inputs)
        smooth.append(moving_average(r.values, _samples(settings.window, r.t))[keep])
        raw.append(r.values[keep])
        inputs.append(r.inputs[keep])
    s, w, u = np.vstack(smooth), np.vstack(raw), np.vstack(inputs)
    if len(s) < _MIN_SAMPLES:
        raise DataError(f"the healthy records hold {len(s)} judged samples (after the "
                        f"{settings.startup:g} s start-up); at least {_MIN_SAMPLES} are needed")
    with np.errstate(all="ignore"):
        std = s.std(axis=0, ddof=1)
    if not np.all(np.isfinite(std)):
        j = int(np.flatnonzero(~np.isfinite(std))[0])
        raise DataError(f"the healthy residual {residual_sets[0].names[j]!r} overflows "
                        "(readings near the float limit?)")
    if not np.all(std > 0):
        raise DataError("the healthy residuals have no spread (noise-free records?)")
    names = residual_sets[0].names
    points, pmean, pstd, notes = (_point_figures(residual_sets, s, u, std, settings)
                                  if settings.by_operating_point else ([], [], [], []))
    n_u = u.shape[1]
    return Normalisation(names, s.mean(axis=0), std, w.std(axis=0, ddof=1), settings.window,
                         f"healthy records ({len(residual_sets)})",
                         np.array(points).reshape(len(points), n_u),
                         np.array(pmean).reshape(len(points), len(names)),
                         np.array(pstd).reshape(len(points), len(names)), tuple(notes))


def _point_figures(sets: Sequence[Residuals], s: FloatArray, u: FloatArray, std: FloatArray,
                   settings: DetectionSettings
                   ) -> tuple[list[FloatArray], list[FloatArray], list[FloatArray], list[str]]:
    """Operating points of the healthy records with enough samples for figures of
    their own: (levels, means, spreads, notes). A continuously varying input has
    no operating points: the pooled figures serve, and a note says so."""
    points: list[FloatArray] = []
    short = total = 0
    for r in sets:  # the operating points met in the healthy records
        starts = operating_segments(r.inputs)
        lengths = np.diff([*starts, len(r.inputs)])
        short += int(lengths[lengths < _samples(settings.min_point_time, r.t)].sum())
        total += len(r.inputs)
        for a, b in zip(starts, [*starts[1:], len(r.inputs)]):
            level = r.inputs[a:b].mean(axis=0)
            if not any(_near(level[None, :], p)[0] for p in points):
                points.append(level)
    if short > 0.5 * total:
        return [], [], [], [f"the known inputs vary continuously in the healthy records "
                            f"({len(points)} levels, most held less than "
                            f"{settings.min_point_time:g} s): pooled normalisation"]
    enough = max(_samples(settings.min_point_time, sets[0].t), _MIN_SAMPLES)
    kept, pmean, pstd = [], [], []
    for level in points if len(points) > 1 else []:
        at = _near(u, level)
        if at.sum() >= enough:
            spread = s[at].std(axis=0, ddof=1)
            if np.all(np.isfinite(spread)):
                kept.append(level)
                pmean.append(s[at].mean(axis=0))
                pstd.append(np.maximum(spread, 1e-12 * std))
    notes = []
    if len(points) > 1 and len(kept) < len(points):
        notes.append(f"{len(points) - len(kept)} of {len(points)} operating points held less "
                     f"than {settings.min_point_time:g} s: pooled figures there")
    return kept, pmean, pstd, notes


def noise_normalisation(model: PlantModel, residuals: Residuals, settings: DetectionSettings
                        ) -> Normalisation:
    """Normalisation from the sensors' declared noise (white, zero mean): the
    fallback when no healthy record is given."""
    n = _samples(settings.window, residuals.t)
    noise = {s.name: s.noise for s in model.sensors}
    raw = np.array([noise[s] for s in residuals.sensors], dtype=np.float64)
    return Normalisation(residuals.names, np.zeros(len(raw)), raw / np.sqrt(n), raw,
                         settings.window, "declared sensor noise")


def detect(residuals: Residuals, norm: Normalisation, settings: DetectionSettings
           ) -> Detection:
    """Debounced threshold test of the normalised residuals.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> from condmon.simulate.plant import simulate_plant
    >>> from condmon.diagnose.structure import residual_generators
    >>> m = load_plant_model("hst")
    >>> gens = residual_generators(m)
    >>> r = compute_residuals(m, simulate_plant(m, ["Rv=+25%@10s"], seed=3), gens)
    >>> d = detect(r, noise_normalisation(m, r, DetectionSettings()), DetectionSettings())
    >>> d.detected, d.fired, 10.0 < d.time < 11.0
    (True, ('r_Ps', 'r_omega_m'), True)
    """
    if norm.names != residuals.names:
        raise ConfigError(f"the normalisation is for residuals {list(norm.names)}, "
                          f"not {list(residuals.names)}")
    t = residuals.t
    smooth = moving_average(residuals.values, _samples(norm.window, t))
    mean, std = norm.figures(residuals.inputs)
    with np.errstate(all="ignore"):
        normalised = (smooth - mean) / (settings.z * std)
    need = _samples(settings.persistence, t) if settings.persistence > 0 else 1
    judged = settings.judged(t, residuals.inputs)
    outside = (np.abs(normalised) > 1.0) & judged[:, None]
    fired, first = [], (np.inf, np.inf)
    for j, name in enumerate(residuals.names):
        start = _first_run(outside[:, j], need)
        if start is not None:
            fired.append(name)
            first = min(first, (float(t[start + need - 1]), float(t[start])))
    if not fired:
        why = None
        if _first_run(judged, need) is None:
            longest = _longest_run(judged) * float(t[1] - t[0])
            why = (f"record too short to decide: it lasts {t[-1] - t[0]:.3g} s and its "
                   f"longest judged stretch (after the {settings.startup:g} s start-up"
                   + (f", outside {settings.input_settle:g} s after input steps"
                      if settings.input_settle > 0 else "")
                   + f") is {longest:.3g} s, less than the {settings.persistence:g} s a "
                   "residual must stay outside its band")
        return Detection(False, None, None, (), normalised, why)
    return Detection(True, first[0], first[1], tuple(fired), normalised)


def _longest_run(flags: NDArray[np.bool_]) -> int:
    """Length of the longest run of True values."""
    padded = np.concatenate([[False], flags, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return int((edges[1::2] - edges[::2]).max()) if len(edges) else 0


def _first_run(flags: NDArray[np.bool_], length: int) -> int | None:
    """Index where the first run of at least ``length`` True values starts."""
    if length <= 1:
        idx = np.flatnonzero(flags)
        return int(idx[0]) if len(idx) else None
    padded = np.concatenate([[False], flags, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    starts, ends = edges[::2], edges[1::2]
    long = np.flatnonzero(ends - starts >= length)
    return int(starts[long[0]]) if len(long) else None
