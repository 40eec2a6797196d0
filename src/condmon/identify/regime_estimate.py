"""One operating regime's estimate: a record's windows, the route, identifiability, holding.

:func:`condmon.identify.estimate.estimate_record` cuts each record into
windows (:func:`plan`), then estimates each regime of the usable windows here
(:func:`estimate_regime`): the route on that regime's windows, the unknowns it
identifies, the others held at the unit's baseline value or the declared one,
the reported quantities, which of them are trended, and the plausibility.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from condmon.errors import CondmonError, EstimationError, ModelError
from condmon.identify._common import TFEstimate
from condmon.identify.defaults import ESTIMATORS
from condmon.identify.greybox import linear_route, not_at_rest
from condmon.identify.identifiability import Identifiability
from condmon.identify.ls import arx, iv
from condmon.identify.oe import oe
from condmon.identify.result import EstimateResult
from condmon.identify.sriv import sriv
from condmon.identify.windows import Window, cut_windows
from condmon.io.records import Record
from condmon.models.machine import Machine
from condmon.models.regimes import regime_key

__all__ = ["Plan", "plan", "estimate_regime", "unusable", "has_balances", "ESTIMATOR_FUNCTIONS"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: How a rejection for a residual the model cannot follow begins.
STRUCTURE_MISMATCH = "structure mismatch"


class Estimator(Protocol):
    """A discrete estimator's signature (see :func:`condmon.identify.sriv`)."""

    def __call__(self, u: ArrayLike, y: ArrayLike, order: int, *, dt: float = ...,
                 excitation: ArrayLike | None = ..., outputs: tuple[str, ...] | None = ...,
                 input_name: str = ...) -> TFEstimate: ...


ESTIMATOR_FUNCTIONS: dict[str, Estimator] = {"sriv": sriv, "oe": oe, "iv": iv, "arx": arx}
assert tuple(ESTIMATOR_FUNCTIONS) == ESTIMATORS, "condmon.identify.defaults names every estimator"


def has_balances(machine: Machine) -> bool:
    """Whether the steady route can use the balances of measured signals (an
    inverse structure), else it solves the model's whole steady state."""
    try:
        machine.inverse()
    except ModelError:
        return False
    return True


def _oe_start(rec: Sequence[Record], machine: Machine, consts: Mapping[str, float],
              fit_threshold: float) -> tuple[dict[str, float], str]:
    """Starting values of the output-error route: the inverse-model estimate when
    that route fits the model and gives positive-definite answers, else the
    declared values."""
    from condmon.identify.inverse_route import inverse_route

    try:
        inv = inverse_route(rec, machine, constants=consts, fit_threshold=fit_threshold)
    except CondmonError:
        return machine.nominal(), "the declared values"
    if inv.identifiability is not None and not inv.identifiability.complete:
        return machine.nominal(), "the declared values"
    if machine.spec.plausibility.check_values(inv.values, machine.units) is None:
        return inv.values, "the inverse-model estimate"
    return machine.nominal(), "the declared values"


def _has_inverse(machine: Machine) -> bool:
    try:
        machine.inverse()
    except ModelError:
        return False
    return True


@dataclass(frozen=True)
class Plan:
    """One record's route signals (inverse and steady routes) and windows.

    Attributes
    ----------
    record : Record
    signals : dict of str to ndarray
        :func:`~condmon.identify.inverse_route.route_signals` (empty for the
        linear and output-error routes).
    windows : tuple of Window
    pooled : str
        The label under which the windows of every regime are estimated
        together ("" when each regime is estimated on its own).
    """

    record: Record
    signals: dict[str, FloatArray]
    windows: tuple[Window, ...]
    pooled: str = ""

    def takes(self, w: Window, regime: str) -> bool:
        """Whether an estimate of ``regime`` uses window ``w`` (every used one
        when the regimes are pooled under the label ``regime``)."""
        return w.used and (w.regime == regime or (bool(self.pooled) and regime == self.pooled))

    def rows(self, regime: str) -> list[IntArray]:
        """Rows of each window an estimate of ``regime`` uses."""
        return [np.arange(w.first, w.stop) for w in self.windows if self.takes(w, regime)]


def plan(rec: Record, machine: Machine, route: str, metadata: Mapping[str, Any] | None,
         window: tuple[float, float] | None) -> Plan:
    """A record's windows, cut on its columns and the route's derived signals."""
    sig: dict[str, FloatArray] = {}
    edge = 0
    if route == "inverse" or (route == "steady" and has_balances(machine)):
        from condmon.identify.inverse_route import filter_edge, route_cutoff, route_signals

        cutoff = route_cutoff(machine, 1.0 / rec.dt, rec.source)
        sig = route_signals(rec, machine, cutoff)
        edge = filter_edge(1.0 / rec.dt, cutoff)
    named = {**rec.columns, **sig}
    windows = cut_windows(rec["t"], named, machine.regimes, metadata, source=rec.source,
                          span=window, edge=edge)
    return Plan(rec, sig, windows)


def _slice(plan: Plan, regime: str, sliced: bool) -> Record:
    """The record, or its longest used window of ``regime`` (a route that needs
    contiguous samples: linear, output error)."""
    if not sliced:
        return plan.record
    longest = max((w for w in plan.windows if plan.takes(w, regime)),
                  key=lambda w: w.stop - w.first)
    return plan.record.slice(longest.first, longest.stop)


def unusable(plans: Sequence[Plan]) -> str:
    """Why no window of the record(s) can be used, in one clause."""
    parts = []
    for p in plans:
        for w in p.windows:
            parts.append(f"{w.regime or 'record'} {w.start:.3g}-{w.end:.3g} s: {w.why}")
    shown = "; ".join(parts[:4]) + (f"; and {len(parts) - 4} more" if len(parts) > 4 else "")
    return f"not identifiable: no window of the record can be used ({shown})"


def _held_values(machine: Machine, regime: str, hold: Mapping[str, float] | None
                 ) -> tuple[dict[str, float], dict[str, str]]:
    """Values the unknowns are held at when not identified, and where each comes
    from: the unit's baseline (``NAME@REGIME``, else ``NAME``) or the declaration."""
    values, origin = {}, {}
    for name, nominal in machine.nominal().items():
        key = regime_key(name, regime)
        if hold and key in hold and math.isfinite(hold[key]):
            values[name], origin[name] = float(hold[key]), "baseline"
        elif hold and name in hold and math.isfinite(hold[name]):
            values[name], origin[name] = float(hold[name]), "baseline"
        else:
            values[name], origin[name] = float(nominal), "nominal"
    return values, origin


def estimate_regime(plans: Sequence[Plan], regime: str, machine: Machine, chosen: str, *,
                     method: str, excitation: Sequence[str], fit_threshold: float,
                     consts: dict[str, float], hold: Mapping[str, float] | None,
                     fixed: dict[str, float], notes: list[str], sliced: bool,
                     common: dict[str, Any]) -> EstimateResult:
    """The estimate of one regime's windows (see
    :func:`~condmon.identify.estimate.estimate_record`)."""
    spec = machine.spec
    records = [p.record for p in plans]
    source = common["source"]
    notes = list(notes)
    held_at, origin = _held_values(machine, regime, hold)
    diagnostics: dict[str, float] = {}
    discrete = None
    cont = None
    rejection = None
    idf: Identifiability | None = None
    unsteady: dict[tuple[int, int], str] = {}
    initial_states: dict[str, tuple[float, float, str]] = {}
    smoothing: float | None = None
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            if chosen == "linear":
                lin = linear_route(_slice(plans[0], regime, sliced), machine,
                                   ESTIMATOR_FUNCTIONS[method], excitation=excitation, constants=consts,
                                   fit_threshold=fit_threshold, hold=held_at)
                values, ucov, fit = lin.values, lin.covariance, lin.fit
                discrete, cont, rejection = lin.discrete, lin.continuous, lin.rejection
                diagnostics = dict(lin.diagnostics)
                notes += [*lin.discrete.notes, *lin.notes]
                idf = lin.identifiability
            elif chosen == "oe":
                from condmon.identify.oe_route import oe_route  # sympy, scipy: only this route

                recs = [_slice(p, regime, sliced) for p in plans]
                start, how = _oe_start(recs, machine, consts, fit_threshold)
                oe_res = oe_route(recs, machine, start, constants=consts,
                                  fit_threshold=fit_threshold)
                values, ucov, fit = oe_res.values, oe_res.covariance, oe_res.fit
                diagnostics = oe_res.diagnostics()
                notes.append(f"output error: the declared model simulated with its "
                             f"linear part exact (ZOH), started from {how}, "
                             f"{oe_res.evaluations} optimiser evaluations")
                if oe_res.widening > 1.1:
                    notes.append(_widening_note(oe_res.bandwidth, oe_res.widening,
                                                "residuals"))
                rejection = not_at_rest(diagnostics, machine,
                                        [s.name for s in machine.plant.sensors], "output-error")
            elif chosen == "simulation":
                from condmon.identify.simulation_route import simulation_route

                recs = [_slice(p, regime, sliced) for p in plans]
                start, how = {k: held_at[k] for k in spec.unknowns}, "the declared values"
                if _has_inverse(machine):   # a nearby start for the simulation error
                    start, how = _oe_start(recs, machine, consts, fit_threshold)
                sim = simulation_route(recs, machine, start, constants=consts,
                                       fit_threshold=fit_threshold)
                notes.append(f"simulation error started from {how}")
                values, ucov, fit, idf = sim.values, sim.covariance, sim.fit, sim.identifiability
                diagnostics = sim.diagnostics()
                initial_states = sim.initial
                smoothing = sim.smoothing if sim.smoothing != machine.plant.smoothing else None
                notes += sim.notes
            elif chosen == "steady":
                from condmon.identify.steady_route import steady_output_error, steady_route

                windows = [p.rows(regime) for p in plans]
                st = (steady_route([p.signals for p in plans], windows, machine,
                                   constants=consts, hold=held_at, fit_threshold=fit_threshold,
                                   source=source)
                      if has_balances(machine) else
                      steady_output_error(records, windows, machine, constants=consts,
                                          hold=held_at, fit_threshold=fit_threshold,
                                          source=source))
                values, ucov, fit, idf = st.values, st.covariance, st.fit, st.identifiability
                diagnostics = st.diagnostics()
                unsteady = st.unsteady
                if st.windows == 0:
                    rejection = ("not identifiable: no steady window ("
                                 + "; ".join(sorted(set(unsteady.values()))) + ")")
                else:
                    notes.append(f"steady balances over {st.windows} window(s), {st.samples} "
                                 f"samples{f' in regime {regime!r}' if regime else ''}")
            else:
                from condmon.identify.inverse_route import fastest_mode, inverse_route

                rows = [np.concatenate(p.rows(regime)) if p.rows(regime) else
                        np.zeros(0, dtype=np.intp) for p in plans]
                inv = inverse_route(records, machine, constants=consts,
                                    fit_threshold=fit_threshold, rows=rows,
                                    signals=[p.signals for p in plans], hold=held_at)
                values, ucov, fit, idf = inv.values, inv.covariance, inv.fit, inv.identifiability
                diagnostics = inv.diagnostics()
                notes.append(f"inverse model (IDIM-LS): zero-phase low-pass at {inv.cutoff:g} Hz, "
                             f"central differences, {inv.samples} samples")
                if inv.widening > 1.1:
                    notes.append(_widening_note(inv.bandwidth, inv.widening,
                                                "filtered residuals"))
                fast = fastest_mode(machine, values, consts, plans[0].signals)
                worst = max(inv.whiteness, key=lambda k: inv.whiteness[k])
                limit = spec.max_residual_correlation
                if fast > inv.cutoff:
                    rejection = (f"the estimated model's fastest mode, {fast:.3g} Hz (time "
                                 f"constant {1e3 / (2 * math.pi * fast):.3g} ms), lies above "
                                 f"the route's low-pass cut-off {inv.cutoff:g} Hz: the filtered "
                                 "derivatives cannot show it; --route oe or --route simulation "
                                 "simulate it")
                elif inv.whiteness[worst] > limit:
                    rejection = (f"{STRUCTURE_MISMATCH}: the residual of {worst} is strongly "
                                 f"correlated ({inv.whiteness[worst]:.2f} > {limit:g}); the "
                                 "model misses part of the dynamics (friction, offset, "
                                 "another mode?)")
    except CondmonError as err:
        # Estimators do not know the file: name it (same error class), once.
        text = str(err)
        raise type(err)(text if text.startswith(source) else f"{source}: {text}") from None
    except (ArithmeticError, np.linalg.LinAlgError, ValueError) as err:
        # The estimators guard every step; this is the last line, never a traceback.
        raise EstimationError(f"{source}: the estimate failed numerically "
                              f"({type(err).__name__}: {err})") from None
    white = {k.split(" ", 1)[1]: v for k, v in diagnostics.items() if k.startswith("whiteness ")}
    if chosen in ("linear", "oe") and white and max(white.values()) > spec.residual_warning:
        worst = max(white, key=lambda k: white[k])
        notes.append(f"possible structure mismatch: the residual of {worst} is correlated "
                     f"({white[worst]:.2f} > {spec.residual_warning:g}); the model may miss "
                     "part of the dynamics" + (f" ({spec.structure_hint})"
                                               if spec.structure_hint else "")
                     + ", or the sensor's noise is coloured (filtered, drifting): the "
                       "standard errors hold either way")
    names = spec.report
    identified = set(idf.identifiable) if idf is not None else set(spec.unknowns)
    if idf is not None and not idf.identifiable and rejection is None:
        rejection = "not identifiable: " + "; ".join(f"{k}: {v}" for k, v in idf.reasons.items())
    if rejection is None or rejection.startswith((STRUCTURE_MISMATCH, "not identifiable")):
        params, G = machine.report_jacobian({**consts, **values})
        pcov = G @ ucov @ G.T
        vals = np.array([params[k] for k in names])
        trended = tuple(k for k, g in zip(names, G.tolist())   # (plain floats: a few each)
                        if any(g) and all(spec.unknowns[j] in identified
                                          for j, x in enumerate(g) if x != 0))
    else:
        vals = np.full(len(names), np.nan)
        pcov = np.full((len(names), len(names)), np.nan)
        trended = ()
    if idf is not None and not idf.identifiable:
        trended = ()
    se = np.sqrt(np.clip(np.diag(pcov), 0.0, None))
    held = {k: ("given" if k in fixed else origin.get(k, "nominal"))
            for k in names if k not in trended} if rejection is None else {}
    if rejection is None:
        judged = {k: v for k, v in zip(names, vals) if k in trended}
        rejection = spec.plausibility.check_values(judged, machine.units,
                                                   {k: v for k, v in zip(names, se)
                                                    if k in trended})
    if rejection is None and fit.accepted:   # a fit below its threshold says so first
        rejection = spec.plausibility.check_precision(
            {k: v for k, v in zip(names, vals) if k in trended}, machine.units,
            {k: v for k, v in zip(names, se) if k in trended})
    if rejection is None and not np.all(np.isfinite(se)):
        rejection = "the standard errors are not finite: the data do not determine the model"
    if rejection is None:
        notes += spec.plausibility.bound_notes(
            {k: v for k, v in zip(names, vals) if k in trended}, machine.units,
            {k: v for k, v in zip(names, se) if k in trended})
    if held and idf is not None and idf.held:
        notes.append("held (not identified by this record): " + ", ".join(
            f"{k} at its {origin.get(k, 'nominal')} value" for k in idf.held)
            + _leaning(idf, values, ucov, list(spec.unknowns)))
    listed: list[Window] = []
    for i, p in enumerate(plans):
        used_j = 0
        for w in p.windows:
            if p.takes(w, regime):
                why = unsteady.get((i, used_j))
                used_j += 1
                if why is not None:
                    w = dataclasses.replace(w, used=False, why=why)
            elif w.used:
                w = dataclasses.replace(w, used=False, why=f"estimated separately (regime "
                                                           f"{w.regime!r})")
            listed.append(w)
    return EstimateResult(
        parameters={k: float(v) for k, v in zip(names, vals)},
        std_errors={k: float(v) for k, v in zip(names, se)},
        covariance=pcov, fit=fit, discrete=discrete, continuous=cont, rejection=rejection,
        notes=tuple(notes), diagnostics=diagnostics, regime=regime, windows=tuple(listed),
        identifiability=idf, held=held, trended=trended, initial_states=initial_states,
        smoothing=smoothing, **common)


def _leaning(idf: Identifiability, values: Mapping[str, float], ucov: FloatArray,
             unknowns: list[str]) -> str:
    """The clause saying which estimates move, beyond their own standard error,
    when a held value is 10 % off ('' when none does): they hold only at it."""
    parts = []
    for h in idf.held:
        if h in idf.held_uncertainty:   # its uncertainty is in the standard errors
            continue
        moved = []
        for k, lean in idf.dependence.items():
            if h not in lean or k not in values or k not in unknowns:
                continue
            i = unknowns.index(k)
            rel = (math.sqrt(max(float(ucov[i, i]), 0.0)) / abs(values[k])
                   if values[k] else math.inf)
            if abs(0.1 * lean[h]) > rel:
                moved.append(f"{k} by {10 * lean[h]:+.2g} % (its standard error "
                             f"{100 * rel:.2g} %)")
        if moved:
            parts.append(f"10 % more {h} moves " + ", ".join(moved))
    if not parts:
        return ""
    return ("; the estimates hold only at the held value" + ("s" if len(parts) > 1 else "")
            + ": " + "; ".join(parts))


def _widening_note(bandwidth: float, widening: float, what: str) -> str:
    """The note of standard errors widened for correlated residuals."""
    return ("standard errors: the larger of the white-noise bound and the Newey-West "
            f"estimate (bandwidth {bandwidth:.0f} samples); the {what} are correlated and "
            f"widen them up to {widening:.1f} times")
