"""What a rule base can tell apart, before any record: the structure of the
fault rules over crisp symptom patterns (``condmon rules check MODEL``).

The fault signature matrix of :mod:`condmon.diagnose.structure` says which
faults of a plant its residuals can isolate; this module asks the same of a
fuzzy rule base. Every parameter's symptom is taken crisp, one of
{low, none, high} (``low(P) = 1`` or ``high(P) = 1`` or both 0), and each
fault is evaluated, after the rule base's preprocessing, over every pattern of
the parameters two faults name (and the dominant symptoms of the
preprocessing rules that clear one of theirs; every other parameter at none).
A fault *fires* on a pattern when its condition holds in full there. Then,
for two faults A and B (a fault is every rule of its name):

- the same set of firing patterns: A and B are **indistinguishable** — no
  symptom pattern tells them apart (the diagnosis names them together as
  candidates);
- A's set inside B's and smaller: A is **never told from** B — wherever A
  fires, B fires too (B may fire alone);
- an empty set: the fault **never fires** (a contradiction such as
  ``high(R) and low(R)``).

Beside these: the parameters the model reports that no fault rule names (a
change of one is diagnosed as "change detected, cause not determined"), the
parameters the rules name that the model does not report (the rules cannot
be used with it), and the symptoms that name no fault on their own (a rule
may still name them with another symptom).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from condmon.diagnose.rules import RuleBase, atoms, evaluate
from condmon.errors import ConfigError

if TYPE_CHECKING:
    from condmon.models.machine import Machine

__all__ = ["RuleCheck", "check_rules", "check_model_rules", "firing_patterns"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Most parameters two faults may name together (3**n patterns are evaluated).
MAX_PARAMETERS = 12


@dataclass(frozen=True)
class RuleCheck:
    """What a rule base can tell apart for a model.

    Attributes
    ----------
    model : str
        The model's name ("" when checked without one).
    source : str
        Where the rules came from.
    parameters : tuple of str
        What the model reports (parameters, then declared features).
    faults : tuple of str
        The rule base's faults, in its order.
    indistinguishable : tuple of tuple of str
        Sets of faults that fire on the same symptom patterns.
    never_told_apart : tuple of (str, str)
        ``(A, B)``: A fires only where B fires too (and B fires alone somewhere).
    never_fire : tuple of str
        Faults no symptom pattern fires.
    unnamed : tuple of str
        Reported parameters no fault rule names.
    unknown : tuple of str
        Parameters the rules name that the model does not report.
    alone_unnamed : tuple of str
        Symptoms (``low(D)``) of reported parameters the rules name that fire
        no fault on their own (information: a rule may name them with another
        symptom).
    """

    model: str
    source: str
    parameters: tuple[str, ...]
    faults: tuple[str, ...]
    indistinguishable: tuple[tuple[str, ...], ...]
    never_told_apart: tuple[tuple[str, str], ...]
    never_fire: tuple[str, ...]
    unnamed: tuple[str, ...]
    unknown: tuple[str, ...]
    alone_unnamed: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """True when every fault can be told from every other, each fires,
        and rules and model name the same parameters."""
        return not (self.indistinguishable or self.never_told_apart or self.never_fire
                    or self.unnamed or self.unknown)

    def findings(self) -> list[tuple[str, str, str]]:
        """``(finding, faults or parameter, why)`` rows, for a table."""
        rows = [("indistinguishable", ", ".join(s),
                 "fire on the same symptom patterns: a diagnosis names them together")
                for s in self.indistinguishable]
        rows += [("never told apart", f"{a} from {b}",
                  f"wherever {a!r} fires, {b!r} fires too") for a, b in self.never_told_apart]
        rows += [("never fires", f, "no symptom pattern fires it") for f in self.never_fire]
        rows += [("not named", p, "no fault rule names it: a change of it is "
                  "'change detected, cause not determined'") for p in self.unnamed]
        rows += [("unknown parameter", p, "the rules name it; the model does not report it")
                 for p in self.unknown]
        return rows

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"model": self.model, "rules": self.source, "ok": self.ok,
                "parameters": list(self.parameters), "faults": list(self.faults),
                "indistinguishable": [list(s) for s in self.indistinguishable],
                "never_told_apart": [{"fault": a, "from": b} for a, b in self.never_told_apart],
                "never_fire": list(self.never_fire), "unnamed": list(self.unnamed),
                "unknown": list(self.unknown), "alone_unnamed": list(self.alone_unnamed)}


def _preprocessed(rules: RuleBase, high: dict[str, FloatArray], low: dict[str, FloatArray]
                  ) -> tuple[dict[str, FloatArray], dict[str, FloatArray]]:
    """The diagnoser's preprocessing, pattern by pattern (vectorised)."""
    high, low = dict(high), dict(low)
    for p in rules.preprocess:
        src = high if p.dominant.kind == "high" else low
        if p.dominant.parameter not in src:
            continue
        value = src[p.dominant.parameter]
        fires = value > 0
        for k, v in high.items():
            if not (p.dominant.kind == "high" and k == p.dominant.parameter):
                fires = fires & (value > v)
        for a in p.clear:
            side = high if a.kind == "high" else low
            if a.parameter in side:
                side[a.parameter] = np.where(fires, 0.0, side[a.parameter])
    return high, low


def firing_patterns(rules: RuleBase, faults: Sequence[str], parameters: Sequence[str]
                    ) -> BoolArray:
    """Where each fault fires over every crisp pattern of ``parameters``.

    Parameters
    ----------
    rules : RuleBase
    faults : sequence of str
        Fault names of the rule base (a fault is every rule of its name).
    parameters : sequence of str
        Each in {low, none, high}: ``3 ** len(parameters)`` patterns, the
        first parameter varying slowest (-1 low, 0 none, 1 high). Parameters
        the rules name and not listed here are none.

    Returns
    -------
    ndarray of bool, shape (len(faults), 3 ** len(parameters))

    Example
    -------
    >>> from condmon.diagnose.rules import load_rules
    >>> fired = firing_patterns(load_rules(), ["friction increase"], ["D"])
    >>> fired.astype(int).tolist()     # D low, none, high
    [[0, 0, 1]]
    """
    names = list(parameters)
    grid = (np.array(list(itertools.product((-1, 0, 1), repeat=len(names))), dtype=np.int64)
            .reshape(-1, len(names)))
    zero = np.zeros(grid.shape[0])
    high = {p: zero for p in rules.parameters()}
    low = dict(high)
    for j, p in enumerate(names):
        high[p] = (grid[:, j] == 1).astype(np.float64)
        low[p] = (grid[:, j] == -1).astype(np.float64)
    high, low = _preprocessed(rules, high, low)
    out = np.zeros((len(faults), grid.shape[0]), dtype=bool)
    for i, name in enumerate(faults):
        for rule in rules.faults:
            if rule.name == name:
                out[i] |= np.broadcast_to(evaluate(rule.condition, high, low),
                                          zero.shape) >= 1.0 - 1e-12
    return out


def _named(rules: RuleBase, fault: str) -> set[str]:
    """The parameters a fault's rules name, with the dominant symptoms of the
    preprocessing rules that clear one of its symptoms."""
    own = {a for r in rules.faults if r.name == fault for a in atoms(r.condition)}
    out = {a.parameter for a in own}
    for p in rules.preprocess:
        if own & set(p.clear):
            out.add(p.dominant.parameter)
    return out


def check_rules(rules: RuleBase, parameters: Sequence[str], model: str = "") -> RuleCheck:
    """What ``rules`` can tell apart, and how they fit the parameters a model
    reports (the module's docstring says how).

    Parameters
    ----------
    rules : RuleBase
    parameters : sequence of str
        What the model reports (regime keys ``Tc@forward`` count for ``Tc``).
    model : str
        Its name, for the report.

    Returns
    -------
    RuleCheck

    Raises
    ------
    ConfigError
        Two faults naming together more than :data:`MAX_PARAMETERS` parameters
        (``3 ** n`` patterns would be evaluated).

    Example
    -------
    >>> from condmon.diagnose.rules import FaultRule, StatusSets, parse_condition
    >>> rb = RuleBase(tuple(FaultRule(n, parse_condition(c), c, "major", "")
    ...                     for n, c in (("seal wear", "low(Tc)"), ("load decoupled", "low(Tc)"))),
    ...               (), StatusSets((0, 0, .25, .5), (.25, .5, .75), (.5, .75, 1, 1)), "")
    >>> check_rules(rb, ["Tc", "J"]).indistinguishable
    (('seal wear', 'load decoupled'),)
    >>> check_rules(rb, ["Tc", "J"]).unnamed
    ('J',)
    """
    from condmon.diagnose.diagnoser import single_faults
    from condmon.errors import ConfigError
    from condmon.models.regimes import split_key

    reported = tuple(dict.fromkeys(split_key(p)[0] for p in parameters))
    faults = tuple(dict.fromkeys(r.name for r in rules.faults))
    named = {f: _named(rules, f) for f in faults}
    for f in faults:
        if len(named[f]) > MAX_PARAMETERS:
            raise ConfigError(f"{rules.source}: {f!r} names {len(named[f])} parameters; at "
                              f"most {MAX_PARAMETERS} can be checked")
    fires = {f: bool(firing_patterns(rules, [f], sorted(named[f])).any()) for f in faults}
    same: set[tuple[str, str]] = set()
    inside: list[tuple[str, str]] = []
    for i, a in enumerate(faults):
        for b in faults[i + 1:]:
            if not (fires[a] and fires[b]):
                continue
            params = sorted(named[a] | named[b])
            if len(params) > MAX_PARAMETERS:
                raise ConfigError(f"{rules.source}: {a!r} and {b!r} name {len(params)} "
                                  f"parameters together; at most {MAX_PARAMETERS} can be "
                                  "checked")
            fa, fb = firing_patterns(rules, [a, b], params)
            if np.array_equal(fa, fb):
                same.add((a, b))
            elif not (fa & ~fb).any():
                inside.append((a, b))
            elif not (fb & ~fa).any():
                inside.append((b, a))
    classes: list[list[str]] = []
    for f in faults:
        home = next((c for c in classes if (c[0], f) in same), None)
        if home is None:
            classes.append([f])
        else:
            home.append(f)
    used = {a.parameter for r in rules.faults for a in atoms(r.condition)}
    every = used | {a.parameter for p in rules.preprocess for a in (p.dominant, *p.clear)}
    single = single_faults(rules)
    return RuleCheck(
        model, rules.source, reported, faults,
        tuple(tuple(c) for c in classes if len(c) > 1), tuple(inside),
        tuple(f for f in faults if not fires[f]),
        tuple(p for p in reported if p not in used),
        tuple(sorted(every - set(reported))),
        tuple(f"{k}({p})" for p in reported if p in used for k in ("high", "low")
              if f"{k}({p})" not in single))


def check_model_rules(model: str | Path, rules: str | Path | None = None) -> RuleCheck:
    """:func:`check_rules` of a declared model's rule base (its ``[monitor]``
    rules, or the generic ones; ``rules``: another file) against what it reports.

    Raises
    ------
    ModelError
        An unknown model.
    ConfigError
        A model that reports nothing for rules to name (one diagnosed by
        isolation from its residuals).

    Example
    -------
    >>> check = check_model_rules("dc-motor")
    >>> check.ok, check.indistinguishable
    (True, ())
    """
    from condmon.diagnose.rules import load_rules, machine_rules
    from condmon.models.registry import get_model

    machine: Machine = get_model(model)
    if not machine.monitored:
        raise ConfigError(f"model {machine.name!r} reports no parameters or features, so no "
                          "fault rule names them: its faults are isolated from residuals "
                          f"(condmon isolate RECORD --model {machine.name})")
    rb = load_rules(rules) if rules is not None else machine_rules(machine)
    return check_rules(rb, machine.monitored, machine.name)
