"""``condmon validate`` and ``condmon simulate record``: a model on a recorded input.

The parameters come from an ``estimate --json`` document (its parameters,
known constants and, from the simulation-error route, initial states), the
declaration's values, and ``--set NAME=VALUE`` over both. The record is read
as ``estimate`` reads it (columns, sample rate, scale, offset).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from condmon.errors import ConfigError, DataError
from condmon.io.records import Record, validate_record
from condmon.models.machine import Machine
from condmon.models.regimes import split_key
from condmon.models.registry import get_model
from condmon.simulate.compare import Comparison, compare_model, initial_states
from condmon.workflows.records import EstimateOptions, RecordLike

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["ParameterFile", "read_parameter_file", "parameter_document", "parse_assignments",
           "validate_file", "simulate_file", "describe_initial"]


@dataclass(frozen=True)
class ParameterFile:
    """What an ``estimate --json`` document says of a model.

    Attributes
    ----------
    path : str
    parameters : dict of str to float
        The model's parameters it holds (estimated and known constants). [SI]
    initial : dict of str to float
        The initial states it estimated (simulation-error route). [state units]
    notes : tuple of str
        Whether it was accepted, what it held.
    smoothing : float, optional
        The smoothing width the estimate simulated with, where the simulation
        route widened it to what its step resolves. [switch units]
    """

    path: str
    parameters: dict[str, float]
    initial: dict[str, float]
    notes: tuple[str, ...]
    smoothing: float | None = None


def read_parameter_file(path: str | Path, machine: Machine) -> ParameterFile:
    """Read an ``estimate --json`` document for ``machine``.

    Raises
    ------
    DataError
        When the file is unreadable, no estimate document, or of another model
        (naming the file and both models).
    """
    src = str(path)
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(f"{src}: no such parameter file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        why = (f"no JSON from line {err.lineno}, column {err.colno} on"
               if isinstance(err, json.JSONDecodeError) else str(err))
        raise DataError(f"{src}: not a parameter file (the JSON of condmon estimate "
                        f"--json): {why}") from None
    return parameter_document(doc, src, machine)


def parameter_document(doc: Any, src: str, machine: Machine) -> ParameterFile:
    """An estimate's document (``EstimateResult.to_dict()``, the JSON of
    ``condmon estimate --json``) for ``machine``, ``src`` naming it in messages.

    Raises
    ------
    DataError
        No estimate document, or of another model (naming both models).
    """
    if not isinstance(doc, dict) or not isinstance(doc.get("parameters"), dict):
        raise DataError(f"{src}: not a parameter file: no 'parameters' table (write one with "
                        "condmon estimate RECORD --model M --json > est.json)")
    model = doc.get("model")
    if model is None:
        raise DataError(f"{src}: no 'model' key: a parameter file says which model its "
                        f"parameters are of (\"model\": \"{machine.name}\"), as condmon "
                        "estimate --json writes it")
    if model != machine.name:
        raise DataError(f"{src}: the parameters are of model {model!r}, not of "
                        f"{machine.name!r} ({machine.origin or 'shipped'}); estimate with "
                        "this model first")
    names = set(machine.plant.parameter_names)
    reported = names | set(machine.monitored) | set(machine.spec.report)
    values: dict[str, float] = {}
    for table in ("constants", "parameters"):
        for k, v in dict(doc.get(table) or {}).items():
            if k not in names:
                if table == "parameters" and split_key(k)[0] not in reported:
                    raise DataError(f"{src}: parameters.{k} is not a parameter of "
                                    f"{machine.name!r}; its parameters: "
                                    f"{', '.join(machine.plant.parameter_names)}")
                continue  # a derived quantity: computed, not simulated with
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise DataError(f"{src}: {table}.{k} is {v!r}, not a finite number")
            values[k] = float(v)
    initial: dict[str, float] = {}
    for k, v in dict(doc.get("initial_states") or {}).items():
        value = v.get("value") if isinstance(v, dict) else v
        if k not in machine.plant.state_names:
            raise DataError(f"{src}: initial state {k!r} is not a state of {machine.name!r}; "
                            f"its states: {', '.join(machine.plant.state_names)}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not math.isfinite(value):
            raise DataError(f"{src}: initial state {k!r} is {value!r}, not a finite number")
        initial[k] = float(value)
    notes = []
    if doc.get("accepted") is False:
        notes.append(f"{src}: the estimate was not accepted: {doc.get('reason')}")
    held = dict(doc.get("held") or {})
    if held:
        notes.append(f"{src}: held (not estimated): {', '.join(sorted(held))}")
    eps = doc.get("smoothing")
    if eps is not None and (isinstance(eps, bool) or not isinstance(eps, (int, float))
                            or not math.isfinite(eps) or eps < 0):
        raise DataError(f"{src}: smoothing is {eps!r}, not a width >= 0")
    return ParameterFile(src, values, initial, tuple(notes),
                         None if eps is None else float(eps))


def parse_assignments(given: str | Mapping[str, Any] | None, allowed: tuple[str, ...],
                      what: str, option: str) -> dict[str, float]:
    """``"a=1,b=2.5"`` (or a mapping) -> ``{"a": 1.0, "b": 2.5}``, every name one
    of ``allowed`` and given once, every value a finite number; ``option``
    names them in messages.

    Example
    -------
    >>> parse_assignments("R=1.2, L=0.003", ("R", "L"), "parameter", "--set")
    {'R': 1.2, 'L': 0.003}
    """
    pairs: list[tuple[str, Any]] = []
    if isinstance(given, Mapping):
        pairs = list(given.items())
    else:
        for part in filter(str.strip, (given or "").split(",")):
            name, sep, value = part.partition("=")
            if not sep:
                raise ConfigError(f"{option}: {part.strip()!r} is not NAME=VALUE")
            pairs.append((name.strip(), value.strip()))
    out: dict[str, float] = {}
    for name, value in pairs:
        if name not in allowed:
            raise ConfigError(f"{option}: {name!r} is not a {what} of the model; allowed: "
                              f"{', '.join(allowed)}")
        if name in out:
            raise ConfigError(f"{option}: {name} is given twice; give each {what} once")
        try:
            if isinstance(value, bool):
                raise TypeError
            v = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"{option}: {name}={value!r} is not a number") from None
        if not math.isfinite(v):
            raise ConfigError(f"{option}: {name}={value} is not finite")
        out[name] = v
    return out


def _setup(record: RecordLike, model: str | Path,
           params: str | Path | Mapping[str, Any] | None,
           set_values: str | Mapping[str, float] | None,
           initial: str | Mapping[str, float], opts: EstimateOptions, sensors: bool = True
           ) -> tuple[Machine, Record, dict[str, float], dict[str, tuple[float, str]],
                      tuple[str, ...]]:
    machine = get_model(str(model))
    plant = machine.plant
    if isinstance(params, Mapping):
        pf: ParameterFile | None = parameter_document(dict(params), "the estimate", machine)
    else:
        pf = read_parameter_file(params, machine) if params is not None else None
    if pf is not None and pf.smoothing is not None:   # the model the estimate simulated
        machine = dataclasses.replace(machine, plant=dataclasses.replace(
            plant, smoothing=pf.smoothing))
        plant = machine.plant
    values = dict(pf.parameters) if pf else {}
    given_values = parse_assignments(set_values, plant.parameter_names, "parameter", "--set")
    values.update(given_values)
    notes = list(pf.notes) if pf else []
    if pf is not None and pf.smoothing is not None:
        notes.append(f"simulated with the estimate's smoothing, {pf.smoothing:.2g} (widened "
                     "by its route to what its step resolved)")
    notes += _parameter_notes(machine, values, given_values, pf)
    if isinstance(record, (str, Path)):
        frame = opts.read(record)
        source = str(record)
    else:
        frame = opts.prepared(record)
        source = str(record.attrs.get("source", "record"))
    # ten samples per state and one more: fewer cannot show a state's dynamics, and an
    # RMSE over a handful of samples is no validation
    rec = validate_record(frame, (*plant.input_names, *(plant.sensor_names if sensors else ())),
                          min_samples=10 * (len(plant.state_names) + 1), source=source)
    machine.spec.plausibility.check_timing(rec.dt, rec.dt * len(rec), rec.source, machine.name,
                                           purpose="a trustworthy validation")
    if isinstance(initial, Mapping) or "=" in initial:
        given = parse_assignments(initial, plant.state_names, "state", "--initial")
        rule = "estimated"
        for k, v in given.items():
            box = machine.spec.simulation.of(k)
            if not box.low <= v <= box.high:
                notes.append(f"--initial {k}={v:g} lies outside [estimation.initial] {k} "
                             f"({box.low:g} .. {box.high:g}); simulated as given")
    else:
        given, rule = {}, initial.strip()
    if not sensors and rule in ("first-sample", "fit"):
        raise DataError(f"{source}: --initial {rule} needs the sensor columns "
                        f"({', '.join(plant.sensor_names)}), which the record does not have; "
                        "use 'estimated' or NAME=VALUE,...")
    start = initial_states(machine, rec, rule, pf.initial if pf else None, given, values)
    if rule == "fit":
        from condmon.identify.simulation_route import fit_initial_states

        fitted = fit_initial_states(rec, machine, values, {k: v for k, (v, _) in start.items()})
        for k, (v, se) in fitted.items():
            if k not in given:
                start[k] = (v, f"fitted on this record, standard error {se:.3g}")
        notes.append("initial states fitted on this record with the parameters fixed "
                     "(MATLAB compare's default): the figures show the parameters, not how "
                     "well the initial states were known")
    elif rule == "estimated":
        notes += _start_mismatch(machine, rec, start, values)
    carried = [k for k, (_, how) in start.items() if how == "estimated"]
    if rule == "first-sample" and carried:
        notes.append(f"{', '.join(carried)}: no sensor gives {'it' if len(carried) == 1 else 'them'}"
                     " back, so the estimation record's initial value is used; if this record "
                     "started elsewhere, --initial fit fits it on this record")
    declared = [k for k, (_, how) in start.items()
                if how == "declared" and machine.spec.simulation.of(k).mode == "estimate"]
    if declared:
        notes.append(f"{', '.join(declared)}: the declaration's initial value (no estimate of "
                     f"it{' in ' + pf.path if pf else ''}); --initial fit or NAME=VALUE sets it")
    return machine, rec, values, start, tuple(notes)


def _compare(rec: Record, machine: Machine, values: Mapping[str, float],
             start: Mapping[str, tuple[float, str]], notes: tuple[str, ...]) -> Comparison:
    """:func:`compare_model`; a simulation that diverges with a value outside
    ``[estimation.plausible]`` names that value as the likely cause (the note
    that says so would else be lost with the run)."""
    from condmon.simulate.recorded import Diverged

    try:
        return compare_model(rec, machine, values, start, notes=notes)
    except Diverged as err:
        implausible = [n.split(" lies outside")[0] for n in notes
                       if "lies outside [estimation.plausible]" in n]
        if not implausible:
            raise
        verb = "lies" if len(implausible) == 1 else "lie"
        err.args = (f"{err}; {', '.join(implausible)} {verb} outside "
                    "[estimation.plausible], the likely cause", *err.args[1:])
        raise


def _parameter_notes(machine: Machine, values: Mapping[str, float],
                     given: Mapping[str, float], pf: ParameterFile | None) -> list[str]:
    """Which estimated quantities fall back on the declaration, and which given
    values lie outside ``[estimation.plausible]``."""
    notes = []
    declared = machine.plant.parameter_values()
    missing = [k for k in machine.spec.unknowns if k not in values and k in declared]
    if missing:
        where = f"not in {pf.path}" if pf else "no parameter file (--params)"
        notes.append(f"{where}: the declaration's values of "
                     + ", ".join(f"{k} = {declared[k]:.6g}" for k in missing))
    bounds = machine.spec.plausibility.bounds
    for k, v in values.items():
        why = bounds[k].violation(v) if k in bounds else None
        if why is not None:
            where = f"--set {k}={v:g}" if k in given else f"{k} = {v:g} in {pf.path if pf else ''}"
            notes.append(f"{where} lies outside [estimation.plausible]: {k} {why}; "
                         "simulated as given")
    return notes


def _start_mismatch(machine: Machine, rec: Record, start: Mapping[str, tuple[float, str]],
                    values: Mapping[str, float]) -> list[str]:
    """A note when a measured state's estimated start is far from this record's
    first reading: the record did not start where the estimation record did."""
    from condmon.models.shooting import state_readers

    plant = machine.plant
    p = plant.compile().parameter_vector(values)
    far = []
    for name, (j, fn) in state_readers(plant).items():
        v, how = start[name]
        if how != "estimated" or plant.sensor_names[j] not in rec.columns:
            continue
        y0 = float(rec[plant.sensor_names[j]][0])
        read = float(fn(y0, p))
        noise = abs(float(fn(y0 + plant.sensors[j].noise, p)) - read)
        if abs(v - read) > 3.0 * max(noise, 1e-12 * max(abs(read), 1.0)):
            far.append(f"{name} starts at {v:.4g} (estimated) but this record's first reading "
                       f"gives {read:.4g}")
    if not far:
        return []
    return ["; ".join(far) + ": the record did not start where the estimation record did, so "
            "the estimated initial states (the unmeasured ones too) may not hold here; "
            "--initial fit fits them on this record, --initial first-sample reads them"]


def validate_file(record: RecordLike, model: str | Path, *,
                  params: str | Path | Mapping[str, Any] | None = None,
                  set_values: str | Mapping[str, float] | None = None,
                  initial: str | Mapping[str, float] = "estimated",
                  options: EstimateOptions | None = None,
                  figure: str | Path | None = None) -> tuple[Comparison, Path | None]:
    """Simulate ``model`` on ``record``'s inputs and compare with its outputs.

    Parameters
    ----------
    record : str, Path or DataFrame
    model : str or Path
        A shipped model's name or a declaration file.
    params : str, Path or mapping, optional
        An ``estimate --json`` document, or an estimate's ``to_dict()``.
    set_values : str or mapping, optional
        ``NAME=VALUE,...`` (or ``{name: value}``) parameters over the file's
        and the declaration's. [SI]
    initial : str or mapping
        "estimated" (the file's initial states), "first-sample", "fit" (fitted
        on this record with the parameters fixed), or ``NAME=VALUE,...`` (or
        ``{state: value}``) per state (the others as "estimated").
    options : EstimateOptions, optional
        How to read the record (columns, sample rate, scale, offset).
    figure : str or Path, optional
        Where to write the measured-against-model figure (PNG).

    Returns
    -------
    (Comparison, Path or None)
        The figures, and the figure's path when one was written.
    """
    opts = options or EstimateOptions(model=str(model))
    machine, rec, values, start, notes = _setup(record, model, params, set_values, initial,
                                                opts)
    c = _compare(rec, machine, values, start, notes)
    path = None
    if figure is not None:
        from condmon.report.comparison import plot_comparison

        path = Path(figure)
        try:
            plot_comparison(c, path)
        except OSError as err:
            raise DataError(f"{path}: the figure could not be written: {err}") from None
    return c, path


def simulate_file(record: str | Path, model: str, out: str | Path, *,
                  params: str | Path | None = None, set_values: str | None = None,
                  initial: str = "estimated",
                  options: EstimateOptions | None = None) -> Comparison:
    """Simulate ``model`` on ``record``'s inputs and write ``t``, the inputs,
    the simulated sensor readings (as ``<sensor>_sim``), the measured ones
    when the record has them (then compared), and the simulated states (as
    ``<state>_sim``) to ``out`` (CSV or Parquet)."""
    from condmon.io.records import check_output_path, write_record

    check_output_path(out)
    if isinstance(record, (str, Path)) and Path(out).resolve() == Path(record).resolve():
        raise DataError(f"{out}: the output is the record being simulated, which it would "
                        "overwrite; write the simulation to another file")
    opts = options or EstimateOptions(model=model)
    machine = get_model(model)
    frame = opts.read(record)
    sensed = all(n in frame.columns for n in machine.plant.sensor_names)
    machine, rec, values, start, notes = _setup(record, model, params, set_values, initial,
                                                opts, sensors=sensed)
    c = _compare(rec, machine, values, start, notes)
    rec_frame = _frame(c, machine, record, opts)
    write_record(rec_frame, out)
    return c


def _frame(c: Comparison, machine: Machine, record: str | Path, opts: EstimateOptions
           ) -> pd.DataFrame:
    import pandas as pd

    frame = opts.read(record)
    cols: dict[str, Any] = {"t": c.t}
    for name in machine.plant.input_names:
        cols[name] = np.asarray(frame[name], dtype=np.float64)
    for j, name in enumerate(c.outputs):
        cols[f"{name}_sim"] = c.simulated[:, j]
        if c.measured is not None:
            cols[name] = c.measured[:, j]
    if c.states is not None:    # the states no sensor column already carries
        for j, name in enumerate(machine.plant.state_names):
            if f"{name}_sim" not in cols and name not in cols:
                cols[f"{name}_sim"] = c.states[:, j]
    return pd.DataFrame(cols)


def describe_initial(initial: Mapping[str, tuple[float, str]]) -> str:
    """``x1 = 7.47 (estimated), x2 = 2.68 (estimated)``."""
    return ", ".join(f"{k} = {v:.6g} ({how})" for k, (v, how) in initial.items())

