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
  The optimum is then polished by single shooting where the whole record
  simulates; the note says which one the figures come from.
- **Sensitivities** by forward differences of a batch of simulations run at
  once (every unknown's perturbation, every segment, one pass): exact
  forward sensitivities would need a second, larger system per declaration;
  the differences cost the same pass and are said in the notes.
- **Bounds** from ``[estimation.plausible]`` and ``[estimation.initial]``.
- **Several starts** (``starts``): the declared values, then draws around
  them (log-normal, deterministic seed), each a short run; the best is
  polished. The cost each start reached, and the spread of the unknowns among
  the starts that reached the best cost, are reported.
- **Standard errors** from the Jacobian at the optimum, ``(JᵀJ)⁻¹`` of the
  residuals divided by each output's residual standard deviation; the
  initial states are unknowns of the same fit, so their uncertainty is in
  the parameters'. The identifiability check (:mod:`condmon.identify.identifiability`)
  runs on the same Jacobian.

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
from condmon.identify.identifiability import assess_identifiability
from condmon.io.records import Record
from condmon.models.machine import Machine
from condmon.models.shooting import state_readers
from condmon.simulate.recorded import choose_substeps, simulate_copies

__all__ = ["SimulationRouteResult", "simulation_route", "bounds_of"]

FloatArray = NDArray[np.float64]
_DEFECT_WEIGHT = 30.0   # a segment's jump counts as this many noise levels per state scale
_SHORT_RUN = 10         # optimiser evaluations of each start before the best is polished
_POLISH = 200
_SAME_COST = 0.01       # starts within 1 % of the best cost reached it
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


def bounds_of(machine: Machine, names: Sequence[str]) -> tuple[FloatArray, FloatArray]:
    """Lower and upper bounds of unknowns from ``[estimation.plausible]`` [SI]
    (a strict bound nudged inside by a millionth of its size)."""
    lo = np.full(len(names), -np.inf)
    hi = np.full(len(names), np.inf)
    for i, n in enumerate(names):
        bound = machine.spec.plausibility.bounds.get(n)
        for op, b in (bound.limits if bound is not None else ()):
            nudge = 1e-6 * max(abs(b), 1e-12) if op in ("gt", "lt") else 0.0
            if op in ("gt", "ge"):
                lo[i] = max(lo[i], b + nudge)
            else:
                hi[i] = min(hi[i], b - nudge)
    return lo, hi


@dataclass
class _Problem:
    """The layout of one fit: which initial states are unknown, segments, data."""

    machine: Machine
    free: list[str]            # unknown parameters, in order
    base: FloatArray           # every parameter (n_p,)
    pidx: list[int]            # positions of the free ones in base
    est0: list[int]            # states whose first-segment initial value is unknown
    x_first: list[FloatArray]  # each record's first-segment initial states (n_x,)
    seg: list[tuple[int, int, int]]   # (record, first sample, stop)
    u: FloatArray              # (L + 1, n_in, S) padded inputs per segment
    y: list[FloatArray]        # measured outputs per segment (len, n_out)
    dt: float
    substeps: int = 1

    @property
    def n_x(self) -> int:
        return len(self.machine.plant.state_names)

    def cont(self) -> list[int]:
        """Segments that continue the one before (their states all unknown)."""
        return [i for i, (r, a, _) in enumerate(self.seg) if a > 0]

    def n_z(self) -> int:
        return len(self.free) + len(self.est0) * len(self.x_first) + self.n_x * len(self.cont())

    def unpack(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Parameters (n_p, B) and segment initial states (n_x, S, B) of columns ``z`` (n_z, B)."""
        b = z.shape[1]
        p = np.repeat(self.base[:, None], b, axis=1)
        nf = len(self.free)
        p[self.pidx] = z[:nf]
        x0 = np.empty((self.n_x, len(self.seg), b))
        k = nf
        firsts = [i for i, (_, a, _) in enumerate(self.seg) if a == 0]
        for i, r in zip(firsts, (s[0] for s in self.seg if s[1] == 0)):
            x0[:, i, :] = self.x_first[r][:, None]
            x0[self.est0, i, :] = z[k:k + len(self.est0)]
            k += len(self.est0)
        for i in self.cont():
            x0[:, i, :] = z[k:k + self.n_x]
            k += self.n_x
        return p, x0

    def run(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """States (L+1, n_x, S, B) and outputs (L+1, n_out, S, B) of columns ``z``."""
        p, x0 = self.unpack(z)
        s, b = x0.shape[1], x0.shape[2]
        compiled = self.machine.plant.compile()
        u = np.repeat(self.u[..., None], b, axis=3).reshape(self.u.shape[0], self.u.shape[1], -1) \
            if s > 1 else self.u[:, :, 0]
        xs, ys = simulate_copies(compiled, u, self.dt, x0.reshape(self.n_x, -1),
                                 np.repeat(p[:, None, :], s, axis=1).reshape(p.shape[0], -1),
                                 self.substeps)
        return (xs.reshape(xs.shape[0], self.n_x, s, b), ys.reshape(ys.shape[0], -1, s, b))


def _layout(records: Sequence[Record], machine: Machine, start: Mapping[str, float],
            consts: Mapping[str, float], segments: int, held: Sequence[str] = ()) -> _Problem:
    plant = machine.plant
    spec = machine.spec
    dts = {r.dt for r in records}
    if max(dts) - min(dts) > 1e-9 * max(dts):
        raise EstimationError("simulation-error route: the records are sampled at different "
                              f"intervals ({', '.join(f'{d:g}' for d in sorted(dts))} s); "
                              "estimate them one by one")
    free = [k for k in spec.unknowns if k in start and k not in held]
    values = {**plant.parameter_values(), **consts, **{k: float(v) for k, v in start.items()}}
    base = np.array([values[n] for n in plant.parameter_names], dtype=np.float64)
    pidx = [plant.parameter_names.index(k) for k in free]
    settings = spec.simulation
    readers = state_readers(plant)
    est0 = [j for j, n in enumerate(plant.state_names) if settings.of(n).mode == "estimate"]
    x_first = []
    for r in records:
        x = np.array([s.initial for s in plant.states], dtype=np.float64)
        for j, n in enumerate(plant.state_names):
            if settings.of(n).mode in ("first-sample", "estimate") and n in readers:
                sensor, fn = readers[n]
                x[j] = float(fn(r[plant.sensor_names[sensor]][0], base))
        x_first.append(x)
    seg: list[tuple[int, int, int]] = []
    for i, r in enumerate(records):
        size = len(r)
        cuts = np.linspace(0, size, min(segments, max(1, size // 20)) + 1).round().astype(int)
        seg += [(i, int(a), int(b)) for a, b in zip(cuts[:-1], cuts[1:])]
    length = max(b - a for _, a, b in seg)
    inputs = plant.input_names
    u = np.empty((length + 1, len(inputs), len(seg)))
    ys = []
    for k, (i, a, b) in enumerate(seg):
        cols = records[i].stack(inputs) if inputs else np.zeros((len(records[i]), 0))
        part = cols[a:min(b + 1, len(cols))]
        u[:len(part), :, k] = part
        u[len(part):, :, k] = part[-1]
        ys.append(records[i].stack(plant.sensor_names)[a:b])
    return _Problem(machine, free, base, pidx, est0, x_first, seg, u, ys, records[0].dt)


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
    single = _layout(records, machine, start, consts, 1, held)
    y_all = np.vstack(single.y)
    spread_y = np.std(y_all, axis=0)
    noise = np.array([s.noise for s in plant.sensors])
    tol = 0.1 * np.maximum(noise, 1e-3 * np.where(spread_y > 0, spread_y, 1.0))
    z1 = _start_vector(single)
    p1, x01 = single.unpack(z1[:, None])
    single.substeps = choose_substeps(plant.compile(), single.u[:, :, 0], single.dt,
                                      x01[:, 0, :], p1, tol)
    sigma = np.where(spread_y > 0, spread_y, 1.0)
    xs_start = single.run(z1[:, None])[0]
    xscale = np.nanstd(xs_start[:, :, 0, 0], axis=0) if np.isfinite(xs_start).all() else \
        np.ones(single.n_x)
    xscale = np.where(np.isfinite(xscale) & (xscale > 0), xscale, 1.0)
    notes: list[str] = []
    prob = single
    if settings.segments > 1:
        prob = _layout(records, machine, start, consts, settings.segments, held)
        prob.substeps = single.substeps
    z0 = _start_vector(prob, single, z1)
    lo, hi = _bounds(prob)
    rng = np.random.default_rng(seed)
    points = [z0]
    nf = len(prob.free)
    for _ in range((settings.starts if starts is None else starts) - 1):
        z = z0.copy()
        z[:nf] = z0[:nf] * np.exp(rng.normal(0.0, 0.5, nf))
        points.append(np.clip(z, lo, hi))
    evaluations = 0
    runs = []
    for z in points:
        sol = _solve(prob, z, lo, hi, sigma, xscale, _SHORT_RUN)
        evaluations += sol[2]
        runs.append(sol)
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
        zs = np.clip(np.concatenate([z[:nf], _first_initials(prob, z)]), *_bounds(single))
        r_single = _residuals(single, zs[:, None], sigma, xscale)[0][:, 0]
        ms_cost = math.sqrt(float(np.mean(_residuals(prob, z[:, None], sigma, xscale)[0]
                                          [:sum(y.size for y in prob.y), 0] ** 2)))
        whole = math.sqrt(float(np.mean(r_single ** 2))) if np.all(np.isfinite(r_single)) \
            else math.inf
        if whole <= _WHOLE_RECORD * ms_cost:
            zs2, cost2, n2 = _solve(single, zs, *_bounds(single), sigma, xscale, 50)
            prob, z, evaluations = single, zs2, evaluations + n2
            notes.append(f"multiple shooting over {settings.segments} segments per record, "
                         "then single shooting from its optimum")
        else:
            notes.append(f"multiple shooting over {settings.segments} segments per record; "
                         f"the whole record simulated from its optimum misses by "
                         f"{whole / ms_cost:.3g} times the segments' error (a drift), so the "
                         "figures are the segments'")
    res = _result(prob, z, sigma, xscale, fit_threshold, runs, spread, evaluations, notes,
                  start, machine)
    assert res.identifiability is not None
    idf = res.identifiability
    weak = [k for k in prob.free if k not in idf.identifiable]
    if not weak or len(weak) == len(prob.free):
        return res
    # Held only when the data allow it: the Wald test of "each one is at its start
    # value" on the full fit's covariance (the likelihood-ratio test to first
    # order), at 1 %. A collinear set the record still determines (a small noise)
    # stays estimated, and its standard errors carry the collinearity.
    from scipy.stats import chi2

    unknowns = machine.spec.unknowns
    pos = [unknowns.index(k) for k in weak]
    d = np.array([res.values[k] - float(start[k]) for k in weak])
    try:
        wald = float(d @ np.linalg.solve(res.covariance[np.ix_(pos, pos)], d))
    except np.linalg.LinAlgError:
        wald = math.inf
    limit = float(chi2.ppf(0.99, len(weak)))
    if not wald <= limit:
        said = (f"{', '.join(weak)}: {'; '.join(idf.reasons[k] for k in weak)}; but "
                f"{'it is' if len(weak) == 1 else 'they are'} away from the start value by more "
                f"than the noise allows (Wald statistic {wald:.3g} > {limit:.3g}, 1 %): the "
                "record determines them, and their standard errors carry the collinearity")
        full = dataclasses.replace(idf, identifiable=tuple(k for k in idf.parameters
                                                           if k not in held),
                                   reasons={k: v for k, v in idf.reasons.items()
                                            if k not in weak})
        return dataclasses.replace(res, identifiability=full, notes=(*res.notes, said))
    moved = {**start, **{k: v for k, v in res.values.items() if k not in weak and k in start}}
    again = simulation_route(records, machine, moved, constants=constants,
                             fit_threshold=fit_threshold, seed=seed, held=(*held, *weak),
                             starts=1)
    kept = dataclasses.replace(idf, identifiable=tuple(k for k in idf.parameters
                                                       if k not in weak and k not in held))
    said = (f"{', '.join(weak)} held at {'its' if len(weak) == 1 else 'their'} start "
            f"value{'s' if len(weak) > 1 else ''} (not identified at the optimum, and within "
            f"the noise of {'it' if len(weak) == 1 else 'them'}: Wald statistic {wald:.3g} <= "
            f"{limit:.3g}); the others estimated again from it: "
            f"normalised RMS error {again.cost:.4g}, {again.evaluations} more evaluations")
    return dataclasses.replace(again, identifiability=kept, start_costs=res.start_costs,
                               spread=res.spread, evaluations=res.evaluations + again.evaluations,
                               notes=(*res.notes, said))

def _start_vector(prob: _Problem, single: _Problem | None = None,
                  z1: FloatArray | None = None) -> FloatArray:
    """Start of the unknowns: the start values, first samples or declared
    initial states, and, per continuing segment, the single-shooting start's
    states at its first sample (the measured ones where a sensor reads them)."""
    lo, hi = _bounds(prob)
    z = [prob.base[prob.pidx]]
    for x in prob.x_first:
        z.append(x[prob.est0])
    cont = prob.cont()
    if cont:
        assert single is not None and z1 is not None
        xs = single.run(z1[:, None])[0][:, :, :, 0]
        plant = prob.machine.plant
        readers = state_readers(plant)
        for i in cont:
            r, a, _ = prob.seg[i]
            first_seg = next(k for k, s in enumerate(single.seg) if s[0] == r)
            x = xs[a, :, first_seg] if a < xs.shape[0] else xs[-1, :, first_seg]
            x = np.where(np.isfinite(x), x, prob.x_first[r])
            for j, n in enumerate(plant.state_names):
                if n in readers:
                    x[j] = float(readers[n][1](prob.y[i][0, readers[n][0]], prob.base))
            z.append(x)
    return np.clip(np.concatenate(z), lo, hi)


def _bounds(prob: _Problem) -> tuple[FloatArray, FloatArray]:
    plo, phi = bounds_of(prob.machine, prob.free)
    settings = prob.machine.spec.simulation
    names = prob.machine.plant.state_names
    xlo = np.array([settings.of(names[j]).low for j in prob.est0])
    xhi = np.array([settings.of(names[j]).high for j in prob.est0])
    n_c = len(prob.cont())
    allx_lo = np.array([settings.of(n).low for n in names])
    allx_hi = np.array([settings.of(n).high for n in names])
    lo = np.concatenate([plo, np.tile(xlo, len(prob.x_first)), np.tile(allx_lo, n_c)])
    hi = np.concatenate([phi, np.tile(xhi, len(prob.x_first)), np.tile(allx_hi, n_c)])
    return lo, hi


def _first_initials(prob: _Problem, z: FloatArray) -> FloatArray:
    nf = len(prob.free)
    return z[nf:nf + len(prob.est0) * len(prob.x_first)]


def _residuals(prob: _Problem, zc: FloatArray, sigma: FloatArray, xscale: FloatArray
               ) -> tuple[FloatArray, FloatArray]:
    """Residual columns (rows, B) of columns ``zc`` (n_z, B), and the states."""
    xs, ys = prob.run(zc)
    parts = []
    for k, y in enumerate(prob.y):
        e = (y[:, :, None] - ys[:len(y), :, k, :]) / sigma[None, :, None]
        parts.append(e.reshape(-1, zc.shape[1]))
    _, x0 = prob.unpack(zc)
    for i in prob.cont():
        prev = i - 1
        end = xs[len(prob.y[prev]), :, prev, :]
        parts.append(_DEFECT_WEIGHT * (end - x0[:, i, :]) / xscale[:, None])
    return np.vstack(parts), xs


def _jacobian(prob: _Problem, z: FloatArray, sigma: FloatArray, xscale: FloatArray,
              lo: FloatArray, hi: FloatArray) -> FloatArray:
    """Forward differences, every unknown at once: one column per parameter
    and one per state (every segment's start moved together; a segment's rows
    depend on its own start only)."""
    nf, nx = len(prob.free), prob.n_x
    cols = [z]
    steps = []
    for i in range(nf):
        h = 1e-6 * max(abs(z[i]), 1e-6)
        h = -h if z[i] + h > hi[i] else h
        c = z.copy()
        c[i] += h
        cols.append(c)
        steps.append(h)
    owners = _state_owners(prob)    # z index -> (segment, state)
    hx = np.array([1e-6 * max(xscale[j], 1e-6) for j in range(nx)])
    for j in range(nx):
        c = z.copy()
        for idx, (_, jj) in owners.items():
            if jj == j:
                c[idx] += hx[j] if z[idx] + hx[j] <= hi[idx] else -hx[j]
        cols.append(c)
    r, _ = _residuals(prob, np.column_stack(cols), sigma, xscale)
    J = np.zeros((r.shape[0], z.size))
    for i in range(nf):
        J[:, i] = (r[:, 1 + i] - r[:, 0]) / steps[i]
    rows, jumps = _row_blocks(prob)
    for idx, (s, j) in owners.items():
        h = cols[1 + nf + j][idx] - z[idx]
        d = (r[:, 1 + nf + j] - r[:, 0]) / h
        for a, b in rows[s]:
            J[a:b, idx] = d[a:b]
        if s in jumps:  # its own start in the jump before it: exact
            J[jumps[s] + j, idx] = -_DEFECT_WEIGHT / xscale[j]
    return J


def _state_owners(prob: _Problem) -> dict[int, tuple[int, int]]:
    out = {}
    k = len(prob.free)
    firsts = [i for i, s in enumerate(prob.seg) if s[1] == 0]
    for i in firsts:
        for j in prob.est0:
            out[k] = (i, j)
            k += 1
    for i in prob.cont():
        for j in range(prob.n_x):
            out[k] = (i, j)
            k += 1
    return out


def _row_blocks(prob: _Problem) -> tuple[dict[int, list[tuple[int, int]]], dict[int, int]]:
    """Rows of each segment (its outputs, the jump at its end), and where each
    continuing segment's jump rows start."""
    rows: dict[int, list[tuple[int, int]]] = {}
    jumps: dict[int, int] = {}
    a = 0
    for k, y in enumerate(prob.y):
        rows[k] = [(a, a + y.size)]
        a += y.size
    for i in prob.cont():
        jumps[i] = a
        rows[i - 1].append((a, a + prob.n_x))
        a += prob.n_x
    return rows, jumps


def _solve(prob: _Problem, z0: FloatArray, lo: FloatArray, hi: FloatArray, sigma: FloatArray,
           xscale: FloatArray, max_nfev: int) -> tuple[FloatArray, float, int]:
    """One bounded least-squares run: (optimum, RMS of the normalised
    output residuals, simulations); cost inf when it does not simulate."""
    from scipy.optimize import least_squares  # ~0.25 s of imports: only when fitting

    def fun(z: FloatArray) -> FloatArray:
        r = _residuals(prob, z[:, None], sigma, xscale)[0][:, 0]
        return r if np.all(np.isfinite(r)) else np.full(r.size, np.inf)

    r0 = fun(z0)
    if not np.all(np.isfinite(r0)):
        return z0, math.inf, 1
    try:
        sol = least_squares(fun, z0, jac=lambda z: _jacobian(prob, z, sigma, xscale, lo, hi),
                            bounds=(lo, hi), method="trf", x_scale="jac", max_nfev=max_nfev)
    except (ValueError, np.linalg.LinAlgError) as err:
        raise EstimationError(f"simulation-error route failed: {err}") from None
    z = np.asarray(sol.x, dtype=np.float64)
    n_out = sum(y.size for y in prob.y)
    return z, float(np.sqrt(np.mean(sol.fun[:n_out] ** 2))), int(sol.nfev + sol.njev)


def _result(prob: _Problem, z: FloatArray, sigma: FloatArray, xscale: FloatArray,
            fit_threshold: float, runs: list[tuple[FloatArray, float, int]],
            spread: dict[str, float], evaluations: int, notes: list[str],
            start: Mapping[str, float], machine: Machine) -> SimulationRouteResult:
    plant = machine.plant
    r, xs = _residuals(prob, z[:, None], sigma, xscale)
    n_out = sum(y.size for y in prob.y)
    cost = math.sqrt(float(np.mean(r[:n_out, 0] ** 2)))
    e = r[:n_out, 0].reshape(-1, len(sigma)) * sigma  # the error in sensor units, stacked
    y = np.vstack(prob.y)
    resid_sd = np.maximum(np.std(e, axis=0), 1e-300)
    lo, hi = _bounds(prob)
    J = _jacobian(prob, z, resid_sd, xscale, lo, hi)
    info = J.T @ J
    with np.errstate(all="ignore"):
        cond = float(np.linalg.cond(info)) if np.all(np.isfinite(info)) else np.inf
    if not (np.isfinite(cond) and cond < 1e14):
        raise EstimationError(f"simulation-error route: the sensitivities are singular "
                              f"(condition number {cond:.3g}); the record does not excite "
                              "every unknown, or an initial state and a parameter trade off")
    cov_z = np.asarray(np.linalg.inv(info), dtype=np.float64)
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
    fit = FitCheck(r2, fit_pct, float(fit_threshold), bool(fit_pct >= fit_threshold))
    costs = tuple(float(c) for _, c, _ in runs)
    best = min(costs)
    reached = sum(c <= best * (1 + _SAME_COST) for c in costs)
    widest = max(spread.values(), default=0.0)
    notes.insert(0, f"simulation error: the model run on the record's inputs (fourth-order "
                    f"Runge-Kutta, {prob.substeps} step(s) per sample), sensitivities by "
                    f"forward differences, {evaluations} optimiser evaluations")
    notes.append(f"{len(costs)} start(s) reached normalised RMS errors "
                 + ", ".join(f"{c:.4g}" for c in costs)
                 + f"; {reached} reached the best"
                 + (f", their unknowns within {100 * widest:.2g} % of each other"
                    if reached > 1 else ""))
    return SimulationRouteResult(values, cov, fit, nrmse, white, initial, costs, spread,
                                 prob.substeps, max(1, len(prob.seg) // len(prob.x_first)),
                                 evaluations, tuple(notes), cost, n_out - z.size,
                                 identifiability=idf)
