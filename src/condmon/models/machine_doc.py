"""Reading a declaration's ``[estimation]``, ``[monitor]``, ``[record]``,
``[regimes]``, ``[features]`` and ``[conditions]`` tables into a :class:`~condmon.models.machine.Machine`."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from condmon.errors import ConfigError
from condmon.io.rig import parse_record_settings
from condmon.models.declared import PlantModel
from condmon.models.features import parse_conditions, parse_features
from condmon.models.machine import (
    DATA_DIR, ROUTES, EstimationSpec, Machine, derived_numeric,
)
from condmon.models.plausibility import parse_identifiability_limits, parse_plausibility
from condmon.models.regimes import parse_regimes
from condmon.models.shooting import parse_simulation_settings, state_readers

__all__ = ["machine_from_doc"]


def _names(value: Any, where: str) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ConfigError(f"{where} must be a list of names, got {value!r}")
    return tuple(value)


def _fraction(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < 1:
        raise ConfigError(f"{where} must be a fraction in [0, 1), got {value!r}")
    return float(value)


def machine_from_doc(plant: PlantModel, doc: Mapping[str, Any],
                     origin: str | None = None) -> Machine:
    """Read a declaration's ``[estimation]`` and ``[monitor]`` tables (validated
    against the plant). ``origin``: the file of a user's declaration (its
    ``[monitor]`` files are relative to it), None for a shipped one.

    Raises
    ------
    ConfigError
        Naming the file and the entry.
    """
    src = plant.source
    mon = doc.get("monitor", {})
    if not isinstance(mon, dict) or set(mon) - {"rules", "breakpoints"}:
        raise ConfigError(f"{src}[monitor]: a table with 'rules' and 'breakpoints' (files, "
                          "relative to the declaration)")
    base = Path(src).parent if origin is not None else DATA_DIR

    def _file(key: str) -> str | None:
        if key not in mon:
            return None
        if not isinstance(mon[key], str):
            raise ConfigError(f"{src}[monitor].{key} must be a file name, got {mon[key]!r}")
        path = base / mon[key]
        if not path.exists():
            raise ConfigError(f"{src}[monitor].{key}: {path} not found")
        return str(path)

    record = parse_record_settings(doc.get("record"), f"{src}[record]")
    regimes = parse_regimes(doc.get("regimes"), src)
    est_table = doc.get("estimation")
    derived_names = tuple(dict(est_table.get("derived", {}))) if isinstance(est_table, dict) \
        else ()
    features = parse_features(doc.get("features"), src,
                              reserved=(*plant.parameter_names, *derived_names),
                              regimes=tuple(r.name for r in regimes.regimes),
                              sample_rate=record.sample_rate)
    conditions = parse_conditions(doc.get("conditions"), src,
                                  reserved=(*plant.parameter_names, *derived_names,
                                            *(f.name for f in features)),
                                  regimes=tuple(r.name for r in regimes.regimes))
    files: dict[str, Any] = {"origin": origin, "rules": _file("rules"),
                             "breakpoints": _file("breakpoints"), "record": record,
                             "regimes": regimes, "features": features,
                             "conditions": conditions}
    est = doc.get("estimation")
    if est is None:  # a model for residuals and isolation only (e.g. the HST)
        return Machine(plant, EstimationSpec((), ()), **files)
    if not isinstance(est, dict):
        raise ConfigError(f"{src}: [estimation] must be a table")
    allowed = {"estimate", "report", "derived", "route", "order", "excitation", "cutoff",
               "decimate", "plausible", "max_change", "min_duration", "sample_interval",
               "max_residual_correlation", "deadband", "residual_warning", "structure_hint",
               "identifiability", "steady_tolerance", "initial", "segments", "starts", "cycle"}
    unknown = set(est) - allowed
    if unknown:
        raise ConfigError(f"{src}[estimation]: unknown key {sorted(unknown)[0]!r}; "
                          f"allowed: {', '.join(sorted(allowed))}")
    unknowns = _names(est.get("estimate"), f"{src}[estimation].estimate")
    if not unknowns:
        raise ConfigError(f"{src}[estimation].estimate lists no parameter to estimate")
    for k in unknowns:
        if k not in plant.parameter_names:
            raise ConfigError(f"{src}[estimation].estimate: unknown parameter {k!r}; "
                              f"allowed: {', '.join(plant.parameter_names)}")
    derived: dict[str, tuple[str, str]] = {}
    for k, v in dict(est.get("derived", {})).items():
        if not isinstance(v, dict) or "equation" not in v:
            raise ConfigError(f"{src}[estimation.derived.{k}] must be {{ equation = \"...\", "
                              "unit = \"...\" }")
        derived[k] = (str(v["equation"]), str(v.get("unit", "")))
    report = _names(est.get("report", [*unknowns, *derived]), f"{src}[estimation].report")
    for k in report:
        if k not in unknowns and k not in derived:
            raise ConfigError(f"{src}[estimation].report: {k!r} is neither estimated nor "
                              "derived")
    route = est.get("route", "auto")
    if route not in ROUTES:
        raise ConfigError(f"{src}[estimation].route: unknown route {route!r}; "
                          f"allowed: {', '.join(ROUTES)}")
    order = est.get("order")
    if order is not None and (not isinstance(order, int) or isinstance(order, bool) or order < 1):
        raise ConfigError(f"{src}[estimation].order must be a positive integer, got {order!r}")
    cutoff = est.get("cutoff")
    if cutoff is not None and (isinstance(cutoff, bool) or not isinstance(cutoff, (int, float))
                               or not cutoff > 0):
        raise ConfigError(f"{src}[estimation].cutoff must be a frequency > 0 [Hz], got {cutoff!r}")
    decimate = est.get("decimate", 1)
    if not isinstance(decimate, int) or isinstance(decimate, bool) or decimate < 1:
        raise ConfigError(f"{src}[estimation].decimate must be an integer >= 1, got {decimate!r}")
    for table in ("plausible", "max_change"):
        for k in dict(est.get(table, {})):
            if k not in report:
                raise ConfigError(f"{src}[estimation.{table}]: {k!r} is not a reported "
                                  f"quantity; allowed: {', '.join(report)}")
    corr = est.get("max_residual_correlation", 0.8)
    if isinstance(corr, bool) or not isinstance(corr, (int, float)) or not 0 < corr <= 1:
        raise ConfigError(f"{src}[estimation].max_residual_correlation must be in (0, 1], "
                          f"got {corr!r}")
    cycle = _names(est.get("cycle", []), f"{src}[estimation].cycle")
    declared = [r.name for r in files["regimes"].regimes if r.use]
    if "cycle" in est and (len(cycle) < 2 or len(set(cycle)) != len(cycle)):
        raise ConfigError(f"{src}[estimation].cycle must name two regimes or more, each "
                          f"once, got {list(cycle)!r}")
    for k in cycle:
        if k not in declared:
            unused = " (use = false: its windows are never estimated)" if k in [
                r.name for r in files["regimes"].regimes] else ""
            raise ConfigError(f"{src}[estimation].cycle: {k!r} is not a declared regime the "
                              f"estimation uses{unused}; allowed: "
                              f"{', '.join(declared) or 'none ([regimes] is empty)'}")
    spec = EstimationSpec(
        unknowns, report, derived, str(route), order,
        _names(est.get("excitation", []), f"{src}[estimation].excitation"),
        None if cutoff is None else float(cutoff), decimate,
        parse_plausibility(est, f"{src}[estimation]"), float(corr),
        _fraction(est.get("deadband", 0.01), f"{src}[estimation].deadband"),
        _fraction(est.get("residual_warning", 0.15), f"{src}[estimation].residual_warning"),
        str(est.get("structure_hint", "")),
        parse_identifiability_limits(est.get("identifiability"), src),
        _fraction(est.get("steady_tolerance", 0.1), f"{src}[estimation].steady_tolerance"),
        parse_simulation_settings(est, plant.state_names, lambda: set(state_readers(plant)),
                                  src), cycle)
    machine = Machine(plant, spec, **files)
    derived_numeric(machine)  # every derived equation parses
    return machine

