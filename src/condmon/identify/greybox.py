"""Grey-box estimation of a declared machine's physical parameters.

Two routes, chosen from the declaration's structure (:mod:`condmon.models.machine`):

- **linear** — the model is linear in its states and one input: the discrete
  common-denominator model is estimated (SRIV by default), converted to
  continuous time by the exact ZOH inverse, and the parameters are solved from
  the symbolic coefficient map (exactly when the equations are as many as the
  unknowns, in least squares otherwise); standard errors by the delta method.
- **inverse** — the equations are linear in the unknown parameters but not in
  the signals (Coulomb friction ``sign(v)``, offsets): every signal is low-passed
  with a zero-phase Butterworth filter, the unmeasured derivatives are taken by
  central differences, and ``Σ θ_k φ_k = known`` is solved by least squares
  (the inverse dynamic identification model, IDIM-LS); standard errors from the
  residual variance.

Written for condmon: no maintained Python package derives these maps from a
declared model (MATLAB's ``greyest`` and CAPTAIN's ``rivcbj`` are the
references; IDIM-LS is the standard method for robot and axis dynamics).

References
----------
.. [1] A. Janot, M. Gautier, M. Brunot, "Data set and reference models of EMPS",
   Nonlinear System Identification Benchmarks, 2019.
.. [2] M. Gautier, "Dynamic identification of robots with power model", ICRA 1997.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConversionError, EstimationError, ModelError
from condmon.identify._common import TFEstimate
from condmon.identify.fit import FitCheck, fit_check, residual_figures
from condmon.io.records import Record
from condmon.models.conversion import d2c_coefficients_fast, tf_d2c
from condmon.models.declared import substituted_equations, symbols_of
from condmon.models.machine import InverseStructure, LinearStructure, Machine
from condmon.models.transfer import ContinuousTF

if TYPE_CHECKING:
    import sympy as sp

# sympy and scipy are imported by the routes and fall-backs that use them: the
# linear route of a cached declaration (condmon.models.derived_cache) needs neither.

__all__ = ["LinearRouteResult", "RouteResult", "InverseRouteResult", "linear_route",
           "inverse_route",
           "choose_route"]

FloatArray = NDArray[np.float64]


def choose_route(machine: Machine, route: str | None = None) -> str:
    """The route to take: the one asked for, or the declaration's; "auto" picks
    "linear" when the model is linear, else "inverse"; "oe" (output error on a
    semi-linear model) is taken only when asked for.

    Raises
    ------
    ModelError
        When the route asked for does not fit the model (with the reason).
    """
    want = route or machine.spec.route
    if want == "oe":
        from condmon.models.semilinear import semilinear_structure

        semilinear_structure(machine)
        return "oe"
    if want == "linear":
        machine.linear()
        return "linear"
    if want == "inverse":
        machine.inverse()
        return "inverse"
    if want != "auto":
        raise ModelError(f"unknown route {want!r}; allowed: auto, linear, inverse, oe")
    try:
        machine.linear()
        return "linear"
    except ModelError as lin_err:
        try:
            machine.inverse()
        except ModelError as inv_err:
            raise ModelError(f"{machine.plant.source}: no estimation route fits this model: "
                             f"{lin_err}; {inv_err}") from None
        return "inverse"


@dataclass(frozen=True, eq=False)
class LinearRouteResult:
    """Outcome of the linear route (values of the unknowns and their covariance)."""

    values: dict[str, float]
    covariance: FloatArray
    discrete: TFEstimate
    continuous: ContinuousTF | None
    fit: FitCheck
    rejection: str | None
    diagnostics: dict[str, float] = field(default_factory=dict)


def _fit_and_diagnostics(est: TFEstimate, u: FloatArray, y: FloatArray,
                         threshold: float) -> tuple[FitCheck, dict[str, float]]:
    """The fit check (SPEC A4) and each output's NRMSE and residual whiteness
    (the system-identification benchmarks' figures; reported, not judged),
    from one simulation of the model."""
    if np.any(np.abs(est.model.poles()) >= 1.0):
        return fit_check(est.model, u, y, threshold), {}
    with np.errstate(all="ignore"):
        e = y - est.model.simulate(u)
    if not np.all(np.isfinite(e)):
        return fit_check(est.model, u, y, threshold), {}
    r2: dict[str, float] = {}
    out: dict[str, float] = {}
    for j, name in enumerate(est.model.outputs):
        figures = residual_figures(y[:, j], e[:, j])
        r2[name] = figures.r2 if np.var(y[:, j]) > 0 else (1.0 if np.var(e[:, j]) == 0
                                                          else float("-inf"))
        out[f"nrmse {name}"] = figures.nrmse
        out[f"whiteness {name}"] = figures.whiteness
    fit = 100.0 * float(np.mean(list(r2.values())))
    return FitCheck(r2, fit, float(threshold), bool(fit >= threshold)), out


def _solve_coefficients(lin: LinearStructure, target: FloatArray, start: FloatArray,
                        known: FloatArray) -> FloatArray:
    scale = np.where(target != 0, np.abs(target), 1.0)

    def res(p: FloatArray) -> FloatArray:
        with np.errstate(all="ignore"):  # far from the solution: inf, judged by the caller
            return (lin.values(p, known) - target) / scale

    def jac(p: FloatArray) -> FloatArray:
        with np.errstate(all="ignore"):
            return lin.jacobian(p, known) / scale[:, None]

    # Newton (Gauss-Newton when over-determined) from the declared values, then
    # from their mirror image: a record with an inverted sign maps to negative
    # parameters, which the plausibility check then names, rather than to a
    # spurious far-away solution. A bounded trust-region search is the fallback.
    best: FloatArray | None = None
    best_cost = np.inf
    for x0 in (start, -start):
        p = _newton(res, jac, x0)
        if p is None or float(np.sum(res(p) ** 2)) > 1e-20:
            from scipy.optimize import least_squares

            try:
                with np.errstate(all="ignore"):
                    sol = least_squares(res, x0, jac=jac, method="trf",
                                        x_scale=np.where(x0 != 0, np.abs(x0), 1.0),
                                        xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200)
            except (ValueError, np.linalg.LinAlgError):
                continue
            x = np.asarray(sol.x, dtype=np.float64)
            polished = _newton(res, jac, x, steps=3)
            found = polished if polished is not None else x
            if p is None or np.sum(res(found) ** 2) < np.sum(res(p) ** 2):
                p = found
        with np.errstate(all="ignore"):
            r = res(p)
        cost = float(np.sum(r ** 2)) if np.all(np.isfinite(r)) else np.inf
        if cost < best_cost:
            best, best_cost = p, cost
        if cost < 1e-20:
            break
    if best is None or not np.all(np.isfinite(best)):
        raise ConversionError("the coefficient map has no finite solution")
    if target.size == start.size and best_cost > 1e-12:
        raise ConversionError("no parameter values reproduce the estimated coefficients "
                              f"(relative mismatch {np.sqrt(best_cost):.2g})")
    return best


def _newton(res: Any, jac: Any, x0: FloatArray, steps: int = 30) -> FloatArray | None:
    """Damped (Gauss-)Newton on ``res(p) = 0``: the last iterate, or None when
    the misfit or its Jacobian stops being finite or the step cannot be solved."""
    p = np.array(x0, dtype=np.float64)
    with np.errstate(all="ignore"):
        r = res(p)
        cost = float(np.sum(r ** 2))
        for _ in range(steps):
            if not np.isfinite(cost):
                return None
            if cost < 1e-26:
                return p
            J = jac(p)
            if not np.all(np.isfinite(J)):
                return None
            try:
                step = (np.linalg.solve(J, -r) if J.shape[0] == J.shape[1]
                        else np.linalg.lstsq(J, -r, rcond=None)[0])
            except np.linalg.LinAlgError:
                return None
            t = 1.0
            for _ in range(20):  # halve the step until the misfit falls
                q = p + t * step
                rq = res(q)
                cq = float(np.sum(rq ** 2))
                if np.isfinite(cq) and cq < cost:
                    break
                t *= 0.5
            else:  # no descent: a (least-squares) stationary point
                return p
            if cost - cq < 1e-30:  # no further progress: converged
                return q
            p, r, cost = q, rq, cq
    return p


def linear_route(rec: Record, machine: Machine, estimator: object, *,
                 excitation: Sequence[str] = (), constants: Mapping[str, float] | None = None,
                 fit_threshold: float = 90.0) -> LinearRouteResult:
    """Estimate the unknowns of a linear declared model from one record.

    Parameters
    ----------
    rec : Record
        Validated record with the input and every sensor column.
    machine : Machine
    estimator : callable
        A discrete estimator with the signature of :func:`condmon.identify.sriv`.
    excitation : sequence of str
        Excitation columns for closed-loop instruments.
    constants : mapping, optional
        Values overriding the declared known constants. [SI]
    fit_threshold : float
        [%]

    Returns
    -------
    LinearRouteResult
    """
    lin = machine.linear()
    spec = machine.spec
    order = spec.order or lin.order
    u = rec[lin.input]
    y = rec.stack(lin.outputs)
    r = rec.stack(excitation) if excitation else None
    est: TFEstimate = estimator(u, y, order, dt=rec.dt, excitation=r,  # type: ignore[operator]
                                outputs=lin.outputs, input_name=lin.input)
    fit, diag = _fit_and_diagnostics(est, u, y, fit_threshold)
    consts = machine.constants(constants)
    known = np.array([consts[k] for k in machine.plant.parameter_names
                      if k not in spec.unknowns])
    nan = {k: float("nan") for k in spec.unknowns}
    nan_cov = np.full((len(spec.unknowns),) * 2, np.nan)
    try:
        cont = tf_d2c(est.model)
    except ModelError as err:
        return LinearRouteResult(nan, nan_cov, est, None, fit, f"no physical parameters: {err}")
    if order != lin.order:
        return LinearRouteResult(nan, nan_cov, est, cont, fit,
                                 f"order {order} differs from the model's {lin.order}")
    theta = np.r_[est.model.den[1:], est.model.nums[:, 1:].ravel()]

    def coefficients(th: FloatArray) -> FloatArray:
        n, m = lin.order, len(lin.outputs)
        cden, cnums = d2c_coefficients_fast(np.r_[1.0, th[:n]],
                                            np.column_stack([np.zeros(m), th[n:].reshape(m, n)]),
                                            rec.dt)
        full = np.r_[cden[1:], cnums[:, 1:].ravel()]
        return np.asarray(full[list(lin.free)], dtype=np.float64)

    c_hat = np.r_[cont.den[1:], cont.nums[:, 1:].ravel()][list(lin.free)]
    start = np.array([machine.nominal()[k] for k in spec.unknowns])
    try:
        p = _solve_coefficients(lin, c_hat, start, known)
    except ConversionError as err:
        return LinearRouteResult(nan, nan_cov, est, cont, fit,
                                 f"no physical parameters: {err}; is the sign of a column "
                                 "inverted or its unit wrong?")
    # Delta method: theta -> continuous coefficients (forward differences, as the
    # ZOH inverse has no closed form) -> parameters (exact Jacobian of the map).
    Jt = np.empty((c_hat.size, theta.size))
    for k in range(theta.size):
        h = 1e-7 * max(abs(theta[k]), 1e-3)
        tp = theta.copy()
        tp[k] += h
        Jt[:, k] = (coefficients(tp) - c_hat) / h
    Jp = lin.jacobian(p, known)
    G = np.linalg.pinv(Jp)
    cov = G @ Jt @ est.covariance @ Jt.T @ G.T
    return LinearRouteResult(dict(zip(spec.unknowns, map(float, p))), cov, est, cont, fit, None,
                             diag)


@dataclass(frozen=True, eq=False)
class RouteResult:
    """What every nonlinear route returns: estimates, covariance and fit figures.

    Attributes
    ----------
    values : dict of str to float
        Estimates of the unknowns. [SI]
    covariance : ndarray
        Covariance of the unknowns, in the declaration's order.
    fit : FitCheck
        R_T² per output or equation.
    nrmse : dict of str to float
        RMS error / RMS of the measured signal, per output or equation. [-]
    whiteness : dict of str to float
        Largest normalised autocorrelation of each residual, lags 1..20. [-]
    """

    values: dict[str, float]
    covariance: FloatArray
    fit: FitCheck
    nrmse: dict[str, float]
    whiteness: dict[str, float]

    def diagnostics(self) -> dict[str, float]:
        """``nrmse <name>`` and ``whiteness <name>`` figures, as in the JSON."""
        return {**{f"nrmse {k}": v for k, v in self.nrmse.items()},
                **{f"whiteness {k}": v for k, v in self.whiteness.items()}}


@dataclass(frozen=True, eq=False)
class InverseRouteResult(RouteResult):
    """Outcome of the inverse-model route (see :class:`RouteResult`).

    ``fit`` compares each equation's measured (filtered, differentiated) state
    derivative with the derivative the estimated model predicts; ``whiteness``
    is taken at twice the cut-off (the residual's bandwidth).

    Attributes
    ----------
    cutoff : float
        Low-pass cut-off used. [Hz]
    samples : int
        Rows of the regression.
    """

    cutoff: float
    samples: int

    def diagnostics(self) -> dict[str, float]:
        """The shared figures, with ``cutoff_hz`` and ``samples``."""
        return {"cutoff_hz": self.cutoff, "samples": float(self.samples),
                **super().diagnostics()}


def _lowpass(x: FloatArray, cutoff: float, fs: float) -> FloatArray:
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, cutoff, fs=fs, output="sos")
    return np.asarray(sosfiltfilt(sos, x), dtype=np.float64)


def inverse_route(rec: Record | Sequence[Record], machine: Machine, *,
                  constants: Mapping[str, float] | None = None,
                  fit_threshold: float = 90.0) -> InverseRouteResult:
    """Inverse-model least squares (IDIM-LS) on filtered and differentiated signals.

    Parameters
    ----------
    rec : Record or sequence of Record
        Validated record(s) with every sensor and input column the equations
        use; several records (one sample interval) are stacked into one
        regression.
    machine : Machine
    constants : mapping, optional
        Values overriding the declared known constants. [SI]
    fit_threshold : float
        [%]

    Returns
    -------
    InverseRouteResult

    Raises
    ------
    EstimationError
        When the regression is singular (a parameter not excited).
    """
    inv: InverseStructure = machine.inverse()
    spec, plant = machine.spec, machine.plant
    records = [rec] if isinstance(rec, Record) else list(rec)
    fs = 1.0 / records[0].dt
    if any(abs(r.dt * fs - 1.0) > 1e-3 for r in records):
        raise EstimationError("records estimated together must share one sample interval: "
                              + ", ".join(f"{r.source} {r.dt:.6g} s" for r in records))
    cutoff = spec.cutoff if spec.cutoff is not None else 0.1 * fs / 2.0
    if not cutoff < 0.5 * fs:
        raise EstimationError(f"{records[0].source}: the low-pass cut-off {cutoff:g} Hz is "
                              f"not below the Nyquist frequency {0.5 * fs:g} Hz")
    consts = machine.constants(constants)
    sym = symbols_of(plant)
    prepared = [_inverse_signals(r, machine, inv, consts, cutoff) for r in records]
    n_rows = sum(int(rows.size) for _, rows in prepared)
    if n_rows < 10 * len(spec.unknowns):
        raise EstimationError(f"{', '.join(r.source for r in records)}: {n_rows} usable "
                              f"samples after filtering are too few for "
                              f"{len(spec.unknowns)} unknowns")
    blocks, rhs = [], []
    for eq in inv.equations:
        X = np.zeros((n_rows, len(spec.unknowns)))
        for unknown, phi in eq.terms:
            X[:, spec.unknowns.index(unknown)] += np.concatenate(
                [_evaluate(phi, sig, consts, rows) for sig, rows in prepared])
        blocks.append(X)
        rhs.append(np.concatenate([_evaluate(eq.known, sig, consts, rows)
                                   for sig, rows in prepared]))
    theta, cov, _ = _weighted_lstsq(blocks, rhs, ", ".join(r.source for r in records))
    # Fit of each equation on the measured (filtered, differentiated) state
    # derivative against the derivative the estimated model predicts.
    values = {**consts, **dict(zip(spec.unknowns, map(float, theta)))}
    derivs = substituted_equations(plant)[1]
    step = max(1, int(round(fs / (2.0 * cutoff * spec.decimate))))
    r2, nrmse, white = {}, {}, {}
    for eq in inv.equations:
        name = f"d{eq.state}/dt"
        model = derivs[eq.state].xreplace({sym[k]: v for k, v in values.items()})
        meas = np.concatenate([sig[f"d_{eq.state}"][rows] for sig, rows in prepared])
        pred = np.concatenate([_evaluate(model, sig, consts, rows) for sig, rows in prepared])
        e = meas - pred
        figures = residual_figures(meas, e)
        r2[name], nrmse[name] = figures.r2, figures.nrmse
        white[name] = residual_figures(meas[::step], e[::step]).whiteness
    fit_pct = 100.0 * float(np.mean(list(r2.values())))
    fit = FitCheck(r2, fit_pct, float(fit_threshold), bool(fit_pct >= fit_threshold))
    return InverseRouteResult(dict(zip(spec.unknowns, map(float, theta))), cov, fit, nrmse,
                              white, float(cutoff), n_rows)


def _inverse_signals(rec: Record, machine: Machine, inv: InverseStructure,
                     consts: Mapping[str, float], cutoff: float
                     ) -> tuple[dict[str, FloatArray], NDArray[np.intp]]:
    """One record's filtered signals and derivatives, and the rows to use
    (filter edges and standstill left out)."""
    import sympy as sp

    plant, spec = machine.plant, machine.spec
    fs = 1.0 / rec.dt
    column_of = {str(e): sensor for sensor, e in substituted_equations(plant)[2].items()
                 if isinstance(e, sp.Symbol)}
    sig: dict[str, FloatArray] = {}
    for state in inv.signals:
        if state in column_of:
            sig[state] = _lowpass(rec[column_of[state]], cutoff, fs)
    for state, of in inv.derivation.items():
        if state not in sig and of in sig:
            sig[state] = np.gradient(sig[of], rec.dt)
    for name in plant.input_names:
        if name in rec.columns:
            sig[name] = _lowpass(rec[name], cutoff, fs)
    for state in list(sig):
        if state in plant.state_names:
            sig[f"d_{state}"] = np.gradient(sig[state], rec.dt)
    edge = int(math.ceil(3.0 * fs / cutoff))
    rows = np.arange(edge, len(rec) - edge, spec.decimate)
    # Rows where the argument of a sign/abs is near zero (an axis standing
    # still: static friction anywhere within +-Fc) are left out.
    for arg in _switch_arguments(inv):
        a = _evaluate(arg, sig, consts, rows)
        rms = float(np.sqrt(np.mean(a ** 2))) if a.size else 0.0
        rows = rows[np.abs(a) > spec.deadband * rms]
    return sig, rows


def _switch_arguments(inv: InverseStructure) -> list[sp.Expr]:
    """Arguments of the sign/abs functions in the equations (unique)."""
    import sympy as sp

    found: list[sp.Expr] = []
    for eq in inv.equations:
        for expr in (*(phi for _, phi in eq.terms), eq.known):
            for f in expr.atoms(sp.sign, sp.Abs):
                if f.args[0] not in found:
                    found.append(f.args[0])
    return found


def _evaluate(expr: sp.Expr, sig: Mapping[str, FloatArray], consts: Mapping[str, float],
              rows: NDArray[np.intp]) -> FloatArray:
    import sympy as sp

    names = sorted(str(s) for s in expr.free_symbols)
    args: list[FloatArray | float] = []
    for n in names:
        if n in sig:
            args.append(sig[n][rows])
        elif n in consts:
            args.append(float(consts[n]))
        else:
            raise EstimationError(f"signal {n!r} is not available for the inverse model")
    fn = sp.lambdify([sp.Symbol(n, real=True) for n in names], expr, modules="numpy")
    with np.errstate(all="ignore"):
        val = np.asarray(fn(*args), dtype=np.float64)
    return np.broadcast_to(val, (rows.size,)).astype(np.float64)


def _weighted_lstsq(blocks: list[FloatArray], rhs: list[FloatArray], source: str
                    ) -> tuple[FloatArray, FloatArray, list[FloatArray]]:
    """Least squares over stacked equations, each weighted by 1/σ of its residual
    (two passes); covariance ``(Xᵀ W X)⁻¹``."""
    w = np.ones(len(blocks))
    theta = np.zeros(blocks[0].shape[1])
    for _ in range(2):
        X = np.vstack([b * wi for b, wi in zip(blocks, w)])
        y = np.concatenate([r * wi for r, wi in zip(rhs, w)])
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(y))):
            raise EstimationError(f"{source}: the inverse-model regressors are not finite")
        scale = np.sqrt(np.sum(X ** 2, axis=0))
        if np.any(scale == 0):
            raise EstimationError(f"{source}: a parameter's regressor is identically zero: "
                                  "the record does not excite it")
        Xs = X / scale
        sv = np.linalg.svd(Xs, compute_uv=False)
        if sv[-1] < 1e-10 * sv[0]:
            raise EstimationError(f"{source}: the inverse-model regression is singular "
                                  f"(condition number {sv[0] / max(sv[-1], 1e-300):.3g}): "
                                  "the record does not excite every parameter")
        theta = np.linalg.lstsq(Xs, y, rcond=None)[0] / scale
        resid = [r - b @ theta for b, r in zip(blocks, rhs)]
        sig = np.array([max(float(np.std(e)), 1e-300) for e in resid])
        w = 1.0 / sig
    X = np.vstack([b * wi for b, wi in zip(blocks, w)])
    cov = np.linalg.inv(X.T @ X)
    return theta, np.asarray(cov, dtype=np.float64), resid
