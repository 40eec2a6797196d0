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
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from condmon.identify.identifiability import Identifiability, assess_identifiability
from condmon.models.declared import CompiledModel, PlantModel
from condmon.models.plausibility import IdentifiabilityLimits
from condmon.simulate.plant import operating_segments

__all__ = ["SteadyWindow", "SteadyStateEstimate", "SteadyFit", "steady_windows",
           "estimate_steady_state", "fit_steady_states"]

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


@dataclass(frozen=True, eq=False)
class SteadyFit:
    """Several unknowns fitted to the steady windows (:func:`fit_steady_states`).

    Attributes
    ----------
    values : dict of str to float
        Each unknown: estimated, or held. [SI]
    covariance : ndarray
        Of the unknowns in their order (zero rows for held ones). [SI²]
    identifiability : Identifiability or None
        Which unknowns the windows identify (None: not assessed).
    consistency : float or None
        sqrt(chi²/dof) of the weighted misfit; None without redundancy. [-]
    converged : bool
        Whether a value made the steady state match and moved it.
    misfit : ndarray
        The weighted residual of each window's sensor means at the estimate. [-]
    """

    values: dict[str, float]
    covariance: FloatArray
    identifiability: Identifiability | None
    consistency: float | None
    converged: bool
    misfit: FloatArray


def fit_steady_states(model: PlantModel, unknowns: Sequence[str],
                      windows: Sequence[SteadyWindow], *,
                      hold: Mapping[str, float] | None = None,
                      limits: IdentifiabilityLimits | None = None,
                      assess: bool = True) -> SteadyFit:
    """Fit unknowns so the model's steady state in each window matches its sensor means.

    The output-error form of the steady route (the model's whole steady state
    solved in every window, :func:`_steady_state`; the one steady-state solver
    of the fault isolation and of a declared machine's steady route). Each
    unknown is searched on a relative scale (its logarithm when its nominal is
    positive, else in steps of its nominal's size, or of half its declared
    ``range`` when the nominal is 0, else 1).

    Parameters
    ----------
    model : PlantModel
    unknowns : sequence of str
        In order of preference.
    windows : sequence of SteadyWindow
    hold : mapping, optional
        Values of the unknowns when not identified (default: nominal). [SI]
    limits : IdentifiabilityLimits, optional
    assess : bool
        Assess identifiability on the sensitivities at the held values and fit
        the identifiable unknowns only (else fit all).

    Returns
    -------
    SteadyFit
    """
    compiled = model.compile()
    names = list(unknowns)
    start = {k: float((hold or {}).get(k, model.parameter(k).value)) for k in names}
    idx = [model.parameter_names.index(k) for k in names]
    p0 = compiled.parameter_vector(start)
    positive = [start[k] > 0 for k in names]
    scale = [abs(start[k]) if start[k] != 0 else _zero_scale(model, k) for k in names]

    def values_of(s: FloatArray, which: Sequence[int]) -> FloatArray:
        p = p0.copy()
        for j, v in zip(which, s):
            base = start[names[j]]
            p[idx[j]] = base * math.exp(float(v)) if positive[j] else base + scale[j] * float(v)
        return p

    def misfit_of(which: Sequence[int]) -> Callable[[FloatArray], FloatArray]:
        def misfit(s: FloatArray) -> FloatArray:
            p = values_of(s, which)
            out = []
            for w in windows:
                xs = _steady_state(compiled, w, p, w.guess)
                if xs is None:
                    return np.full(len(windows) * len(w.mean), 1e6)
                out.append((compiled.outputs(xs, w.inputs, p) - w.mean) / w.std_error)
            return np.concatenate(out)
        return misfit

    k = len(names)
    held_values = {n: start[n] for n in names}
    if not windows:
        return SteadyFit(held_values, np.zeros((k, k)), None, None, False, np.zeros(0))
    idf = None
    chosen = list(range(k))
    if assess:
        base_misfit = misfit_of(chosen)
        r0 = base_misfit(np.zeros(k))
        p_start = values_of(np.zeros(k), chosen)
        lost = next((w for w in windows if _steady_state(compiled, w, p_start, w.guess) is None),
                    None)
        if lost is not None:   # no sensitivities to judge by: say so, not "absent"
            why = (f"the model has no steady state at the start values in the window "
                   f"{lost.start:g}-{lost.end:g} s (the solver found no root), so the route "
                   "cannot judge it")
            idf = Identifiability(tuple(names), (), {n: why for n in names})
            return SteadyFit(held_values, np.zeros((k, k)), idf, None, False, r0)
        S = np.empty((r0.size, k))
        for j in range(k):
            step = np.zeros(k)
            step[j] = 1e-4
            S[:, j] = (base_misfit(step) - r0) / 1e-4
        idf = assess_identifiability(S, names, limits=limits)
        chosen = [names.index(n) for n in idf.identifiable]
        if not chosen:
            return SteadyFit(held_values, np.zeros((k, k)), idf, None, False, r0)
    misfit = misfit_of(chosen)
    sol = optimize.least_squares(misfit, np.zeros(len(chosen)), method="lm", x_scale=1.0,
                                 diff_step=1e-6, max_nfev=200 * len(chosen))
    p = values_of(sol.x, chosen)
    values = {n: float(p[idx[j]]) for j, n in enumerate(names)}
    resid = misfit(sol.x)
    dof = len(resid) - len(chosen)
    chi2 = float(resid @ resid)
    moves = bool(np.all(np.any(np.abs(sol.jac) > 1e-9, axis=0)))
    # a value that runs off by orders of magnitude means no finite value explains the data
    runaway = any(positive[j] and abs(float(v)) >= _RUNAWAY for j, v in zip(chosen, sol.x))
    ok = bool(sol.success) and moves and chi2 < 1e11 and not runaway
    cov = np.zeros((k, k))
    try:
        cov_s = np.linalg.inv(sol.jac.T @ sol.jac)
        d = np.array([values[names[j]] if positive[j] else scale[j] for j in chosen])
        cov[np.ix_(chosen, chosen)] = d[:, None] * cov_s * d[None, :]
    except np.linalg.LinAlgError:
        cov[np.ix_(chosen, chosen)] = np.nan
    consistency = math.sqrt(chi2 / dof) if dof > 0 else None
    return SteadyFit(values, cov, idf, consistency, ok, resid)


def _zero_scale(model: PlantModel, name: str) -> float:
    """A step size for an unknown whose nominal is 0: half its declared range, else 1."""
    rng = model.parameter(name).range
    if rng is not None and math.isfinite(rng[1] - rng[0]):
        return float(rng[1] - rng[0]) / 2.0
    return 1.0


def estimate_steady_state(model: PlantModel, parameter: str, windows: Sequence[SteadyWindow]
                          ) -> SteadyStateEstimate:
    """Estimate ``parameter`` from the steady windows, all others nominal
    (a suspect of the fault isolation: :func:`fit_steady_states` of one unknown).

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
    >>> from condmon.models.registry import load_plant_model
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
    nominal = model.parameter(parameter).value
    if not windows:
        return SteadyStateEstimate(parameter, nominal, nominal, None, False)
    fit = fit_steady_states(model, [parameter], windows, assess=False)
    return SteadyStateEstimate(parameter, fit.values[parameter], nominal, fit.consistency,
                               fit.converged)


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
