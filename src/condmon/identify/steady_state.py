"""Steady-state estimation of one suspect parameter of a declared model.

After a fault is detected and the plant has settled, the record holds one or
more steady windows (one per operating point of the test). For a suspect θ, with
every other parameter nominal, the model's steady state in each window solves
``f(x, u, θ) = 0`` (all derivatives zero; the orifice makes it nonlinear, so it is
solved numerically). θ is the value whose steady-state sensor readings best
match the window means of the measurements, weighted by their standard errors
(a maximum-likelihood estimate under white sensor noise). The weighted misfit
left over says how consistent the single-fault hypothesis is: about 1 when the
suspect explains the data, much more when it does not.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from condmon.models.declared import CompiledModel, PlantModel
from condmon.simulate.plant import operating_segments

__all__ = ["SteadyWindow", "SteadyStateEstimate", "steady_windows", "estimate_steady_state"]

FloatArray = NDArray[np.float64]
_RUNAWAY = 8.0  # |log(value/nominal)| beyond which the search ran away (factor ~3000)


@dataclass(frozen=True)
class SteadyWindow:
    """A window of the record at one operating point.

    Attributes
    ----------
    start, end : float
        [s]
    inputs : ndarray
        The known inputs in the window. [input units]
    mean : ndarray
        Window mean of each sensor. [sensor unit]
    std_error : ndarray
        Standard error of each mean. [sensor unit]
    guess : ndarray
        Starting point for the steady state (states). [state units]
    """

    start: float
    end: float
    inputs: FloatArray
    mean: FloatArray
    std_error: FloatArray
    guess: FloatArray


@dataclass(frozen=True)
class SteadyStateEstimate:
    """Estimate of one suspect parameter.

    Attributes
    ----------
    parameter : str
    value : float
        Estimate. [parameter unit]
    nominal : float
        Healthy value. [parameter unit]
    consistency : float or None
        sqrt(chi²/dof) of the weighted misfit of the window means; None when
        there is no redundancy (as many equations as unknowns). [-]
    converged : bool
        False when no value made the steady state match (the suspect cannot
        explain the data at all) or the parameter does not move the steady state.
    """

    parameter: str
    value: float
    nominal: float
    consistency: float | None
    converged: bool

    @property
    def change_percent(self) -> float | None:
        """(value − nominal)/nominal × 100, None for a zero nominal. [%]"""
        return None if self.nominal == 0 else 100.0 * (self.value / self.nominal - 1.0)


def steady_windows(t: FloatArray, u: FloatArray, y: FloatArray, states: FloatArray,
                   start: float, settle: float, min_length: float, noise: FloatArray
                   ) -> list[SteadyWindow]:
    """Steady windows after ``start`` [s]: ``settle`` [s] after it and after each
    change of operating point (:func:`~condmon.simulate.plant.operating_segments`),
    up to the next change; windows shorter than
    ``min_length`` [s] are dropped. ``states`` (the healthy model's) give the
    starting guesses; ``noise`` the per-sample standard deviation of each sensor."""
    changes = [float(t[i]) for i in operating_segments(u)[1:]]
    bounds = sorted({start, *(c for c in changes if c > start)})
    out = []
    for k, a in enumerate(bounds):
        b = bounds[k + 1] if k + 1 < len(bounds) else float(t[-1]) + 1e-9
        lo = a + settle
        mask = (t >= lo) & (t < b)
        if mask.sum() < 2 or (t[mask][-1] - t[mask][0]) < min_length:
            continue
        n = int(mask.sum())
        out.append(SteadyWindow(float(t[mask][0]), float(t[mask][-1]), u[mask].mean(axis=0),
                                y[mask].mean(axis=0), noise / math.sqrt(n),
                                states[mask][-1].copy()))
    return out


def estimate_steady_state(model: PlantModel, parameter: str, windows: Sequence[SteadyWindow]
                          ) -> SteadyStateEstimate:
    """Estimate ``parameter`` from the steady windows, all others nominal.

    Parameters
    ----------
    model : PlantModel
    parameter : str
        The suspect.
    windows : sequence of SteadyWindow
        From :func:`steady_windows`.

    Returns
    -------
    SteadyStateEstimate

    Example
    -------
    >>> import numpy as np
    >>> from condmon.models.declared import load_plant_model
    >>> from condmon.simulate.plant import simulate_plant, integrate, input_signals
    >>> m = load_plant_model("hst")
    >>> rec = simulate_plant(m, ["Rv=+25%@10s"], seed=2)
    >>> t = rec["t"].to_numpy(); u = input_signals(m, t, rec)
    >>> x = integrate(m.compile(), t, u)
    >>> w = steady_windows(t, u, rec[["Ps", "omega_m"]].to_numpy(), x, 10.6, 4.0, 1.0,
    ...                    np.array([2.5e4, 0.05236]))
    >>> est = estimate_steady_state(m, "Rv", w)
    >>> round(est.value / 11.271, 2)
    1.25
    """
    compiled = model.compile()
    nominal = model.parameter(parameter).value
    pi = model.parameter_names.index(parameter)
    p0 = compiled.parameter_vector()
    positive = nominal > 0
    scale = abs(nominal) if nominal != 0 else 1.0

    def value_of(s: float) -> float:
        return nominal * math.exp(s) if positive else nominal + scale * s

    def misfit(s_arr: FloatArray) -> FloatArray:
        p = p0.copy()
        p[pi] = value_of(float(s_arr[0]))
        out = []
        for w in windows:
            xs = _steady_state(compiled, w, p, w.guess)
            if xs is None:
                return np.full(len(windows) * len(w.mean), 1e6)
            out.append((compiled.outputs(xs, w.inputs, p) - w.mean) / w.std_error)
        return np.concatenate(out)

    if not windows:
        return SteadyStateEstimate(parameter, nominal, nominal, None, False)
    sol = optimize.least_squares(misfit, np.zeros(1), method="lm", x_scale=1.0,
                                 diff_step=1e-6, max_nfev=200)
    value = value_of(float(sol.x[0]))
    resid = misfit(sol.x)
    dof = len(resid) - 1
    chi2 = float(resid @ resid)
    moves = bool(np.any(np.abs(sol.jac) > 1e-9))
    # a value that runs off by orders of magnitude means no finite value explains the data
    ok = bool(sol.success) and moves and chi2 < 1e11 and (not positive or abs(float(sol.x[0])) < _RUNAWAY)
    consistency = math.sqrt(chi2 / dof) if dof > 0 else None
    return SteadyStateEstimate(parameter, value, nominal, consistency, ok)


def _steady_state(compiled: CompiledModel, w: SteadyWindow, p: FloatArray, guess: FloatArray
                  ) -> FloatArray | None:
    """Root of the state derivatives near ``guess`` (scaled), or None."""
    scale = np.maximum(np.abs(guess), 1e-6 * (np.max(np.abs(guess)) + 1.0))

    def f(z: FloatArray) -> FloatArray:
        x = z * scale
        # derivatives scaled by the state size: a relative rate [1/s]
        rate: FloatArray = compiled.rhs(x, w.inputs, p) / scale
        return rate

    sol = optimize.root(f, guess / scale, method="hybr", options={"xtol": 1e-12})
    if not sol.success or not np.all(np.isfinite(sol.x)):
        return None
    out: FloatArray = np.asarray(sol.x * scale, dtype=np.float64)
    return out
