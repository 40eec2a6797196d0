"""Simulation-error route: any declared model, unmeasured states included.

The unknowns, and the initial states a declaration leaves unknown
(:mod:`condmon.models.shooting`), minimise the simulation error of the
measured outputs, ``Σ_j Σ_k (y_j - ŷ_j)² / σ_j²``: the model runs on the
record's inputs alone (:mod:`condmon.simulate.recorded`), as MATLAB's
``nlgreyest`` does with its default simulation focus.

- **Multiple shooting** (``segments`` > 1): the record is cut into segments,
  each simulated from its own initial states (unknowns too), and a jump
  between one segment's end and the next one's start is a residual with a
  heavy weight. A drifting or unstable model (an axis whose position
  integrates its speed) stays near the data while the parameters settle.
  The optimum is polished by single shooting where the whole record
  simulates and the parameters stay within a standard error of the
  segments' (else the whole record bends them to carry a drift); else the
  segments are doubled while the parameters move by more than a standard
  error, or while a finer cut from the start finds another optimum.
- **Sensitivities** by forward differences of a batch of simulations in one
  pass (exact forward sensitivities would need a second, larger system).
- **Bounds** from ``[estimation.plausible]`` and ``[estimation.initial]``.
- **Several starts** (``starts``): the declared values, then log-normal draws
  around them (a fixed seed), each a short run; the best is polished. Each
  start's cost, and the unknowns' spread among the best ones, are reported.
- **Standard errors** from the Jacobian at the optimum (residuals over each
  output's residual sd; initial states are unknowns of the same fit), with
  the integrator step's bias in them; identifiability checked on it.
- **Smoothing** of ``sign()``, ``max()``... widened to what the step resolves.

Why by hand: no maintained Python package fits a declared grey-box model with
unmeasured states by simulation error (``nlgreyest`` is the reference); the
optimiser is scipy's ``least_squares``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from condmon.errors import EstimationError
from condmon.identify.fit import FitCheck, residual_figures
from condmon.identify.greybox import RouteResult
from condmon.identify.identifiability import assess_identifiability, hold_limit
from condmon.identify.long_run import normalised_inverse
from condmon.identify.multistart import Evaluate, Jacobian, solve, solve_starts
from condmon.identify.shooting_fit import (
    batch_widened, fit_bounds, first_initials, jacobian, fit_layout, FitProblem, on_bounds,
    residuals, restart_vector, smoothed_for_step, start_vector, state_owners, step_shift,
)
from condmon.io.records import Record
from condmon.models.machine import Machine
from condmon.simulate.compare import beyond_noise
from condmon.simulate.recorded import choose_substeps

__all__ = ["SimulationRouteResult", "fit_initial_states", "simulation_route"]

FloatArray = NDArray[np.float64]
_SHORT_RUN = 10         # optimiser evaluations of each start before the best is polished
_POLISH = 200
_SAME_COST = 0.01       # starts within 1 % of the best cost reached it
_REFINE = 3             # a drifting fit's segments are doubled at most this many times
# The whole record is simulated from the segments' optimum and kept when its error stays
# within a quarter of theirs: a right model's errors are the noise either way, while a
# drift (an integrator, an unmodelled slow effect) grows with the time simulated.
_WHOLE_RECORD = 1.25


@dataclass(frozen=True, eq=False)
class SimulationRouteResult(RouteResult):
    """Outcome of the simulation-error route (see :class:`~condmon.identify.greybox.RouteResult`;
    the figures are per sensor, on the simulated output).

    Attributes
    ----------
    initial : dict of str to (float, float, str)
        Each state's initial value in the (first) record, its standard error
        and how it was set ("estimated", "first sample", "declared"). [state units]
    start_costs : tuple of float
        The RMS of the normalised residuals each start reached. [-]
    spread : dict of str to float
        Largest relative difference of each unknown among the starts that
        reached the best cost (0: one start did). [-]
    substeps : int
        Runge-Kutta steps per sample.
    segments : int
        Shooting segments per record of the figures' fit (1: single shooting).
    evaluations : int
        Simulations run by the optimiser.
    notes : tuple of str
        How the fit was made: integration, starts and their costs, shooting.
    cost : float
        RMS of the output residuals at the optimum, each divided by its
        output's spread in the record. [-]
    dof : int
        Output residuals less the unknowns fitted (initial states included).
    covariance_white : ndarray, optional
        The unknowns' covariance as if the residuals were white (before the
        batch-means widening). [SI²]
    smoothing : float, optional
        The smoothing width simulated with (None: the default). [switch units]
    """

    initial: dict[str, tuple[float, float, str]]
    start_costs: tuple[float, ...]
    spread: dict[str, float]
    substeps: int
    segments: int
    evaluations: int
    notes: tuple[str, ...] = ()
    cost: float = math.nan
    dof: int = 0
    covariance_white: FloatArray | None = None
    smoothing: float | None = None


def simulation_route(rec: Record | Sequence[Record], machine: Machine,
                     start: Mapping[str, float], *, constants: Mapping[str, float] | None = None,
                     fit_threshold: float = 90.0, seed: int = 0,
                     held: Sequence[str] = (), starts: int | None = None
                     ) -> SimulationRouteResult:
    """Simulation-error estimate of any declared model from one record or several.

    Parameters
    ----------
    rec : Record or sequence of Record
        Validated records with the model's inputs and every sensor column.
    machine : Machine
    start : mapping
        Starting values of the unknowns (the declared or held ones). [SI]
    constants : mapping, optional
        Known constants overriding the declared ones. [SI]
    fit_threshold : float
        [%]
    seed : int
        Seed of the further starts' draws.
    held : sequence of str
        Unknowns held at their ``start`` value (not estimated). An unknown the
        record does not identify (on the optimum's Jacobian) is held, and the
        others are estimated again, from their optimum, with one start.
    starts : int, optional
        Optimiser starts (default: the declaration's ``starts``).

    Returns
    -------
    SimulationRouteResult

    Raises
    ------
    EstimationError
        When no start simulates the record, or the sensitivities are singular.
    """
    records = [rec] if isinstance(rec, Record) else list(rec)
    consts = machine.constants(constants)
    settings = machine.spec.simulation
    plant = machine.plant
    single = fit_layout(records, machine, start, consts, 1, held)
    y_all = np.vstack(single.y)
    spread_y = np.std(y_all, axis=0)
    noise = np.array([s.noise for s in plant.sensors])
    tol = 0.1 * np.maximum(noise, 1e-3 * np.where(spread_y > 0, spread_y, 1.0))
    z1 = start_vector(single)
    p1, x01 = single.unpack(z1[:, None])
    single.substeps = choose_substeps(plant.compile(), single.u[:, :, 0], single.dt,
                                      x01[:, 0, :], p1, tol)
    sigma = np.where(spread_y > 0, spread_y, 1.0)
    xs_start = single.run(z1[:, None])[0]
    xscale = np.nanstd(xs_start[:, :, 0, 0], axis=0) if np.isfinite(xs_start).all() else \
        np.ones(single.n_x)
    xscale = np.where(np.isfinite(xscale) & (xscale > 0), xscale, 1.0)
    single, said = smoothed_for_step(single, xs_start[:, :, 0, 0], p1[:, 0])
    machine, notes = single.machine, [said] if said else []
    prob = single
    if settings.segments > 1:
        prob = fit_layout(records, machine, start, consts, settings.segments, held)
        prob.substeps = single.substeps
    z0 = start_vector(prob, single, z1)
    lo, hi = fit_bounds(prob)
    rng = np.random.default_rng(seed)
    points = [z0]
    nf = len(prob.free)
    for _ in range((settings.starts if starts is None else starts) - 1):
        z = z0.copy()
        z[:nf] = z0[:nf] * np.exp(rng.normal(0.0, 0.5, nf))
        points.append(np.clip(z, lo, hi))
    # the starts run together, one pass over the record per round (multistart.py)
    runs = solve_starts(_evaluator(prob, sigma, xscale), _differences(prob, sigma, xscale, lo, hi),
                        points, lo, hi, _SHORT_RUN, sum(y.size for y in prob.y))
    evaluations = sum(r[2] for r in runs)
    finite = [r for r in runs if math.isfinite(r[1])]
    if not finite:
        raise EstimationError("simulation-error route: no start simulates the record (every "
                              "start diverged or left the finite numbers); check the "
                              "declared values and [estimation.initial]")
    best = min(finite, key=lambda r: r[1])
    z, cost, n = _solve(prob, best[0], lo, hi, sigma, xscale, _POLISH)
    evaluations += n
    near = [r[0][:nf] for r in finite if r[1] <= best[1] * (1 + _SAME_COST)]
    spread = {k: (float(np.ptp([v[i] for v in near]) / max(abs(z[i]), 1e-300))
                  if len(near) > 1 else 0.0) for i, k in enumerate(prob.free)}
    if prob is not single:
        zs = np.clip(np.concatenate([z[:nf], first_initials(prob, z)]), *fit_bounds(single))
        r_single = residuals(single, zs[:, None], sigma, xscale)[0][:, 0]
        ms_cost = math.sqrt(float(np.mean(residuals(prob, z[:, None], sigma, xscale)[0]
                                          [:sum(y.size for y in prob.y), 0] ** 2)))
        whole = math.sqrt(float(np.mean(r_single ** 2))) if np.all(np.isfinite(r_single)) \
            else math.inf
        polished = None
        if whole <= _WHOLE_RECORD * ms_cost:
            zs2, cost2, n2 = _solve(single, zs, *fit_bounds(single), sigma, xscale, 50)
            evaluations += n2
            # the whole record may only polish what the segments found: parameters that
            # move beyond the segments' standard errors when the segments are joined
            # were bent to carry a drift the model does not have (the whole record's
            # own error bars grow with the drift's error, so they would let it pass)
            se = np.sqrt(np.maximum(np.diag(_covariance(prob, z, sigma, xscale)[3])[:nf],
                                    1e-300))
            shift = float(np.max(np.abs(zs2[:nf] - z[:nf]) / se)) if nf else 0.0
            if shift <= 1.0:
                polished = zs2
                prob, z = single, zs2
                notes.append(f"multiple shooting over {settings.segments} segments per "
                             "record, then single shooting from its optimum")
            else:
                why = (f"simulated whole, the parameters move by {shift:.3g} standard errors "
                       "from the segments' (the whole record bends them to carry a drift)")
        else:
            why = (f"the whole record simulated from its optimum misses by "
                   f"{whole / ms_cost:.3g} times the segments' error (a drift)")
        if polished is None:
            notes.append(f"multiple shooting over {settings.segments} segments per record; "
                         f"{why}, so the figures are the segments'")
            prob, z, n_refine, said = _refine(records, machine, start, consts, held, prob, z,
                                              sigma, xscale, (single, z1))
            evaluations += n_refine
            notes.append(said)
    res = _result(prob, z, sigma, xscale, fit_threshold, runs, spread, evaluations, notes,
                  start, machine)
    assert res.identifiability is not None
    idf = res.identifiability
    weak = [k for k in prob.free if k not in idf.identifiable]
    if not weak or len(weak) == len(prob.free):
        return res
    # Held only when the data allow it: the Wald test of "each one is at its start
    # value" on the white-noise covariance (the likelihood-ratio test to first
    # order), at 1 %, and then the likelihood ratio itself on the refit. The
    # white-noise figures are the strict ones: a correlated residual only makes
    # holding look cheaper, and a held value that is wrong biases every other.
    unknowns = machine.spec.unknowns
    pos = [unknowns.index(k) for k in weak]
    d = np.array([res.values[k] - float(start[k]) for k in weak])
    cov_w = res.covariance if res.covariance_white is None else res.covariance_white
    try:
        wald = float(d @ np.linalg.solve(cov_w[np.ix_(pos, pos)], d))
    except np.linalg.LinAlgError:
        wald = math.inf
    limit = hold_limit(len(weak))
    again = None
    if wald <= limit:
        moved = {**start, **{k: v for k, v in res.values.items() if k not in weak and k in start}}
        again = simulation_route(records, machine, moved, constants=constants,
                                 fit_threshold=fit_threshold, seed=seed, held=(*held, *weak),
                                 starts=1)
    lr = math.inf if again is None or again.segments != res.segments else \
        res.dof * 2.0 * math.log(max(again.cost, 1e-300)
                                                     / max(res.cost, 1e-300))
    if again is None or lr > limit:
        why = (f"Wald statistic {wald:.3g} > {limit:.3g}, 1 %" if again is None else
               f"holding {'it' if len(weak) == 1 else 'them'} would raise the error from "
               f"{res.cost:.4g} to {again.cost:.4g}: likelihood ratio {lr:.3g} > {limit:.3g}, "
               "1 %")
        said = (f"{', '.join(weak)}: {'; '.join(idf.reasons[k] for k in weak)}; but "
                f"{'it is' if len(weak) == 1 else 'they are'} away from the start value by more "
                f"than the noise allows ({why}): the record determines them, and their "
                "standard errors carry the collinearity")
        full = dataclasses.replace(idf, identifiable=tuple(k for k in idf.parameters
                                                           if k not in held),
                                   reasons={k: v for k, v in idf.reasons.items()
                                            if k not in weak})
        return dataclasses.replace(res, identifiability=full, notes=(*res.notes, said))
    kept = dataclasses.replace(idf, identifiable=tuple(k for k in idf.parameters
                                                       if k not in weak and k not in held))
    said = (f"{', '.join(weak)} held at {'its' if len(weak) == 1 else 'their'} start "
            f"value{'s' if len(weak) > 1 else ''} (not identified at the optimum, and within "
            f"the noise of {'it' if len(weak) == 1 else 'them'}: Wald statistic {wald:.3g} <= "
            f"{limit:.3g}; held, the error went from {res.cost:.4g} to {again.cost:.4g}, "
            f"likelihood ratio {lr:.3g} <= {limit:.3g}); the others estimated again from it, "
            f"{again.evaluations} more evaluations")
    return dataclasses.replace(again, identifiability=kept, start_costs=res.start_costs,
                               spread=res.spread, evaluations=res.evaluations + again.evaluations,
                               notes=(*res.notes, said))


def _refine(records: Sequence[Record], machine: Machine, start: Mapping[str, float],
            consts: Mapping[str, float], held: Sequence[str], prob: FitProblem, z: FloatArray,
            sigma: FloatArray, xscale: FloatArray, first: tuple[FitProblem, FloatArray]
            ) -> tuple[FitProblem, FloatArray, int, str]:
    """Where the model drifts, the segment length is a choice the figures must not
    hang on: the segments are doubled while the parameters move by more than one
    standard error, at most :data:`_REFINE` times. Each finer fit runs from the
    coarser optimum and from the route's start (``first``: the single-shooting
    problem and its start) and keeps the lower error. Where the two end in two
    optima (a longer segment's error has more minima), the segments are doubled
    once more, from both, and the lower there is kept: the shorter horizon is
    less bent by the drift. On EMPS, 100 segments put M 91.7 kg below 95.0 kg
    by 49 %, 200 put 95.0 kg below by 21 %: the figures are 200's."""
    nf = len(prob.free)
    per = [len(prob.seg) // len(records)]
    moves: list[float] = []
    evaluations = 0
    fresh_won = 0
    other, decided = "", False   # a cut's other optimum; a finer cut ran from the two
    rival: tuple[FitProblem, FloatArray] | None = None   # the coarser cut's other optimum
    seen, turned = "", False   # a cut's two optima; the finer cut put the other lower
    for _ in range(_REFINE):
        finer = fit_layout(records, machine, start, consts, 2 * per[-1], held)
        if len(finer.seg) <= len(prob.seg):
            break   # segments of 20 samples: as fine as a segment goes
        finer.substeps = prob.substeps
        bounds = fit_bounds(finer)
        z2, cost, n = _solve(finer, restart_vector(finer, prob, z), *bounds, sigma, xscale,
                             _POLISH)
        z3, cost3, n3 = _solve(finer, start_vector(finer, *first) if rival is None else
                               restart_vector(finer, *rival), *bounds, sigma, xscale, _POLISH)
        evaluations += n + n3
        came = z[:nf]
        if cost3 < cost * (1.0 - _SAME_COST / 10.0):
            z2, z3, cost, cost3 = z3, z2, cost3, cost
            fresh_won += 1
            if rival is not None:
                came = rival[1][:nf]
                turned = True
        if not math.isfinite(cost):
            break
        cov = _covariance(finer, z2, sigma, xscale)[3]
        se = np.sqrt(np.maximum(np.diag(cov)[:nf], 1e-300))
        moves.append(float(np.max(np.abs(z2[:nf] - came) / se)) if nf else 0.0)
        apart = np.abs(z3[:nf] - z2[:nf]) / se
        decided, rival, other = rival is not None, None, ""
        if nf and math.isfinite(cost3) and float(np.max(apart)) > 1.0:
            k = int(np.argmax(apart))
            # as many digits as tell the two apart (1.501 against 1.501 said nothing)
            d = 4 + max(0, int(-math.log10(max(abs(z3[k] - z2[k]) / max(abs(z2[k]), 1e-300),
                                               1e-12))) - 2)
            other = (f"{finer.free[k]} {z3[k]:.{d}g} (the other) against {z2[k]:.{d}g}, "
                     f"{float(apart[k]):.2g} standard errors away, at an error "
                     f"{100.0 * (cost3 / cost - 1.0):.0f} % higher")
            if not decided:
                rival, seen = (finer, z3), f"{len(finer.seg) // len(records)} segments put {other}"
        prob, z = finer, z2
        per.append(len(finer.seg) // len(records))
        if moves[-1] <= 1.0 and rival is None:
            break
    if not moves:
        return prob, z, evaluations, "the segments could not be cut finer"
    path = " -> ".join(str(k) for k in per)
    moved = ", then ".join(f"{m:.2g}" if m >= 0.01 else "under 0.01" for m in moves) + (
        " (from the optimum the figures continue)" if turned else "")
    tail = ("" if moves[-1] <= 1.0 else "; they still move by more than one standard error: "
            "the estimates hang on how the record is cut (an unmodelled drift), beyond what "
            "their standard errors say")
    fresh = "" if not fresh_won or decided else (
        f" ({fresh_won} of the finer fits reached a lower error from the start than from the "
        "coarser optimum: a local optimum of the longer segments, left)")
    if decided:
        fresh += (f"; the error has several minima: {seen}; {per[-1]}, run from both, put "
                  f"{other or 'them within a standard error'}" +
                  (": their order hangs on how the record is cut, and the figures are the "
                   "finer cut's" if turned else "; the figures are the lower"))
    elif other:
        fresh += (f"; the finer cut, run from the {'coarser optimum' if fresh_won else 'start'}"
                  f" too, reached another optimum ({other}): the error has several minima, "
                  "and the figures are the lowest found")
    return prob, z, evaluations, (f"segments refined {path} per record, the parameters moving "
                                  f"by {moved} standard errors; the figures are those of "
                                  f"{per[-1]} segments{fresh}{tail}")


def _trading(prob: FitProblem, J: FloatArray, z: FloatArray, xscale: FloatArray) -> str:
    """Which unknowns make up the direction the record does not see: the
    weakest singular vector of the column-normalised Jacobian, taken back to
    the unknowns' own (scaled) units, its entries above a third of the largest;
    and how to fix one of them."""
    with np.errstate(all="ignore"):
        norms = np.linalg.norm(J, axis=0)
        if not np.all(np.isfinite(J)):
            return ""
        cols = J / np.where(norms > 0, norms, 1.0)
        try:
            v = np.linalg.svd(cols, full_matrices=False)[2][-1]
        except np.linalg.LinAlgError:
            return ""
    names = list(prob.free)
    owners = sorted(state_owners(prob).items())
    states = prob.machine.plant.state_names
    names += [f"{states[j]} at segment {seg + 1}" for _, (seg, j) in owners]
    dead = [names[i] for i in np.flatnonzero(norms == 0)]
    if dead:
        return f"; the record does not move the outputs with {', '.join(dead)}"
    # In relative units (a parameter's own size, a state's spread): the
    # normalised matrix's null vector weighs each entry by its column's norm,
    # and a scaling that moves five parameters alike was named by three.
    nf = len(prob.free)
    size = np.r_[np.abs(z[:nf]), [xscale[j] for _, (_, j) in owners]][: v.size]
    own = np.abs(v / norms / np.where(size > 0, size, 1.0))   # (the move over the size)
    big = np.flatnonzero(own >= np.max(own) / 3)
    named = [names[i] for i in big]
    fix = [n for n in named if n in prob.free]
    hint = (f"; give one of {', '.join(fix)} a known value (--constants {fix[-1]}=VALUE), "
            "or leave it out of [estimation] estimate" if len(fix) > 1 else "")
    return f"; the direction it cannot see: {', '.join(named)}{hint}"


def _evaluator(prob: FitProblem, sigma: FloatArray, xscale: FloatArray) -> Evaluate:
    """The residual columns of ``prob``'s unknowns' columns."""
    return lambda zc: residuals(prob, zc, sigma, xscale)[0]


def _differences(prob: FitProblem, sigma: FloatArray, xscale: FloatArray, lo: FloatArray,
                 hi: FloatArray) -> Jacobian:
    """The forward-difference Jacobian of ``prob``, its simulations through the evaluator given."""
    return lambda z, evaluate: jacobian(prob, z, sigma, xscale, lo, hi, evaluate)


def _solve(prob: FitProblem, z0: FloatArray, lo: FloatArray, hi: FloatArray, sigma: FloatArray,
           xscale: FloatArray, max_nfev: int) -> tuple[FloatArray, float, int]:
    """One bounded least-squares run: (optimum, RMS of the normalised
    output residuals, simulations); cost inf when it does not simulate."""
    return solve(_evaluator(prob, sigma, xscale), _differences(prob, sigma, xscale, lo, hi),
                 z0, lo, hi, max_nfev, sum(y.size for y in prob.y))


def _covariance(prob: FitProblem, z: FloatArray, sigma: FloatArray, xscale: FloatArray
                ) -> tuple[float, FloatArray, FloatArray, FloatArray, FloatArray, float, int]:
    """At the optimum ``z``: the cost, the output errors [sensor units], the
    Jacobian, the widened and the white-noise covariances of ``z``, the largest
    widening and the batches it was measured over."""
    r, _ = residuals(prob, z[:, None], sigma, xscale)
    n_out = sum(y.size for y in prob.y)
    cost = math.sqrt(float(np.mean(r[:n_out, 0] ** 2)))
    e = r[:n_out, 0].reshape(-1, len(sigma)) * sigma  # the error in sensor units, stacked
    resid_sd = np.maximum(np.std(e, axis=0), 1e-300)
    lo, hi = fit_bounds(prob)
    J = jacobian(prob, z, resid_sd, xscale, lo, hi)
    white_inv, cond = normalised_inverse(J.T @ J)
    if white_inv is None or not cond < 1e14:
        missed = beyond_noise(prob.machine.plant, e)
        raise EstimationError(f"simulation-error route: the sensitivities are singular "
                              f"(condition number {cond:.3g}); the record does not excite "
                              "every unknown, or an initial state and a parameter trade off"
                              + _trading(prob, J, z, xscale)
                              + (f"; at the optimum {missed[0]}" if missed else ""))
    white = white_inv
    cov, widened, batches = batch_widened(prob, J, e / resid_sd, white)
    return cost, e, J, cov, white, widened, batches


def _result(prob: FitProblem, z: FloatArray, sigma: FloatArray, xscale: FloatArray,
            fit_threshold: float, runs: list[tuple[FloatArray, float, int]],
            spread: dict[str, float], evaluations: int, notes: list[str],
            start: Mapping[str, float], machine: Machine) -> SimulationRouteResult:
    plant = machine.plant
    cost, e, J, cov_z, white_z, widened, batches = _covariance(prob, z, sigma, xscale)
    n_out = sum(y.size for y in prob.y)
    # the integrator's step biases the unknowns: its shift is part of their error
    shift, step_rms = step_shift(prob, z, np.maximum(np.std(e, axis=0), 1e-300), xscale, J,
                                 white_z)
    with np.errstate(all="ignore"):
        past = np.abs(shift) / np.sqrt(np.diag(cov_z))
    cov_z = cov_z + np.outer(shift, shift)
    big = [(k, float(past[i])) for i, k in enumerate(prob.free) if past[i] > 1.0]
    if big:
        notes.append(f"the integrator's step ({prob.substeps} per sample) moves "
                     + ", ".join(f"{k} by {r:.3g}" for k, r in big) + " of the statistical "
                     "standard errors (simulated at half the step, the bias it leaves): "
                     "the standard errors include it, as the root of variance plus bias "
                     "squared")
    y = np.vstack(prob.y)
    if widened > 1.0:
        # the batch-means estimate scatters about the bound by about 1/sqrt(batches) on
        # white residuals, so a widening within that is the scatter, not a correlation
        why = ("the residuals are correlated and widen them" if widened > 1 + 2 / math.sqrt(
            max(batches, 1)) else "on these residuals, as white as the batches can tell, it "
               "is the estimate's own scatter that widens them")
        notes.append(f"standard errors: the larger of the white-noise bound and the batch-means "
                     f"estimate over {batches} contiguous batches; {why} up to "
                     f"{widened:.3g} times")
    names = plant.state_names
    nf = len(prob.free)
    # identifiability of the parameters on their own columns; the initial states are
    # unknowns of the same fit, and what they trade with a parameter is in its
    # standard error (the full inverse below)
    rel = J[:, :nf] * np.where(z[:nf] != 0, np.abs(z[:nf]), 1.0)
    idf = assess_identifiability(rel, prob.free, limits=machine.spec.identifiability)
    unknowns = machine.spec.unknowns
    values = {k: float(start.get(k, prob.base[plant.parameter_names.index(k)])) for k in unknowns}
    values.update({k: float(z[i]) for i, k in enumerate(prob.free)})
    cov = np.zeros((len(unknowns), len(unknowns)))
    pos = [unknowns.index(k) for k in prob.free]
    cov[np.ix_(pos, pos)] = cov_z[:nf, :nf]
    cov_white = np.zeros_like(cov)
    cov_white[np.ix_(pos, pos)] = white_z[:nf, :nf]
    first = prob.x_first[0].copy()
    se0 = np.zeros(len(first))
    for i, j in enumerate(prob.est0):
        first[j] = z[nf + i]
        se0[j] = math.sqrt(max(cov_z[nf + i, nf + i], 0.0))
    settings = machine.spec.simulation
    how = {"estimate": "estimated", "first-sample": "first sample", "declared": "declared"}
    initial = {n: (float(first[j]), float(se0[j]), how[settings.of(n).mode])
               for j, n in enumerate(names)}
    r2, nrmse, white = {}, {}, {}
    for j, name in enumerate(plant.sensor_names):
        figures = residual_figures(y[:, j], e[:, j])
        r2[name], nrmse[name], white[name] = figures.r2, figures.nrmse, figures.whiteness
    fit_pct = 100.0 * float(np.mean(list(r2.values())))
    notes.extend(f"{n}; the estimates are the best this model does, and their standard "
                 "errors hold only as far as the model does"
                 for n in beyond_noise(plant, e, step_rms))
    fit = FitCheck(r2, fit_pct, float(fit_threshold), bool(fit_pct >= fit_threshold))
    notes.extend(on_bounds(prob, z))
    costs = tuple(float(c) for _, c, _ in runs)
    best = min(costs)
    reached = sum(c <= best * (1 + _SAME_COST) for c in costs)
    widest = max(spread.values(), default=0.0)
    notes.insert(0, f"simulation error: the model run on the record's inputs (fourth-order "
                    f"Runge-Kutta, {prob.substeps} step(s) per sample), sensitivities by "
                    f"forward differences, {evaluations} optimiser evaluations")
    notes.append(f"{len(costs)} start(s) reached RMS errors (each output's over its "
                 "standard deviation in the record) of "
                 + ", ".join(f"{c:.4g}" for c in costs)
                 + f"; {reached} reached the best"
                 + (f", their unknowns within {100 * widest:.2g} % of each other"
                    if reached > 1 else ""))
    return SimulationRouteResult(values, cov, fit, nrmse, white, initial, costs, spread,
                                 prob.substeps, max(1, len(prob.seg) // len(prob.x_first)),
                                 evaluations, tuple(notes), cost, n_out - z.size,
                                 cov_white, identifiability=idf, smoothing=plant.smoothing)



def fit_initial_states(rec: Record, machine: Machine, params: Mapping[str, float],
                       start: Mapping[str, float]) -> dict[str, tuple[float, float]]:
    """The initial states that best simulate ``rec`` with the parameters fixed
    (MATLAB ``compare``'s default): the states ``[estimation.initial]`` leaves
    unknown, within its bounds, from ``start``; by single shooting.

    Parameters
    ----------
    rec : Record
    machine : Machine
    params : mapping
        Parameter values over the declared ones. [SI]
    start : mapping
        Every state's starting value. [state units]

    Returns
    -------
    dict of str to (float, float)
        Each fitted state's value and standard error (white-noise bound). [state units]

    Raises
    ------
    EstimationError
        When the model does not simulate the record from ``start``.
    """
    plant = machine.plant
    prob = fit_layout([rec], machine, params, {}, 1, held=machine.spec.unknowns)
    if not prob.est0:
        return {}
    names = plant.state_names
    prob.x_first[0] = np.array([float(start[n]) for n in names], dtype=np.float64)
    y = prob.y[0]
    spread = np.std(y, axis=0)
    noise = np.array([s.noise for s in plant.sensors])
    tol = 0.1 * np.maximum(noise, 1e-3 * np.where(spread > 0, spread, 1.0))
    z0 = start_vector(prob)
    p, x0 = prob.unpack(z0[:, None])
    prob.substeps = choose_substeps(plant.compile(), prob.u[:, :, 0], prob.dt, x0[:, 0, :], p,
                                    tol)
    sigma = np.where(spread > 0, spread, 1.0)
    xscale = np.ones(prob.n_x)
    lo, hi = fit_bounds(prob)
    z, cost, _ = _solve(prob, z0, lo, hi, sigma, xscale, _POLISH)
    if not math.isfinite(cost):
        raise EstimationError(f"{rec.source}: the model does not simulate this record from "
                              "the starting initial states; give them with --initial "
                              "NAME=VALUE,...")
    r, _ = residuals(prob, z[:, None], sigma, xscale)
    sd = np.maximum(np.std(r[:, 0].reshape(-1, len(sigma)) * sigma, axis=0), 1e-300)
    J = jacobian(prob, z, sd, xscale, lo, hi)
    with np.errstate(all="ignore"):
        cov = np.linalg.pinv(J.T @ J)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return {names[j]: (float(z[i]), float(se[i])) for i, j in enumerate(prob.est0)}
