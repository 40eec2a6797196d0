"""The one registry of machine models: every machine is a declaration (TOML).

Shipped entries: ``dc-motor`` (linear, estimated by SRIV through its transfer
functions), ``dc-motor-coulomb`` (with Coulomb friction, estimated by output
error) and ``hst`` (the hydrostatic transmission, monitored by residuals and
isolation). A user's declaration file is used by its path, or
registered under a name with :func:`register_model`.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from condmon.errors import CondmonError, ConfigError, MissingColumnsError, ModelError
from condmon.io.config import load_default, load_toml
from condmon.models.declared import PlantModel, plant_from_doc
from condmon.models.indicators import indicator_machine, indicators_from_doc, is_indicator_doc
from condmon.models.limits import equation_limits
from condmon.models.machine import Machine
from condmon.models.machine_doc import machine_from_doc

__all__ = ["get_model", "list_models", "register_model", "recognise_record",
           "recognised_records", "load_plant_model", "list_plant_models"]

#: Shipped declarations: name -> file in condmon/data.
_SHIPPED = {"dc-motor": "dc-motor.toml", "dc-motor-coulomb": "dc-motor-coulomb.toml",
            "hst": "hst.toml"}
_USER: dict[str, Path] = {}
_CACHE: dict[str, Machine] = {}


def list_models() -> list[str]:
    """Names of the machine models: shipped and registered.

    Example
    -------
    >>> [m for m in list_models() if m in ("dc-motor", "dc-motor-coulomb", "hst")]
    ['dc-motor', 'dc-motor-coulomb', 'hst']
    """
    return sorted({*_SHIPPED, *_USER})


def register_model(name: str, path: str | Path) -> Machine:
    """Register a declaration file under ``name`` (validated now, not at first use).

    Raises
    ------
    ConfigError
        When the file does not exist or is not a valid declaration.
    """
    machine = _load(Path(path))
    _USER[name] = Path(path)
    _CACHE[name] = machine
    return machine


def get_model(model: str | Path) -> Machine:
    """A machine model by name (shipped or registered) or declaration file.

    Raises
    ------
    ModelError
        Unknown name (the allowed ones listed).
    ConfigError
        An invalid declaration (file and entry named).

    Example
    -------
    >>> get_model("dc-motor").spec.unknowns
    ('R', 'L', 'Kt', 'J', 'D')
    """
    key = str(model)
    if key in _USER or key in _SHIPPED:
        if key in _CACHE:
            return _CACHE[key]
        machine = (_load(_USER[key]) if key in _USER else
                   _machine(load_default(_SHIPPED[key]), _SHIPPED[key], shipped=True))
        _CACHE[key] = machine
        return machine
    if not (Path(key).suffix.lower() == ".toml" or Path(key).is_file()):
        raise ModelError(f"unknown model {key!r}; give a declaration file (.toml) or one "
                         f"of: {', '.join(list_models())}")
    # a file: known by its content too, so an edited declaration is read again
    cached = f"{key}\0{_content(Path(key))}"
    if cached not in _CACHE:
        _CACHE[cached] = _load(Path(key))
    return _CACHE[cached]


def _content(path: Path) -> str:
    """A digest of a declaration file's bytes ("" when it cannot be read: the
    loading says why)."""
    import hashlib

    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return ""


def _load(path: Path) -> Machine:
    if not path.exists():
        raise ConfigError(f"{path}: declaration file not found")
    return _machine(load_toml(path), str(path))


def _machine(doc: dict[str, Any], source: str, shipped: bool = False) -> Machine:
    origin = None if shipped else str(Path(source).resolve())
    if is_indicator_doc(doc):
        return indicator_machine(indicators_from_doc(doc, source), origin)
    with _time_limit(equation_limits().time_limit, source):
        return machine_from_doc(plant_from_doc(doc, source), doc, origin)


@contextmanager
def _time_limit(seconds: float, source: str) -> Iterator[None]:
    """Refuse a declaration whose reading takes longer than ``seconds`` (a
    backstop behind the equations' limits; on the main thread where the
    platform has interval timers, else not enforced)."""
    if (threading.current_thread() is not threading.main_thread()
            or not hasattr(signal, "setitimer")):
        yield
        return

    def expired(signum: int, frame: Any) -> None:
        raise ConfigError(f"{source}: reading the declaration took longer than {seconds:g} s "
                          "([equations] time_limit of condmon/data/limits.toml)")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _record_columns(machine: Machine) -> list[set[str]]:
    """The column sets a record of ``machine`` is known by: its sensors under
    the model's names, and under its rig's file names when it has a ``[record]``."""
    own = set(machine.plant.sensor_names)
    raw = {machine.record.columns.get(n, n) for n in own}
    return [own, raw] if raw != own else [own]


def recognise_record(columns: Iterable[str], model: str | Machine) -> list[str]:
    """The other models (shipped and registered) whose records have these columns.

    A model is recognised when the columns hold every one of its sensors (under
    the model's names or its rig's) and ``model``'s own sensors are not all there.

    Example
    -------
    >>> recognise_record(["t", "Ps", "omega_m", "omega_p"], "dc-motor")
    ['hst']
    >>> recognise_record(["t", "V", "I", "omega"], "dc-motor")
    []
    """
    current = model if isinstance(model, Machine) else get_model(model)
    have = set(columns)
    if any(cols <= have for cols in _record_columns(current)):
        return []
    found = []
    for name in list_models():
        try:
            other = get_model(name)
        except CondmonError:
            continue  # a registered file since broken: not a candidate
        if other.name != current.name and any(cols <= have for cols in _record_columns(other)):
            found.append(name)
    return found


@contextmanager
def recognised_records(model: str | Machine | None) -> Iterator[None]:
    """Turn a record's missing columns into "this looks like a ... record" when
    the record is one of another model (a file in the wrong unit, a unit with
    the wrong model); other errors pass as they are.

    Example
    -------
    >>> with recognised_records("dc-motor"):
    ...     raise MissingColumnsError("r.csv: missing column(s) 'V'", ("V",),
    ...                               ("t", "Ps", "omega_m", "omega_p"))
    Traceback (most recent call last):
    ...
    condmon.errors.MissingColumnsError: r.csv: this looks like a record of model 'hst' (its columns t, Ps, omega_m, omega_p), not of model 'dc-motor' (missing V): is the model, or the unit, the right one?
    """
    try:
        yield
    except MissingColumnsError as err:
        if model is None:
            raise
        current = model if isinstance(model, Machine) else get_model(model)
        others = recognise_record(err.columns, current)
        if not others:
            raise
        text = str(err)
        source = text.split(": ", 1)[0] if ": " in text else "record"
        kind = " or ".join(repr(o) for o in others)
        raise MissingColumnsError(
            f"{source}: this looks like a record of model {kind} (its columns "
            f"{', '.join(err.columns)}), not of model {current.name!r} (missing "
            f"{', '.join(err.missing)}): is the model, or the unit, the right one?",
            err.missing, err.columns) from None


def list_plant_models() -> list[str]:
    """Names of the registered machine models (see :func:`condmon.models.list_models`)."""
    return list_models()


def load_plant_model(model: str | Path = "hst", params: str | Path | Mapping[str, float] | None = None
                     ) -> PlantModel:
    """Read and validate a model declaration.

    Parameters
    ----------
    model : str or Path
        A shipped model's name (``"hst"``) or the path of a declaration file.
    params : str, Path or mapping, optional
        Parameter values overriding the declaration's: a TOML file with
        ``name = value`` lines (top level or under ``[parameters]``), or a mapping.

    Returns
    -------
    PlantModel

    Example
    -------
    >>> m = load_plant_model("hst", {"Rv": 12.0})
    >>> m.parameter("Rv").value
    12.0
    """
    # The one registry of machine models, for a name or a file alike: a
    # declaration is validated whole, once, the same way for every command.
    try:
        plant = get_model(model).plant
    except ModelError as err:
        raise ConfigError(str(err)) from None
    if params is None:
        return plant
    if isinstance(params, Mapping):
        return plant.with_parameters(params)
    pdoc = load_toml(params)
    values = pdoc.get("parameters", pdoc)
    bad = {k: v for k, v in values.items()
           if isinstance(v, bool) or not isinstance(v, (int, float))}
    if bad:
        k = next(iter(bad))
        raise ConfigError(f"{params}: parameter {k!r} must be a number, not {bad[k]!r}")
    for k, v in values.items():
        if not any(p.name == k for p in plant.parameters):
            continue   # named by with_parameters below
        declared = plant.parameter(k)
        unit = f" {declared.unit}" if declared.unit else ""
        if declared.range is not None and not declared.range[0] <= v <= declared.range[1]:
            raise ConfigError(f"{params}: {k} = {v:g}{unit} lies outside its declared range "
                              f"[{declared.range[0]:g}, {declared.range[1]:g}]{unit}")
        if declared.range is None and declared.value != 0 and not v * declared.value > 0:
            raise ConfigError(f"{params}: {k} = {v:g}{unit} is not of the sign of its declared "
                              f"value {declared.value:g}{unit}: a sign or unit error?")
    try:
        return plant.with_parameters(values, str(params))
    except ConfigError as err:
        raise ConfigError(f"{params}: {err}") from None
