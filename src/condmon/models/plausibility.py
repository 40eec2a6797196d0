"""What a physical model declares physically possible, and the checks made with it.

Declared as data per model (``condmon/data/models.toml``): bounds on each
parameter, the record duration and sample interval the model needs, and the
largest believable change against a unit's baseline. An estimate outside its
bounds is rejected with the reason; a record outside the timing limits, or a
test whose parameters jump beyond the believable change or flip sign, is
refused as a likely unit or sign error.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from condmon.errors import ConfigError, DataError

__all__ = ["Bound", "Plausibility", "parse_plausibility", "IdentifiabilityLimits",
           "parse_identifiability_limits"]

_OPS: dict[str, tuple[str, Callable[[float, float], bool]]] = {
    "gt": (">", operator.gt), "ge": (">=", operator.ge),
    "lt": ("<", operator.lt), "le": ("<=", operator.le)}


@dataclass(frozen=True)
class Bound:
    """Bounds of one parameter: ``{op: value}`` with op in gt, ge, lt, le. [SI]"""

    limits: tuple[tuple[str, float], ...]

    def violation(self, value: float, tolerance: float = 0.0) -> str | None:
        """The first violated bound as text (``"must be > 0"``), or None; a
        bound at 0 is not violated within ``tolerance``."""
        if not math.isfinite(value):
            return "is not finite"
        for op, b in self.limits:
            sym, ok = _OPS[op]
            # the tolerance serves sign constraints only: a quantity that may be
            # exactly zero (a friction a rig does not have) scatters around it
            if not (ok(value, b) or (b == 0.0 and tolerance > 0 and abs(value) <= tolerance)):
                return f"must be {sym} {b:g}"
        return None

    def __str__(self) -> str:
        return " and ".join(f"{_OPS[op][0]} {b:g}" for op, b in self.limits)


@dataclass(frozen=True)
class Plausibility:
    """The physically possible of one model.

    Attributes
    ----------
    bounds : dict of str to Bound
        Per parameter. [SI units]
    min_duration : float
        Shortest record. [s]
    sample_interval : tuple of float
        Allowed sample interval (low, high). [s]
    max_change : dict of str to float
        Largest believable ratio to the baseline mean, either way. [-]
    """

    bounds: dict[str, Bound] = field(default_factory=dict)
    min_duration: float = 0.0
    sample_interval: tuple[float, float] = (0.0, math.inf)
    max_change: dict[str, float] = field(default_factory=dict)

    def check_values(self, values: Mapping[str, float], units: Mapping[str, str],
                     std_errors: Mapping[str, float] | None = None) -> str | None:
        """Why an estimate is not physically possible (None when it is).

        With ``std_errors``, a value beyond a sign bound (at 0) by less than 3
        standard errors is consistent with it (e.g. a Coulomb friction of
        -2e-4 ± 3e-4 N m on a rig that has none) and is not rejected.

        Example
        -------
        >>> p = Plausibility({"R": Bound((("gt", 0.0),))})
        >>> p.check_values({"R": -1.0}, {"R": "ohm"})
        'not physically possible: R = -1 ohm must be > 0'
        """
        bad = []
        for name, bound in self.bounds.items():
            if name in values:
                why = bound.violation(float(values[name]))
                se = float((std_errors or {}).get(name, 0.0))
                if why is not None and math.isfinite(se) and se > 0 and \
                        bound.violation(float(values[name]), 3.0 * se) is None:
                    why = None
                if why is not None:
                    bad.append(f"{name} = {values[name]:.4g} {units.get(name, '')}".rstrip()
                               + f" {why}")
        if not bad:
            return None
        negative = [n for n in self.bounds if n in values and values[n] < 0]
        hint = ("; a sign may be inverted (input or output column negated?)"
                if len(negative) >= 2 else "")
        return "not physically possible: " + ", ".join(bad) + hint

    def excludes_zero(self, name: str) -> bool:
        """Whether the bounds of ``name`` leave 0 out (``R > 0``): a magnitude
        that every unit of the model has, not one that may vanish."""
        bound = self.bounds.get(name)
        if bound is None:
            return False
        return any((op == "gt" and b >= 0) or (op == "ge" and b > 0) or
                   (op == "lt" and b <= 0) or (op == "le" and b < 0) for op, b in bound.limits)

    def check_precision(self, values: Mapping[str, float], units: Mapping[str, str],
                        std_errors: Mapping[str, float]) -> str | None:
        """Why an estimate is not a measurement (None when it is): a parameter
        that cannot be 0 (:meth:`excludes_zero`) whose standard error exceeds
        its value. Its 68 % interval then holds 0 and twice the value alike:
        the record does not tell the unit's value, and a change computed from
        it would be read as any fault (the symptom band spans both ways).

        Example
        -------
        >>> p = Plausibility({"R": Bound((("gt", 0.0),))})
        >>> p.check_precision({"R": 1.08}, {"R": "ohm"}, {"R": 40.5})
        'not a measurement: R = 1.08 ± 40.5 ohm (the standard error exceeds the value)'
        """
        bad = [f"{k} = {values[k]:.3g} ± {std_errors[k]:.3g} {units.get(k, '')}".rstrip()
               for k in self.bounds if k in values and k in std_errors
               and self.excludes_zero(k) and math.isfinite(values[k])
               and math.isfinite(std_errors[k]) and std_errors[k] > abs(values[k])]
        if not bad:
            return None
        return ("not a measurement: " + ", ".join(bad)
                + f" (the standard error exceeds the value{'s' if len(bad) > 1 else ''})")

    def bound_notes(self, values: Mapping[str, float], units: Mapping[str, str],
                    std_errors: Mapping[str, float]) -> list[str]:
        """What to say of estimates near a bound: one outside it by less than 3
        standard errors (kept: consistent with it), or inside it by less than
        one (the data cannot tell it from the bound).

        Example
        -------
        >>> p = Plausibility({"Tc": Bound((("ge", 0.0),))})
        >>> p.bound_notes({"Tc": -6.5e-5}, {"Tc": "N m"}, {"Tc": 1.6e-4})[0][:62]
        'Tc = -6.5e-05 N m lies outside its bound >= 0 by 0.41 standard'
        """
        notes = []
        for name, bound in self.bounds.items():
            if name not in values or name not in std_errors:
                continue
            v, se = float(values[name]), float(std_errors[name])
            if not (math.isfinite(v) and math.isfinite(se) and se > 0):
                continue
            unit = f" {units.get(name, '')}".rstrip()
            for op, b in bound.limits:
                sym, ok = _OPS[op]
                gap = abs(v - b) / se
                if not ok(v, b) and gap <= 3.0:
                    notes.append(f"{name} = {v:.3g}{unit} lies outside its bound {sym} {b:g} "
                                 f"by {gap:.2g} standard errors: consistent with {b:g}, kept")
                elif ok(v, b) and gap < 1.0:
                    notes.append(f"{name} = {v:.3g}{unit} is within one standard error "
                                 f"({se:.2g}{unit}) of its bound {sym} {b:g}: the record "
                                 f"cannot tell it from {b:g}")
        return notes

    def check_timing(self, dt: float, duration: float, source: str, model: str,
                     purpose: str = "a trustworthy estimate") -> None:
        """Refuse a record the model cannot be estimated from.

        Raises
        ------
        DataError
            Naming the file, the measured interval or duration and the limits.
        """
        lo, hi = self.sample_interval
        # a relative tolerance on the bounds: a 500 Hz record's interval reads
        # 0.002 +- 2e-16 s, and 0.002 s is the bound
        if not lo * (1 - 1e-9) <= dt <= hi * (1 + 1e-9):
            hint = ""
            if dt == 1.0:   # 0, 1, 2, ...: the rig's sample counter, or ms at 1 kHz
                hint = (" — is column 't' a sample number (0, 1, 2, ...) or in "
                        "milliseconds? give the sample rate: --sample-rate HZ (or "
                        "sample_rate in [record]); condmon expects t in seconds")
            elif dt >= 0.05 and lo <= dt / 1000.0 <= hi:
                hint = " — is column 't' in milliseconds? (condmon expects seconds)"
            elif dt < lo and lo <= dt * 1000.0 <= hi:
                hint = " — is column 't' in kiloseconds or scaled by 1/1000?"
            raise DataError(f"{source}: sample interval {dt:.6g} s is outside the "
                            f"{lo:g}..{hi:g} s the {model} model needs{hint}")
        if duration < self.min_duration * (1 - 1e-9):
            raise DataError(f"{source}: the record lasts {duration:.4g} s; the {model} model "
                            f"needs at least {self.min_duration:g} s for {purpose}")

    def check_against_baseline(self, values: Mapping[str, float],
                               baseline: Mapping[str, float],
                               units: Mapping[str, str]) -> str | None:
        """Why a test looks like a unit or sign error against the baseline (or None).

        Example
        -------
        >>> p = Plausibility(max_change={"Kt": 5.0})
        >>> p.check_against_baseline({"Kt": 0.005}, {"Kt": 0.05}, {"Kt": "N m/A"})[:40]
        'likely unit or sign error: Kt = 0.005 N '
        """
        bad = []
        for name, ratio_max in self.max_change.items():
            if name not in values or name not in baseline or baseline[name] == 0:
                continue
            ratio = float(values[name]) / float(baseline[name])
            unit = units.get(name, "")
            if ratio <= 0:
                bad.append(f"{name} = {values[name]:.4g} {unit} has the opposite sign of its "
                           f"baseline {baseline[name]:.4g} {unit}")
            elif ratio > ratio_max or ratio < 1.0 / ratio_max:
                bad.append(f"{name} = {values[name]:.4g} {unit} is {ratio:.3g} x its baseline "
                           f"{baseline[name]:.4g} {unit} (believable: /{ratio_max:g} to "
                           f"x{ratio_max:g})")
        if not bad:
            return None
        return ("likely unit or sign error: " + "; ".join(bad)
                + " — check the units and signs of the record's columns")


@dataclass(frozen=True)
class IdentifiabilityLimits:
    """When an unknown counts as identifiable (``[estimation.identifiability]``;
    see :mod:`condmon.identify.identifiability`).

    Attributes
    ----------
    max_collinearity : float
        Largest collinearity index of the estimated set (5 to 20 is usual). [-]
    max_relative_se : float
        Largest relative standard error of an estimated unknown. [-]
    """

    max_collinearity: float = 10.0
    max_relative_se: float = 0.5


def parse_identifiability_limits(table: Any, where: str) -> IdentifiabilityLimits:
    """Read ``[estimation.identifiability]`` (absent: the defaults).

    Example
    -------
    >>> parse_identifiability_limits({"max_collinearity": 20}, "m.toml").max_collinearity
    20.0
    """
    if table is None:
        return IdentifiabilityLimits()
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where}[estimation.identifiability] must be a table with "
                          "max_collinearity, max_relative_se")
    extra = [k for k in table if k not in ("max_collinearity", "max_relative_se")]
    if extra:
        raise ConfigError(f"{where}[estimation.identifiability]: unknown key {extra[0]!r}; "
                          "allowed: max_collinearity, max_relative_se")
    values = {}
    for key, low in (("max_collinearity", 1.0), ("max_relative_se", 0.0)):
        if key in table:
            v = table[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                    math.isfinite(v) and v > low):
                raise ConfigError(f"{where}[estimation.identifiability].{key} must be a "
                                  f"number > {low:g}, not {v!r}")
            values[key] = float(v)
    return IdentifiabilityLimits(**values)


def _bound(name: str, spec: Any, where: str) -> Bound:
    if not isinstance(spec, Mapping) or not spec:
        raise ConfigError(f"{where}: bounds of {name!r} must be a table like "
                          "{ gt = 0.0, lt = 1e3 }")
    limits = []
    for op, value in spec.items():
        if op not in _OPS:
            raise ConfigError(f"{where}: unknown bound {op!r} for {name!r}; "
                              f"allowed: {', '.join(_OPS)}")
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise ConfigError(f"{where}: bound {op} of {name!r} must be a number, got {value!r}")
        limits.append((op, float(value)))
    return Bound(tuple(limits))


def parse_plausibility(cfg: Mapping[str, Any], where: str) -> Plausibility:
    """Read a model's ``plausible``, ``max_change``, ``min_duration`` and
    ``sample_interval`` entries (all optional).

    Raises
    ------
    ConfigError
        Naming the entry.
    """
    bounds = {k: _bound(k, v, where) for k, v in dict(cfg.get("plausible", {})).items()}
    changes: dict[str, float] = {}
    for k, v in dict(cfg.get("max_change", {})).items():
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not v > 1.0:
            raise ConfigError(f"{where}: max_change of {k!r} must be a number > 1, got {v!r}")
        changes[k] = float(v)
    interval = cfg.get("sample_interval", [0.0, math.inf])
    if (not isinstance(interval, (list, tuple)) or len(interval) != 2
            or not all(isinstance(x, (int, float)) for x in interval)
            or not 0 <= interval[0] < interval[1]):
        raise ConfigError(f"{where}: sample_interval must be [low, high] in seconds, "
                          f"got {interval!r}")
    duration = cfg.get("min_duration", 0.0)
    if not isinstance(duration, (int, float)) or duration < 0:
        raise ConfigError(f"{where}: min_duration must be a number >= 0 [s], got {duration!r}")
    return Plausibility(bounds, float(duration), (float(interval[0]), float(interval[1])),
                        changes)
