"""Fault detection and isolation of a declared plant from one record.

The flow (SPEC part B): run the model beside the plant → normalised residuals
and debounced detection → suspects from the fault signature matrix (single-fault
hypothesis) → steady-state estimate of each suspect → one model per suspect,
simulated with its estimate, in parallel → the least output error isolates the
fault; suspects whose error is not significantly worse are reported with it as
an ambiguity set. Each sensor's own gain and offset error compete with them
(:mod:`condmon.diagnose.sensor_faults`): a sensor that reads wrong is named as
such, not as the component that imitates it best.

Each suspect's simulation is a pure function of a small picklable task
(:func:`simulate_suspect`), so it can be shipped to a process pool, as here, or
to a distributed engine (:mod:`condmon.diagnose.suspects`).

The flow always ends and never claims more than the record shows:

- each suspect's run has a wall-time limit (a multiple of the nominal model
  run's, with a floor) checked inside the solver, so a runaway stops;
- an estimate outside the parameter's plausible range (declared, or a factor
  around nominal), one that did not converge, and a run that failed or timed
  out reject that suspect with the reason; the others still decide;
- a record that cannot show a fault (too short to judge) or cannot isolate one
  (no steady window after the detection, every suspect rejected) gives
  ``decided = False`` with the reason, never "no fault".
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from condmon._threads import one_blas_thread
from condmon.diagnose.checks import RecordSettings, validate_plant_record
from condmon.diagnose.isolation_result import IsolationResult
from condmon.diagnose.sensor_faults import (
    SensorFit, alike, f_limit, own_sensor_faults, sensor_fits, sensor_statement,
)
from condmon.diagnose.residuals import (
    Detection, DetectionSettings, Normalisation, Residuals, compute_residuals, detect,
    learn_normalisation, load_settings, noise_normalisation,
)
from condmon.diagnose.structure import (
    ResidualKind, fault_signature, residual_generators, suspects,
)
from condmon.diagnose.suspects import SuspectTask, plausible_range, run_suspects, simulate_suspect
from condmon.errors import ConfigError, DataError, EstimationError
from condmon.io.columns import Columns, column_matrix
from condmon.identify.steady_state import (
    SteadyStateEstimate, SteadyWindow, estimate_steady_state, steady_windows,
)
from condmon.models.declared import PlantModel
from condmon.simulate.plant import (
    SimulationLimits, integrate, operating_segments, sensor_readings, simulate_plant,
)

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

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
    time_limit_factor : float
        A suspect's model may run this many times the wall time of the nominal
        model run beside the record... [-]
    time_limit_floor : float
        ...and at least this long. [s]
    range_factor : float
        An estimate of a parameter without a declared range must lie within
        this factor of its (non-zero) nominal value. [-]
    explain_limit : float
        A suspect whose model leaves a larger output error (RMS, in noise
        standard deviations) does not explain the record; when none does, the
        fault is not isolated. [-]
    record : RecordSettings
        Checks of the record.
    simulation : SimulationLimits
        Bounds on the nominal model run (a suspect's wall time is bounded as above).
    """

    detection: DetectionSettings = field(default_factory=DetectionSettings)
    estimation_settle: float = 4.0
    min_window: float = 1.0
    compare_settle: float = 4.0
    significance: float = 0.01
    time_limit_factor: float = 5.0
    time_limit_floor: float = 5.0
    range_factor: float = 100.0
    explain_limit: float = 10.0
    record: RecordSettings = field(default_factory=RecordSettings)
    simulation: SimulationLimits = field(default_factory=SimulationLimits)

    @classmethod
    def load(cls, path: str | Path | None = None) -> IsolationSettings:
        """Settings from the shipped file, overridden by ``path`` (named in
        every error of its values)."""
        try:
            return cls._checked(load_settings(path))
        except ConfigError as err:
            if path is None or str(err).startswith(str(path)):
                raise
            raise ConfigError(f"{path}: {err}") from None

    @classmethod
    def _checked(cls, cfg: Mapping[str, Any]) -> IsolationSettings:
        iso = cfg["isolation"]
        out = cls(DetectionSettings.from_config(cfg), float(cfg["estimation"]["settle"]),
                  float(cfg["estimation"]["min_window"]), float(iso["settle"]),
                  float(iso["significance"]), float(iso["time_limit_factor"]),
                  float(iso["time_limit_floor"]), float(iso["range_factor"]),
                  float(iso["explain_limit"]), RecordSettings.from_config(cfg), SimulationLimits.from_config(cfg))
        if not 0 < out.significance < 1:
            raise ConfigError(f"[isolation].significance must be in (0, 1), not {out.significance}")
        if not (out.time_limit_factor > 0 and out.time_limit_floor > 0 and out.range_factor > 1
                and out.explain_limit > 0):
            raise ConfigError("[isolation]: time_limit_factor, time_limit_floor and "
                              "explain_limit must be > 0 and range_factor > 1 (got "
                              f"{out.time_limit_factor:g}, {out.time_limit_floor:g}, "
                              f"{out.explain_limit:g}, {out.range_factor:g})")
        return out


def healthy_normalisation(model: PlantModel, healthy: Sequence[pd.DataFrame | Columns],
                          kind: ResidualKind = "simulation",
                          settings: DetectionSettings | None = None, *,
                          record: RecordSettings | None = None,
                          limits: SimulationLimits | None = None,
                          sources: Sequence[str] | None = None) -> Normalisation:
    """Learn the residuals' normalisation from healthy records.

    Parameters
    ----------
    model : PlantModel
    healthy : sequence of DataFrame
    kind : {"simulation", "structured"}
    settings : DetectionSettings, optional
    record : RecordSettings, optional
        Checks of each record.
    limits : SimulationLimits, optional
        Bounds on each model run.
    sources : sequence of str, optional
        Names of the records for error messages (default "healthy record N").

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> from condmon.simulate.plant import simulate_plant
    >>> m = load_plant_model("hst")
    >>> norm = healthy_normalisation(m, [simulate_plant(m, seed=s) for s in range(3)])
    >>> norm.names
    ('r_Ps', 'r_omega_m')
    """
    gens = residual_generators(model, kind)
    names = list(sources) if sources is not None else \
        [f"healthy record {i + 1}" for i in range(len(healthy))]
    sets = [compute_residuals(model, validate_plant_record(model, r, name, record), gens,
                              limits=limits, source=name)
            for r, name in zip(healthy, names)]
    norm = learn_normalisation(sets, settings or DetectionSettings.from_config())
    return dataclasses.replace(norm, notes=(*norm.notes, *_beyond_noise(model, sets[0], norm)))


#: How far above the declared sensor noise a healthy residual's spread is said:
#: twice the noise is no longer noise alone (the model misses the machine, or the
#: "healthy" record holds a fault). [-]
NOISE_FACTOR_SAID = 2.0


def _beyond_noise(model: PlantModel, residuals: Residuals, norm: Normalisation) -> list[str]:
    """A note for each residual whose healthy spread exceeds its sensor's
    declared noise by :data:`NOISE_FACTOR_SAID` or more: a fault must then
    move it that many times further to be detected than the sensor alone
    would need (a faulty record given as healthy hides its own fault)."""
    noise = {s.name: s.noise for s in model.sensors}
    notes = []
    for name, sensor, raw in zip(norm.names, residuals.sensors, norm.raw_std):
        sd = noise.get(sensor, 0.0)
        if sd > 0 and raw >= NOISE_FACTOR_SAID * sd:
            notes.append(f"the healthy records' residual {name} spreads {raw:.4g} "
                         f"({raw / sd:.3g}x the declared {sd:.4g} noise of sensor {sensor}): "
                         "a fault must move it that much further to be detected; healthy "
                         "records this far from the model hold a fault, or the model's "
                         "parameters do not fit this machine")
    return notes


@one_blas_thread
def isolate(record: pd.DataFrame | Columns, model: PlantModel, *,
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
        Default: one after the other unless a process pool pays (the first
        suspect's run timed; see :func:`condmon.diagnose.suspects.run_suspects`).
    progress : callable, optional
        ``progress(done, total, label)`` after each stage.
    source : str
        Name of the record for error messages.

    Returns
    -------
    IsolationResult

    Raises
    ------
    DataError
        When the record is unusable (naming ``source`` and the column).
    EstimationError
        When the nominal model cannot be run beside the record.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> from condmon.simulate.plant import simulate_plant
    >>> m = load_plant_model("hst")
    >>> res = isolate(simulate_plant(m, ["Dm=-25%@10s"], seed=4), m, workers=1)
    >>> res.isolated, round(res.estimates["Dm"].change_percent)
    (('Dm',), -25)
    """
    settings = settings or IsolationSettings.load()
    record = validate_plant_record(model, record, source, settings.record)
    tick = progress or (lambda done, total, label: None)
    gens = residual_generators(model, kind)
    fsm = fault_signature(model, kind)
    started = time.monotonic()
    try:
        res = compute_residuals(model, record, gens, limits=settings.simulation, source=source)
    except EstimationError as exc:
        raise EstimationError(f"{source}: the model cannot be run beside the record: {exc}"
                              ) from None
    nominal_time = time.monotonic() - started
    _scale_error(res, source)
    if normalisation is not None:
        norm = normalisation
    elif kind == "simulation":
        norm = noise_normalisation(model, res, settings.detection)
    else:
        norm = healthy_normalisation(model, [simulate_plant(model, seed=s) for s in range(3)],
                                     kind, settings.detection, limits=settings.simulation)
        norm = dataclasses.replace(norm, source="simulated healthy records (3)")
    det = detect(res, norm, settings.detection)
    _check_finite(det, res, source)
    tick(1, 4, "residuals")
    noise = _sensor_noise(model, norm, gens)
    quiet = IsolationResult(model.name, False, None, None, (), fsm, (), {}, {}, (),
                            "no fault detected", res, norm, det, {}, None, noise,
                            notes=(*norm.notes, *_input_notes(model, res)),
                            units=model.parameter_units())
    if not det.detected or det.time is None or det.onset is None:
        if det.undecidable is not None:
            return dataclasses.replace(quiet, statement=f"undecided: {det.undecidable}",
                                       decided=False, reason=det.undecidable)
        return quiet
    sus = suspects(fsm, det.fired)
    t, u = res.t, res.inputs
    y = column_matrix(record, model.sensor_names)
    try:
        x_nominal = res.states if res.states is not None else \
            integrate(model.compile(), t, u, limits=settings.simulation)
    except EstimationError as exc:
        raise EstimationError(f"{source}: the model cannot be run beside the record: {exc}"
                              ) from None
    windows = steady_windows(t, u, y, x_nominal, det.time, settings.estimation_settle,
                             settings.min_window, noise)
    estimates, rejected = {}, {}
    for p in sus:
        estimates[p], why = _estimate(model, p, windows, settings.range_factor)
        if why is not None:
            rejected[p] = why
    ruled_out = {p for p in rejected if math.isfinite(estimates[p].value)}  # by the record
    tick(2, 4, "steady-state estimates")
    limit = min(settings.simulation.time_limit,
                max(settings.time_limit_floor, settings.time_limit_factor * nominal_time))
    limits = dataclasses.replace(settings.simulation, time_limit=limit)
    tasks = [SuspectTask(model, p, estimates[p].value, det.onset, t, u, limits)
             for p in sus if p not in rejected] if windows else []
    outputs: dict[str, FloatArray] = {}
    for task, outcome in zip(tasks, run_suspects(tasks, workers)):
        if outcome.outputs is None:
            rejected[task.parameter] = outcome.failure or "simulation failed"
        else:
            outputs[task.parameter] = outcome.outputs
    tick(3, 4, "suspect models")
    compare_from = det.time + settings.compare_settle
    mask = t >= compare_from
    errors: dict[str, float] = {}
    for p in outputs if mask.any() else ():
        e = (y[mask] - outputs[p][mask]) / noise
        errors[p] = float(math.sqrt(np.mean(e ** 2)))
    n = int(mask.sum()) * y.shape[1]
    # a sensor's gain or offset error beside the components (simulation residuals: the
    # nominal model's readings are the plant's from its inputs alone)
    fits: tuple[SensorFit, ...] = ()
    if kind == "simulation" and errors:
        own = own_sensor_faults(model)   # the sensors' errors the declaration models itself
        fits = tuple(f for f in sensor_fits(
            y, sensor_readings(model.compile(), x_nominal, u, (), t), noise, mask,
            model.sensor_names, [s.unit for s in model.sensors]) if (f.sensor, f.kind) not in own)
    sensed, alike_components = alike(fits, errors, n, settings.significance,
                                     settings.explain_limit)
    why_not = _undecided(windows, errors, rejected, det.time, float(t[-1]), settings)
    if sensed:  # (with suspects compared, what is undecided is "none explains the record")
        statement, why_not = sensor_statement(sensed, alike_components, errors, n,
                                              settings.significance)
        isolated: tuple[str, ...] = alike_components if why_not is None else ()
        if why_not is not None:
            statement = f"fault detected at {det.time:.2f} s but not isolated: {why_not}"
    elif why_not is not None:
        statement = f"fault detected at {det.time:.2f} s but not isolated: {why_not}"
        isolated = ()
    else:
        isolated, statement = _conclude(sus, errors, n, settings.significance, windows)
    if why_not is None:
        # a run or estimate that failed, not one the record rules out, could have fitted better
        unjudged = sorted(set(rejected) - ruled_out)
        if unjudged:
            statement += (f"; not compared: {', '.join(unjudged)} (estimate or run failed; "
                          "see why)")
    tick(4, 4, "isolated")
    return dataclasses.replace(quiet, detected=True, detection_time=det.time,
                               onset_time=det.onset, fired_residuals=det.fired, suspects=sus,
                               estimates=estimates, errors=errors, isolated=isolated,
                               statement=statement, outputs=outputs, compare_from=compare_from,
                               decided=why_not is None, reason=why_not, rejected=rejected,
                               time_limit=limit, sensor_faults=sensed,
                               notes=quiet.notes + (() if kind == "simulation" or not errors else (
                                   "a sensor's own gain or offset error is weighed with "
                                   "simulation residuals only (the default), not these",)))


def _estimate(model: PlantModel, parameter: str, windows: Sequence[SteadyWindow],
              factor: float) -> tuple[SteadyStateEstimate, str | None]:
    """A suspect's steady-state estimate and, when it must not be used, why."""
    param = model.parameter(parameter)
    nominal = param.value
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the solvers' complaints: judged by the result
            est = estimate_steady_state(model, parameter, windows)
    except Exception as exc:  # noqa: BLE001 - a failed estimate rejects only this suspect
        return (SteadyStateEstimate(parameter, math.nan, nominal, None, False),
                f"estimation failed: {type(exc).__name__}: {exc}")
    if not windows:   # nothing estimated: no value to show, not the nominal one
        return (SteadyStateEstimate(parameter, math.nan, nominal, None, False),
                "no steady window to estimate from")
    if not math.isfinite(est.value):
        return est, "estimate is not finite"
    bounds = plausible_range(param, factor)
    unit = f" {param.unit}" if param.unit else ""
    if bounds is not None and not bounds[0] <= est.value <= bounds[1]:
        return est, (f"estimate {est.value:.4g}{unit} outside the plausible range "
                     f"[{bounds[0]:.4g}, {bounds[1]:.4g}]{unit}")
    if not est.converged:
        return est, "no value makes the model's steady state match the record (not converged)"
    return est, None


def _undecided(windows: Sequence[SteadyWindow], errors: Mapping[str, float],
               rejected: Mapping[str, str], detected: float, end: float,
               settings: IsolationSettings) -> str | None:
    """Why a detected fault cannot be isolated from this record, or None."""
    if not windows:
        need = detected + settings.estimation_settle + settings.min_window
        if end < need:
            return (f"the record ends at {end:.2f} s, before a steady window "
                    f"({settings.estimation_settle:g} s settling + {settings.min_window:g} s) "
                    f"after the detection at {detected:.2f} s (needs {need:.2f} s)")
        return (f"no steady window of {settings.min_window:g} s after the detection: the "
                "known inputs never hold one level long enough")
    if not errors:
        if rejected:
            return "every suspect was rejected (" + "; ".join(
                f"{p}: {why}" for p, why in rejected.items()) + ")"
        return (f"the record ends before the comparison window (from "
                f"{detected + settings.compare_settle:.2f} s)")
    best = min(errors, key=lambda p: errors[p])
    if not errors[best] <= settings.explain_limit:
        return (f"no suspect's model explains the record: the best, {best}, leaves an error "
                f"of {errors[best]:.3g} noise standard deviations (limit "
                f"{settings.explain_limit:g}); the fault may be none of the candidates, "
                "several, or the data may be wrong")
    return None


#: Factors a column in another unit reads, against what the model predicts.
_UNIT_FACTORS = ((60.0 / (2.0 * math.pi), "rpm for rad/s"), (2.0 * math.pi / 60.0, "rad/s for rpm"),
                 (1e-5, "bar for Pa"), (1e5, "Pa for bar"), (1e-6, "MPa for Pa"),
                 (1e6, "Pa for MPa"), (1e3, "a factor 1000: milli-units?"),
                 (1e-3, "a factor 1/1000: kilo-units?"), (60.0, "per minute for per second"),
                 (1.0 / 60.0, "per second for per minute"))


def _scale_error(res: Residuals, source: str) -> None:
    """Refuse a record whose sensor column reads a unit factor (rpm for rad/s, bar
    for Pa) or the opposite sign of what the nominal model predicts, steadily: no
    fault does that, a unit or sign error does."""
    measured = res.values + res.predicted
    for j, sensor in enumerate(res.sensors):
        y, p = measured[:, j], res.predicted[:, j]
        big = np.abs(p) > 0.2 * float(np.max(np.abs(p), initial=0.0))
        if int(big.sum()) < 10:
            continue
        q = y[big] / p[big]
        m = float(np.median(q))
        if not math.isfinite(m) or m == 0.0 or np.median(np.abs(q - m)) > 0.2 * abs(m):
            continue  # no single factor: a fault or noise, for the isolation to weigh
        if m < 0.0 and abs(abs(m) - 1.0) < 0.5:
            why = "the opposite sign: likely a sign error (a sensor mounted the other way?)"
        else:
            hits = [what for f, what in _UNIT_FACTORS if abs(abs(m) / f - 1.0) < 0.1]
            if not hits:
                continue
            why = f"likely a unit error ({hits[0]}?)"
        raise DataError(f"{source}: column {sensor!r} reads {m:.3g} x what the model predicts "
                        f"from the record's inputs, throughout: {why}; convert the column "
                        "(nothing was isolated)")


def _check_finite(det: Detection, res: Residuals, source: str) -> None:
    """Refuse a record whose normalised residuals are not finite (an overflow)."""
    bad = ~np.isfinite(det.normalised)
    if bad.any():
        k, j = (int(v[0]) for v in np.nonzero(bad))
        raise DataError(f"{source}: residual {res.names[j]!r} of column {res.sensors[j]!r} "
                        f"overflows at row {k} (t = {res.t[k]:g} s): readings near the float "
                        "limit?")


def _input_notes(model: PlantModel, res: Residuals) -> list[str]:
    """A note when the record's known inputs vary continuously (no operating points)."""
    if res.inputs.shape[1] == 0 or len(res.t) < 2:
        return []
    starts = operating_segments(res.inputs)
    if len(starts) > max(4.0, (res.t[-1] - res.t[0]) / 2.0):
        return [f"the known inputs ({', '.join(model.input_names)}) vary continuously in the "
                f"record ({len(starts)} levels): steady windows only where they hold still"]
    return []


def _sensor_noise(model: PlantModel, norm: Normalisation, gens: Sequence[Any]) -> FloatArray:
    """Per-sample noise of each sensor: from the normalisation of its simulation
    residual when there is one, else the declaration."""
    out = []
    for s in model.sensors:
        k = next((i for i, g in enumerate(gens) if g.sensor == s.name and not g.inputs), None)
        out.append(float(norm.raw_std[k]) if k is not None else s.noise)
    return np.array(out, dtype=np.float64)


def _conclude(sus: Sequence[str], errors: Mapping[str, float], n: int, alpha: float,
              windows: Sequence[Any]) -> tuple[tuple[str, ...], str]:
    usable = [p for p in sus if p in errors and math.isfinite(errors[p])]
    best = min(usable, key=lambda p: errors[p])
    # mean squared errors of white noise: their ratio is F(n, n) when both models
    # explain the data; beyond the (1 - alpha) quantile a model is significantly worse
    limit = f_limit(n, alpha)
    floor = max(errors[best], 1e-300)
    isolated = tuple(sorted((p for p in usable if (errors[p] / floor) ** 2 <= limit),
                            key=lambda p: errors[p]))
    note = ""
    if errors[best] ** 2 > limit:
        note = (f" — but even its model leaves an error of {errors[best]:.3g} noise "
                f"standard deviations, beyond the {math.sqrt(limit):.3g} that noise alone "
                f"reaches at {alpha:g} over {n} samples (F test): the fault may be none of "
                "the candidates, or several, or a sensor's")
    if len(isolated) == 1:
        return isolated, f"fault isolated: {best}{note}"
    why = " (a single operating point after the fault)" if len(windows) < 2 else ""
    return isolated, (f"ambiguous: {', '.join(isolated)} explain the data equally well"
                      f"{why}{note}")
