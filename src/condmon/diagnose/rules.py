"""Rule bases of the fuzzy fault diagnoser: loading, validation, condition parsing.

A condition such as ``high(R) and not (low(L) or high(J))`` is parsed once, at
load, into a small expression tree (no ``eval``); evaluation is vectorised.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Union

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConfigError
from condmon.io.config import load_default, load_toml

if TYPE_CHECKING:
    from condmon.models.machine import Machine
    from condmon.monitor.generic import GenericSettings

__all__ = ["Atom", "Expr", "parse_condition", "evaluate", "FaultRule", "Preprocess",
           "StatusSets", "RuleBase", "load_rules", "SEVERITIES", "generic_rules", "machine_rules"]

FloatArray = NDArray[np.float64]
SEVERITIES = ("major", "minor")


@dataclass(frozen=True)
class Atom:
    """A symptom reference: ``kind`` is "high" or "low", ``parameter`` its name."""

    kind: str
    parameter: str

    def __str__(self) -> str:
        return f"{self.kind}({self.parameter})"


@dataclass(frozen=True)
class _Op:
    op: str  # "and", "or", "not"
    args: tuple[Expr, ...]


Expr = Union[Atom, _Op]

_TOKEN = re.compile(r"\s*(?:(?P<word>[A-Za-z_][A-Za-z0-9_]*)|(?P<sym>[()]))")


def _tokens(text: str) -> list[str]:
    out, pos = [], 0
    text = text.strip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            raise ConfigError(f"cannot read condition {text!r} at {text[pos:]!r}")
        out.append(m.group("word") or m.group("sym"))
        pos = m.end()
    return out


def parse_condition(text: str) -> Expr:
    """Parse ``high(P)``/``low(P)`` terms joined by and/or/not and parentheses.

    Example
    -------
    >>> str(parse_condition("high(R) and not high(L)").args[1].args[0])
    'high(L)'
    """
    toks = _tokens(text)
    pos = 0

    def peek() -> str | None:
        return toks[pos] if pos < len(toks) else None

    def take(expected: str | None = None) -> str:
        nonlocal pos
        if pos >= len(toks):
            raise ConfigError(f"condition {text!r} ends early")
        tok = toks[pos]
        if expected is not None and tok.lower() != expected:
            raise ConfigError(f"condition {text!r}: expected {expected!r}, found {tok!r}")
        pos += 1
        return tok

    def expr() -> Expr:
        node = term()
        while (peek() or "").lower() == "or":
            take()
            node = _Op("or", (node, term()))
        return node

    def term() -> Expr:
        node = factor()
        while (peek() or "").lower() == "and":
            take()
            node = _Op("and", (node, factor()))
        return node

    def factor() -> Expr:
        tok = peek()
        if tok is None:
            raise ConfigError(f"condition {text!r} ends early")
        if tok.lower() == "not":
            take()
            return _Op("not", (factor(),))
        if tok == "(":
            take("(")
            node = expr()
            take(")")
            return node
        kind = take().lower()
        if kind not in ("high", "low"):
            raise ConfigError(f"condition {text!r}: expected high(P), low(P), not or '(', "
                              f"found {tok!r}")
        take("(")
        name = take()
        take(")")
        return Atom(kind, name)

    tree = expr()
    if pos != len(toks):
        raise ConfigError(f"condition {text!r}: unexpected {toks[pos]!r}")
    return tree


def atoms(e: Expr) -> list[Atom]:
    """Every symptom an expression refers to."""
    if isinstance(e, Atom):
        return [e]
    return [a for arg in e.args for a in atoms(arg)]


def evaluate(e: Expr, high: Mapping[str, FloatArray | float],
             low: Mapping[str, FloatArray | float]) -> FloatArray:
    """Degree of an expression: and = min, or = max, not = 1 - x (vectorised)."""
    if isinstance(e, Atom):
        return np.asarray((high if e.kind == "high" else low)[e.parameter], dtype=np.float64)
    vals = [evaluate(a, high, low) for a in e.args]
    if e.op == "and":
        return np.minimum(vals[0], vals[1])
    if e.op == "or":
        return np.maximum(vals[0], vals[1])
    return 1.0 - vals[0]


@dataclass(frozen=True)
class FaultRule:
    """IF ``condition`` THEN fault ``name`` (with ``severity`` and ``advice``)."""

    name: str
    condition: Expr
    text: str
    severity: str
    advice: str


@dataclass(frozen=True)
class Preprocess:
    """IF ``dominant`` exceeds every other SymH THEN set the ``clear`` symptoms to 0."""

    name: str
    dominant: Atom
    clear: tuple[Atom, ...]
    why: str = ""


@dataclass(frozen=True)
class StatusSets:
    """Membership functions of the output variable "condition" on [0, 1]."""

    go: tuple[float, ...]
    advisory: tuple[float, ...]
    no_go: tuple[float, ...]


@dataclass(frozen=True)
class RuleBase:
    """A validated rule base.

    Attributes
    ----------
    faults : tuple of FaultRule
    preprocess : tuple of Preprocess
    status : StatusSets
    source : str
        File it came from.
    """

    faults: tuple[FaultRule, ...]
    preprocess: tuple[Preprocess, ...]
    status: StatusSets
    source: str

    def parameters(self) -> set[str]:
        """Every parameter the rules refer to."""
        out = {a.parameter for r in self.faults for a in atoms(r.condition)}
        for p in self.preprocess:
            out |= {p.dominant.parameter, *(a.parameter for a in p.clear)}
        return out

    def check_parameters(self, available: Sequence[str]) -> None:
        """Refuse rules about parameters the monitor does not produce."""
        unknown = sorted(self.parameters() - set(available))
        if unknown:
            raise ConfigError(f"{self.source}: rules refer to unknown parameter(s) {unknown}; "
                              f"available: {list(available)}")


def _single_atom(text: str, where: str) -> Atom:
    e = parse_condition(text)
    if not isinstance(e, Atom):
        raise ConfigError(f"{where}: expected a single high(P) or low(P), got {text!r}")
    return e


def _set(raw: Any, name: str, src: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in raw)
    except (TypeError, ValueError):
        raise ConfigError(f"{src}: [status] {name} must be a list of numbers") from None
    if len(vals) not in (3, 4) or list(vals) != sorted(vals) or vals[0] < 0 or vals[-1] > 1:
        raise ConfigError(f"{src}: [status] {name} must be 3 (triangle) or 4 (trapezoid) "
                          f"non-decreasing points in [0, 1], got {list(vals)}")
    return vals


def load_rules(path: str | Path | None = None) -> RuleBase:
    """Load and validate a rule base (the shipped default if ``path`` is None).

    Example
    -------
    >>> rb = load_rules()
    >>> [r.name for r in rb.faults][:2]
    ['friction increase', 'winding resistance increase']
    """
    src = str(path) if path is not None else "condmon/data/rules.toml"
    raw = load_toml(path) if path is not None else load_default("rules.toml")
    faults: list[FaultRule] = []
    for i, item in enumerate(raw.get("fault", [])):
        where = f"{src}: [[fault]] #{i + 1}"
        for key in ("name", "if", "severity", "advice"):
            if key not in item:
                raise ConfigError(f"{where} has no {key!r}")
        if item["severity"] not in SEVERITIES:
            raise ConfigError(f"{where}: severity {item['severity']!r}; allowed: "
                              f"{', '.join(SEVERITIES)}")
        try:
            cond = parse_condition(str(item["if"]))
        except ConfigError as err:
            raise ConfigError(f"{where} ({item['name']}): {err}") from None
        rule = FaultRule(str(item["name"]), cond, str(item["if"]), str(item["severity"]),
                         str(item["advice"]))
        # rules of one name are one fault (the largest degree): one severity, one advice
        first = next((f for f in faults if f.name == rule.name), None)
        if first is not None and (first.severity, first.advice) != (rule.severity, rule.advice):
            what = "severity" if first.severity != rule.severity else "advice"
            raise ConfigError(f"{where} ({rule.name}): another rule of this name has another "
                              f"{what}; rules of one name are one fault, with one severity and "
                              "one advice: give them the same, or name the faults apart")
        faults.append(rule)
    if not faults:
        raise ConfigError(f"{src}: no [[fault]] rules")
    pre = []
    for i, item in enumerate(raw.get("preprocess", [])):
        where = f"{src}: [[preprocess]] #{i + 1}"
        if "if_dominant" not in item or "clear" not in item:
            raise ConfigError(f"{where} needs 'if_dominant' and 'clear'")
        pre.append(Preprocess(str(item.get("name", f"preprocess {i + 1}")),
                              _single_atom(str(item["if_dominant"]), where),
                              tuple(_single_atom(str(c), where) for c in item["clear"]),
                              str(item.get("why", ""))))
    # no [status]: the shipped membership functions of the output (a rules file
    # names faults; how a degree reads as go / advisory / no-go is rarely its own)
    st = raw["status"] if "status" in raw else load_default("rules.toml")["status"]
    for key in ("go", "advisory", "no_go"):
        if key not in st:
            raise ConfigError(f"{src}: [status] has no {key!r}; it takes three membership "
                              "functions on [0, 1], e.g. go = [0.0, 0.0, 0.25, 0.5], "
                              "advisory = [0.25, 0.5, 0.75], no_go = [0.5, 0.75, 1.0, 1.0] "
                              "(leave [status] out for these)")
    status = StatusSets(_set(st["go"], "go", src), _set(st["advisory"], "advisory", src),
                        _set(st["no_go"], "no_go", src))
    return RuleBase(tuple(faults), tuple(pre), status, src)


def generic_rules(parameters: Sequence[str], descriptions: Mapping[str, str],
                  settings: GenericSettings | None = None) -> RuleBase:
    """``<parameter> increase`` (high) and ``<parameter> decrease`` (low) for each parameter.

    Example
    -------
    >>> rb = generic_rules(["Tc"], {"Tc": "Coulomb friction"})
    >>> [r.name for r in rb.faults]
    ['Coulomb friction (Tc) increase', 'Coulomb friction (Tc) decrease']
    """
    from condmon.models.regimes import split_key
    from condmon.monitor.generic import load_generic_settings

    cfg = settings or load_generic_settings()
    faults = []
    names = list(dict.fromkeys(split_key(p)[0] for p in parameters))
    for p in names:
        label = f"{descriptions[p]} ({p})" if descriptions.get(p) else p
        for kind, way in (("high", "increase"), ("low", "decrease")):
            faults.append(FaultRule(
                f"{label} {way}", Atom(kind, p), f"{kind}({p})", cfg.severity,
                f"{label} has {'risen' if kind == 'high' else 'fallen'} beyond the spread of "
                "the baseline it is compared with; the declaration names no fault rules, so "
                "inspect what drives this parameter."))
    return RuleBase(tuple(faults), (), StatusSets(*cfg.status),
                    "generic rules (no [monitor] table)")


def machine_rules(machine: Machine) -> RuleBase:
    """The rule base of a machine: its ``[monitor]`` rules, or the generic
    ``<parameter> increase / decrease`` ones when it declares none.

    Example
    -------
    >>> from condmon.models.registry import get_model
    >>> machine_rules(get_model("dc-motor")).faults[0].name
    'friction increase'
    """
    if machine.rules is not None:
        return load_rules(machine.rules)
    described = {p.name: p.description for p in machine.plant.parameters}
    described.update({f.name: f.description or f"{f.statistic} of {f.channel}"
                      for f in machine.features})
    return generic_rules(machine.monitored, described)
