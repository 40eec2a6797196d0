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
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from condmon._threads import one_blas_thread
from condmon.errors import CondmonError, DataError, ModelError
from condmon.identify.defaults import list_estimators
from condmon.identify.extras import systematic_part, with_features
from condmon.identify.fit import DEFAULT_FIT_THRESHOLD, FitCheck
from condmon.identify.greybox import NOT_AT_REST, auto_reason, choose_route
from condmon.identify.regime_estimate import (
    ESTIMATOR_FUNCTIONS, estimate_regime, has_balances, plan, unusable,
)
from condmon.identify.result import EstimateResult
from condmon.io.columns import Columns, as_columns
from condmon.io.records import Record, validate_record
from condmon.io.rig import RecordSettings, apply_record_settings
from condmon.models.machine import Machine
from condmon.models.registry import get_model, recognised_records

if TYPE_CHECKING:  # pandas only where a DataFrame is made or read: not on import
    import pandas as pd

__all__ = ["EstimateResult", "estimate", "estimate_record", "estimate_joint", "list_estimators",
           "systematic_part", "used_regimes", "DEFAULT_EXCITATION"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: Excitation columns used when present and not told otherwise.
DEFAULT_EXCITATION = ("yd", "ud")


def _excitation_columns(record: pd.DataFrame | Columns | Record, machine: Machine,
                        excitation: Sequence[str] | str | None) -> tuple[str, ...]:
    cols = record.columns if isinstance(record, Record) else list(record.columns)
    if excitation == "auto":
        names = machine.spec.excitation or DEFAULT_EXCITATION
        found = [c for c in names if c in cols]
        if isinstance(record, Record):
            return tuple(found)
        # a recorded but constant excitation (a perturbation switched off) is left out
        return tuple(c for c in found if _varies(record, c))
    if excitation is None or isinstance(excitation, str):
        return ()
    return tuple(excitation)


def _varies(record: pd.DataFrame | Columns, column: str) -> bool:
    """Whether a column takes more than one value (missing values not counted)."""
    if isinstance(record, Columns):  # plain numbers, none missing
        values = record[column]
        return bool(values.size and np.any(values != values[0]))
    import pandas as pd

    col = record[column]
    values = (col.to_numpy() if col.dtype == np.float64 else
              pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan))
    values = values[~np.isnan(values)]
    return bool(values.size and np.any(values != values[0]))


def _required_columns(machine: Machine, route: str) -> tuple[str, ...]:
    """Record columns a route needs (inputs, then sensors)."""
    if route == "simulation" or (route == "steady" and not has_balances(machine)):
        return (*machine.plant.input_names, *machine.plant.sensor_names)
    if route == "oe":
        from condmon.models.semilinear import semilinear_structure  # sympy: only for this route

        s = semilinear_structure(machine)
        return (*s.inputs, *s.sensors)
    if route == "linear":
        lin = machine.linear()
        return (lin.input, *lin.outputs)
    return machine.inverse().columns


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
            bound = machine.spec.plausibility.bounds.get(k)
            why = None if bound is None else bound.violation(val)
            if why is not None:
                raise ModelError(f"--constants {k}={val:g}: {k} {why} "
                                 f"({machine.plant.source}[estimation.plausible])")
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


def _record_frame(record: pd.DataFrame | Columns, machine: Machine,
                  columns: Mapping[str, str] | None, settings: RecordSettings | None,
                  source: str | None) -> pd.DataFrame | Columns:
    """The record in model columns: the machine's ``[record]`` settings, then
    ``settings``, then ``columns`` (unless the frame says they were applied)."""
    applied = record.attrs.get("record_settings") is not None
    merged = machine.record.merged(settings).merged(RecordSettings(dict(columns or {})))
    if (applied and not columns) or (not applied and merged.empty):
        return record  # nothing to rename or apply
    frame = record.to_frame() if isinstance(record, Columns) else record
    if applied:
        return frame.rename(columns={v: k for k, v in (columns or {}).items()})
    return apply_record_settings(frame, merged, source)


@one_blas_thread
def estimate(record: pd.DataFrame | Columns, model: str | Machine = "dc-motor", *,
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
    record : pandas.DataFrame or Columns
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
    if method not in ESTIMATOR_FUNCTIONS:
        raise ModelError(f"unknown method {method!r}; allowed: {', '.join(ESTIMATOR_FUNCTIONS)}")
    given, fixed = _split_constants(machine, dict(constants or {}))
    machine = machine.with_fixed(fixed)
    chosen = choose_route(machine, route)
    with recognised_records(machine):
        df = as_columns(_record_frame(record, machine, columns, settings, source))
        exc = _excitation_columns(df, machine, excitation) if chosen == "linear" else ()
        rec = _validated(df, machine, chosen, source, exc)
    consts = dict(df.attrs.get("constants", {}) or {})
    _check_constants(machine, given, strict=tuple(given))
    consts.update(given)
    consts.update(fixed)
    if gamma is not None:
        consts["gamma"] = gamma
    notes = tuple(f"{k} fixed at {v:.6g} {machine.plant.parameter(k).unit} for this estimate "
                  "(--constants): not estimated".replace("  ", " ") for k, v in fixed.items())
    if df.attrs.get("record_settings") not in (None, "", "as written"):
        notes += (f"record read with its settings: {df.attrs['record_settings']}",)
    def run(r: Record) -> EstimateResult:
        return with_features(estimate_record(
            r, machine, method=method, excitation=exc, fit_threshold=fit_threshold,
            route=route or machine.spec.route, constants=consts, metadata=metadata,
            window=window, hold=hold, fixed=fixed, notes=notes), r, machine, metadata,
            tuple(map(str, df.columns)))

    res = run(rec)
    accuracy = machine.record.merged(settings).accuracy
    if not accuracy or not res.usable:
        return res
    return dataclasses.replace(res, systematic=systematic_part(
        res, [rec], accuracy, lambda rs: run(rs[0])))


def _validated(df: pd.DataFrame | Columns, machine: Machine, route: str, source: str | None,
               excitation: Sequence[str] = ()) -> Record:
    """``df`` validated as every estimate of ``machine`` by ``route`` validates a
    record: the route's columns and ``excitation`` required, the optional ones
    kept, ten samples per unknown and one."""
    return validate_record(df, (*_required_columns(machine, route), *excitation),
                           input_name=machine.linear().input if route == "linear" else None,
                           inputs=machine.plant.input_names,
                           min_samples=10 * (len(machine.spec.unknowns) + 1), source=source,
                           optional=_optional_columns(machine))


def _optional_columns(machine: Machine) -> tuple[str, ...]:
    """Record columns kept when present: those the regimes' conditions name,
    the features' and the operating conditions' channels."""
    return (*sorted({n for r in machine.regimes.regimes for n in r.condition.names}),
            *(f.channel for f in machine.features),
            *(c.feature.channel for c in machine.conditions if c.feature is not None))


@one_blas_thread
def estimate_joint(records: Sequence[pd.DataFrame | Columns], model: str | Machine = "dc-motor", *,
                   fit_threshold: float = DEFAULT_FIT_THRESHOLD,
                   columns: Mapping[str, str] | None = None,
                   sources: Sequence[str] | None = None, route: str | None = None,
                   constants: Mapping[str, float] | None = None,
                   settings: RecordSettings | None = None,
                   metadata: Mapping[str, Any] | None = None,
                   hold: Mapping[str, float] | None = None,
                   window: tuple[float, float] | None = None) -> EstimateResult:
    """Estimate one set of physical parameters from several records at once.

    The records (one sample interval) enter one criterion: the output error
    summed over all of them (each simulated from rest), one stacked
    inverse-model regression, or the balances of every steady window, the
    windows of every regime together (strokes in both directions tell a
    Coulomb friction from a load torque). A linear model takes the
    output-error route.

    Parameters
    ----------
    records : sequence of pandas.DataFrame or Columns
        As for :func:`estimate`.
    model, fit_threshold, columns, route, constants, settings, metadata, hold, window
        As for :func:`estimate` (``window`` only with one record).
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
    if window is not None and len(records) != 1:
        raise DataError("--window applies to one record; several are estimated over their "
                        "windows")
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
        with recognised_records(machine):
            frame = _record_frame(df, machine, columns, settings, name)
            recs.append(_validated(frame, machine, chosen, name))
        consts.update(dict(frame.attrs.get("constants", {}) or {}))
    consts.update(given)
    consts.update(fixed)

    def run(rs: list[Record]) -> EstimateResult:
        return with_features(estimate_record(
            rs, machine, fit_threshold=fit_threshold, route=chosen, constants=consts,
            metadata=metadata, hold=hold, fixed=fixed, pool=True, window=window), rs, machine,
            metadata)

    res = run(recs)
    accuracy = machine.record.merged(settings).accuracy
    if not accuracy or not res.usable:
        return res
    return dataclasses.replace(res, systematic=systematic_part(res, recs, accuracy, run))


def used_regimes(record: pd.DataFrame | Columns, model: str | Machine, *,
                 source: str = "record", route: str | None = None,
                 metadata: Mapping[str, Any] | None = None,
                 window: tuple[float, float] | None = None,
                 constants: Mapping[str, Any] | None = None) -> tuple[str, ...]:
    """The declared regimes of a record's usable windows, in time order (the
    regime names, without the metadata that split them): what
    ``[estimation] cycle`` groups records by. The record, ``window`` and
    ``constants`` are checked as :func:`estimate` checks them, and refused as
    it would refuse them.

    Example
    -------
    >>> from condmon.simulate import simulate_actuator
    >>> used_regimes(simulate_actuator(seed=1), "dc-motor")   # no regimes declared
    ('',)
    """
    machine = model if isinstance(model, Machine) else get_model(model)
    given, _ = _split_constants(machine, dict(constants or {}))
    _check_constants(machine, given, strict=tuple(given))
    chosen = choose_route(machine, route)
    with recognised_records(machine):
        df = as_columns(_record_frame(record, machine, None, None, source))
        rec = _validated(df, machine, chosen, source)
    try:
        windows = plan(rec, machine, chosen, metadata, window).windows
    except CondmonError as err:
        text = str(err)
        raise type(err)(text if text.startswith(source) else f"{source}: {text}") from None
    return tuple(dict.fromkeys(w.regime.split(",")[0].strip() for w in windows if w.used))


def _metadata_notes(machine: Machine, metadata: Mapping[str, Any] | None) -> list[str]:
    """What to say of the record's metadata: fields the regimes split by but
    the record lacks, fields given that no regime uses."""
    spec = machine.regimes
    given = dict(metadata or {})
    notes = []
    missing = [k for k in spec.metadata if k not in given]
    if missing:
        notes.append(f"metadata {', '.join(missing)} not given (unit.toml [metadata], a "
                     "manifest row's metadata or --meta): its regimes read "
                     + ", ".join(f"{k}=?" for k in missing))
    used = set(spec.metadata) | {n for r in spec.regimes for n in r.condition.names}
    unused = [k for k in given if k not in used]
    if unused:
        notes.append(f"metadata {', '.join(unused)} not used: the declaration's regimes name "
                     f"{', '.join(sorted(used)) or 'no metadata'}")
    return notes


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
    auto = (route or spec.route) == "auto"
    notes = list(notes)
    if chosen == "simulation" and auto and auto_reason(machine):
        notes.append(str(auto_reason(machine)))
    if len(records) > 1:
        if chosen == "linear":
            chosen = choose_route(machine, "oe")
            notes.append("several records: the linear model is estimated by output error")
        notes.append(f"estimated jointly from {len(records)} records")
    try:
        plans = [plan(r, machine, chosen, metadata, window) for r in records]
    except CondmonError as err:
        text = str(err)
        raise type(err)(text if text.startswith(source) else f"{source}: {text}") from None
    if pool:
        label = " + ".join(sorted({w.regime for p in plans for w in p.windows if w.used}))
        plans = [dataclasses.replace(p, pooled=label) for p in plans]
    notes += _metadata_notes(machine, metadata)
    durations: dict[str, float] = {}
    for p in plans:
        for w in p.windows:
            if w.used:
                key = p.pooled or w.regime
                durations[key] = durations.get(key, 0.0) + w.duration
    regimes = sorted(durations, key=lambda k: -durations[k])
    common = dict(model=machine.name, constants=consts, source=source, units=machine.units,
                  route=chosen, model_source=machine.origin)
    if not regimes:
        names = spec.report
        nan = {k: float("nan") for k in names}
        return EstimateResult(nan, dict(nan), np.full((len(names),) * 2, np.nan),
                              FitCheck({}, float("nan"), float(fit_threshold), False), None,
                              None, rejection=unusable(plans), notes=tuple(notes),
                              windows=tuple(w for p in plans for w in p.windows),
                              trended=(), **common)  # type: ignore[arg-type]
    sliced = machine.regimes.declared or window is not None
    results = []
    for regime in regimes:
        res = estimate_regime(plans, regime, machine, chosen, method=method,
                               excitation=excitation, fit_threshold=fit_threshold,
                               consts=consts, hold=hold, fixed=dict(fixed or {}),
                               notes=notes, sliced=sliced, common=common)
        if auto and chosen == "linear" and (res.rejection or "").startswith(NOT_AT_REST):
            res = _by_simulation(records, res, regime, machine, method=method,
                                 excitation=excitation, fit_threshold=fit_threshold,
                                 consts=consts, hold=hold, fixed=dict(fixed or {}),
                                 notes=notes, metadata=metadata, window=window,
                                 common=common)
        results.append(res)
    return dataclasses.replace(results[0], others=tuple(
        dataclasses.replace(r, windows=()) for r in results[1:]))


def _by_simulation(records: Sequence[Record], refused: EstimateResult, regime: str,
                   machine: Machine, *, notes: Sequence[str], metadata: Mapping[str, Any] | None,
                   window: tuple[float, float] | None, common: dict[str, Any],
                   **given: Any) -> EstimateResult:
    """Route "auto" after the linear route refused a record that does not start
    at rest: the simulation error, which estimates the initial states, with a note
    saying why. Its own result stands, accepted or not."""
    plans = [plan(r, machine, "simulation", metadata, window) for r in records]
    first = str(refused.rejection).split(" and the linear route")[0]
    why = (f"route auto took the simulation error, which estimates the initial states: the "
           f"linear route refused the record ({first})")
    sliced = machine.regimes.declared or window is not None
    return estimate_regime(plans, regime, machine, "simulation", notes=[*notes, why],
                           sliced=sliced, common={**common, "route": "simulation"}, **given)
