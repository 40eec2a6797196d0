"""Simulation of declared plant models (:mod:`condmon.models.declared`).

The integration is scipy's LSODA, which switches between a non-stiff and a stiff
method as the solution requires (the orifice's square root is stiff near zero
pressure drop, at start-up). Known input steps and parameter faults are
discontinuities: the integration stops and restarts at each, so none is smeared.
The same routine runs the model beside a record, with some states taken from
measured signals instead of integrated (the structured residual generators).

Every integration is bounded (:class:`SimulationLimits`, defaults in the
``[simulation]`` table of ``condmon/data/isolation.toml``): a wall-clock limit and
a cap on right-hand-side evaluations per sample, both checked inside the
right-hand side, so a runaway (stiff, chattering) integration stops with
:class:`SimulationTimeout` instead of running on. Non-finite derivatives stop it
at once with :class:`~condmon.errors.EstimationError`.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from condmon._threads import one_blas_thread
from condmon.errors import CondmonError, ConfigError, DataError, EstimationError
from condmon.io.columns import Columns, column_values
from condmon.io.config import load_default
from condmon.models.declared import CompiledModel, PlantModel
from condmon.models.excitation import excitation_signal
from condmon.simulate.faults import Fault, apply_fault, parse_fault

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["ParameterStep", "SimulationLimits", "SimulationTimeout", "parameter_steps",
           "input_signals", "operating_segments", "integrate", "sensor_readings",
           "simulate_plant", "time_grid"]

FloatArray = NDArray[np.float64]
_MAX_RESTARTS = 100  # more input changes than this: the inputs are measured, not stepped
_HELD_SAMPLES = 16   # ... unless an input is held this many samples per change on average


class SimulationTimeout(EstimationError):
    """A simulation went beyond its wall-time or evaluation limit and was stopped."""


class _Stop(Exception):
    """Raised inside the right-hand side to leave the solver (internal)."""


@dataclass(frozen=True)
class SimulationLimits:
    """Bounds on the cost of one simulation (defaults: ``[simulation]`` of
    ``condmon/data/isolation.toml``).

    Attributes
    ----------
    time_limit : float
        Wall-clock time one integration may take. [s]
    max_evaluations_per_sample : float
        Right-hand-side evaluations allowed per sample of the time grid. [-]
    """

    time_limit: float = math.inf
    max_evaluations_per_sample: float = math.inf

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any] | None = None) -> SimulationLimits:
        """The ``[simulation]`` table of a settings document (default: the shipped one)."""
        sim = (cfg or load_default("isolation.toml"))["simulation"]
        out = cls(float(sim["time_limit"]), float(sim["max_evaluations_per_sample"]))
        if not (out.time_limit > 0 and out.max_evaluations_per_sample > 0):
            raise ConfigError(f"[simulation]: time_limit and max_evaluations_per_sample must "
                              f"be > 0 (got {out.time_limit:g}, "
                              f"{out.max_evaluations_per_sample:g})")
        return out


@dataclass(frozen=True)
class ParameterStep:
    """Parameter ``name`` takes ``value`` [SI] from time ``at`` [s] on."""

    name: str
    at: float
    value: float


def parameter_steps(model: PlantModel, faults: Iterable[str | Fault]) -> tuple[ParameterStep, ...]:
    """Turn fault specifications (``Rv=+40%@10s``) into parameter steps.

    A fault without a time is present from t = 0. Unknown parameter names raise
    :class:`ConfigError` naming the allowed ones.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> parameter_steps(load_plant_model("hst"), ["Rv=+10%@5s"])[0].value
    12.3981
    """
    out = []
    values = model.parameter_values()
    for f in faults:
        fault = parse_fault(f) if isinstance(f, str) else f
        if fault.name not in values:
            raise ConfigError(f"fault {str(fault)!r}: model {model.name!r} has no parameter "
                              f"{fault.name!r}; allowed: {', '.join(model.parameter_names)}")
        out.append(ParameterStep(fault.name, 0.0 if fault.at is None else fault.at,
                                 round(apply_fault(values[fault.name], fault), 12)))
    return tuple(sorted(out, key=lambda s: s.at))


def time_grid(model: PlantModel, duration: float | None = None,
              sample_rate: float | None = None) -> FloatArray:
    """Sample times of the built-in test [s].

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> t = time_grid(load_plant_model("hst"))
    >>> len(t), float(t[-1])
    (3001, 30.0)
    """
    d = model.test.duration if duration is None else duration
    fs = model.test.sample_rate if sample_rate is None else sample_rate
    n = int(round(d * fs)) + 1
    return np.arange(n, dtype=np.float64) / fs


def input_signals(model: PlantModel, t: FloatArray, record: pd.DataFrame | Columns | None = None,
                  params: Mapping[str, float] | None = None) -> FloatArray:
    """Known inputs on the grid ``t``, shape (len(t), n_inputs).

    A column of the record named like the input is used as it is; otherwise the
    input is its nominal value with the test's schedule of known steps and its
    excitation (:mod:`condmon.models.excitation`) added.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> m = load_plant_model("hst")
    >>> u = input_signals(m, time_grid(m))
    >>> u[[0, -1], 0].tolist()      # nominal pump speed, then 75 % from 20 s [rad/s]
    [152.0, 114.0]
    """
    u = np.empty((len(t), len(model.inputs)), dtype=np.float64)
    for j, name in enumerate(model.input_names):
        if record is not None and name in record.columns:
            u[:, j] = column_values(record, name)
            continue
        nominal = model.input_nominal(name, params)
        u[:, j] = nominal
        for step in model.test.schedule:
            if step.input == name:
                level = nominal * step.factor if step.factor is not None else step.value
                u[t >= step.at - 1e-12, j] = level
        for exc in model.test.excitation:
            if exc.input == name:
                u[:, j] += excitation_signal(exc, t)
    return u


def operating_segments(u: FloatArray, rel_tol: float = 0.02) -> NDArray[np.intp]:
    """Start indices of the operating points of a record's known inputs.

    A new segment starts where an input leaves the running mean of the current
    segment by more than ``rel_tol`` of its size, so a measured (noisy) input
    keeps one segment per level while a step starts a new one.

    Example
    -------
    >>> u = np.r_[np.full(5, 152.0), np.full(5, 114.0)][:, None]
    >>> operating_segments(u + 0.05 * np.sin(np.arange(10))[:, None]).tolist()
    [0, 5]
    """
    starts = [0]
    if len(u) == 0:
        return np.array(starts, dtype=np.intp)
    total = u[0].astype(np.float64).copy()
    n = 1
    for k in range(1, len(u)):
        level = total / n
        if np.any(np.abs(u[k] - level) > rel_tol * np.maximum(np.abs(level), 1e-12)):
            starts.append(k)
            total, n = u[k].astype(np.float64).copy(), 1
        else:
            total += u[k]
            n += 1
    return np.array(starts, dtype=np.intp)


def integrate(compiled: CompiledModel, t: FloatArray, u: FloatArray,
              steps: Sequence[ParameterStep] = (), params: Mapping[str, float] | None = None,
              measured: Mapping[str, FloatArray] | None = None,
              integrated: Sequence[str] | None = None,
              limits: SimulationLimits | None = None) -> FloatArray:
    """States of the model on the grid ``t``, shape (len(t), n_states).

    Parameters
    ----------
    compiled : CompiledModel
    t : ndarray
        Increasing sample times [s]; the integration starts at ``t[0]`` from the
        declared initial states.
    u : ndarray
        Inputs on the grid (held between samples).
    steps : sequence of ParameterStep
        Parameter changes at given times (faults).
    params : mapping, optional
        Parameter values replacing the nominal ones from the start.
    measured : mapping of state name to ndarray, optional
        States taken from measured signals (linearly interpolated), not integrated.
    integrated : sequence of str, optional
        States to integrate (default: every state not in ``measured``); the
        others stay at their initial values.
    limits : SimulationLimits, optional
        Wall-time and evaluation limits (default: none).

    Returns
    -------
    ndarray
        Integrated states as computed, measured ones as given.

    Raises
    ------
    SimulationTimeout
        When a limit is reached (checked inside the right-hand side).
    EstimationError
        When the solver fails or the derivatives become non-finite.


    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> m = load_plant_model("hst")
    >>> t = time_grid(m)
    >>> x = integrate(m.compile(), t, input_signals(m, t))
    >>> round(float(x[1999, 0]) / 1e5, 1), round(float(x[1999, 2]), 1)   # Ps [bar], omega_m [rad/s]
    (39.4, 14.4)
    """
    model = compiled.model
    names = model.state_names
    measured = dict(measured or {})
    integ = [n for n in (integrated if integrated is not None else names) if n not in measured]
    idx = np.array([names.index(n) for n in integ], dtype=np.intp)
    fixed = [(names.index(n), np.asarray(v, dtype=np.float64)) for n, v in measured.items()]
    x_full0 = np.array([s.initial for s in model.states], dtype=np.float64)
    p = compiled.parameter_vector(params)
    pindex = {n: i for i, n in enumerate(model.parameter_names)}

    # breakpoints: input changes and parameter steps, each a restart of the solver.
    # A measured input that moves at every sample is interpolated instead (a
    # restart per sample would be exact for a held input, and very slow).
    # An input held over many samples (a test's steps and binary excitation) keeps
    # its restarts however many there are.
    changes = np.flatnonzero(np.any(np.diff(u, axis=0) != 0, axis=1)) + 1
    smooth_inputs = len(changes) > max(_MAX_RESTARTS, len(t) // _HELD_SAMPLES)
    if smooth_inputs:
        changes = operating_segments(u)[1:]
    bps = sorted({float(t[0]), float(t[-1]), *(float(t[i]) for i in changes),
                  *(s.at for s in steps if t[0] < s.at < t[-1])})
    x_out = np.tile(x_full0, (len(t), 1))
    for i, v in fixed:
        x_out[:, i] = v
    if len(idx) == 0:
        return x_out
    x = x_full0[idx].copy()
    for s in steps:
        if s.at <= t[0]:
            p[pindex[s.name]] = s.value
    lim = limits or SimulationLimits()
    started = time.monotonic()
    deadline = started + lim.time_limit
    max_calls = lim.max_evaluations_per_sample * len(t)
    calls = [0]

    def rhs(tt: float, xi: FloatArray, uk: FloatArray) -> FloatArray:
        calls[0] += 1
        if calls[0] > max_calls or (calls[0] % 16 == 0 and time.monotonic() > deadline):
            raise _Stop(tt)
        xf = x_full0.copy()
        xf[idx] = xi
        for i, v in fixed:
            xf[i] = np.interp(tt, t, v)
        if smooth_inputs:
            uk = np.array([np.interp(tt, t, u[:, j]) for j in range(u.shape[1])])
        d: FloatArray = compiled.rhs(xf, uk, p)[idx]
        if not np.isfinite(d).all():  # the method: no Python wrapper at every call
            raise _Stop(tt, "non-finite")
        return d

    # with measured (noisy) signals as inputs the right-hand side has a kink at
    # every sample; a relative tolerance of 1e-5 keeps the integration error
    # near 1e-3 of the sensor noise at a quarter of the cost of 1e-7
    rtol = 1e-5 if fixed or smooth_inputs else 1e-7
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the solver's own warnings: its failure is raised below
        for a, b in zip(bps[:-1], bps[1:]):
            k = int(np.searchsorted(t, a + 1e-9 * max(1.0, abs(a)), side="right")) - 1
            uk = u[max(k, 0)]
            mask = (t >= a) & (t < b)
            sol = _solve(rhs, a, b, x, np.append(t[mask], b), uk, rtol, model.name,
                         lim, started)
            x_out[np.ix_(mask, idx)] = sol.y[:, :-1].T
            x = sol.y[:, -1].copy()
            for s in steps:
                if a < s.at <= b:
                    p[pindex[s.name]] = s.value
    x_out[-1, idx] = x
    if not np.all(np.isfinite(x_out)):
        raise EstimationError(f"simulation of {model.name!r} gave non-finite states")
    return x_out


def _solve(rhs: Any, a: float, b: float, x: FloatArray, t_eval: FloatArray, uk: FloatArray,
           rtol: float, name: str, lim: SimulationLimits, started: float) -> Any:
    """One solver run from ``a`` to ``b`` [s]; every failure as a condmon error."""
    try:
        sol = solve_ivp(rhs, (a, b), x, method="LSODA", t_eval=t_eval, args=(uk,),
                        rtol=rtol, atol=1e-9)
    except _Stop as stop:
        at = float(stop.args[0])
        if len(stop.args) > 1:
            raise EstimationError(f"simulation of {name!r} gave non-finite derivatives at "
                                  f"t = {at:g} s") from None
        spent = time.monotonic() - started
        raise SimulationTimeout(
            f"simulation of {name!r} stopped at t = {at:g} s of {t_eval[-1]:g} s after "
            f"{spent:.1f} s (limits: {lim.time_limit:g} s wall time, "
            f"{lim.max_evaluations_per_sample:g} evaluations per sample)") from None
    except CondmonError:
        raise
    except Exception as exc:  # noqa: BLE001 - no raw solver error reaches a user
        raise EstimationError(f"simulation of {name!r} failed at t = {a:g} s: "
                              f"{type(exc).__name__}: {exc}") from None
    if not sol.success:
        raise EstimationError(f"simulation of {name!r} failed at t = {a:g} s: {sol.message}")
    return sol


@one_blas_thread
def simulate_plant(model: PlantModel, faults: Iterable[str | Fault] = (), *, seed: int = 0,
                   duration: float | None = None, sample_rate: float | None = None,
                   noise: bool = True, limits: SimulationLimits | None = None) -> pd.DataFrame:
    """Simulate the model's built-in test: a record like one from the rig.

    Parameters
    ----------
    model : PlantModel
        The declared plant (its parameters are the healthy ones).
    faults : iterable of str or Fault
        Parameter faults, e.g. ``"Rv=+40%@10s"`` (a step at 10 s) or ``"Tld=+20@10s"``.
    seed : int
        Seed of the sensor noise.
    duration, sample_rate : float, optional
        Override the test's [s] and [Hz].
    noise : bool
        Add each sensor's noise (standard deviation from the declaration).
    limits : SimulationLimits, optional
        Default: the shipped ``[simulation]`` settings.

    Returns
    -------
    pandas.DataFrame
        Columns ``t`` [s], one per sensor, one per input.

    Raises
    ------
    SimulationTimeout
        When the integration goes beyond ``limits`` (a stiff or chattering model).

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> rec = simulate_plant(load_plant_model("hst"), seed=1)
    >>> list(rec.columns), round(float(rec["omega_m"].iloc[1900]))
    (['t', 'Ps', 'omega_m', 'omega_p'], 14)
    """
    compiled = model.compile()
    t = time_grid(model, duration, sample_rate)
    if len(t) < 2:
        raise DataError("the simulated test needs at least two samples")
    u = input_signals(model, t)
    steps = parameter_steps(model, faults)
    x = integrate(compiled, t, u, steps, limits=limits or SimulationLimits.from_config())
    y = sensor_readings(compiled, x, u, steps, t)
    rng = np.random.default_rng(seed)
    cols: dict[str, FloatArray] = {"t": t}
    for j, s in enumerate(model.sensors):
        cols[s.name] = y[:, j] + (rng.normal(0.0, s.noise, len(t)) if noise else 0.0)
    for j, name in enumerate(model.input_names):
        cols[name] = u[:, j]
    import pandas as pd

    return pd.DataFrame(cols)


def sensor_readings(compiled: CompiledModel, x: FloatArray, u: FloatArray,
                    steps: Sequence[ParameterStep], t: FloatArray,
                    params: Mapping[str, float] | None = None) -> FloatArray:
    """Noise-free sensor readings on the grid, shape (len(t), n_sensors)."""
    p0 = compiled.parameter_vector(params)
    pindex = {n: i for i, n in enumerate(compiled.model.parameter_names)}
    out = np.empty((len(t), len(compiled.model.sensors)), dtype=np.float64)
    bounds = sorted({0, len(t), *(int(np.searchsorted(t, s.at)) for s in steps)})
    for a, b in zip(bounds[:-1], bounds[1:]):
        if a == b:
            continue
        p = p0.copy()
        for s in steps:
            if s.at <= t[a]:
                p[pindex[s.name]] = s.value
        with np.errstate(all="ignore"):  # non-finite readings are the caller's to judge
            out[a:b] = compiled.outputs_on(x[a:b], u[a:b], p)
    return out
