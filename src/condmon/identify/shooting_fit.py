"""The layout of a simulation-error fit: unknowns, shooting segments, residuals, Jacobian.

The pieces :mod:`condmon.identify.simulation_route` fits with: which initial
states are unknown, how a record is cut into shooting segments, the residuals
(outputs and the jumps between segments), their forward-difference Jacobian in
one batched pass, the batch-means widening of the standard errors, and the
shift the integrator's step puts in the unknowns.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from condmon.errors import EstimationError
from condmon.io.records import Record
from condmon.models.machine import Machine
from condmon.models.shooting import state_readers
from condmon.simulate.recorded import resolvable_smoothing, simulate_copies

__all__ = ["DEFECT_WEIGHT", "FitProblem", "batch_widened", "bounds_of", "first_initials",
           "fit_bounds", "fit_layout", "jacobian", "on_bounds", "residuals", "restart_vector",
           "row_blocks", "smoothed_for_step", "start_vector", "state_owners", "step_shift"]

FloatArray = NDArray[np.float64]
DEFECT_WEIGHT = 30.0   # a segment's jump counts as this many noise levels per state scale


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
class FitProblem:
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


def fit_layout(records: Sequence[Record], machine: Machine, start: Mapping[str, float],
            consts: Mapping[str, float], segments: int, held: Sequence[str] = ()) -> FitProblem:
    """The fit of ``records``: the unknowns (``spec.unknowns`` not ``held``), each
    record's first initial states (a sensed state from its first reading), and
    ``segments`` shooting segments per record (at least 20 samples each), their
    inputs padded to one length."""
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
    return FitProblem(machine, free, base, pidx, est0, x_first, seg, u, ys, records[0].dt)


def start_vector(prob: FitProblem, single: FitProblem | None = None,
                  z1: FloatArray | None = None) -> FloatArray:
    """Start of the unknowns: the start values, first samples or declared
    initial states, and, per continuing segment, the single-shooting start's
    states at its first sample (the measured ones where a sensor reads them)."""
    lo, hi = fit_bounds(prob)
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


def restart_vector(prob: FitProblem, old: FitProblem, z_old: FloatArray) -> FloatArray:
    """Start of ``prob`` (the same records cut finer) from ``old``'s optimum: its
    parameters and first initial states, and each new segment's states where
    ``old``'s segment through that sample had them (a sensed state read)."""
    lo, hi = fit_bounds(prob)
    nf = len(old.free)
    z = [z_old[:nf], first_initials(old, z_old)]
    xs = old.run(z_old[:, None])[0][:, :, :, 0]
    readers = state_readers(prob.machine.plant)
    for i in prob.cont():
        r, a, _ = prob.seg[i]
        k = next(k for k, (rr, aa, bb) in enumerate(old.seg) if rr == r and aa <= a < bb)
        x = xs[a - old.seg[k][1], :, k].copy()
        for j, n in enumerate(prob.machine.plant.state_names):
            if n in readers:
                x[j] = float(readers[n][1](prob.y[i][0, readers[n][0]], prob.base))
        z.append(x)
    return np.clip(np.concatenate(z), lo, hi)


def fit_bounds(prob: FitProblem) -> tuple[FloatArray, FloatArray]:
    """Bounds of every unknown of ``prob``: the parameters' ``[estimation.plausible]``,
    the initial states' ``[estimation.initial]``. [SI, state units]"""
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


def first_initials(prob: FitProblem, z: FloatArray) -> FloatArray:
    """The unknown initial states of each record's first segment, out of ``z``."""
    nf = len(prob.free)
    return z[nf:nf + len(prob.est0) * len(prob.x_first)]


def residuals(prob: FitProblem, zc: FloatArray, sigma: FloatArray, xscale: FloatArray
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
        parts.append(DEFECT_WEIGHT * (end - x0[:, i, :]) / xscale[:, None])
    return np.vstack(parts), xs


def jacobian(prob: FitProblem, z: FloatArray, sigma: FloatArray, xscale: FloatArray,
              lo: FloatArray, hi: FloatArray,
              evaluate: Callable[[FloatArray], FloatArray] | None = None) -> FloatArray:
    """Forward differences, every unknown at once: one column per parameter
    and one per state (every segment's start moved together; a segment's rows
    depend on its own start only). ``evaluate`` gives the residual columns of
    unknowns' columns (default: :func:`residuals` of ``prob``)."""
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
    owners = state_owners(prob)    # z index -> (segment, state)
    hx = np.array([1e-6 * max(xscale[j], 1e-6) for j in range(nx)])
    for j in range(nx):
        c = z.copy()
        for idx, (_, jj) in owners.items():
            if jj == j:
                c[idx] += hx[j] if z[idx] + hx[j] <= hi[idx] else -hx[j]
        cols.append(c)
    zc = np.column_stack(cols)
    r = residuals(prob, zc, sigma, xscale)[0] if evaluate is None else evaluate(zc)
    J = np.zeros((r.shape[0], z.size))
    for i in range(nf):
        J[:, i] = (r[:, 1 + i] - r[:, 0]) / steps[i]
    rows, jumps = row_blocks(prob)
    for idx, (s, j) in owners.items():
        h = cols[1 + nf + j][idx] - z[idx]
        d = (r[:, 1 + nf + j] - r[:, 0]) / h
        for a, b in rows[s]:
            J[a:b, idx] = d[a:b]
        if s in jumps:  # its own start in the jump before it: exact
            J[jumps[s] + j, idx] = -DEFECT_WEIGHT / xscale[j]
    return J


def state_owners(prob: FitProblem) -> dict[int, tuple[int, int]]:
    """Each initial-state unknown's position in ``z`` -> (segment, state)."""
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


def batch_widened(prob: FitProblem, J: FloatArray, r: FloatArray, cov: FloatArray
                   ) -> tuple[FloatArray, float, int]:
    """The covariance with each variance widened to the batch-means (cluster-robust
    sandwich) estimate where that is larger: ``A⁻¹ (Σ_b g_b g_bᵀ) A⁻¹``, ``g_b``
    the scores ``Jᵀr`` summed over contiguous batches of samples (the shooting
    segments when there are 10 or more, else 20 blocks), so a correlated
    residual (a model that misses part of the dynamics) widens the error bars
    while white noise keeps the bound. Correlations kept. Returns (covariance,
    largest widening, batches)."""
    n_s, n_out = r.shape
    per_sample = (J[:n_s * n_out] * r.ravel()[:, None]).reshape(n_s, n_out, -1).sum(axis=1)
    if len(prob.seg) >= 10:
        edges = np.concatenate([[0], np.cumsum([len(y) for y in prob.y])])
    else:
        edges = np.linspace(0, n_s, min(20, n_s // 10) + 1).round().astype(int)
    b = len(edges) - 1
    if b < 5:
        return cov, 1.0, b
    g = np.array([per_sample[a:c].sum(axis=0) for a, c in zip(edges[:-1], edges[1:])])
    robust = cov @ (g.T @ g * (b / (b - 1))) @ cov
    with np.errstate(all="ignore"):
        ratio = np.sqrt(np.clip(np.diag(robust), 0.0, None) / np.diag(cov))
    s = np.where(np.isfinite(ratio), np.maximum(ratio, 1.0), 1.0)
    return cov * s[:, None] * s[None, :], float(np.max(s)), b


def row_blocks(prob: FitProblem) -> tuple[dict[int, list[tuple[int, int]]], dict[int, int]]:
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


def step_shift(prob: FitProblem, z: FloatArray, scale: FloatArray, xscale: FloatArray,
               J: FloatArray, inverse: FloatArray) -> tuple[FloatArray, FloatArray]:
    """How far the integrator's step moves the unknowns at the optimum ``z``, and
    each output's step error [sensor units, RMS].

    The outputs are simulated again at half the step. The step error of the
    fit's own simulation is taken as twice the change: what a first-order
    method gives, the larger bound for Runge-Kutta, whose fourth order falls to
    the first across a ``sign()`` or ``max()`` switch (on a friction axis, the
    step the search had chosen left 20 µm where the encoder reads 1 µm). It is
    carried into the unknowns by the Gauss-Newton step ``(JᵀJ)⁻¹ Jᵀ Δr``
    (``J`` the residuals' Jacobian at ``scale``, ``inverse`` its ``(JᵀJ)⁻¹``):
    the bias the step leaves in them. Zero where the finer run does not
    simulate.
    """
    sub = prob.substeps
    r1 = residuals(prob, z[:, None], scale, xscale)[0][:, 0]
    prob.substeps = 2 * sub
    try:
        r2 = residuals(prob, z[:, None], scale, xscale)[0][:, 0]
    finally:
        prob.substeps = sub
    n_out = sum(y.size for y in prob.y)
    change = 2.0 * (r2 - r1)
    if not np.all(np.isfinite(change)):
        return np.zeros(z.size), np.zeros(scale.size)
    rms = np.sqrt(np.mean((change[:n_out].reshape(-1, scale.size) * scale) ** 2, axis=0))
    return np.asarray(inverse @ (J.T @ change), dtype=np.float64), rms


def on_bounds(prob: FitProblem, z: FloatArray) -> list[str]:
    """A note per parameter the optimiser left on an ``[estimation.plausible]``
    bound (within a millionth of its size, the nudge of a strict bound): there
    the fit stopped because it could go no further, and the standard error, a
    curvature at the optimum, does not say how far beyond the data would go."""
    lo, hi = fit_bounds(prob)
    out = []
    for i, k in enumerate(prob.free):
        for b, side in ((lo[i], "lower"), (hi[i], "upper")):
            if np.isfinite(b) and abs(z[i] - b) <= 2e-6 * max(abs(b), 1e-12):
                out.append(f"{k} = {z[i]:.6g} sits on its {side} bound in "
                           "[estimation.plausible]: the optimiser stopped there; the data "
                           "may want a value beyond it, so the bound or the model is "
                           "worth a look")
    return out


def smoothed_for_step(prob: FitProblem, states: FloatArray, p: FloatArray
                      ) -> tuple[FitProblem, str]:
    """``prob`` on its machine with the smoothing of ``sign()``, ``abs()``,
    ``min()`` and ``max()`` widened to what its step resolves along ``states``
    (N, n_x) of its first record, at parameters ``p``
    (:func:`~condmon.simulate.recorded.resolvable_smoothing`), and the note;
    ``prob`` itself and "" where the step is stable there."""
    machine = prob.machine
    plant, said = resolvable_smoothing(machine.plant, states, prob.u[: len(states), :, 0], p,
                                       prob.dt / prob.substeps)
    if not said:
        return prob, ""
    return dataclasses.replace(prob, machine=dataclasses.replace(machine, plant=plant)), said
