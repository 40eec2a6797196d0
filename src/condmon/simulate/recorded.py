"""A declared model run on a record's inputs: many copies at once, fixed step.

The simulation-error route (:mod:`condmon.identify.simulation_route`) and
``condmon validate`` simulate a declared model (:mod:`condmon.models.declared`)
on the inputs a record carries, held over each sample (zero-order hold, as a
data logger's samples are read). Each copy has its own parameters and initial
states, so the finite-difference sensitivities of every unknown, and every
shooting segment, take one pass over the record instead of one each.

The integrator is the classical fourth-order Runge-Kutta with ``substeps``
steps per sample. Why by hand: scipy's ``solve_ivp`` integrates one copy per
call and restarts at every held input sample (a thousand restarts per record,
each with its own step-size search); a fixed step over sampled inputs is what
``nlgreyest``'s fixed-step solvers and the simulation-error literature use. The
step count is chosen by halving the step until the outputs stop moving
(:func:`choose_substeps`), and said.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from condmon.errors import EstimationError
from condmon.models.declared import CompiledModel, PlantModel, smoothing_width

__all__ = ["Diverged", "RecordedSimulation", "choose_substeps", "fastest_rate", "growth_rate",
           "resolvable_smoothing", "simulate_copies", "simulate_recorded", "stable_substeps",
           "state_jacobian"]

FloatArray = NDArray[np.float64]
_MAX_SUBSTEPS = 64


class Diverged(EstimationError):
    """A simulation left the finite numbers (``at`` [s] from the record's start,
    ``state`` the first state that did)."""

    def __init__(self, message: str, at: float = float("nan"), state: str = "") -> None:
        super().__init__(message)
        self.at, self.state = at, state


@dataclass(frozen=True)
class RecordedSimulation:
    """A model run on a record's inputs.

    Attributes
    ----------
    t : ndarray
        Sample times from the record's start. [s]
    states : ndarray, shape (N, n_states)
        The states at each sample. [state units]
    outputs : ndarray, shape (N, n_sensors)
        The noise-free sensor readings. [sensor units]
    substeps : int
        Runge-Kutta steps per sample.
    """

    t: FloatArray
    states: FloatArray
    outputs: FloatArray
    substeps: int


def simulate_copies(compiled: CompiledModel, u: FloatArray, dt: float, x0: FloatArray,
                    p: FloatArray, substeps: int) -> tuple[FloatArray, FloatArray]:
    """Run ``B`` copies of the model over the same inputs.

    Parameters
    ----------
    compiled : CompiledModel
    u : ndarray, shape (N, n_inputs) or (N, n_inputs, B)
        Inputs, held over each sample: shared, or each copy's own. [input units]
    dt : float
        Sample interval. [s]
    x0 : ndarray, shape (n_states, B)
        Each copy's initial states. [state units]
    p : ndarray, shape (n_params, B)
        Each copy's parameters, in declaration order. [SI]
    substeps : int
        Runge-Kutta steps per sample.

    Returns
    -------
    states : ndarray, shape (N, n_states, B)
    outputs : ndarray, shape (N, n_sensors, B)
        Non-finite where a copy diverged (from there on); the caller judges.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> c = load_plant_model("dc-motor").compile()
    >>> x, y = simulate_copies(c, np.full((5, 1), 12.0), 1e-3, np.zeros((2, 1)),
    ...                        c.parameter_vector()[:, None], 4)
    >>> x.shape, y.shape
    ((5, 2, 1), (5, 2, 1))
    """
    n = u.shape[0]
    b = x0.shape[1]
    h = dt / substeps
    f = compiled.rhs_batch   # each copy's own parameters: p is (n_params, B)
    out_fn = compiled._outputs_raw
    xs = np.empty((n, x0.shape[0], b))
    ys = np.empty((n, len(compiled.model.sensors), b))
    x = np.array(x0, dtype=np.float64)
    ub = np.empty((u.shape[1], b))

    def rhs(xx: FloatArray) -> FloatArray:
        return f(xx, ub, p)

    with np.errstate(all="ignore"):  # a diverging copy goes non-finite; judged by the caller
        for k in range(n):
            ub[:] = u[k][:, None] if u.ndim == 2 else u[k]
            xs[k] = x
            for i, v in enumerate(out_fn(x, ub, p)):
                ys[k, i] = v
            if k % 64 == 63 and not np.isfinite(x).all(axis=0).any():
                # every copy has left the finite numbers, for good (inf and NaN stay so
                # under the RK steps): the rest of the record would only cost time
                # (looked at every 64 samples: this loop is the simulation's hot path)
                xs[k + 1:] = np.nan
                ys[k + 1:] = np.nan
                break
            for _ in range(substeps):
                k1 = rhs(x)
                k2 = rhs(x + 0.5 * h * k1)
                k3 = rhs(x + 0.5 * h * k2)
                k4 = rhs(x + h * k3)
                x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return xs, ys


def _first_bad(y: FloatArray) -> int:
    """The first sample at which any copy's output is not finite (``len(y)``: none)."""
    bad = ~np.isfinite(y).all(axis=tuple(range(1, y.ndim)))
    return int(np.argmax(bad)) if bad.any() else len(y)


def choose_substeps(compiled: CompiledModel, u: FloatArray, dt: float, x0: FloatArray,
                    p: FloatArray, tolerance: FloatArray) -> int:
    """Fewest Runge-Kutta steps per sample (1, 2, 4, ...) whose outputs move by
    less than ``tolerance`` [sensor units, per sensor] when the step is halved
    (at most 64). Judged on the copies given (``x0``, ``p`` as in
    :func:`simulate_copies`), over at most the record's first 2,000 samples.
    """
    m = min(len(u), 2000)
    sub = 1
    prev = simulate_copies(compiled, u[:m], dt, x0, p, sub)[1]
    while sub < _MAX_SUBSTEPS:
        nxt = simulate_copies(compiled, u[:m], dt, x0, p, 2 * sub)[1]
        with np.errstate(invalid="ignore"):
            moved = np.nanmax(np.abs(nxt - prev), axis=(0, 2)) if np.isfinite(nxt).any() \
                else np.full(tolerance.shape, np.inf)
        if np.all(np.isfinite(prev)) and np.all(moved <= tolerance):
            return sub
        before, after = _first_bad(prev), _first_bad(nxt)
        if before < m and after < m and after <= before + max(2, before // 10):
            # halving the step did not put the divergence off: the model diverges with
            # these values, at any step (finer ones would only take longer to say so)
            return 2 * sub
        sub, prev = 2 * sub, nxt
    return sub


#: The classical fourth-order Runge-Kutta is stable on a decaying mode of rate λ
#: [1/s] while its step h keeps h·λ inside its stability region: 2.785 on the
#: negative real axis (Butcher, Numerical Methods for ODEs, 2016, sec. 238).
_RK4_REAL_LIMIT = 2.785


def state_jacobian(compiled: CompiledModel, x: FloatArray, u: FloatArray, p: FloatArray
                   ) -> FloatArray | None:
    """The state equations' Jacobian at one operating point, by central
    differences [1/s] (None where it is not finite).

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> c = load_plant_model("dc-motor").compile()
    >>> J = state_jacobian(c, np.zeros(2), np.array([12.0]), c.parameter_vector())
    >>> round(float(J[0, 0]))        # dI/dI = -R/L [1/s]
    -833
    """
    n = len(x)
    J = np.zeros((n, n))
    with np.errstate(all="ignore"):
        for i in range(n):
            h = 1e-6 * max(abs(float(x[i])), 1e-3)
            up, down = x.copy(), x.copy()
            up[i] += h
            down[i] -= h
            J[:, i] = (np.asarray(compiled.rhs(up, u, p)) - np.asarray(compiled.rhs(down, u, p))
                       ) / (2 * h)
    return J if np.all(np.isfinite(J)) else None


def fastest_rate(compiled: CompiledModel, x: FloatArray, u: FloatArray, p: FloatArray
                 ) -> float:
    """The model's fastest rate at one operating point [1/s]: the largest
    eigenvalue magnitude of its state equations' Jacobian (central
    differences). NaN where it cannot be evaluated.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> c = load_plant_model("dc-motor").compile()
    >>> p = c.parameter_vector()
    >>> rate = fastest_rate(c, np.zeros(2), np.array([12.0]), p)
    >>> bool(rate > 100.0)          # the electrical mode, about R/L
    True
    """
    J = state_jacobian(compiled, x, u, p)
    if J is None:
        return float("nan")
    return float(np.max(np.abs(np.linalg.eigvals(J)))) if J.size else 0.0


def growth_rate(compiled: CompiledModel, x: FloatArray, u: FloatArray, p: FloatArray) -> float:
    """The fastest growth of the model at one operating point [1/s]: the
    largest real part of its Jacobian's eigenvalues (> 0: an unstable mode;
    NaN where it cannot be evaluated).

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> c = load_plant_model("dc-motor").compile()
    >>> growth_rate(c, np.zeros(2), np.array([12.0]), c.parameter_vector()) < 0
    True
    """
    J = state_jacobian(compiled, x, u, p)
    if J is None:
        return float("nan")
    return float(np.max(np.linalg.eigvals(J).real)) if J.size else -math.inf


def stable_substeps(compiled: CompiledModel, x: FloatArray, u: FloatArray, p: FloatArray,
                    dt: float) -> int:
    """Runge-Kutta steps per sample that keep the model's fastest mode at one
    operating point within half the method's stability limit (at most
    :data:`_MAX_SUBSTEPS`; 1 where the mode cannot be evaluated): the step
    count where searching is no use, a model that grows at every step.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> c = load_plant_model("dc-motor").compile()
    >>> stable_substeps(c, np.zeros(2), np.array([12.0]), c.parameter_vector(), 1e-3)
    1
    """
    rate = fastest_rate(compiled, x, u, p)
    if not math.isfinite(rate):
        return 1
    return int(min(_MAX_SUBSTEPS, max(1, math.ceil(2.0 * rate * dt / _RK4_REAL_LIMIT))))


def resolvable_smoothing(plant: PlantModel, states: FloatArray, u: FloatArray, p: FloatArray,
                         step: float) -> tuple[PlantModel, str]:
    """``plant`` with its smoothing widened to what a Runge-Kutta ``step`` [s]
    resolves, and a note saying so; ``plant`` itself and "" where the step is
    stable on the model's fastest rate along ``states`` (N, n_x) with inputs
    ``u`` (N, n_u), or where that rate does not come from the smoothing.

    A ``sign()`` smoothed over ``eps`` has the slope ``1/eps`` at its switch:
    on an axis with 8 N of Coulomb friction over 12 kg, at the default 1e-6
    m/s, a rate of 6.7e5 /s, where a 125 µs step is stable only to 2.2e4 /s.
    The simulation then chatters at each switch, the fit's error is rough in
    the parameters, and the search stops short of the optimum (the true values
    simulated that record to 3.6 µm, the fit's to 36 µm). Widened until the
    step is stable there (the rate falls as the width grows), the switch
    stays far inside the speeds a record reaches (3e-5 m/s on that axis).

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> plant = load_plant_model("dc-motor")
    >>> c = plant.compile()
    >>> x, u = np.zeros((5, 2)), np.full((5, 1), 12.0)
    >>> resolvable_smoothing(plant, x, u, c.parameter_vector(), 1e-4)[1]
    ''
    """
    eps0 = smoothing_width(plant)
    if not eps0 > 0 or len(states) == 0:
        return plant, ""
    pick = np.unique(np.linspace(0, len(states) - 1, min(len(states), 400)).astype(int))

    def fastest(model: PlantModel) -> float:
        c = model.compile()
        rates = np.array([fastest_rate(c, states[i], u[i], p) for i in pick])
        return float(np.max(rates[np.isfinite(rates)])) if np.isfinite(rates).any() else math.nan

    rate0 = rate = fastest(plant)
    if not (math.isfinite(rate0) and rate0 * step > _RK4_REAL_LIMIT):
        return plant, ""
    eps, widened = eps0, plant
    for _ in range(4):   # the rate falls as 1/eps at a sign(), more slowly at a root
        eps = float(f"{eps * 1.5 * rate * step / _RK4_REAL_LIMIT:.2g}")
        widened = dataclasses.replace(plant, smoothing=eps)
        rate = fastest(widened)
        if not (math.isfinite(rate) and rate < rate0 / 2):
            return plant, ""   # the fast rate is the model's own, not the smoothing's
        if rate * step <= _RK4_REAL_LIMIT:
            said = "declared" if plant.smoothing is not None else "default"
            return widened, (f"sign(), abs(), min() and max() smoothed over {eps:.2g} (the "
                             f"{said} {eps0:.2g} gives the equations a rate of {rate0:.2g} "
                             f"/s at a switch, where the {step:.3g} s step is stable to "
                             f"{_RK4_REAL_LIMIT / step:.2g} /s: the simulation chattered there)")
    return plant, ""


def _too_fast(compiled: CompiledModel, x: FloatArray, u: FloatArray, p: FloatArray,
              dt: float, substeps: int) -> str:
    """Why a fixed step diverged where the model's fastest mode outruns it: the
    mode, the step it allows and the step taken ("" when the step is not why)."""
    rate = fastest_rate(compiled, x, u, p)
    step = dt / substeps
    if not np.isfinite(rate):
        return ("; the state equations are not finite at the start with these values (a "
                "division by zero, a root or logarithm of a negative number?): check the values")
    if rate * step <= _RK4_REAL_LIMIT:
        return ""
    grows = growth_rate(compiled, x, u, p)
    if grows > 0:   # a growing mode: no step makes it stay
        return (f"; with these values the model is unstable: a mode grows e-fold every "
                f"{1.0 / grows:.3g} s: check the values (a sign, unit or decimal error), and "
                "the initial states")
    return (f"; with these values the model's fastest mode has a time constant of "
            f"{1.0 / rate:.3g} s, and a Runge-Kutta step of {step:.3g} s follows it only "
            f"below {_RK4_REAL_LIMIT / rate:.3g} s, {rate * step / _RK4_REAL_LIMIT:.3g} times "
            "smaller: check the values (a unit or decimal error makes a mode this fast); a "
            "model really this fast needs a record sampled that much faster")


def simulate_recorded(compiled: CompiledModel, u: FloatArray, dt: float,
                      initial: FloatArray, params: FloatArray, *, substeps: int,
                      source: str = "") -> RecordedSimulation:
    """One run of the model on a record's inputs; a divergence is an error
    naming the time and the state.

    Parameters
    ----------
    compiled : CompiledModel
    u : ndarray, shape (N, n_inputs)
        [input units]
    dt : float
        [s]
    initial : ndarray, shape (n_states,)
        [state units]
    params : ndarray, shape (n_params,)
        [SI]
    substeps : int
    source : str
        The record, named in an error.

    Returns
    -------
    RecordedSimulation

    Raises
    ------
    Diverged
        When a state leaves the finite numbers.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> c = load_plant_model("dc-motor").compile()
    >>> sim = simulate_recorded(c, np.full((2000, 1), 12.0), 1e-3, np.zeros(2),
    ...                         c.parameter_vector(), substeps=2)
    >>> round(float(sim.states[-1, 1]), 1)      # the speed after 2 s [rad/s]
    242.4
    """
    xs, ys = simulate_copies(compiled, u, dt, initial[:, None], params[:, None], substeps)
    xs, ys = xs[..., 0], ys[..., 0]
    bad = ~np.isfinite(xs)
    if bad.any():
        k = int(np.argwhere(bad)[0][0])
        names = [compiled.model.state_names[j] for j in np.flatnonzero(bad[k])]
        last = ", ".join(f"{n} = {float(xs[k - 1][compiled.model.state_names.index(n)]):.4g}"
                         for n in names) if k > 0 else ""
        raise Diverged(f"{source + ': ' if source else ''}the simulation diverged at "
                       f"t = {k * dt:g} s: state{'s' if len(names) > 1 else ''} "
                       f"{', '.join(repr(n) for n in names)} left the finite numbers"
                       + (f" (last finite at t = {(k - 1) * dt:g} s: {last})" if last else "")
                       + (_too_fast(compiled, initial, u[0], params, dt, substeps) or
                          f"; {substeps} Runge-Kutta step(s) per sample, and its fastest "
                          "mode at the start is within their reach: the model is unstable "
                          "with these values (check them, and the initial states)"),
                       k * dt, names[0])
    return RecordedSimulation(np.arange(len(u), dtype=np.float64) * dt, xs, ys, substeps)
