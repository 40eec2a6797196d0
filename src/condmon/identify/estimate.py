"""From one test record to physical parameters: the estimation pipeline (SPEC A3-A5).

record -> validate -> the machine's declaration -> route: linear (discrete
estimate, SRIV by default with closed-loop instruments when the excitation is
recorded -> fit check -> ZOH inverse -> parameters from the symbolic
coefficient map) or inverse model (filtered, differentiated signals -> least
squares) -> physical parameters with standard errors -> plausibility.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from condmon.errors import CondmonError, EstimationError, ModelError
from condmon.identify._common import TFEstimate
from condmon.identify.defaults import ESTIMATORS, list_estimators
from condmon.identify.fit import DEFAULT_FIT_THRESHOLD, FitCheck
from condmon.identify.greybox import choose_route, linear_route
from condmon.identify.identifiability import Identifiability
from condmon.identify.ls import arx, iv
from condmon.identify.oe import oe
from condmon.identify.result import EstimateResult
from condmon.identify.sriv import sriv
from condmon.identify.windows import Window, cut_windows
from condmon.io.records import Record, validate_record
from condmon.io.rig import RecordSettings, apply_record_settings
from condmon.models.machine import Machine
from condmon.models.regimes import regime_key
from condmon.models.registry import get_model

__all__ = ["EstimateResult", "estimate", "estimate_record", "estimate_joint", "list_estimators",
           "DEFAULT_EXCITATION"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Excitation columns used when present and not told otherwise.
DEFAULT_EXCITATION = ("yd", "ud")


class Estimator(Protocol):
    def __call__(self, u: ArrayLike, y: ArrayLike, order: int, *, dt: float = ...,
                 excitation: ArrayLike | None = ..., outputs: tuple[str, ...] | None = ...,
                 input_name: str = ...) -> TFEstimate: ...


_ESTIMATORS: dict[str, Estimator] = {"sriv": sriv, "oe": oe, "iv": iv, "arx": arx}
assert tuple(_ESTIMATORS) == ESTIMATORS, "condmon.identify.defaults names every estimator"


def _excitation_columns(record: pd.DataFrame | Record, machine: Machine,
                        excitation: Sequence[str] | str | None) -> tuple[str, ...]:
    cols = record.columns if isinstance(record, Record) else list(record.columns)
    if excitation == "auto":
        names = machine.spec.excitation or DEFAULT_EXCITATION
        found = [c for c in names if c in cols]
        if isinstance(record, Record):
            return tuple(found)
        # a recorded but constant excitation (a perturbation switched off) is left out
        return tuple(c for c in found
                     if pd.to_numeric(record[c], errors="coerce").nunique(dropna=True) > 1)
    if excitation is None or isinstance(excitation, str):
        return ()
    return tuple(excitation)


def _required_columns(machine: Machine, route: str) -> tuple[str, ...]:
    """Record columns a route needs (inputs, then sensors)."""
    if route == "oe":
        from condmon.models.semilinear import semilinear_structure  # sympy: only for this route

        s = semilinear_structure(machine)
        return (*s.inputs, *s.sensors)
    if route == "linear":
        lin = machine.linear()
        return (lin.input, *lin.outputs)
    if route == "steady" and not _has_balances(machine):
        return machine.plant.sensor_names
    return machine.inverse().columns


def _has_balances(machine: Machine) -> bool:
    """Whether the steady route can use the balances of measured signals (an
    inverse structure), else it solves the model's whole steady state."""
    try:
        machine.inverse()
    except ModelError:
        return False
    return True


def _split_constants(machine: Machine, constants: Mapping[str, Any]
                     ) -> tuple[dict[str, Any], dict[str, float]]:
    """``(constants, fixed unknowns)``: a user's ``constants`` naming an unknown fix it
    for the run; any other name must be a known constant of the model.

    Raises
    ------
    ModelError
        A name that is neither (the allowed ones listed), a value that is not
        a finite number.
    """
    fixed: dict[str, float] = {}
    rest: dict[str, Any] = {}
    for k, v in constants.items():
        if k in machine.spec.unknowns:
            try:
                val = float(v)
            except (TypeError, ValueError):
                raise ModelError(f"--constants {k}: {v!r} is not a number") from None
            if not math.isfinite(val):
                raise ModelError(f"--constants {k}: must be finite, got {val!r}")
            fixed[k] = val
        else:
            rest[k] = v
    known = machine.constants()
    bad = [k for k in rest if k not in known]
    if bad:
        raise ModelError(f"unknown constant {bad[0]!r} for model {machine.name!r}: not a "
                         f"parameter; known constants: {', '.join(known) or 'none'}; "
                         f"unknowns that may be fixed: {', '.join(machine.spec.unknowns)}")
    return rest, fixed


def _record_frame(record: pd.DataFrame, machine: Machine, columns: Mapping[str, str] | None,
                  settings: RecordSettings | None, source: str | None) -> pd.DataFrame:
    """The record in model columns: the machine's ``[record]`` settings, then
    ``settings``, then ``columns`` (unless the frame says they were applied)."""
    if record.attrs.get("record_settings") is not None:
        return record.rename(columns={v: k for k, v in columns.items()}) if columns else record
    merged = machine.record.merged(settings).merged(RecordSettings(dict(columns or {})))
    return apply_record_settings(record, merged, source)


def estimate(record: pd.DataFrame, model: str | Machine = "dc-motor", *,
             method: str = "sriv", gamma: float | None = None,
             excitation: Sequence[str] | str | None = "auto",
             fit_threshold: float = DEFAULT_FIT_THRESHOLD,
             columns: Mapping[str, str] | None = None,
             source: str | None = None, route: str | None = None,
             constants: Mapping[str, float] | None = None,
             settings: RecordSettings | None = None,
             metadata: Mapping[str, Any] | None = None,
             window: tuple[float, float] | None = None,
             hold: Mapping[str, float] | None = None) -> EstimateResult:
    """Estimate the physical parameters of a machine from one test record.

    Parameters
    ----------
    record : pandas.DataFrame
        Columns ``t`` [s] and the model's input and sensors (DC motor: ``V`` [V],
        ``I`` [A], ``omega`` [rad/s]); optionally the excitation signals; or
        the rig's own columns, read with the machine's ``[record]`` settings
        and ``settings``. Constants in ``record.attrs["constants"]`` (e.g.
        scalars of a .mat file) override the declared ones.
    model : str, path or Machine
        A declared machine: a name from :func:`condmon.models.list_models`
        or a declaration file (.toml).
    method : {"sriv", "oe", "iv", "arx"}
        Discrete estimator of the linear route: SRIV (falls back to
        output-error refinement when its iterations fail), output error
        (maximum likelihood, started from SRIV), basic IV, least squares.
    gamma : float, optional
        Ke/Kt of a DC motor (shorthand for ``constants={"gamma": ...}``). [-]
    excitation : "auto", sequence of str or None
        Excitation columns for closed-loop instruments. "auto" uses the
        declared ones (``yd``, ``ud``) when present; None (or an empty list)
        forces the direct approach.
    fit_threshold : float
        Reject below this percentage fit. [%]
    columns : mapping, optional
        ``{canonical: column}`` renames applied first.
    source : str, optional
        Name of the record in messages and results.
    route : {"auto", "linear", "inverse", "oe", "steady"}, optional
        Override the declaration's route.
    constants : mapping, optional
        Known constants overriding the declared ones; naming an unknown fixes
        it for this estimate (reported as held, not estimated). [SI]
    settings : RecordSettings, optional
        How the rig writes the record (over the declaration's ``[record]``).
    metadata : mapping, optional
        The record's metadata fields (``load = "ball"``) the regimes may name.
    window : (float, float), optional
        Only this span of the record ``[start, end]``. [s]
    hold : mapping, optional
        Values for the unknowns the record does not identify: a unit's
        baseline (``{"Tc@forward": 41.0, "J": 0.5}``); default the declared. [SI]

    Returns
    -------
    EstimateResult
        For a record with windows in several regimes, the estimate of the
        regime with the longest windows, the others in ``others``.

    Example
    -------
    >>> from condmon.simulate import simulate_actuator
    >>> res = estimate(simulate_actuator(seed=1))
    >>> res.accepted, res.method, res.closed_loop_instruments, res.route
    (True, 'sriv', True, 'linear')
    """
    machine = model if isinstance(model, Machine) else get_model(model)
    machine.require_estimation()
    if method not in _ESTIMATORS:
        raise ModelError(f"unknown method {method!r}; allowed: {', '.join(_ESTIMATORS)}")
    given, fixed = _split_constants(machine, dict(constants or {}))
    machine = machine.with_fixed(fixed)
    chosen = choose_route(machine, route)
    df = _record_frame(record, machine, columns, settings, source)
    exc = _excitation_columns(df, machine, excitation) if chosen == "linear" else ()
    n_unknowns = len(machine.spec.unknowns)
    rec = validate_record(df, (*_required_columns(machine, chosen), *exc),
                          input_name=machine.linear().input if chosen == "linear" else None,
                          min_samples=10 * (n_unknowns + 1), source=source,
                          optional=_condition_columns(machine))
    consts = dict(df.attrs.get("constants", {}) or {})
    _check_constants(machine, given, strict=tuple(given))
    consts.update(given)
    consts.update(fixed)
    if gamma is not None:
        consts["gamma"] = gamma
    notes = tuple(f"{k} fixed at {v:.6g} {machine.plant.parameter(k).unit} for this estimate "
                  "(--constants): not estimated".replace("  ", " ") for k, v in fixed.items())
    if df.attrs.get("record_settings"):
        notes += (f"record read with its settings: {df.attrs['record_settings']}",)
    return estimate_record(rec, machine, method=method, excitation=exc,
                           fit_threshold=fit_threshold, route=chosen, constants=consts,
                           metadata=metadata, window=window, hold=hold, fixed=fixed,
                           notes=notes)


def _condition_columns(machine: Machine) -> tuple[str, ...]:
    """Record columns the regimes' conditions may name (kept when present)."""
    return tuple(sorted({n for r in machine.regimes.regimes for n in r.condition.names}))


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


def estimate_joint(records: Sequence[pd.DataFrame], model: str | Machine = "dc-motor", *,
                   fit_threshold: float = DEFAULT_FIT_THRESHOLD,
                   columns: Mapping[str, str] | None = None,
                   sources: Sequence[str] | None = None, route: str | None = None,
                   constants: Mapping[str, float] | None = None,
                   settings: RecordSettings | None = None,
                   metadata: Mapping[str, Any] | None = None,
                   hold: Mapping[str, float] | None = None) -> EstimateResult:
    """Estimate one set of physical parameters from several records at once.

    The records (one sample interval) enter one criterion: the output error
    summed over all of them (each simulated from rest), one stacked
    inverse-model regression, or the balances of every steady window, the
    windows of every regime together (strokes in both directions tell a
    Coulomb friction from a load torque). A linear model takes the
    output-error route.

    Parameters
    ----------
    records : sequence of pandas.DataFrame
        As for :func:`estimate`.
    model, fit_threshold, columns, route, constants, settings, metadata, hold
        As for :func:`estimate`.
    sources : sequence of str, optional
        Names of the records in messages and results.

    Returns
    -------
    EstimateResult
        ``source`` joins the records' names with " + ".

    Example
    -------
    >>> from condmon.simulate import simulate_actuator
    >>> res = estimate_joint([simulate_actuator(seed=1), simulate_actuator(seed=2)])
    >>> res.route, res.accepted, res.source
    ('oe', True, 'record 1 + record 2')
    """
    machine = model if isinstance(model, Machine) else get_model(model)
    machine.require_estimation()
    given, fixed = _split_constants(machine, dict(constants or {}))
    machine = machine.with_fixed(fixed)
    chosen = choose_route(machine, route)
    if chosen == "linear":
        chosen = choose_route(machine, "oe")
    names = list(sources) if sources is not None else [
        str(df.attrs.get("source", f"record {i + 1}")) for i, df in enumerate(records)]
    consts: dict[str, float] = {}
    recs = []
    for df, name in zip(records, names):
        frame = _record_frame(df, machine, columns, settings, name)
        consts.update(dict(frame.attrs.get("constants", {}) or {}))
        recs.append(validate_record(frame, _required_columns(machine, chosen),
                                    min_samples=10 * (len(machine.spec.unknowns) + 1),
                                    source=name, optional=_condition_columns(machine)))
    consts.update(given)
    consts.update(fixed)
    return estimate_record(recs, machine, fit_threshold=fit_threshold, route=chosen,
                           constants=consts, metadata=metadata, hold=hold, fixed=fixed,
                           pool=True)


def _check_constants(machine: Machine, constants: Mapping[str, float],
                     strict: Sequence[str] = ()) -> dict[str, float]:
    """Validated constants; names in ``strict`` (given by the user) must be known
    constants of the model, others (a .mat file's scalars) are skipped."""
    known = machine.constants()
    out = {}
    for k, v in constants.items():
        if k not in known:
            if k in strict:
                raise ModelError(f"unknown constant {k!r} for model {machine.name!r}; "
                                 f"known constants: {', '.join(known) or 'none'}")
            continue  # constants of a file that this model does not use
        try:
            val = float(v)
        except (TypeError, ValueError):
            raise ModelError(f"constant {k} must be a number, got {v!r}") from None
        if k == "gamma" and not (math.isfinite(val) and val > 0):
            raise ModelError(f"gamma (Ke/Kt) must be a positive number, got {val!r}")
        if not math.isfinite(val):
            raise ModelError(f"constant {k} must be finite, got {val!r}")
        out[k] = val
    return out


@dataclass(frozen=True)
class _Plan:
    """One record's route signals (inverse and steady routes) and windows."""

    record: Record
    signals: dict[str, FloatArray]
    windows: tuple[Window, ...]

    def rows(self, regime: str) -> list[IntArray]:
        """Rows of each used window of ``regime``."""
        return [np.arange(w.first, w.stop) for w in self.windows
                if w.used and w.regime == regime]


def _plan(rec: Record, machine: Machine, route: str, metadata: Mapping[str, Any] | None,
          window: tuple[float, float] | None) -> _Plan:
    sig: dict[str, FloatArray] = {}
    edge = 0
    if route == "inverse" or (route == "steady" and _has_balances(machine)):
        from condmon.identify.inverse_route import filter_edge, route_cutoff, route_signals

        cutoff = route_cutoff(machine, 1.0 / rec.dt, rec.source)
        sig = route_signals(rec, machine, cutoff)
        edge = filter_edge(1.0 / rec.dt, cutoff)
    named = {**rec.columns, **sig}
    windows = cut_windows(rec["t"], named, machine.regimes, metadata, source=rec.source,
                          span=window, edge=edge)
    return _Plan(rec, sig, windows)


def _slice(plan: _Plan, regime: str, sliced: bool) -> Record:
    """The record, or its longest used window of ``regime`` (a route that needs
    contiguous samples: linear, output error)."""
    if not sliced:
        return plan.record
    longest = max((w for w in plan.windows if w.used and w.regime == regime),
                  key=lambda w: w.stop - w.first)
    return plan.record.slice(longest.first, longest.stop)


def _unusable(plans: Sequence[_Plan]) -> str:
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


def estimate_record(rec: Record | Sequence[Record], model: str | Machine = "dc-motor", *,
                    method: str = "sriv", gamma: float | None = None,
                    excitation: Sequence[str] = (),
                    fit_threshold: float = DEFAULT_FIT_THRESHOLD, route: str | None = None,
                    constants: Mapping[str, float] | None = None,
                    metadata: Mapping[str, Any] | None = None,
                    window: tuple[float, float] | None = None,
                    hold: Mapping[str, float] | None = None,
                    fixed: Mapping[str, float] | None = None,
                    notes: Sequence[str] = (), pool: bool = False) -> EstimateResult:
    """:func:`estimate` on already validated :class:`~condmon.io.Record` (s).

    Several records are estimated together by the output-error, inverse-model
    or steady route (a linear model takes the output-error route then).
    ``fixed``: unknowns fixed for the run (already constants of ``model``),
    reported as held; ``notes``: said in the result; ``pool``: the windows of
    every regime in one estimate (regime ``forward + reverse``: friction
    against speed and direction), not one estimate per regime.
    """
    machine = model if isinstance(model, Machine) else get_model(model)
    records = [rec] if isinstance(rec, Record) else list(rec)
    if not records:
        raise ModelError("no record to estimate from")
    source = " + ".join(r.source for r in records)
    given = dict(constants or {})
    if gamma is not None:
        given["gamma"] = gamma
    consts = machine.constants(_check_constants(machine, given))
    if not (math.isfinite(fit_threshold) and 0.0 <= fit_threshold <= 100.0):
        raise ModelError(f"the fit threshold must be in 0..100 %, got {fit_threshold!r}")
    spec = machine.spec
    for r in records:
        spec.plausibility.check_timing(r.dt, r.dt * len(r), r.source, machine.name)
    chosen = choose_route(machine, route)
    notes = list(notes)
    if len(records) > 1:
        if chosen == "linear":
            chosen = choose_route(machine, "oe")
            notes.append("several records: the linear model is estimated by output error")
        notes.append(f"estimated jointly from {len(records)} records")
    try:
        plans = [_plan(r, machine, chosen, metadata, window) for r in records]
    except CondmonError as err:
        text = str(err)
        raise type(err)(text if text.startswith(source) else f"{source}: {text}") from None
    if pool:
        label = " + ".join(sorted({w.regime for p in plans for w in p.windows if w.used}))
        plans = [dataclasses.replace(p, windows=tuple(
            dataclasses.replace(w, regime=label) if w.used else w for w in p.windows))
            for p in plans]
    durations: dict[str, float] = {}
    for p in plans:
        for w in p.windows:
            if w.used:
                durations[w.regime] = durations.get(w.regime, 0.0) + w.duration
    regimes = sorted(durations, key=lambda k: -durations[k])
    common = dict(model=machine.name, constants=consts, source=source, units=machine.units,
                  route=chosen, model_source=machine.origin)
    if not regimes:
        names = spec.report
        nan = {k: float("nan") for k in names}
        return EstimateResult(nan, dict(nan), np.full((len(names),) * 2, np.nan),
                              FitCheck({}, float("nan"), float(fit_threshold), False), None,
                              None, rejection=_unusable(plans), notes=tuple(notes),
                              windows=tuple(w for p in plans for w in p.windows),
                              trended=(), **common)  # type: ignore[arg-type]
    sliced = machine.regimes.declared or window is not None
    results = []
    for regime in regimes:
        res = _estimate_regime(plans, regime, machine, chosen, method=method,
                               excitation=excitation, fit_threshold=fit_threshold,
                               consts=consts, hold=hold, fixed=dict(fixed or {}),
                               notes=notes, sliced=sliced, common=common)
        results.append(res)
    return dataclasses.replace(results[0], others=tuple(
        dataclasses.replace(r, windows=()) for r in results[1:]))


def _estimate_regime(plans: Sequence[_Plan], regime: str, machine: Machine, chosen: str, *,
                     method: str, excitation: Sequence[str], fit_threshold: float,
                     consts: dict[str, float], hold: Mapping[str, float] | None,
                     fixed: dict[str, float], notes: list[str], sliced: bool,
                     common: dict[str, Any]) -> EstimateResult:
    """The estimate of one regime's windows (see :func:`estimate_record`)."""
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
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            if chosen == "linear":
                lin = linear_route(_slice(plans[0], regime, sliced), machine,
                                   _ESTIMATORS[method], excitation=excitation, constants=consts,
                                   fit_threshold=fit_threshold, hold=held_at)
                values, ucov, fit = lin.values, lin.covariance, lin.fit
                discrete, cont, rejection = lin.discrete, lin.continuous, lin.rejection
                diagnostics = dict(lin.diagnostics)
                notes += list(lin.discrete.notes)
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
            elif chosen == "steady":
                from condmon.identify.steady_route import steady_output_error, steady_route

                windows = [p.rows(regime) for p in plans]
                st = (steady_route([p.signals for p in plans], windows, machine,
                                   constants=consts, hold=held_at, fit_threshold=fit_threshold,
                                   source=source)
                      if _has_balances(machine) else
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
                from condmon.identify.inverse_route import inverse_route

                rows = [np.concatenate(p.rows(regime)) if p.rows(regime) else
                        np.zeros(0, dtype=np.intp) for p in plans]
                inv = inverse_route(records, machine, constants=consts,
                                    fit_threshold=fit_threshold, rows=rows,
                                    signals=[p.signals for p in plans], hold=held_at)
                values, ucov, fit, idf = inv.values, inv.covariance, inv.fit, inv.identifiability
                diagnostics = inv.diagnostics()
                notes.append(f"inverse model (IDIM-LS): zero-phase low-pass at {inv.cutoff:g} Hz, "
                             f"central differences, {inv.samples} samples")
                worst = max(inv.whiteness, key=lambda k: inv.whiteness[k])
                limit = spec.max_residual_correlation
                if inv.whiteness[worst] > limit:
                    rejection = (f"structure mismatch: the residual of {worst} is strongly "
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
                                               if spec.structure_hint else ""))
    names = spec.report
    identified = set(idf.identifiable) if idf is not None else set(spec.unknowns)
    if idf is not None and not idf.identifiable and rejection is None:
        rejection = "not identifiable: " + "; ".join(f"{k}: {v}" for k, v in idf.reasons.items())
    if rejection is None or rejection.startswith(("structure mismatch", "not identifiable")):
        params, G = machine.report_jacobian({**consts, **values})
        pcov = G @ ucov @ G.T
        vals = np.array([params[k] for k in names])
        trended = tuple(k for k, g in zip(names, G)
                        if np.any(g != 0) and all(spec.unknowns[j] in identified
                                                  for j in np.flatnonzero(g)))
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
    if rejection is None and not np.all(np.isfinite(se)):
        rejection = "the standard errors are not finite: the data do not determine the model"
    if held and idf is not None and idf.held:
        notes.append("held (not identified by this record): " + ", ".join(
            f"{k} at its {origin.get(k, 'nominal')} value" for k in idf.held))
    listed: list[Window] = []
    for i, p in enumerate(plans):
        used_j = 0
        for w in p.windows:
            if w.used and w.regime == regime:
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
        identifiability=idf, held=held, trended=trended, **common)
