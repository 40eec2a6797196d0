"""Many units of one plant model tracked online: model beside each stream, residuals, detection.

A :class:`ModelTracker` holds one :class:`~condmon.simulate.stepper.BatchStepper`
(the model's copies, one per unit, advanced together) and one
:class:`~condmon.diagnose.online.OnlineDetector` per unit. Each call of
:meth:`ModelTracker.feed` takes the chunks that arrived (any number of units,
any lengths), advances every unit's model through its chunk, forms the
residuals (measured − model) and judges them.

What a stream does that a file does not is handled here, once:

- a chunk that starts at or before the end of the unit's last one (a duplicate,
  or one out of order) is dropped and counted;
- a gap longer than ``max_gap`` samples, a change of sample interval, or a
  restart of the clock (a chunk wholly before the last, by more than
  ``max_gap`` samples) resets the unit's model and detector, with a note;
- a chunk's known inputs come from its columns, or the input's nominal value.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from condmon.diagnose.online import OnlineDetection, OnlineDetector, noise_figures
from condmon.diagnose.residuals import DetectionSettings, Normalisation
from condmon.errors import DataError
from condmon.models.declared import PlantModel
from condmon.simulate.stepper import BatchStepper

__all__ = ["ChunkOutcome", "ModelTracker", "measured_start", "started_at"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ChunkOutcome:
    """What one chunk of one unit gave.

    Attributes
    ----------
    unit : str
    samples : int
        Samples judged (0 when the chunk was dropped).
    detection : OnlineDetection or None
        The unit's detection, when it happened in this chunk.
    dropped : str or None
        Why the chunk was dropped (duplicate, out of order), None when used.
    notes : tuple of str
        Resets and assumptions (a gap, a restart, an input at its nominal value).
    end : float
        Time of the chunk's last sample. [s]
    """

    unit: str
    samples: int
    detection: OnlineDetection | None = None
    dropped: str | None = None
    notes: tuple[str, ...] = ()
    end: float = math.nan


@dataclass
class _Unit:
    slot: int
    detector: OnlineDetector | None = None
    last_t: float = -math.inf
    dt: float = math.nan
    last_u: FloatArray | None = None
    pending: dict[str, FloatArray] | None = None
    initial: dict[str, float] = field(default_factory=dict)


@dataclass
class ModelTracker:
    """Track every unit of ``model`` beside its stream.

    Parameters
    ----------
    model : PlantModel
    settings : DetectionSettings
    substeps : int
        Runge-Kutta steps per sample of the model's copies.
    max_gap : float
        A gap longer than this many sample intervals resets the unit. [-]
    normalisation : mapping of unit to Normalisation, optional
        Learned figures per unit; others use the sensors' declared noise.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> from condmon.simulate.plant import simulate_plant
    >>> m = load_plant_model("hst")
    >>> rec = simulate_plant(m, ["Rv=+40%@10s"], seed=2, duration=16.0)
    >>> tr = ModelTracker(m, DetectionSettings())
    >>> cols = {c: rec[c].to_numpy() for c in rec.columns}
    >>> out = [tr.feed({"HST-1": {c: v[k:k + 100] for c, v in cols.items()}})[0]
    ...        for k in range(0, len(rec), 100)]
    >>> [(o.end, o.detection.time) for o in out if o.detection]
    [(10.99, 10.53)]
    """

    model: PlantModel
    settings: DetectionSettings
    substeps: int = 10
    max_gap: float = 5.0
    normalisation: Mapping[str, Normalisation] = field(default_factory=dict)
    dropped: int = 0
    _stepper: BatchStepper = field(init=False, repr=False)
    _units: dict[str, _Unit] = field(init=False, repr=False, default_factory=dict)

    def __post_init__(self) -> None:
        self._stepper = BatchStepper(self.model, self.substeps)

    @property
    def units(self) -> list[str]:
        """The units tracked."""
        return list(self._units)

    def detection(self, unit: str) -> OnlineDetection | None:
        """The unit's detection since its last reset (None: none)."""
        u = self._units.get(unit)
        return u.detector.detected if u is not None and u.detector is not None else None

    def reset(self, unit: str) -> None:
        """Start the unit's model and detector again (after an isolation, say)."""
        u = self._units.get(unit)
        if u is not None:
            self._stepper.reset([u.slot])
            if u.detector is not None:
                u.detector.reset()

    def initial_states(self, unit: str) -> dict[str, float]:
        """The states the unit's model started from at its stream's (re)start. [SI]"""
        u = self._units.get(unit)
        return dict(u.initial) if u is not None else {}

    def feed(self, chunks: Mapping[str, Mapping[str, FloatArray]]) -> list[ChunkOutcome]:
        """Advance and judge one chunk per unit (columns ``t`` and the sensors).

        Chunks are validated first (:func:`condmon.io.stream.chunk_columns`
        does it for a message); one of unequal lengths here is a DataError.
        """
        outcomes: dict[str, ChunkOutcome] = {}
        ready: list[tuple[str, _Unit, FloatArray, FloatArray, FloatArray, list[str]]] = []
        for name, given in chunks.items():
            unit = self._units.get(name)
            if unit is None:
                unit = self._units[name] = _Unit(self._stepper.add())
            cols = {c: np.asarray(v, dtype=np.float64) for c, v in given.items()}
            if unit.pending is not None:
                cols = {c: np.concatenate([unit.pending[c], v]) for c, v in cols.items()
                        if c in unit.pending}
                unit.pending = None
            t = cols["t"]
            if unit.detector is None and len(t) == 1:
                # a stream's first sample alone tells no sample interval: kept for the next
                unit.pending = cols
                outcomes[name] = ChunkOutcome(name, 0, notes=(
                    "first sample held until the next gives the sample interval",),
                    end=float(t[0]))
                continue
            if len(t) == 0:
                outcomes[name] = ChunkOutcome(name, 0, dropped="empty chunk")
                continue
            if t[0] <= unit.last_t and t[-1] >= unit.last_t - self.max_gap * unit.dt:
                self.dropped += 1
                what = "a duplicate" if t[-1] <= unit.last_t else "out of order"
                outcomes[name] = ChunkOutcome(name, 0, dropped=(
                    f"{what}: starts at t = {t[0]:g} s, not after the last sample "
                    f"(t = {unit.last_t:g} s)"), end=float(t[-1]))
                continue
            notes = self._restart_if_needed(name, unit, t, cols)
            y = np.column_stack([np.asarray(cols[s], dtype=np.float64)
                                 for s in self.model.sensor_names])
            u = np.empty((len(t), len(self.model.inputs)))
            for j, inp in enumerate(self.model.inputs):
                if inp.name in cols:
                    u[:, j] = np.asarray(cols[inp.name], dtype=np.float64)
                else:
                    u[:, j] = self.model.input_nominal(inp.name)
                    notes.append(f"input {inp.name!r} not in the stream: at its nominal value")
            ready.append((name, unit, t, y, u, notes))
        predicted = self._advance(ready)
        for (name, unit, t, y, u, notes), pred in zip(ready, predicted):
            bad = np.asarray(~np.isfinite(pred).all(axis=1), dtype=bool)
            if bad.any():
                notes.append(f"the model's states overflowed at t = {t[int(np.argmax(bad))]:g} s: "
                             "reset")
                self.reset(name)
            assert unit.detector is not None
            found = unit.detector.feed(t, np.where(bad[:, None], 0.0, y - pred), u)
            unit.last_t = float(t[-1])
            outcomes[name] = ChunkOutcome(name, len(t), found, None, tuple(notes), float(t[-1]))
        return [outcomes[n] for n in chunks]

    def _restart_if_needed(self, name: str, unit: _Unit, t: FloatArray,
                           chunk: Mapping[str, FloatArray]) -> list[str]:
        """Start the unit afresh at its first chunk, after a gap, or at a new
        sample interval; say why."""
        dt = float(np.median(np.diff(t))) if len(t) > 1 else (
            unit.dt if math.isfinite(unit.dt) else math.nan)
        if not dt > 0:
            if math.isfinite(unit.last_t):
                dt = float(t[0]) - unit.last_t
            if not dt > 0:
                raise DataError(f"unit {name!r}: the chunk's sample interval is unknown "
                                "(one sample, and none before it)")
        notes: list[str] = []
        if unit.detector is not None:
            gap = float(t[0]) - unit.last_t
            if gap <= 0:
                notes.append(f"the stream's clock went back (t = {t[0]:g} s after "
                             f"{unit.last_t:g} s): a restart; the model is started again")
            elif abs(dt - unit.dt) > 1e-6 * unit.dt:
                notes.append(f"sample interval changed from {unit.dt:g} s to {dt:g} s: the "
                             "model is started again")
            elif gap > self.max_gap * unit.dt:
                notes.append(f"a gap of {gap:g} s in the stream (from t = {unit.last_t:g} s): "
                             "the model is started again")
            else:
                return notes
        norm = self.normalisation.get(name) or noise_figures(self.model, dt, self.settings)
        unit.initial = measured_start(self.model, chunk)
        self._stepper.set_states(unit.slot, unit.initial)
        unit.last_u = None
        unit.detector = OnlineDetector(norm, self.settings, dt)
        unit.dt = dt
        return notes

    def _advance(self, ready: list[tuple[str, _Unit, FloatArray, FloatArray, FloatArray,
                                        list[str]]]) -> list[FloatArray]:
        """The model's readings for every ready chunk, the units advanced together
        sample by sample (a shorter chunk's unit stands still once it is done)."""
        if not ready:
            return []
        slots = np.array([r[1].slot for r in ready], dtype=np.intp)
        lengths = np.array([len(r[2]) for r in ready])
        n_max = int(lengths.max())
        n_in = len(self.model.inputs)
        inputs = np.zeros((n_max, n_in, len(ready)))
        steps = np.zeros((n_max, len(ready)))
        for i, (_, unit, t, _, u, _) in enumerate(ready):
            # the step to sample k holds the input of sample k-1 (as a logger
            # holds it); the first sample of a fresh unit is its initial state
            held = u[:1] if unit.last_u is None else unit.last_u
            fresh = unit.last_u is None
            inputs[: len(t), :, i] = np.vstack([held, u[:-1]])
            first = 0.0 if fresh else float(t[0]) - unit.last_t
            steps[: len(t), i] = np.diff(t, prepend=float(t[0]) - first)
            unit.last_u = u[-1:].copy()
        out = np.empty((n_max, len(self.model.sensors), len(ready)))
        for k in range(n_max):
            out[k] = self._stepper.step(slots, inputs[k], steps[k])
        return [out[: lengths[i], :, i] for i in range(len(ready))]


def measured_start(model: PlantModel, chunk: Mapping[str, FloatArray]) -> dict[str, float]:
    """Initial states of a stream joined at any moment.

    Each state a sensor reads directly starts at the stream's first reading (a
    plant at rest gives its declared initial state within the sensor's noise; a
    running one its operating point; one sample, as a plant starting up moves
    fast). Each other state starts where its own derivative is zero with those
    readings and the first known inputs (the quasi-steady value: the motor
    plenum's pressure that passes the flow the motor takes), solved by least
    squares from its declared initial value; where that fails, it stays at the
    declared value and settles in the start-up, which is not judged.
    [state units]

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> x = measured_start(load_plant_model("hst"), {"t": np.arange(3.0),
    ...     "Ps": np.full(3, 4.0e6), "omega_m": np.full(3, 14.4), "omega_p": np.full(3, 152.0)})
    >>> {k: round(v / 1e5, 2) if k != "omega_m" else v for k, v in x.items()}   # [bar]
    {'Ps': 40.0, 'omega_m': 14.4, 'Pm': 36.94}
    """
    from scipy.optimize import least_squares

    out: dict[str, float] = {}
    states = model.state_names
    for s in model.sensors:
        name = s.measures.strip()
        if name in states and s.name in chunk and len(chunk[s.name]):
            out[name] = float(np.asarray(chunk[s.name], dtype=np.float64)[0])
    free = [i for i, n in enumerate(states) if n not in out]
    if not out or not free:
        return out
    compiled = model.compile()
    p = compiled.parameter_vector()
    u = np.array([float(np.asarray(chunk[i.name])[0]) if i.name in chunk and len(chunk[i.name])
                  else model.input_nominal(i.name) for i in model.inputs], dtype=np.float64)
    x = np.array([out.get(n, st.initial) for n, st in zip(states, model.states)])
    scale = np.maximum(np.abs(x[free]), max(1.0, float(np.max(np.abs(x)))))

    def residual(z: FloatArray) -> FloatArray:
        xx = x.copy()
        xx[free] = z * scale
        with np.errstate(all="ignore"):
            d = compiled.rhs(xx, u, p)[free]
        return np.where(np.isfinite(d), d, 1e30)

    try:
        sol = least_squares(residual, x[free] / scale, method="trf")
    except (ValueError, ArithmeticError):
        return out
    start = residual(x[free] / scale)
    if sol.success and np.all(np.isfinite(sol.x)) and np.linalg.norm(sol.fun) < np.linalg.norm(start):
        for i, z in zip(free, sol.x):
            out[states[i]] = float(z * scale[free.index(i)])
    return out


def started_at(model: PlantModel, initial: Mapping[str, float]) -> PlantModel:
    """The model with some states starting elsewhere than declared (a stream
    joined while the plant runs: the isolation's model runs from there too).

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> [s.initial for s in started_at(load_plant_model("hst"), {"Ps": 4e6}).states]
    [4000000.0, 0.0, 0.0]
    """
    import dataclasses

    return dataclasses.replace(model, states=tuple(
        dataclasses.replace(s, initial=float(initial[s.name])) if s.name in initial else s
        for s in model.states))

