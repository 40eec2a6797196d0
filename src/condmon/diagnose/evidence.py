"""What the symptoms of one test tell apart: ambiguity sets of fault rules and
changes no rule explains.

The fuzzy diagnoser (:mod:`condmon.diagnose.diagnoser`) gives every fault rule
a degree. Two rules may hold to the same degree on the same symptoms: then
nothing observed tells one from the other, and naming one of them would claim
more than the record shows. This module groups the rules that fire into
ambiguity sets, as the hydrostatic transmission's multi-model isolation does
with its suspects (:mod:`condmon.diagnose.isolation`: "ambiguous: A, B explain
the data equally well"), and names the strong symptoms no rule accounts for
("change detected in P (low), cause not determined").

The rule, precisely (``mu(s)`` is the degree of symptom ``s`` = ``high(P)`` or
``low(P)`` after the rule base's preprocessing; ``tol`` is
:data:`AMBIGUITY_TOLERANCE`):

1. **Polarity.** A symptom is a *positive* literal of a fault (+1) when it
   occurs in the fault's rules (every rule of that name) only under an even
   number of ``not``, *negated* (-1) when only under an odd number; a symptom
   the fault names both ways, or does not name, gives it no prediction (0).
2. **Discrimination.** The weight of symptom ``s`` between faults A and B
   (polarities ``a``, ``b``) is ``w = a (2 mu(s) - 1)`` when one names ``s``
   positive and the other negated (contradicted: its presence favours the
   positive one, its absence the negated one, a degree of 0.5 neither), and
   ``w = (a - b) mu(s)`` otherwise (only one names it: a present symptom
   favours the fault naming it positive and counts against one negating it;
   an absent symptom tells nothing, nor one weaker than the advisory degree,
   a tendency; both the same way: 0). ``s`` *discriminates* when
   ``|w| > tol``; ``w > 0`` favours A.
3. **Told apart.** Two fired rules (degree at least
   :data:`~condmon.diagnose.diagnoser.WATCH_DEGREE`) are told apart when their
   degrees differ by more than ``tol`` or some symptom discriminates between
   them; otherwise the symptoms do not tell them apart.
4. **Ambiguity sets.** The rules not told apart, taken transitively
   (connected components), form one set; a set is reported when it holds at
   least one listed fault (a rule below advisory level in the same set is a
   candidate too: the symptoms cannot exclude it). Members of a set are
   equally likely and listed in the rule base's order.
5. **Ranking.** Sets are ordered by degree, largest first; sets whose degrees
   lie within ``tol`` of the next form one tier, ranked inside by how many of
   the tier's other sets they beat less how many beat them (A beats B when
   the weights of the symptoms discriminating between their first faults sum
   to more than ``tol`` in A's favour), then by degree and the rule base's
   order. Only a discriminating symptom can put one set of a tier ahead of
   another of higher degree.
6. **Cause not determined.** A symptom at least at the advisory degree (where a
   single major fault turns a check advisory,
   :func:`~condmon.diagnose.diagnoser.advisory_degree`) is a change with no
   determined cause unless some fault naming it as a positive literal (or
   both ways) holds to the advisory degree at least: no rule names it, or the
   rules naming it fire only weakly (they need another symptom that is absent).
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from condmon.diagnose.rules import Atom, Expr, RuleBase, evaluate

__all__ = ["AMBIGUITY_TOLERANCE", "CandidateSet", "UnexplainedChange", "UnseenFault",
           "unseen_faults", "polarities",
           "discriminating", "candidate_sets", "unexplained_changes"]

#: Degrees (and evidence) closer than this are "equal": no discrimination. [-]
AMBIGUITY_TOLERANCE = 0.05

#: Polarity of a symptom in a fault's condition: +1 positive, -1 negated, 0 both ways.
Polarity = dict[Atom, int]


@dataclass(frozen=True)
class CandidateSet:
    """Faults the symptoms do not tell apart (one fault: told from the others).

    Attributes
    ----------
    faults : tuple of str
        The faults of the set, equally likely, in the rule base's order.
    degree : float
        The largest degree of its faults. [-]
    least : float
        The smallest (within the tolerance of ``degree`` when the set is
        ambiguous, by construction). [-]

    Example
    -------
    >>> CandidateSet(("seal wear", "load decoupled"), 1.0, 1.0).text
    'candidates: seal wear, load decoupled (1.00), the symptoms do not tell them apart'
    >>> CandidateSet(("seal wear",), 0.8, 0.8).text
    'seal wear (0.80)'
    """

    faults: tuple[str, ...]
    degree: float
    least: float

    @property
    def ambiguous(self) -> bool:
        """More than one fault: the symptoms cannot tell which."""
        return len(self.faults) > 1

    @property
    def degree_text(self) -> str:
        """``0.80``, or ``0.78-0.80`` when the degrees differ (within the tolerance)."""
        return (f"{self.degree:.2f}" if f"{self.degree:.2f}" == f"{self.least:.2f}"
                else f"{self.least:.2f}-{self.degree:.2f}")

    @property
    def text(self) -> str:
        """``name (0.80)``, or ``candidates: A, B (0.80), the symptoms do not
        tell them apart``."""
        deg = self.degree_text
        if not self.ambiguous:
            return f"{self.faults[0]} ({deg})"
        return (f"candidates: {', '.join(self.faults)} ({deg}), the symptoms do not tell "
                "them apart")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"faults": list(self.faults), "degree": self.degree, "least": self.least,
                "ambiguous": self.ambiguous, "text": self.text}


@dataclass(frozen=True)
class UnexplainedChange:
    """A clear symptom that no fault rule accounts for.

    Attributes
    ----------
    parameter : str
    kind : {"high", "low"}
        Which way the parameter moved.
    degree : float
        The symptom's degree, after preprocessing. [-]

    Example
    -------
    >>> UnexplainedChange("Tc", "low", 0.9).text
    'change detected in Tc (low), cause not determined'
    """

    parameter: str
    kind: str
    degree: float

    @property
    def text(self) -> str:
        """``change detected in P (low), cause not determined``."""
        return f"change detected in {self.parameter} ({self.kind}), cause not determined"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"parameter": self.parameter, "direction": self.kind, "degree": self.degree,
                "text": self.text}


def _walk(e: Expr, negated: bool, out: dict[Atom, set[bool]]) -> None:
    if isinstance(e, Atom):
        out.setdefault(e, set()).add(negated)
        return
    for arg in e.args:
        _walk(arg, negated ^ (e.op == "not"), out)


def polarities(rules: RuleBase) -> dict[str, Polarity]:
    """Each fault's symptoms with their polarity: +1 positive (under an even
    number of ``not``), -1 negated, 0 both ways (over every rule of the name).

    Example
    -------
    >>> from condmon.diagnose.rules import load_rules
    >>> pol = polarities(load_rules())["winding resistance increase"]
    >>> sorted((str(a), v) for a, v in pol.items())
    [('high(L)', -1), ('high(R)', 1)]
    """
    seen: dict[str, dict[Atom, set[bool]]] = {}
    for rule in rules.faults:
        _walk(rule.condition, False, seen.setdefault(rule.name, {}))
    return {name: {a: (0 if len(s) == 2 else -1 if True in s else 1) for a, s in atoms.items()}
            for name, atoms in seen.items()}


@dataclass(frozen=True)
class UnseenFault:
    """A fault this test cannot see: a symptom its rules need is of a
    parameter the test has no value of (not identified by the record, held
    at a declared or baseline value, or not in the baseline).

    Example
    -------
    >>> UnseenFault("friction increase", ("D",)).text
    'friction increase (no judged value of D)'
    """

    fault: str
    parameters: tuple[str, ...]

    @property
    def text(self) -> str:
        """``friction increase (no judged value of D)``."""
        return f"{self.fault} (no judged value of {', '.join(self.parameters)})"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"fault": self.fault, "parameters": list(self.parameters), "text": self.text}


def unseen_faults(rules: RuleBase, absent: Collection[str]) -> tuple[UnseenFault, ...]:
    """The faults none of whose rules can fire without a symptom of a
    parameter in ``absent``: with no value of it, the test cannot show them,
    and a "go" says nothing of them. A rule that can fire on the parameters
    the test has (``high(Tc) or high(b)`` with ``b`` judged) sees its fault.

    Example
    -------
    >>> from condmon.diagnose.rules import load_rules
    >>> [u.fault for u in unseen_faults(load_rules(), {"D"})]
    ['friction increase']
    """
    if not absent:
        return ()
    gone = frozenset(absent)
    out = []
    for name, positives in _positive_parameters(rules):
        conditions = [r.condition for r in rules.faults if r.name == name]
        missing = [p & gone for p in positives]
        if all(missing) and not any(_can_fire(c, gone) for c in conditions):
            out.append(UnseenFault(name, tuple(sorted(set().union(*missing)))))
    return tuple(out)


#: Most symptoms of a rule whose every combination is tried (more: the rule is
#: taken as needing each positive symptom it names, as a conjunction would).
_CORNERS = 12


@functools.lru_cache(maxsize=256)
def _can_fire(condition: Expr, absent: frozenset[str]) -> bool:
    """Whether ``condition`` can reach a positive degree with the symptoms of
    ``absent`` parameters at 0 (no value) and the others free: min/max/1-x is
    extreme at the corners, so every 0/1 combination of the others is tried
    (once per rule and set of absent parameters: a fleet's checks share them)."""
    atoms: dict[Atom, set[bool]] = {}
    _walk(condition, False, atoms)
    free = [a for a in atoms if a.parameter not in absent]
    if len(free) > _CORNERS:
        return False
    fixed = {a: 0.0 for a in atoms if a.parameter in absent}
    for bits in itertools.product((0.0, 1.0), repeat=len(free)):
        value = {**fixed, **dict(zip(free, bits))}
        high = {a.parameter: v for a, v in value.items() if a.kind == "high"}
        low = {a.parameter: v for a, v in value.items() if a.kind == "low"}
        if float(evaluate(condition, high, low)) > 0.0:
            return True
    return False


@functools.lru_cache(maxsize=32)
def _positive_parameters(rules: RuleBase) -> tuple[tuple[str, tuple[frozenset[str], ...]], ...]:
    """Each fault's rules as the parameters of their positive symptoms (one
    walk of the rule base, however many checks ask)."""
    needs: dict[str, list[frozenset[str]]] = {}
    for rule in rules.faults:
        signs: dict[Atom, set[bool]] = {}
        _walk(rule.condition, False, signs)
        needs.setdefault(rule.name, []).append(
            frozenset(a.parameter for a, s in signs.items() if False in s))
    return tuple((name, tuple(sets)) for name, sets in needs.items())


def _mu(a: Atom, high: Mapping[str, float], low: Mapping[str, float]) -> float:
    return float((high if a.kind == "high" else low).get(a.parameter, 0.0))


def discriminating(a: Polarity, b: Polarity, high: Mapping[str, float],
                   low: Mapping[str, float], tolerance: float = AMBIGUITY_TOLERANCE,
                   evidence: float = 0.0) -> dict[Atom, float]:
    """The symptoms that tell fault A from fault B (polarities ``a``, ``b`` of
    :func:`polarities`), with their weight (> 0 favours A; step 2 of the
    module's docstring). A symptom only one of them names counts when it is
    at least ``evidence`` strong (the diagnoser passes its advisory degree:
    a weaker symptom is a tendency to watch, not evidence for one fault over
    another).

    Example
    -------
    >>> tc, vib = Atom("low", "Tc"), Atom("high", "vib")
    >>> seal, load = {tc: 1, vib: -1}, {tc: 1, vib: 1}
    >>> discriminating(seal, load, {"vib": 1.0}, {"Tc": 1.0})
    {Atom(kind='high', parameter='vib'): -1.0}
    >>> discriminating(seal, load, {"vib": 0.5}, {"Tc": 1.0})
    {}
    >>> discriminating({tc: 1}, load, {"vib": 0.0}, {"Tc": 1.0})
    {}
    """
    out = {}
    for s in dict.fromkeys([*a, *b]):
        pa, pb, mu = a.get(s, 0), b.get(s, 0), _mu(s, high, low)
        w = pa * (2.0 * mu - 1.0) if pa * pb == -1 else (pa - pb) * mu
        if pa * pb != -1 and mu < evidence:
            continue
        if abs(w) > tolerance:
            out[s] = w
    return out


def candidate_sets(degrees: Mapping[str, float], listed: Sequence[str], rules: RuleBase,
                   high: Mapping[str, float], low: Mapping[str, float],
                   tolerance: float = AMBIGUITY_TOLERANCE, evidence: float = 0.0
                   ) -> tuple[CandidateSet, ...]:
    """The ambiguity sets of the fired rules that hold a listed fault, ranked
    (the rule of the module's docstring, steps 3 to 5).

    Parameters
    ----------
    degrees : mapping
        ``{fault: degree}`` of the fired rules (those to consider). [-]
    listed : sequence of str
        The listed faults (at advisory level at least); a set without one is
        not reported.
    rules : RuleBase
    high, low : mapping
        Symptom degrees after preprocessing, by parameter. [-]
    tolerance : float
        Degrees and evidence closer than this are equal. [-]

    Returns
    -------
    tuple of CandidateSet
        Best supported first; every listed fault in exactly one set.

    Example
    -------
    >>> from condmon.diagnose.rules import FaultRule, RuleBase, StatusSets, parse_condition
    >>> rb = RuleBase(tuple(FaultRule(n, parse_condition(c), c, "major", "")
    ...                     for n, c in (("seal wear", "low(Tc)"), ("load decoupled", "low(Tc)"))),
    ...               (), StatusSets((0, 0, .25, .5), (.25, .5, .75), (.5, .75, 1, 1)), "")
    >>> sets = candidate_sets({"seal wear": 1.0, "load decoupled": 1.0},
    ...                       ["seal wear", "load decoupled"], rb, {"Tc": 0.0}, {"Tc": 1.0})
    >>> [s.faults for s in sets]
    [('seal wear', 'load decoupled')]
    """
    order = {n: i for i, n in enumerate(dict.fromkeys(r.name for r in rules.faults))}
    pol = polarities(rules)
    names = sorted(degrees, key=lambda n: order.get(n, len(order)))
    parent = {n: n for n in names}

    def root(n: str) -> str:
        while parent[n] != n:
            parent[n] = parent[parent[n]]
            n = parent[n]
        return n

    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if (abs(degrees[a] - degrees[b]) <= tolerance
                    and not discriminating(pol.get(a, {}), pol.get(b, {}), high, low, tolerance,
                                           evidence)):
                parent[root(b)] = root(a)
    groups: dict[str, list[str]] = {}
    for n in names:
        groups.setdefault(root(n), []).append(n)
    shown = set(listed)
    sets = sorted((m for m in groups.values() if shown & set(m)),
                  key=lambda m: -max(degrees[n] for n in m))

    def beats(x: list[str], y: list[str]) -> bool:
        w = discriminating(pol.get(x[0], {}), pol.get(y[0], {}), high, low, tolerance,
                           evidence)
        return sum(w.values()) > tolerance

    ranked: list[list[str]] = []
    tier: list[list[str]] = []
    for m in [*sets, None]:
        if m is None or (tier and max(degrees[n] for n in tier[-1])
                         - max(degrees[n] for n in m) > tolerance):
            score = {id(x): sum(beats(x, y) - beats(y, x) for y in tier if y is not x)
                     for x in tier}
            ranked += sorted(tier, key=lambda x: (-score[id(x)], -max(degrees[n] for n in x),
                                                  order.get(x[0], len(order))))
            tier = []
        if m is not None:
            tier.append(m)
    return tuple(CandidateSet(tuple(m), max(degrees[n] for n in m),
                              min(degrees[n] for n in m)) for m in ranked)


def unexplained_changes(degrees: Mapping[str, float], rules: RuleBase,
                        high: Mapping[str, float], low: Mapping[str, float],
                        advisory: float) -> tuple[UnexplainedChange, ...]:
    """The clear symptoms (at least ``advisory``) that no fault holding to
    ``advisory`` names as a positive or mixed literal (step 6 of the module's
    docstring), strongest first.

    Parameters
    ----------
    degrees : mapping
        ``{fault: degree}`` of every rule. [-]
    rules : RuleBase
    high, low : mapping
        Symptom degrees after preprocessing, by parameter. [-]
    advisory : float
        The degree at which a single major fault turns a check advisory
        (inf: never, and nothing is reported). [-]

    Example
    -------
    >>> from condmon.diagnose.rules import load_rules
    >>> rb = load_rules()
    >>> [c.text for c in unexplained_changes({}, rb, {"D": 0.0}, {"D": 0.9}, 0.3)]
    ['change detected in D (low), cause not determined']
    >>> unexplained_changes({"friction increase": 0.9}, rb, {"D": 0.9}, {"D": 0.0}, 0.3)
    ()
    """
    pol = polarities(rules)
    out = []
    for p in dict.fromkeys([*high, *low]):
        for kind, side in (("high", high), ("low", low)):
            mu = float(side.get(p, 0.0))
            if not mu >= advisory:
                continue
            s = Atom(kind, p)
            if any(pol[n].get(s, -1) >= 0 and degrees.get(n, 0.0) >= advisory - 1e-9
                   for n in pol):
                continue
            out.append(UnexplainedChange(p, kind, mu))
    return tuple(sorted(out, key=lambda c: -c.degree))
