"""``condmon validate`` and ``condmon simulate record``: a model on a recorded input.

The parameters come from an ``estimate --json`` document (its parameters,
known constants and, from the simulation-error route, initial states), the
declaration's values, and ``--set NAME=VALUE`` over both. The record is read
as ``estimate`` reads it (columns, sample rate, scale, offset).
"""

from __future__ import annotations

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
from condmon.models.registry import get_model
from condmon.simulate.compare import Comparison, compare_model, initial_states
from condmon.workflows.records import EstimateOptions

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["ParameterFile", "read_parameter_file", "parse_assignments", "validate_file",
           "simulate_file", "describe_initial"]


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
    """

    path: str
    parameters: dict[str, float]
    initial: dict[str, float]
    notes: tuple[str, ...]


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
        raise DataError(f"{src}: not a parameter file (the JSON of condmon estimate "
                        f"--json): {err}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("parameters"), dict):
        raise DataError(f"{src}: not a parameter file: no 'parameters' table (write one with "
                        "condmon estimate RECORD --model M --json > est.json)")
    model = doc.get("model")
    if model != machine.name:
        raise DataError(f"{src}: the parameters are of model {model!r}, not of "
                        f"{machine.name!r} ({machine.origin or 'shipped'}); estimate with "
                        "this model first")
    names = set(machine.plant.parameter_names)
    values: dict[str, float] = {}
    for table in ("constants", "parameters"):
        for k, v in dict(doc.get(table) or {}).items():
            if k not in names:
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
        notes.append(f"the estimate in {src} was not accepted: {doc.get('reason')}")
    held = dict(doc.get("held") or {})
    if held:
        notes.append(f"held in {src} (not estimated): {', '.join(sorted(held))}")
    return ParameterFile(src, values, initial, tuple(notes))


def parse_assignments(text: str | None, allowed: tuple[str, ...], what: str,
                      option: str) -> dict[str, float]:
    """``"a=1,b=2.5"`` -> ``{"a": 1.0, "b": 2.5}``, every name one of ``allowed``.

    Example
    -------
    >>> parse_assignments("R=1.2, L=0.003", ("R", "L"), "parameter", "--set")
    {'R': 1.2, 'L': 0.003}
    """
    out: dict[str, float] = {}
    for part in (text or "").split(","):
        if not part.strip():
            continue
        name, sep, value = part.partition("=")
        name = name.strip()
        if not sep:
            raise ConfigError(f"{option}: {part.strip()!r} is not NAME=VALUE")
        if name not in allowed:
            raise ConfigError(f"{option}: {name!r} is not a {what} of the model; allowed: "
                              f"{', '.join(allowed)}")
        try:
            v = float(value)
        except ValueError:
            raise ConfigError(f"{option}: {name}={value.strip()!r} is not a number") from None
        if not math.isfinite(v):
            raise ConfigError(f"{option}: {name}={value.strip()} is not finite")
        out[name] = v
    return out


def _setup(record: str | Path, model: str, params: str | Path | None, set_values: str | None,
           initial: str, opts: EstimateOptions
           ) -> tuple[Machine, Record, dict[str, float], dict[str, tuple[float, str]],
                      tuple[str, ...]]:
    machine = get_model(model)
    plant = machine.plant
    pf = read_parameter_file(params, machine) if params is not None else None
    values = dict(pf.parameters) if pf else {}
    values.update(parse_assignments(set_values, plant.parameter_names, "parameter", "--set"))
    frame = opts.read(record)
    rec = validate_record(frame, (*plant.input_names, *plant.sensor_names),
                          min_samples=2, source=str(record))
    if "=" in initial:
        given = parse_assignments(initial, plant.state_names, "state", "--initial")
        rule = "estimated"
    else:
        given, rule = {}, initial.strip()
    start = initial_states(machine, rec, rule, pf.initial if pf else None, given, values)
    return machine, rec, values, start, pf.notes if pf else ()


def validate_file(record: str | Path, model: str, *, params: str | Path | None = None,
                  set_values: str | None = None, initial: str = "estimated",
                  options: EstimateOptions | None = None,
                  figure: str | Path | None = None) -> tuple[Comparison, Path | None]:
    """Simulate ``model`` on ``record``'s inputs and compare with its outputs.

    Parameters
    ----------
    record : str or Path
    model : str
        A shipped model's name or a declaration file.
    params : str or Path, optional
        An ``estimate --json`` document.
    set_values : str, optional
        ``NAME=VALUE,...`` parameters over the file's and the declaration's. [SI]
    initial : str
        "estimated" (the file's initial states), "first-sample", or
        ``NAME=VALUE,...`` per state (the others as "estimated").
    options : EstimateOptions, optional
        How to read the record (columns, sample rate, scale, offset).
    figure : str or Path, optional
        Where to write the measured-against-model figure (PNG).

    Returns
    -------
    (Comparison, Path or None)
        The figures, and the figure's path when one was written.
    """
    opts = options or EstimateOptions(model=model)
    machine, rec, values, start, notes = _setup(record, model, params, set_values, initial, opts)
    c = compare_model(rec, machine, values, start, notes=notes)
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
    the simulated sensor readings (as ``<sensor>_sim``) and the measured ones
    to ``out`` (CSV or Parquet)."""
    from condmon.io.records import write_record

    c, _ = validate_file(record, model, params=params, set_values=set_values, initial=initial,
                         options=options)
    machine = get_model(model)
    rec_frame = _frame(c, machine, record, options or EstimateOptions(model=model))
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
        cols[name] = c.measured[:, j]
    return pd.DataFrame(cols)


def describe_initial(initial: Mapping[str, tuple[float, str]]) -> str:
    """``x1 = 7.47 (estimated), x2 = 2.68 (estimated)``."""
    return ", ".join(f"{k} = {v:.6g} ({how})" for k, (v, how) in initial.items())

