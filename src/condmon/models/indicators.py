"""Indicator declarations: a machine's health indicators measured elsewhere,
with their units and end-of-life levels, and no equations.

A battery's capacity per charge cycle, a resistance from an impedance test, a
value another system computes: condmon stores them as checks of a unit
(``condmon import``), trends them against the unit's baseline and forecasts
when they reach their end of life, like the parameters it estimates itself.

A declaration::

    name = "li-ion-18650"
    description = "18650 Li-ion cell, rated 2 Ah"

    [indicators]
    capacity = { unit = "Ah", rated = 2.0, end_of_life = "< 1.4 Ah",
                 fault = "capacity fade", description = "discharge capacity" }

    [forecast]
    method = "path"        # or "trend"

An end of life (:class:`EndOfLife`) is an absolute level in the indicator's
unit (``"< 1.4 Ah"``, the unit optional), a share of the rated value
(``"< 70 % rated"``) or a change from the unit's baseline (``"-30 %"``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from condmon.errors import ConfigError

if TYPE_CHECKING:
    from condmon.models.machine import Machine

__all__ = ["EndOfLife", "Indicator", "IndicatorModel", "parse_end_of_life", "is_indicator_doc",
           "indicators_from_doc", "load_indicators", "override_end_of_life", "with_end_of_life", "with_own_end_of_life",
           "indicator_machine"]

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_LEVEL = re.compile(rf"^\s*([<>])\s*({_NUMBER})\s*(.*?)\s*$")
_CHANGE = re.compile(rf"^\s*([-+]\s*{_NUMBER})\s*%\s*$")
_NAMED = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(.*)$")
_FORMS = ("'< 1.4 Ah' (a level in the indicator's unit), '< 70 % rated' (a share of its "
          "rated value) or '-30 %' (a change from the unit's baseline)")


@dataclass(frozen=True)
class EndOfLife:
    """Where an indicator reaches its end of life: the unit turns no-go.

    Attributes
    ----------
    kind : {"level", "rated", "change"}
        An absolute level, a share of the rated value, or a change from the
        baseline's mean.
    below : bool
        The end of life is below it (a fall: capacity), else above (a rise).
    value : float
        The level [the indicator's unit], the share [% of rated], or the
        change, signed [%].
    text : str
        As written.

    Example
    -------
    >>> e = parse_end_of_life("< 70 % rated", "capacity", "Ah", rated=2.0)
    >>> e.level(1.9, rated=2.0), round(e.change(1.9, rated=2.0), 2)
    (1.4, -26.32)
    """

    kind: str
    below: bool
    value: float
    text: str

    def level(self, mean: float, rated: float | None = None) -> float:
        """The end of life as a value, against a baseline ``mean``. [indicator unit]"""
        if self.kind == "level":
            return self.value
        if self.kind == "rated":
            return self.value / 100.0 * float(rated if rated is not None else math.nan)
        return mean * (1.0 + self.value / 100.0)

    def change(self, mean: float, rated: float | None = None) -> float:
        """The end of life as a change from the baseline ``mean``, signed. [%]"""
        if self.kind == "change":
            return self.value
        return 100.0 * (self.level(mean, rated) - mean) / abs(mean) if mean else math.nan

    def reached(self, value: float, mean: float, rated: float | None = None) -> bool:
        """Whether ``value`` is past the end of life."""
        lvl = self.level(mean, rated)
        return value < lvl if self.below else value > lvl


@dataclass(frozen=True)
class Indicator:
    """One health indicator of an indicator declaration.

    Attributes
    ----------
    name, unit, description : str
    end_of_life : EndOfLife
    rated : float or None
        The rated (new) value. [unit]
    fault : str
        What reaching the end of life is called ("capacity fade").
    advice : str
    """

    name: str
    unit: str
    end_of_life: EndOfLife
    description: str = ""
    rated: float | None = None
    fault: str = ""
    advice: str = ""


@dataclass(frozen=True)
class IndicatorModel:
    """An indicator declaration (see the module).

    Attributes
    ----------
    name, description : str
    indicators : tuple of Indicator
    method : {"path", "trend"}
        How its forecasts are made (:mod:`condmon.forecast.measured`).
    source : str
        The declaration file.
    """

    name: str
    indicators: tuple[Indicator, ...]
    method: str = "path"
    description: str = ""
    source: str = ""

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(i.name for i in self.indicators)

    @property
    def units(self) -> dict[str, str]:
        """Unit of every indicator."""
        return {i.name: i.unit for i in self.indicators}

    def indicator(self, name: str) -> Indicator:
        """The indicator ``name``.

        Raises
        ------
        ConfigError
            Not declared (the declared ones named).
        """
        for i in self.indicators:
            if i.name == name:
                return i
        raise ConfigError(f"{self.source or self.name}: no indicator {name!r}; it declares "
                          f"{', '.join(self.names)}")


def parse_end_of_life(text: str, name: str, unit: str, rated: float | None = None,
                      where: str = "") -> EndOfLife:
    """Read an end of life as written (see :class:`EndOfLife`).

    Raises
    ------
    ConfigError
        Another form, a level in other units than ``unit``, a share of a
        rated value the indicator does not declare.

    Example
    -------
    >>> parse_end_of_life("< 1.4 Ah", "capacity", "Ah")
    EndOfLife(kind='level', below=True, value=1.4, text='< 1.4 Ah')
    >>> parse_end_of_life("-30 %", "capacity", "Ah").change(2.0)
    -30.0
    """
    at = where or f"end of life of {name!r}"
    raw = str(text).strip()
    m = _CHANGE.match(raw)
    if m:
        value = float(m.group(1).replace(" ", ""))
        if value == 0 or not math.isfinite(value):
            raise ConfigError(f"{at}: {raw!r} is no change; give {_FORMS}")
        return EndOfLife("change", value < 0, value, raw)
    m = _LEVEL.match(raw)
    if not m:
        raise ConfigError(f"{at}: {raw!r} is not an end of life; give {_FORMS}")
    below, value, rest = m.group(1) == "<", float(m.group(2)), m.group(3)
    if not math.isfinite(value):
        raise ConfigError(f"{at}: {raw!r}: the level must be a finite number")
    share = re.fullmatch(r"%\s*(?:of\s+)?rated", rest)
    if share:
        if rated is None:
            raise ConfigError(f"{at}: {raw!r} is a share of the rated value, but {name!r} "
                              "declares no 'rated' value")
        return EndOfLife("rated", below, value, raw)
    if rest and rest != unit:
        raise ConfigError(f"{at}: {raw!r} is in {rest!r}, but {name!r} is in {unit!r}; "
                          f"give the level in {unit}")
    return EndOfLife("level", below, value, raw)


def override_end_of_life(model: IndicatorModel, text: str, where: str = "--no-go"
                         ) -> tuple[str, EndOfLife]:
    """Read ``'capacity<0.88'`` (an indicator's name, then its end of life)
    against ``model``: the indicator and its end of life.

    Raises
    ------
    ConfigError
        No indicator of that name, or an end of life it cannot take.

    Example
    -------
    >>> m = IndicatorModel("cell", (Indicator("capacity", "Ah",
    ...                     parse_end_of_life("< 1.4", "capacity", "Ah")),))
    >>> override_end_of_life(m, "capacity<0.88")[1].value
    0.88
    """
    m = _NAMED.match(str(text))
    if not m or not m.group(2):
        raise ConfigError(f"{where} {text!r}: give an indicator and its end of life, "
                          f"e.g. '{model.names[0]}<1.4'")
    ind = model.indicator(m.group(1))
    return ind.name, parse_end_of_life(m.group(2), ind.name, ind.unit, ind.rated,
                                       f"{where} {text!r}")


def is_indicator_doc(doc: Mapping[str, Any]) -> bool:
    """Whether a declaration's document declares indicators, not equations."""
    return "indicators" in doc and "states" not in doc


_KEYS = {"unit", "end_of_life", "description", "rated", "fault", "advice"}


def indicators_from_doc(doc: Mapping[str, Any], source: str) -> IndicatorModel:
    """An :class:`IndicatorModel` from a declaration's document.

    Raises
    ------
    ConfigError
        A missing or unknown entry, naming the file and the entry.
    """
    unknown = sorted(set(doc) - {"name", "description", "indicators", "forecast"})
    if unknown:
        raise ConfigError(f"{source}: unknown entry {unknown[0]!r}; an indicator declaration "
                          "holds name, description, [indicators] and [forecast]")
    name = doc.get("name")
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.-]{1,64}", name):
        raise ConfigError(f"{source}: 'name' must be a model name (letters, digits, . _ -)")
    table = doc.get("indicators")
    if not isinstance(table, Mapping) or not table:
        raise ConfigError(f"{source}: [indicators] must name at least one indicator")
    out = []
    for key, entry in table.items():
        at = f"{source}[indicators.{key}]"
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,63}", key):
            raise ConfigError(f"{at}: not a valid name (letters, digits, _)")
        if not isinstance(entry, Mapping):
            raise ConfigError(f"{at} must be a table with unit and end_of_life")
        bad = sorted(set(entry) - _KEYS)
        if bad:
            raise ConfigError(f"{at}: unknown key {bad[0]!r}; allowed: {', '.join(sorted(_KEYS))}")
        for need in ("unit", "end_of_life"):
            if not isinstance(entry.get(need), str):
                raise ConfigError(f"{at}: missing {need!r} (text)")
        rated = entry.get("rated")
        if rated is not None and (isinstance(rated, bool) or not isinstance(rated, (int, float))
                                  or not math.isfinite(rated) or rated == 0):
            raise ConfigError(f"{at}.rated must be a finite number other than 0")
        eol = parse_end_of_life(entry["end_of_life"], key, entry["unit"],
                                None if rated is None else float(rated), f"{at}.end_of_life")
        out.append(Indicator(key, entry["unit"], eol, str(entry.get("description", "")),
                             None if rated is None else float(rated),
                             str(entry.get("fault", "") or f"{key} at end of life"),
                             str(entry.get("advice", ""))))
    forecast = doc.get("forecast", {})
    method = forecast.get("method", "path") if isinstance(forecast, Mapping) else None
    if method not in ("path", "trend"):
        raise ConfigError(f"{source}[forecast].method must be 'path' or 'trend', not {method!r}")
    return IndicatorModel(name, tuple(out), method, str(doc.get("description", "")), source)


def load_indicators(path: str | Path) -> IndicatorModel:
    """Read an indicator declaration file.

    Raises
    ------
    ConfigError
        Not found, not TOML, not an indicator declaration, or invalid.
    """
    from condmon.io.config import load_toml

    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: declaration file not found")
    doc = load_toml(p)
    if not is_indicator_doc(doc):
        raise ConfigError(f"{p}: not an indicator declaration (it has no [indicators] table, "
                          "or has [states]: a model condmon estimates)")
    return indicators_from_doc(doc, str(p))


def with_own_end_of_life(model: IndicatorModel, own: Mapping[str, str], where: str = ""
                         ) -> IndicatorModel:
    """``model`` with a unit's own end of life per indicator, as written
    (``{"capacity": "<0.88"}``; an indicator the model lacks is ignored).

    Raises
    ------
    ConfigError
        An end of life the indicator cannot take.
    """
    return with_end_of_life(model, {
        k: parse_end_of_life(v, k, model.indicator(k).unit, model.indicator(k).rated,
                             f"{where}: end of life of {k!r}" if where else "")
        for k, v in own.items() if k in model.names})


def indicator_machine(model: IndicatorModel, origin: str | None) -> Machine:
    """The :class:`~condmon.models.machine.Machine` an indicator declaration
    is to the rest of condmon: its indicators are the plant's parameters
    (candidate faults, at their rated values) and what is monitored; it has
    no equations, nothing to estimate (``require_estimation`` says to
    import), and generic monitoring."""
    from condmon.models.declared import BuiltInTest, Parameter, PlantModel
    from condmon.models.machine import EstimationSpec, Machine

    plant = PlantModel(model.name, model.description, tuple(
        Parameter(i.name, i.rated if i.rated is not None else 1.0, i.unit, i.description,
                  fault=True) for i in model.indicators), (), (), (), (),
        BuiltInTest(1.0, 1.0), model.source)
    return Machine(plant, EstimationSpec(unknowns=(), report=model.names), origin,
                   indicators=model)


def with_end_of_life(model: IndicatorModel, overrides: Mapping[str, EndOfLife]
                     ) -> IndicatorModel:
    """``model`` with some indicators' end of life replaced (a unit's own)."""
    return replace(model, indicators=tuple(
        replace(i, end_of_life=overrides[i.name]) if i.name in overrides else i
        for i in model.indicators))
