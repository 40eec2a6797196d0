"""Output-error route: simulate the declared model, minimise the output error.

For models linear in their states with nonlinear terms of measured signals
(:mod:`condmon.models.semilinear`: Coulomb friction ``sign(omega)``, offsets):
each simulation discretises the linear part exactly (zero-order hold, one
matrix exponential) and drives it with the inputs and the nonlinear terms
evaluated on the measured signals, held over each sample; the sensors'
simulated outputs are compared with the measured ones. The unknowns minimise
``Σ_j Σ_k (y_j - ŷ_j)² / σ_j²`` (``scipy.optimize.least_squares``,
sensitivities by forward differences, the noise variances re-estimated once);
standard errors come from the Jacobian at the optimum.

Why by hand: no maintained Python package fits a declared grey-box model's
physical parameters by output error (MATLAB's ``greyest``/``nlgreyest`` are the
references); only the optimiser and the matrix exponential are borrowed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import sympy as sp
from numpy.typing import NDArray
from scipy.linalg import expm

from condmon._filter import lfilter
from condmon.errors import EstimationError
from condmon.identify.fit import FitCheck, residual_figures
from condmon.identify.greybox import RouteResult
from condmon.identify.long_run import normalised_inverse, widened
from condmon.io.records import Record
from condmon.models.machine import Machine
from condmon.models.semilinear import SemiLinearStructure, semilinear_structure

__all__ = ["OERouteResult", "oe_route"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class OERouteResult(RouteResult):
    """Outcome of the output-error route (see :class:`~condmon.identify.greybox.RouteResult`;
    the figures are per sensor, on its simulated output).

    Attributes
    ----------
    evaluations : int
        Simulations run by the optimiser.
    widening : float
        Largest factor by which the residuals' correlation widened a standard
        error over the white-noise bound (Newey–West). [-]
    bandwidth : float
        Bartlett bandwidth of that estimate. [samples]
    """

    evaluations: int
    widening: float = 1.0
    bandwidth: float = 0.0
    initial: dict[str, float] = field(default_factory=dict)

    def diagnostics(self) -> dict[str, float]:
        """The shared figures, with ``se_widening``, ``se_bandwidth_samples`` and
        the ``initial response`` figures."""
        return {"se_widening": self.widening, "se_bandwidth_samples": self.bandwidth,
                **self.initial, **super().diagnostics()}


class _Simulator:
    def __init__(self, structure: SemiLinearStructure, w: FloatArray, known: FloatArray,
                 dt: float) -> None:
        self.s, self.w, self.known, self.dt = structure, w, known, dt

    def outputs(self, p: FloatArray) -> FloatArray:
        A, B, C = self.s.matrices(p, self.known)
        n, r = B.shape
        M = np.zeros((n + r, n + r))
        M[:n, :n] = A * self.dt
        M[:n, n:] = B * self.dt
        with np.errstate(all="ignore"):
            E = expm(M)
        Ad, Bd = E[:n, :n], E[:n, n:]
        if not (np.all(np.isfinite(Ad)) and np.all(np.abs(np.linalg.eigvals(Ad)) < 1.0)):
            return np.full((self.w.shape[0], C.shape[0]), np.inf)
        return np.asarray(_through(Ad, Bd, C, self.w).sum(axis=2), dtype=np.float64)

    def free_responses(self, p: FloatArray) -> FloatArray:
        """What each initial state adds to the outputs, shape (N, outputs,
        states): ``C Ad^k e_i`` (the model starts at rest; a record that does
        not is told by these): the impulse through each state's column, its
        one sample of delay dropped."""
        A, _, C = self.s.matrices(p, self.known)
        n, N = A.shape[0], self.w.shape[0]
        with np.errstate(all="ignore"):
            Ad = expm(A * self.dt)
        impulse = np.zeros((N + 1, n))
        impulse[0] = 1.0
        return _through(Ad, np.eye(n), C, impulse)[1:]


def _through(Ad: FloatArray, B: FloatArray, C: FloatArray, w: FloatArray) -> FloatArray:
    """Each column of ``w`` (N, r) through ``x(k+1) = Ad x(k) + B w(k)``,
    ``y = C x`` from rest, shape (N, outputs, r): one sample of delay, as
    ``ss2tf`` gives."""
    from scipy.signal import ss2tf  # only this route needs it (~1 s of imports)

    out = np.zeros((w.shape[0], C.shape[0], B.shape[1]))
    with np.errstate(all="ignore"):
        for i in range(B.shape[1]):
            num, den = ss2tf(Ad, B[:, i:i + 1], C, np.zeros((C.shape[0], 1)))
            for j in range(C.shape[0]):
                out[:, j, i] = lfilter(num[j], den, w[:, i])
    return out


def _initial_figures(sims: Sequence[_Simulator], p: FloatArray, e: FloatArray,
                     sensors: Sequence[str]) -> dict[str, float]:
    """Each output's largest share of its simulation error an initial state
    explains over the records, and that part's RMS (``initial response NAME``,
    ``initial response rms NAME``, as the linear route's)."""
    from condmon.identify.greybox import initial_response

    out: dict[str, float] = {}
    first = 0
    for one in sims:
        n = one.w.shape[0]
        free = one.free_responses(p)
        for j, name in enumerate(sensors):
            if not np.all(np.isfinite(free[:, j, :])):
                continue
            share, rms = initial_response(free[:, j, :], e[first:first + n, j])
            if share >= out.get(f"initial response {name}", -1.0):
                out[f"initial response {name}"] = share
                out[f"initial response rms {name}"] = rms
        first += n
    return out


def _driving_signals(rec: Record, s: SemiLinearStructure) -> FloatArray:
    """The inputs and the nonlinear terms evaluated on the measured signals, (N, r)."""
    sym = {n: sp.Symbol(n, real=True) for n in (*s.inputs, *s.measured)}
    columns = {**{u: rec[u] for u in s.inputs},
               **{state: rec[col] for state, col in s.measured.items()}}
    w = [rec[u] for u in s.inputs]
    for g in s.signal_terms:
        names = sorted(str(x) for x in g.free_symbols)
        fn = sp.lambdify([sym[n] for n in names], g, modules="numpy")
        with np.errstate(all="ignore"):
            val = np.asarray(fn(*[columns[n] for n in names]), dtype=np.float64)
        w.append(np.broadcast_to(val, (len(rec),)).astype(np.float64))
    return np.column_stack(w)


def oe_route(rec: Record | Sequence[Record], machine: Machine, start: Mapping[str, float], *,
             constants: Mapping[str, float] | None = None,
             fit_threshold: float = 90.0) -> OERouteResult:
    """Output-error estimate of a semi-linear declared model from one record or
    several at once (each simulated from rest, one criterion over all).

    Parameters
    ----------
    rec : Record or sequence of Record
        Validated records with the inputs and every sensor column.
    machine : Machine
    start : mapping
        Starting values of the unknowns. [SI]
    constants : mapping, optional
        Known constants overriding the declared ones. [SI]
    fit_threshold : float
        [%]

    Returns
    -------
    OERouteResult

    Raises
    ------
    EstimationError
        When no stable model simulates the records or the sensitivities are singular.
    """
    from scipy.optimize import least_squares  # ~0.25 s of imports: only when refining
    s = semilinear_structure(machine)
    spec = machine.spec
    consts = machine.constants(constants)
    known = np.array([consts[k] for k in machine.plant.parameter_names
                      if k not in spec.unknowns])
    records = [rec] if isinstance(rec, Record) else list(rec)
    sims = [_Simulator(s, _driving_signals(r, s), known, r.dt) for r in records]
    y = np.vstack([r.stack(s.sensors) for r in records])

    def simulate(q: FloatArray) -> FloatArray:
        return np.vstack([one.outputs(q) for one in sims])
    p0 = np.array([float(start[k]) for k in spec.unknowns])
    scale = np.where(p0 != 0, np.abs(p0), 1.0)
    e0 = y - simulate(p0)
    if not np.all(np.isfinite(e0)):
        raise EstimationError("output-error route: the starting model does not simulate "
                              "(unstable or non-finite)")
    sigma = np.maximum(np.std(e0, axis=0), 1e-300)
    nfev = 0
    p = p0
    for _ in range(2):  # second pass with the noise levels of the first optimum
        def res(q: FloatArray, sig: FloatArray = sigma) -> FloatArray:
            out = ((y - simulate(q)) / sig).ravel()
            return out if np.all(np.isfinite(out)) else np.full(out.size, np.inf)

        try:
            sol = least_squares(res, p, method="trf", x_scale=scale, diff_step=1e-6,
                                max_nfev=100 * len(p0))
        except (ValueError, np.linalg.LinAlgError) as err:
            raise EstimationError(f"output-error route failed: {err}") from None
        p, nfev = np.asarray(sol.x, dtype=np.float64), nfev + int(sol.nfev)
        e = y - simulate(p)
        if not np.all(np.isfinite(e)):
            raise EstimationError("output-error route ended on a model that does not simulate")
        sigma = np.maximum(np.std(e, axis=0), 1e-300)
    jac = np.asarray(sol.jac, dtype=np.float64)
    info = jac.T @ jac
    white_cov, cond = normalised_inverse(info)
    if white_cov is None or not cond < 1e14:
        raise EstimationError(f"output-error route: the sensitivities are singular (condition "
                              f"number {cond:.3g}); the record does not excite every parameter")
    # coloured noise (or a model that misses a slow effect) correlates the residuals:
    # the standard errors are widened to the Newey-West sandwich where it is larger
    r = np.asarray(sol.fun, dtype=np.float64)
    m = y.shape[1]
    scores = (jac * r[:, None]).reshape(-1, m, p.size).sum(axis=1)
    cov, widening, bandwidth = widened(white_cov, scores)
    r2, nrmse, white = {}, {}, {}
    for j, name in enumerate(s.sensors):
        figures = residual_figures(y[:, j], e[:, j])
        r2[name], nrmse[name], white[name] = figures.r2, figures.nrmse, figures.whiteness
    fit_pct = 100.0 * float(np.mean(list(r2.values())))
    fit = FitCheck(r2, fit_pct, float(fit_threshold), bool(fit_pct >= fit_threshold))
    return OERouteResult(dict(zip(spec.unknowns, map(float, p))), cov, fit, nrmse, white, nfev,
                         widening, bandwidth, _initial_figures(sims, p, e, s.sensors))
