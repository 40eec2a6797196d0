"""Grey-box estimation of a declared machine's physical parameters.

Two routes, chosen from the declaration's structure (:mod:`condmon.models.machine`):

- **linear** — the model is linear in its states and one input: the discrete
  common-denominator model is estimated (SRIV by default), converted to
  continuous time by the exact ZOH inverse, and the parameters are solved from
  the symbolic coefficient map (exactly when the equations are as many as the
  unknowns, in least squares otherwise); standard errors by the delta method.
- **inverse** (:mod:`condmon.identify.inverse_route`) — the equations are
  linear in the unknown parameters but not in the signals (Coulomb friction
  ``sign(v)``, offsets): IDIM-LS on filtered, differentiated signals.
- **steady** (:mod:`condmon.identify.steady_route`) — the equations as
  balances over a record's steady windows.

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

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConversionError, ModelError
from condmon.identify._common import TFEstimate, schur_stable, signals
from condmon.identify.coefficients import rank_short, solve_coefficients
from condmon.identify.fit import FitCheck, fit_check, residual_figures
from condmon.identify.identifiability import (
    HOLD_LEVEL, Identifiability, assess_identifiability, dependence_at, held_covariance,
    hold_limit,
)
from condmon.io.records import Record
from condmon.models.conversion import tf_d2c_jacobian
from condmon.models.machine import LinearStructure, Machine
from condmon.models.transfer import ContinuousTF

# sympy and scipy are imported by the routes and fall-backs that use them: the
# linear route of a cached declaration (condmon.models.derived_cache) needs neither.

__all__ = ["LinearRouteResult", "RouteResult", "linear_route", "choose_route", "auto_reason",
           "NOT_AT_REST", "not_at_rest", "initial_response"]

FloatArray = NDArray[np.float64]


def choose_route(machine: Machine, route: str | None = None) -> str:
    """The route to take: the one asked for, or the declaration's; "auto" picks
    "linear" when the model is linear, else "inverse" when every state the
    equations need is measured, else "simulation" (simulation error, which
    fits any declared model: :func:`auto_reason` says why it was taken); "oe"
    (output error on a semi-linear model) is taken only when asked for. When
    the linear route then refuses a record that does not start at rest (an
    initial state explains a quarter of its simulation error), the estimate
    takes the simulation error too.

    Raises
    ------
    ModelError
        When the route asked for does not fit the model (with the reason).
    """
    want = route or machine.spec.route
    if want == "steady":  # balances of measured signals, else the model's whole steady state
        return "steady"
    if want == "simulation":
        return "simulation"
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
        raise ModelError(f"unknown route {want!r}; allowed: auto, linear, inverse, oe, steady, "
                         "simulation")
    if _linear_error(machine) is None:
        return "linear"
    return "inverse" if auto_reason(machine) is None else "simulation"


def _linear_error(machine: Machine) -> str | None:
    try:
        machine.linear()
    except ModelError as err:
        return str(err)
    return None


def auto_reason(machine: Machine) -> str | None:
    """Why "auto" takes the simulation-error route (None when a cheaper one fits)."""
    lin = _linear_error(machine)
    if lin is None:
        return None
    try:
        machine.inverse()
    except ModelError as inv_err:
        return (f"route auto took the simulation error: not linear ({lin}); no inverse model "
                f"({inv_err})")
    return None


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
    identifiability: Identifiability | None = None
    notes: tuple[str, ...] = ()



def _fit_and_diagnostics(est: TFEstimate, u: FloatArray, y: FloatArray,
                         threshold: float) -> tuple[FitCheck, dict[str, float]]:
    """The fit check (SPEC A4) and each output's NRMSE and residual whiteness
    (the system-identification benchmarks' figures; reported, not judged),
    from one simulation of the model."""
    if not schur_stable(est.model.den) and np.any(np.abs(est.model.poles()) >= 1.0):
        return fit_check(est.model, u, y, threshold), {}
    with np.errstate(all="ignore"):
        e = y - est.model.simulate(u)
    if not np.all(np.isfinite(e)):
        return fit_check(est.model, u, y, threshold), {}
    r2: dict[str, float] = {}
    out: dict[str, float] = {}
    free = _free_response_basis(est.model.den, e.shape[0])
    for j, name in enumerate(est.model.outputs):
        figures = residual_figures(y[:, j], e[:, j])
        # -inf: a constant output, matched exactly (1) or not
        r2[name] = figures.r2 if figures.r2 != float("-inf") else (
            1.0 if np.var(e[:, j]) == 0 else float("-inf"))
        out[f"nrmse {name}"] = figures.nrmse
        out[f"whiteness {name}"] = figures.whiteness
        out[f"initial response {name}"], out[f"initial response rms {name}"] = \
            initial_response(free, e[:, j])
    fit = 100.0 * sum(r2.values()) / len(r2)
    return FitCheck(r2, fit, float(threshold), bool(fit >= threshold)), out


#: How a linear-route refusal of a record that does not start at rest begins.
NOT_AT_REST = "not at rest"

#: Share of the simulation error an initial state must explain for the record
#: to count as not starting at rest. Coloured sensor noise puts well under 1 %
#: on the model's few decaying free responses; a record that starts away from
#: rest puts most of its error there.
_INITIAL_SHARE = 0.25


def not_at_rest(diag: Mapping[str, float], machine: Machine,
                outputs: Sequence[str] | None = None, route: str = "linear") -> str | None:
    """Why a route that starts the model at rest cannot take a record (None:
    it can): an initial state explains at least :data:`_INITIAL_SHARE` of an
    output's simulation error (``diag``'s ``initial response NAME``), and that
    part is more than twice the sensor's declared noise."""
    noise = {s.name: s.noise for s in machine.plant.sensors}
    for name in (machine.linear().outputs if outputs is None else outputs):
        share = diag.get(f"initial response {name}", 0.0)
        rms = diag.get(f"initial response rms {name}", 0.0)
        sd = noise.get(name, 0.0)
        if share >= _INITIAL_SHARE and rms > 2.0 * sd:
            size = f", {rms / sd:.3g} times the sensor's noise" if sd > 0 else ""
            return (f"{NOT_AT_REST}: the record does not start where the model rests; an "
                    f"initial state explains {100 * share:.0f} % of the simulation error of "
                    f"{name} ({rms:.3g} RMS{size}) and the {route} route starts the model "
                    "at rest: --route simulation estimates the initial state")
    return None


def _free_response_basis(den: FloatArray, n: int) -> FloatArray:
    """The model's free responses (shape (n, order)): what an initial state
    adds to its output, ``q^-k / A(q)`` impulses for k = 0 .. order − 1 (any
    output's free response is a combination of these; a common denominator)."""
    from condmon._filter import lfilter   # (not scipy's: the linear route imports no scipy)

    order = den.size - 1
    g = lfilter([1.0], den, np.r_[1.0, np.zeros(n - 1)])   # (each column shifts it)
    cols = [np.r_[np.zeros(k), g[: n - k]] for k in range(order)]
    return np.column_stack(cols) if cols else np.zeros((n, 0))


def initial_response(free: FloatArray, e: FloatArray) -> tuple[float, float]:
    """The share of the simulation error's energy an initial state explains
    (least squares on the free responses) [-], and that part's RMS [output unit]."""
    if free.shape[1] == 0 or not float(e @ e) > 0.0:
        return 0.0, 0.0
    coef, *_ = np.linalg.lstsq(free, e, rcond=None)
    part = free @ coef
    energy = float(part @ part)
    return energy / float(e @ e), math.sqrt(energy / e.size)


def linear_route(rec: Record, machine: Machine, estimator: object, *,
                 excitation: Sequence[str] = (), constants: Mapping[str, float] | None = None,
                 fit_threshold: float = 90.0, hold: Mapping[str, float] | None = None
                 ) -> LinearRouteResult:
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
    hold : mapping, optional
        Values of the unknowns the record does not identify (default: the
        declared ones). [SI]

    Returns
    -------
    LinearRouteResult
        ``identifiability`` from the estimate's information (the
        coefficients' covariance mapped to the unknowns); unknowns not
        identified are held and the others solved again.
    """
    lin = machine.linear()
    spec = machine.spec
    order = spec.order or lin.order
    u = rec[lin.input]
    y = signals(*(rec[c] for c in lin.outputs))   # (each column contiguous)
    # the excitation is stacked in the call, so the estimator can let it go once
    # it has built its instruments (a long record's memory)
    est: TFEstimate = estimator(u, y, order, dt=rec.dt,  # type: ignore[operator]
                                excitation=signals(*(rec[c] for c in excitation)) if excitation else None,
                                outputs=lin.outputs, input_name=lin.input)
    fit, diag = _fit_and_diagnostics(est, u, y, fit_threshold)
    consts = machine.constants(constants)
    nan = {k: float("nan") for k in spec.unknowns}
    nan_cov = np.full((len(spec.unknowns),) * 2, np.nan)
    moving = not_at_rest(diag, machine)
    if moving:
        return LinearRouteResult(nan, nan_cov, est, None, fit, moving, diag)
    known = np.array([consts[k] for k in machine.plant.parameter_names
                      if k not in spec.unknowns])
    try:
        cont, J_cont = tf_d2c_jacobian(est.model)
    except ModelError as err:
        # least squares over the equation error is biased by output noise, and the
        # bias can put a pole where no continuous model has one
        biased = ("; equation-error least squares (ARX) is biased by output noise: "
                  "--method sriv estimates the same model without that bias"
                  if est.method.lower() == "arx" else "")
        return LinearRouteResult(nan, nan_cov, est, None, fit,
                                 f"no physical parameters: {err}{biased}")
    if order != lin.order:
        return LinearRouteResult(nan, nan_cov, est, cont, fit,
                                 f"order {order} differs from the model's {lin.order}")
    c_hat = np.r_[cont.den[1:], cont.nums[:, 1:].ravel()][list(lin.free)]
    start = np.array([machine.nominal()[k] for k in spec.unknowns])
    # Delta method: theta = [den[1:], nums[:, 1:]] -> continuous coefficients ->
    # parameters, by the exact Jacobians of both maps
    Jt = J_cont[list(lin.free)]
    cov_c = Jt @ est.covariance @ Jt.T
    W = _whitened(cov_c, np.eye(c_hat.size))
    # more coefficients than unknowns (a parameter given a value, say): weighted
    # by the coefficients' covariance, as a re-fit around a held one is, so a
    # value given and the same value held give one answer
    # (or as many, but the map's Jacobian short of full rank at the declared
    # values: a structure that fixes a relation among the coefficients, so no
    # values reproduce estimated ones exactly and a line of values nearly does;
    # the screen below then holds what the coefficients do not determine)
    over = c_hat.size > start.size or rank_short(
        lin.jacobian(start, known) * np.where(start != 0, np.abs(start), 1.0))
    try:
        p = solve_coefficients(lin, c_hat, start, known, weight=W if over else None,
                                exact=not over)
    except ConversionError as err:
        return LinearRouteResult(nan, nan_cov, est, cont, fit,
                                 f"no physical parameters: {err}; either the record does "
                                 "not determine every unknown (a short or weakly exciting "
                                 "record: give one a value with --constants NAME=VALUE, or "
                                 "record longer), or a column's sign or unit is wrong")
    Jp = lin.jacobian(p, known)
    held = {**machine.nominal(), **dict(hold or {})}
    scales = np.array([abs(held[k]) or abs(v) or 1.0 for k, v in zip(spec.unknowns, p)])
    # the screen's relative standard errors are over the given value, unless the
    # record contradicts it (the free estimate beyond it at the held values' 1 %
    # level): then over the smaller of the two. Over the given value alone, a
    # value given high made a badly determined estimate look precise (R2a
    # 6.7 ± 4.3, given 85: 5 %, not 65 %)
    Jw = W @ Jp
    se = np.sqrt(np.maximum(np.diag(_gauss_newton_cov(Jw, scales)), 0.0))
    screen = np.array([min(abs(held[k]), abs(v))
                       if held[k] and v and (v - held[k]) ** 2 > hold_limit(1) * e ** 2
                       else sc for k, v, e, sc in zip(spec.unknowns, p, se, scales)])
    idf = assess_identifiability(W @ (Jp * screen), spec.unknowns,
                                 limits=spec.identifiability)
    if not idf.identifiable:
        return LinearRouteResult(nan, nan_cov, est, cont, fit, None, diag, identifiability=idf)
    notes: tuple[str, ...] = ()
    if not idf.complete:  # the identifiable ones again, the others held
        keep = [spec.unknowns.index(k) for k in idf.identifiable]
        fixed = np.array([held[k] for k in spec.unknowns])
        sub = _Subset(lin, keep, fixed)
        try:
            p_sub = solve_coefficients(sub, c_hat, start[keep], known,  # type: ignore[arg-type]
                                       weight=W)
        except ConversionError as err:
            return LinearRouteResult(nan, nan_cov, est, cont, fit,
                                     f"no physical parameters: {err}", diag, identifiability=idf)
        p_held = fixed.copy()
        p_held[keep] = p_sub
        contradicted = _contradicted(lin, known, W, c_hat, p, p_held, spec.unknowns,
                                     [k for k in spec.unknowns if k not in idf.identifiable])
        if contradicted is None:
            p = p_held
            Jf = lin.jacobian(p, known)
            Jw = W @ Jf[:, keep]
            cov = np.zeros((len(spec.unknowns),) * 2)
            cov[np.ix_(keep, keep)] = _gauss_newton_cov(Jw, scales[keep])
            # how the others lean on the held values, where they are held (the full
            # solution the screening ran at may lie far off, and its lean with it)
            idf = dataclasses.replace(idf, dependence=dependence_at(W @ (Jf * scales), idf))
            carried = held_covariance(W @ (Jf * scales), scales, keep, spec.unknowns)
            if carried is not None:
                cov[np.ix_(keep, keep)], own = carried
                idf = dataclasses.replace(idf, held_uncertainty=own)
                notes = ("the standard errors carry the held "
                         f"{'values’' if len(own) > 1 else 'value’s'} own uncertainty in the "
                         "record ("
                         + ", ".join(f"{k} ±{100 * v:.3g} %" if v <= 0.5 else
                                     f"{k} only to a factor of {1 + v:.3g}"
                                     for k, v in own.items())
                         + ", one standard error): the estimates lean on "
                         f"{'it' if len(own) == 1 else 'them'}, and the record knows "
                         f"{'it' if len(own) == 1 else 'them'} no better",)
        else:
            # the record contradicts the held value: every unknown estimated, the
            # collinearity in their standard errors
            weak = [k for k in spec.unknowns if k not in idf.identifiable]
            said = (f"{', '.join(weak)}: {'; '.join(idf.reasons[k] for k in weak)}; but held "
                    f"at {', '.join(f'{held[k]:.4g}' for k in weak)} the estimated "
                    f"coefficients would not be reproduced ({contradicted}): the record "
                    "determines it, and the standard errors carry the collinearity")
            idf = dataclasses.replace(idf, identifiable=tuple(spec.unknowns),
                                      reasons={k: v for k, v in idf.reasons.items()
                                               if k not in weak})
            Jw, G = W @ Jp, _scaled_pinv(Jp, scales)
            cov = _gauss_newton_cov(Jw, scales) if over else \
                G @ cov_c @ G.T
            return LinearRouteResult(dict(zip(spec.unknowns, map(float, p))), cov, est, cont,
                                     fit, None, diag, identifiability=idf, notes=(said,))
    elif over:
        Jw = W @ Jp
        cov = _gauss_newton_cov(Jw, scales)
    else:
        G = _scaled_pinv(Jp, scales)
        cov = G @ cov_c @ G.T
    return LinearRouteResult(dict(zip(spec.unknowns, map(float, p))), cov, est, cont, fit, None,
                             diag, identifiability=idf, notes=notes)


@dataclass(frozen=True)
class _Subset:
    """The coefficient map over some unknowns, the others fixed (the linear
    route's re-solve when a record does not identify every unknown)."""

    lin: LinearStructure
    keep: list[int]
    fixed: FloatArray

    def _full(self, p: FloatArray) -> FloatArray:
        full = self.fixed.copy()
        full[self.keep] = p
        return full

    def values(self, p: FloatArray, known: FloatArray) -> FloatArray:
        return self.lin.values(self._full(p), known)

    def jacobian(self, p: FloatArray, known: FloatArray) -> FloatArray:
        return self.lin.jacobian(self._full(p), known)[:, self.keep]


def _contradicted(lin: LinearStructure, known: FloatArray, W: FloatArray, c_hat: FloatArray,
                  p_free: FloatArray, p_held: FloatArray, names: Sequence[str],
                  weak: Sequence[str]) -> str | None:
    """Why the held values contradict the record (None: they do not). The
    coefficients' whitened misfit ``χ²`` with the ``weak`` unknowns held
    against free: their difference is the likelihood ratio, ``χ²`` with as
    many degrees of freedom as unknowns held when the held values are right. A collinear unknown the record still fixes (a shaft's
    stiffness beside two inertias) is held only where the data allow it."""
    with np.errstate(all="ignore"):
        r_held = W @ (lin.values(p_held, known) - c_hat)
        r_free = W @ (lin.values(p_free, known) - c_hat)
    if not (np.all(np.isfinite(r_held)) and np.all(np.isfinite(r_free))):
        return None
    lr = float(r_held @ r_held) - float(r_free @ r_free)
    limit = hold_limit(len(weak))
    if lr <= limit:
        return None
    return (f"likelihood ratio {lr:.3g} > {limit:.3g}, {100 * HOLD_LEVEL:g} %; free, "
            + ", ".join(f"{k} = {p_free[list(names).index(k)]:.4g}" for k in weak))


def _scaled_pinv(J: FloatArray, scales: FloatArray) -> FloatArray:
    """``J⁺`` taken over columns scaled to the unknowns' sizes: unscaled, a
    resistance in ohms beside a capacitance in farads puts 10⁸ between the
    columns, and the pseudo-inverse's cut-off drops the small one (R2 came out
    ± 7e-17 ohm)."""
    return np.asarray(np.linalg.pinv(J * scales) * scales[:, None], dtype=np.float64)


def _gauss_newton_cov(Jw: FloatArray, scales: FloatArray) -> FloatArray:
    """``(JwᵀJw)⁺`` of whitened sensitivities ``Jw``, over columns scaled as in
    :func:`_scaled_pinv`."""
    S = Jw * scales
    return np.asarray(np.linalg.pinv(S.T @ S) * np.outer(scales, scales), dtype=np.float64)


def _whitened(cov: FloatArray, J: FloatArray) -> FloatArray:
    """``W J`` with ``WᵀW`` the (pseudo-)inverse of ``cov``: the sensitivities of
    the coefficients, each direction divided by its standard deviation."""
    lam, U = np.linalg.eigh((cov + cov.T) / 2.0)
    good = lam > 1e-12 * max(float(lam.max()), 1e-300)
    W = (U[:, good] / np.sqrt(lam[good])).T
    return np.asarray(W @ J, dtype=np.float64)


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
    identifiability : Identifiability or None
        Which unknowns the record identified (None: the route estimates all
        of them without assessing it); the others hold their given values.
    """

    values: dict[str, float]
    covariance: FloatArray
    fit: FitCheck
    nrmse: dict[str, float]
    whiteness: dict[str, float]
    identifiability: Identifiability | None = field(default=None, kw_only=True)

    def diagnostics(self) -> dict[str, float]:
        """``nrmse <name>`` and ``whiteness <name>`` figures, as in the JSON."""
        return {**{f"nrmse {k}": v for k, v in self.nrmse.items()},
                **{f"whiteness {k}": v for k, v in self.whiteness.items()}}
