"""A model against a record it was not fitted on (MATLAB's ``compare`` and ``sim``).

The model runs on the record's inputs alone, from given initial states, and
its sensor readings are set beside the measured ones:

- **RMSE** per output, ``sqrt(mean((y - ŷ)²))`` [sensor unit], the figure the
  system-identification benchmarks publish;
- **fit** per output, ``100 (1 - ||y - ŷ|| / ||y - mean(y)||)`` [%], the
  normalised figure of MATLAB's ``compare`` (100 % is a perfect simulation,
  0 % no better than the mean, negative worse).

Which initial states to start from is the benchmark's rule, and the caller's
choice (:func:`initial_states`): the ones the estimate found (the cascaded
tanks' rule: the validation record starts where the estimation record did),
each measured state from the record's first reading, or the states that best
simulate the record itself (MATLAB ``compare``'s default, fitted by
:func:`~condmon.identify.simulation_route.fit_initial_states`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConfigError
from condmon.io.records import Record
from condmon.models.declared import PlantModel
from condmon.models.machine import Machine
from condmon.models.shooting import state_readers
from condmon.simulate.recorded import (Diverged, choose_substeps, growth_rate, simulate_recorded,
                                       stable_substeps)

__all__ = ["Comparison", "beyond_noise", "compare_model", "initial_states", "INITIAL_RULES"]

FloatArray = NDArray[np.float64]

#: How ``condmon validate`` may start the simulation ("fit": the states fitted on the
#: record itself, MATLAB ``compare``'s default; :func:`initial_states` gives its start).
INITIAL_RULES = ("estimated", "first-sample", "fit")


@dataclass(frozen=True)
class Comparison:
    """A model simulated on a record's inputs, beside the measured outputs.

    Attributes
    ----------
    source : str
        The record.
    model : str
    t : ndarray
        Sample times from the record's start. [s]
    outputs : tuple of str
        The sensors compared.
    measured : ndarray, shape (N, n_outputs), or None
        The record's readings (None: it has no sensor columns, nothing is
        compared). [sensor units]
    simulated : ndarray, shape (N, n_outputs)
        [sensor units]
    units : dict of str to str
        Each output's unit.
    rmse : dict of str to float
        Root-mean-square simulation error per output. [sensor unit]
    fit_percent : dict of str to float
        ``100 (1 - ||y - ŷ|| / ||y - mean(y)||)`` per output. [%]
    initial : dict of str to (float, str)
        Each state's initial value and where it came from. [state units]
    parameters : dict of str to float
        The parameters simulated with. [SI]
    substeps : int
        Runge-Kutta steps per sample.
    notes : tuple of str
    states : ndarray, shape (N, n_states), optional
        The simulated states, in the model's order. [state units]
    """

    source: str
    model: str
    t: FloatArray
    outputs: tuple[str, ...]
    measured: FloatArray | None
    simulated: FloatArray
    units: dict[str, str]
    rmse: dict[str, float]
    fit_percent: dict[str, float]
    initial: dict[str, tuple[float, str]]
    parameters: dict[str, float]
    substeps: int
    notes: tuple[str, ...] = field(default=())
    states: FloatArray | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures (no samples)."""
        return {"source": self.source, "model": self.model, "samples": int(len(self.t)),
                "rmse": dict(self.rmse), "fit_percent": dict(self.fit_percent),
                "units": {k: self.units[k] for k in self.outputs},
                "initial_states": {k: {"value": v, "from": how}
                                   for k, (v, how) in self.initial.items()},
                "parameters": dict(self.parameters), "substeps": self.substeps,
                "notes": list(self.notes)}


def initial_states(machine: Machine, record: Record, rule: str,
                   estimated: Mapping[str, float] | None = None,
                   given: Mapping[str, float] | None = None,
                   params: Mapping[str, float] | None = None) -> dict[str, tuple[float, str]]:
    """Where the simulation starts, per state, and why.

    Parameters
    ----------
    machine : Machine
    record : Record
    rule : {"estimated", "first-sample", "fit"}
        "estimated": the estimate's initial states (``estimated``); a state it
        lacks starts from the first reading when a sensor gives it back, else
        from its declared initial value. "first-sample": every state a sensor
        gives back (:func:`~condmon.models.shooting.state_readers`) from the
        record's first reading, the others as "estimated". "fit": as
        "estimated", the start of
        :func:`~condmon.identify.simulation_route.fit_initial_states`.
    estimated : mapping, optional
        The estimate's initial states. [state units]
    given : mapping, optional
        States set by the user; they win. [state units]
    params : mapping, optional
        Parameters the readings are inverted with (a sensor offset). [SI]

    Raises
    ------
    ConfigError
        For an unknown rule or a state the model does not have.
    """
    plant = machine.plant
    if rule not in INITIAL_RULES:
        raise ConfigError(f"unknown initial-state rule {rule!r}; allowed: "
                          f"{', '.join(INITIAL_RULES)}, or NAME=VALUE,... per state")
    for name in (*(estimated or {}), *(given or {})):
        if name not in plant.state_names:
            raise ConfigError(f"initial state {name!r}: model {machine.name!r} has no such "
                              f"state; its states: {', '.join(plant.state_names)}")
    p = plant.compile().parameter_vector(params)
    readers = state_readers(plant)
    out: dict[str, tuple[float, str]] = {}
    for s in plant.states:
        if given and s.name in given:
            out[s.name] = (float(given[s.name]), "given")
        elif rule in ("estimated", "fit") and estimated and s.name in estimated:
            out[s.name] = (float(estimated[s.name]), "estimated")
        elif s.name in readers and plant.sensor_names[readers[s.name][0]] in record.columns:
            j, fn = readers[s.name]
            out[s.name] = (float(fn(record[plant.sensor_names[j]][0], p)), "first sample")
        elif estimated and s.name in estimated:
            out[s.name] = (float(estimated[s.name]), "estimated")
        else:
            out[s.name] = (float(s.initial), "declared")
    return out


def compare_model(record: Record, machine: Machine, params: Mapping[str, float],
                  initial: Mapping[str, tuple[float, str]], *, notes: tuple[str, ...] = ()
                  ) -> Comparison:
    """Simulate ``machine`` on ``record``'s inputs and compare its outputs.

    Parameters
    ----------
    record : Record
        With the model's inputs, and its sensors to compare with (without
        them the model is only simulated: no RMSE or fit).
    machine : Machine
    params : mapping
        Parameter values over the declared ones. [SI]
    initial : mapping of str to (float, str)
        :func:`initial_states`. [state units]
    notes : tuple of str

    Returns
    -------
    Comparison

    Raises
    ------
    ~condmon.simulate.recorded.Diverged
        When the simulation diverges (naming the time and the state).

    Example
    -------
    >>> from condmon.models.registry import get_model
    >>> from condmon.simulate.plant import simulate_plant
    >>> from condmon.io.records import validate_record
    >>> m = get_model("dc-motor")
    >>> rec = validate_record(simulate_plant(m.plant, seed=1), ("V", "I", "omega"))
    >>> c = compare_model(rec, m, {}, initial_states(m, rec, "first-sample"))
    >>> round(c.fit_percent["omega"]), c.initial["omega"][1]   # the sensor noise limits it
    (98, 'first sample')
    """
    plant = machine.plant
    compiled = plant.compile()
    p = compiled.parameter_vector(params)
    x0 = np.array([initial[s][0] for s in plant.state_names], dtype=np.float64)
    u = record.stack(plant.input_names) if plant.input_names else np.zeros((len(record), 0))
    measured = all(n in record.columns for n in plant.sensor_names)
    y = record.stack(plant.sensor_names) if measured else None
    spread = np.std(y, axis=0) if y is not None else np.zeros(len(plant.sensors))
    noise = np.array([s.noise for s in plant.sensors])
    tol = 0.1 * np.maximum(noise, np.where(spread > 0, 1e-3 * spread, 1e-9))
    t = np.arange(len(record), dtype=np.float64) * record.dt
    growth = _growth(compiled, x0, u, p, t)
    if growth:   # unstable: the step its fastest mode needs, no search (every step diverges)
        sub = stable_substeps(compiled, x0, u[0] if len(u) else np.zeros(0), p, record.dt)
    else:
        sub = choose_substeps(compiled, u, record.dt, x0[:, None], p[:, None], tol)
    sim = simulate_recorded(compiled, u, record.dt, x0, p, substeps=sub, source=record.source)
    step = None
    if y is not None and not growth:   # the step's own error, against which a miss is read
        with np.errstate(all="ignore"):
            half = simulate_recorded(compiled, u, record.dt, x0, p, substeps=2 * sub).outputs
            step = 2.0 * np.sqrt(np.mean((half - sim.outputs) ** 2, axis=0))
        step = np.where(np.isfinite(step), step, 0.0)
    rmse, fit = {}, {}
    for j, name in enumerate(plant.sensor_names if y is not None else ()):
        assert y is not None
        e = y[:, j] - sim.outputs[:, j]
        with np.errstate(over="ignore", invalid="ignore"):   # (an overflow: refused below)
            rmse[name] = float(np.sqrt(np.mean(e ** 2)))
            dev = float(np.linalg.norm(y[:, j] - np.mean(y[:, j])))
            fit[name] = float(100.0 * (1.0 - np.linalg.norm(e) / dev)) if dev > 0 else \
                (100.0 if rmse[name] == 0 else -math.inf)
    values = dict(zip(plant.parameter_names, map(float, p)))
    bad = [n for n in rmse if not math.isfinite(rmse[n])]
    if bad:   # outputs so large their squares overflow: no figure to give
        raise Diverged(f"{record.source}: the simulation diverged: the simulated "
                       f"{', '.join(bad)} grew past what a float can square (states finite "
                       f"to the end){growth}; check the values",
                       float(sim.t[-1]), plant.sensor_names[0])
    if growth and y is not None:
        reach = np.max(np.abs(sim.outputs), axis=0)
        seen = np.maximum(np.max(np.abs(y), axis=0), noise)
        grown = [n for n, a, b in zip(plant.sensor_names, reach, seen) if a > 1e6 * b]
        if grown:   # it did grow: a million times what the record measured is no model of it
            k = int(np.argmax(np.any(np.abs(sim.outputs) > 1e6 * seen, axis=1)))
            raise Diverged(f"{record.source}: the simulation diverged: the simulated "
                           f"{', '.join(grown)} passed a million times the record's largest "
                           f"reading at t = {sim.t[k]:g} s{growth}; check the values, or the "
                           "initial states", float(sim.t[k]), grown[0])
    if growth:
        notes = (*notes, growth[2:] + ": the figures measure that growth, not the model's "
                 "fit (check the values, or the initial states)")
    if y is not None:
        notes = (*notes, *beyond_noise(plant, y - sim.outputs, step))
    return Comparison(record.source, machine.name, sim.t, plant.sensor_names, y, sim.outputs,
                      {s.name: s.unit for s in plant.sensors}, rmse, fit, dict(initial), values,
                      sub, notes, sim.states)


def _growth(compiled: Any, x0: FloatArray, u: FloatArray, p: FloatArray, t: FloatArray) -> str:
    """``"; ..."`` saying the model is unstable with these values where a mode
    grows more than a millionfold over the record ("" otherwise): a growth the
    record's own length shows, not a slow drift (e^13.8 = 10^6)."""
    rate = growth_rate(compiled, x0, u[0] if len(u) else np.zeros(0), p)
    span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    if not (math.isfinite(rate) and rate * span > math.log(1e6)):
        return ""
    return (f"; with these values the model is unstable: a mode grows e-fold every "
            f"{1.0 / rate:.3g} s, about 10^{rate * span / math.log(10):.0f}-fold over "
            f"the record's {span:.3g} s")


# A model that describes the record leaves the sensor's noise: an RMS error twice the
# declared noise is a variance four times what the sensor makes, more than a noise level
# declared from a data sheet is normally off by.
NOISE_FACTOR = 2.0


def beyond_noise(plant: PlantModel, e: FloatArray, step: FloatArray | None = None) -> list[str]:
    """What each sensor whose simulation error ``e`` (N, n_sensors) [sensor
    units] is beyond :data:`NOISE_FACTOR` times its declared noise says;
    ``step``, each output's step error (RMS) [sensor units], names the
    integrator where it is a third of the miss or more.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> p = load_plant_model("dc-motor")
    >>> e = np.zeros((100, len(p.sensors)))
    >>> beyond_noise(p, e)
    []
    """
    out = []
    for j, s in enumerate(plant.sensors):
        rms = math.sqrt(float(np.mean(e[:, j] ** 2)))
        if s.noise > 0 and rms > NOISE_FACTOR * s.noise:
            unit = f" {s.unit}".rstrip()
            said = (f"the simulation misses {s.name} by {rms:.3g}{unit} RMS, "
                    f"{rms / s.noise:.3g} times the sensor's declared noise ({s.noise:g}{unit})")
            if step is not None and step[j] >= rms / 3:
                out.append(f"{said}; of that, the integrator's own step error is about "
                           f"{step[j]:.2g}{unit} RMS (twice what halving the step changes): "
                           "the step, not only the model, misses (fourth-order Runge-Kutta "
                           "falls to first order across a sign() or max() switch)")
                continue
            out.append(f"{said}: the model, a declared value or a 'declared' initial state "
                       "does not describe this record to the sensor's accuracy")
    return out
