"""Fault detection and isolation of a declared plant from one record.

The flow (SPEC part B): run the model beside the plant → normalised residuals
and debounced detection → suspects from the fault signature matrix (single-fault
hypothesis) → steady-state estimate of each suspect → one model per suspect,
simulated with its estimate, in parallel → the least output error isolates the
fault; suspects whose error is not significantly worse are reported with it as
an ambiguity set.

Each suspect's simulation is a pure function of a small picklable task
(:func:`simulate_suspect`), so it can be shipped to a process pool, as here, or
to a distributed engine.
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy import stats

from condmon.diagnose.residuals import (
    Detection, DetectionSettings, Normalisation, Residuals, compute_residuals, detect,
    learn_normalisation, load_settings, noise_normalisation, validate_plant_record,
)
from condmon.diagnose.structure import (
    FaultSignature, ResidualKind, fault_signature, residual_generators, suspects,
)
from condmon.errors import ConfigError
from condmon.identify.steady_state import (
    SteadyStateEstimate, estimate_steady_state, steady_windows,
)
from condmon.models.declared import PlantModel
from condmon.simulate.plant import ParameterStep, integrate, sensor_readings, simulate_plant

__all__ = ["IsolationSettings", "SuspectTask", "IsolationResult", "simulate_suspect",
           "isolate", "healthy_normalisation"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class IsolationSettings:
    """Settings of the whole flow (defaults: ``condmon/data/isolation.toml``).

    Attributes
    ----------
    detection : DetectionSettings
    estimation_settle : float
        Wait after detection or a known input step before a steady window. [s]
    min_window : float
        Shortest steady window used. [s]
    compare_settle : float
        Model outputs are compared from this long after detection. [s]
    significance : float
        Level of the test "not significantly worse than the best". [-]
    """

    detection: DetectionSettings = field(default_factory=DetectionSettings)
    estimation_settle: float = 4.0
    min_window: float = 1.0
    compare_settle: float = 4.0
    significance: float = 0.01

    @classmethod
    def load(cls, path: str | Path | None = None) -> IsolationSettings:
        """Settings from the shipped file, overridden by ``path``."""
        cfg = load_settings(path)
        out = cls(DetectionSettings.from_config(cfg), float(cfg["estimation"]["settle"]),
                  float(cfg["estimation"]["min_window"]), float(cfg["isolation"]["settle"]),
                  float(cfg["isolation"]["significance"]))
        if not 0 < out.significance < 1:
            raise ConfigError(f"[isolation].significance must be in (0, 1), not {out.significance}")
        return out


@dataclass(frozen=True)
class SuspectTask:
    """One suspect's model run: ``parameter`` steps to ``value`` at ``at`` [s]."""

    model: PlantModel
    parameter: str
    value: float
    at: float
    t: FloatArray
    u: FloatArray


def simulate_suspect(task: SuspectTask) -> FloatArray:
    """Sensor readings of the model with the suspect's estimate, shape (n, n_sensors).

    A pure function of its task: safe to run in another process.
    """
    compiled = task.model.compile()
    steps = (ParameterStep(task.parameter, task.at, task.value),)
    x = integrate(compiled, task.t, task.u, steps)
    return sensor_readings(compiled, x, task.u, steps, task.t)


@dataclass(frozen=True)
class IsolationResult:
    """Everything the isolation found, with what it was found from.

    Attributes
    ----------
    model : str
    detected : bool
    detection_time, onset_time : float or None
        [s]
    fired_residuals : tuple of str
    fsm : FaultSignature
    suspects : tuple of str
    estimates : dict of str to SteadyStateEstimate
    errors : dict of str to float
        RMS of each suspect model's output error after the transient, in units
        of each sensor's noise (about 1 for a model that explains the data). [-]
    isolated : tuple of str
        The least-error suspect and those not significantly worse (ambiguity set).
    statement : str
        The conclusion in words.
    residuals : Residuals
    normalisation : Normalisation
    detection : Detection
    outputs : dict of str to ndarray
        Each suspect model's sensor readings. [sensor units]
    compare_from : float or None
        Start of the comparison window. [s]
    sensor_noise : ndarray
        Per-sample noise of each sensor the errors are expressed in. [sensor units]
    """

    model: str
    detected: bool
    detection_time: float | None
    onset_time: float | None
    fired_residuals: tuple[str, ...]
    fsm: FaultSignature
    suspects: tuple[str, ...]
    estimates: dict[str, SteadyStateEstimate]
    errors: dict[str, float]
    isolated: tuple[str, ...]
    statement: str
    residuals: Residuals
    normalisation: Normalisation
    detection: Detection
    outputs: dict[str, FloatArray]
    compare_from: float | None
    sensor_noise: FloatArray

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (keys ``detected``, ``detection_time``,
        ``fired_residuals``, ``fsm``, ``suspects``, ``estimates``, ``errors``,
        ``isolated``, ...)."""
        return {
            "model": self.model,
            "detected": self.detected,
            "detection_time": self.detection_time,
            "onset_time": self.onset_time,
            "fired_residuals": list(self.fired_residuals),
            "fsm": self.fsm.to_dict(),
            "suspects": list(self.suspects),
            "estimates": {p: e.value for p, e in self.estimates.items()},
            "estimate_change_percent": {p: e.change_percent for p, e in self.estimates.items()},
            "consistency": {p: e.consistency for p, e in self.estimates.items()},
            "errors": dict(self.errors),
            "isolated": list(self.isolated),
            "ambiguous": len(self.isolated) > 1,
            "statement": self.statement,
            "normalisation": self.normalisation.to_dict(),
        }


def healthy_normalisation(model: PlantModel, healthy: Sequence[pd.DataFrame],
                          kind: ResidualKind = "simulation",
                          settings: DetectionSettings | None = None) -> Normalisation:
    """Learn the residuals' normalisation from healthy records.

    Example
    -------
    >>> from condmon.models.declared import load_plant_model
    >>> from condmon.simulate.plant import simulate_plant
    >>> m = load_plant_model("hst")
    >>> norm = healthy_normalisation(m, [simulate_plant(m, seed=s) for s in range(3)])
    >>> norm.names
    ('r_Ps', 'r_omega_m')
    """
    gens = residual_generators(model, kind)
    sets = [compute_residuals(model, validate_plant_record(model, r, f"healthy record {i + 1}"), gens)
            for i, r in enumerate(healthy)]
    return learn_normalisation(sets, settings or DetectionSettings.from_config())


def isolate(record: pd.DataFrame, model: PlantModel, *,
            normalisation: Normalisation | None = None, kind: ResidualKind = "simulation",
            settings: IsolationSettings | None = None, workers: int | None = None,
            progress: Callable[[int, int, str], None] | None = None,
            source: str = "record") -> IsolationResult:
    """Detect, estimate and isolate a parameter fault in one record.

    Parameters
    ----------
    record : DataFrame
        ``t`` [s], the model's sensor columns and optionally its input columns.
    model : PlantModel
        The declared healthy plant.
    normalisation : Normalisation, optional
        Learned from healthy records (:func:`healthy_normalisation`). Default:
        from the sensors' declared noise for simulation residuals; for structured
        ones (whose measured inputs carry noise through the dynamics) learned
        from three healthy records simulated with the declared noise.
    kind : {"simulation", "structured"}
        Residual set (see :mod:`condmon.diagnose.structure`).
    settings : IsolationSettings, optional
    workers : int, optional
        Processes for the suspects' models; 1 runs them one after the other.
        Default: one per suspect, at most the number of CPUs.
    progress : callable, optional
        ``progress(done, total, label)`` after each stage.
    source : str
        Name of the record for error messages.

    Returns
    -------
    IsolationResult

    Example
    -------
    >>> from condmon.models.declared import load_plant_model
    >>> from condmon.simulate.plant import simulate_plant
    >>> m = load_plant_model("hst")
    >>> res = isolate(simulate_plant(m, ["Dm=-25%@10s"], seed=4), m, workers=1)
    >>> res.isolated, round(res.estimates["Dm"].change_percent)
    (('Dm',), -25)
    """
    settings = settings or IsolationSettings.load()
    record = validate_plant_record(model, record, source)
    tick = progress or (lambda done, total, label: None)
    gens = residual_generators(model, kind)
    fsm = fault_signature(model, kind)
    res = compute_residuals(model, record, gens)
    if normalisation is not None:
        norm = normalisation
    elif kind == "simulation":
        norm = noise_normalisation(model, res, settings.detection)
    else:
        norm = healthy_normalisation(model, [simulate_plant(model, seed=s) for s in range(3)],
                                     kind, settings.detection)
        norm = dataclasses.replace(norm, source="simulated healthy records (3)")
    det = detect(res, norm, settings.detection)
    tick(1, 4, "residuals")
    empty: dict[str, Any] = {}
    noise = _sensor_noise(model, norm, gens)
    if not det.detected or det.time is None or det.onset is None:
        return IsolationResult(model.name, False, None, None, (), fsm, (), empty, empty, (),
                               "no fault detected", res, norm, det, empty, None, noise)
    sus = suspects(fsm, det.fired)
    t, u = res.t, res.inputs
    y = record[list(model.sensor_names)].to_numpy(dtype=np.float64)
    x_nominal = res.states if res.states is not None else integrate(model.compile(), t, u)
    windows = steady_windows(t, u, y, x_nominal, det.time, settings.estimation_settle,
                             settings.min_window, noise)
    estimates = {p: estimate_steady_state(model, p, windows) for p in sus}
    tick(2, 4, "steady-state estimates")
    tasks = [SuspectTask(model, p, estimates[p].value, det.onset, t, u) for p in sus]
    outputs = dict(zip(sus, _run(tasks, workers)))
    tick(3, 4, "suspect models")
    compare_from = det.time + settings.compare_settle
    mask = t >= compare_from
    errors: dict[str, float] = {}
    for p in sus if mask.any() else ():
        e = (y[mask] - outputs[p][mask]) / noise
        errors[p] = float(math.sqrt(np.mean(e ** 2)))
    isolated, statement = _conclude(sus, estimates, errors, int(mask.sum()) * y.shape[1],
                                    settings.significance, windows)
    tick(4, 4, "isolated")
    return IsolationResult(model.name, True, det.time, det.onset, det.fired, fsm, sus, estimates,
                           errors, isolated, statement, res, norm, det, outputs, compare_from, noise)


def _sensor_noise(model: PlantModel, norm: Normalisation, gens: Sequence[Any]) -> FloatArray:
    """Per-sample noise of each sensor: from the normalisation of its simulation
    residual when there is one, else the declaration."""
    out = []
    for s in model.sensors:
        k = next((i for i, g in enumerate(gens) if g.sensor == s.name and not g.inputs), None)
        out.append(float(norm.raw_std[k]) if k is not None else s.noise)
    return np.array(out, dtype=np.float64)


def _run(tasks: Sequence[SuspectTask], workers: int | None) -> list[FloatArray]:
    n = min(len(tasks), workers if workers is not None else (os.cpu_count() or 1))
    if n <= 1:
        return [simulate_suspect(task) for task in tasks]
    tasks[0].model.compile()  # forked workers inherit the compiled model
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    with ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context(method)) as pool:
        return list(pool.map(simulate_suspect, tasks))


def _conclude(sus: Sequence[str], estimates: Mapping[str, SteadyStateEstimate],
              errors: Mapping[str, float], n: int, alpha: float, windows: Sequence[Any]
              ) -> tuple[tuple[str, ...], str]:
    usable = [p for p in sus if p in errors and estimates[p].converged]
    if not usable:
        return (), ("a fault was detected but no suspect could be estimated at steady state "
                    "(record too short after detection?)")
    best = min(usable, key=lambda p: errors[p])
    # mean squared errors of white noise: their ratio is F(n, n) when both models
    # explain the data; beyond the (1 - alpha) quantile a model is significantly worse
    limit = float(stats.f.ppf(1.0 - alpha, n, n))
    isolated = tuple(sorted((p for p in usable if (errors[p] / errors[best]) ** 2 <= limit),
                            key=lambda p: errors[p]))
    note = ""
    if errors[best] ** 2 > limit:
        note = (f" — but even its model leaves an error of {errors[best]:.1f} noise "
                "standard deviations: the fault may be none of the candidates, or several")
    if len(isolated) == 1:
        return isolated, f"fault isolated: {best}{note}"
    why = " (a single operating point after the fault)" if len(windows) < 2 else ""
    return isolated, (f"ambiguous: {', '.join(isolated)} explain the data equally well"
                      f"{why}{note}")
