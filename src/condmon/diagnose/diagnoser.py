"""Fuzzy fault diagnosis of one test's symptoms (SPEC A7).

symptoms -> preprocessing rules (e.g. bias compensation) -> fault rules (fuzzy
and/or/not) -> Mamdani inference on the output variable "condition" with
centroid defuzzification -> go / advisory / no-go, and each fault's degree.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from condmon.diagnose.evidence import (
    AMBIGUITY_TOLERANCE, CandidateSet, UnexplainedChange, UnseenFault, candidate_sets,
    unexplained_changes, unseen_faults,
)
from condmon.diagnose.rules import RuleBase, evaluate, load_rules
from condmon.models.regimes import split_key

__all__ = ["FaultDegree", "Diagnosis", "diagnose", "STATUSES", "WATCH_DEGREE", "LEVEL_NOTE",
           "nogo_degree", "advisory_degree", "single_faults", "joint_faults", "CandidateSet",
           "UnexplainedChange", "AMBIGUITY_TOLERANCE"]

FloatArray = NDArray[np.float64]
STATUSES = ("go", "advisory", "no-go")
#: Smallest degree kept as a tendency to watch (below it, printed as 0.00: nothing).
WATCH_DEGREE = 0.005
#: What a listed fault's severity means, for reports.
LEVEL_NOTE = ("A fault is listed when, on its own, it would raise an advisory at least; "
              "major: at no-go level in this test, minor: at advisory level (a rule that can "
              "ground the unit but has not yet is listed minor). Weaker degrees are tendencies "
              "to watch, not faults.")
_UNIVERSE = np.linspace(0.0, 1.0, 1001)


@dataclass(frozen=True)
class FaultDegree:
    """One diagnosed fault.

    Attributes
    ----------
    name : str
    degree : float
        Degree of the rule's condition, in [0, 1].
    severity : str
        What the fault amounts to in this test: "major" when it is at no-go
        level (the test is no-go and this fault alone would ground the unit),
        "minor" when at advisory level. A rule marked major whose degree has
        not reached no-go is listed minor, so a go or advisory test never
        lists a major fault. (Under ``Diagnosis.watch``: the rule's own.)
    advice : str
    rule_severity : str
        The rule's severity, as declared: the most the fault can amount to.
    """

    name: str
    degree: float
    severity: str
    advice: str
    rule_severity: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"name": self.name, "degree": self.degree, "severity": self.severity,
                "advice": self.advice, "rule_severity": self.rule_severity or self.severity}


@dataclass(frozen=True)
class Diagnosis:
    """Outcome of the fault diagnoser for one test.

    Attributes
    ----------
    status : {"go", "advisory", "no-go"}
        Overall condition for the operator.
    condition : float
        Defuzzified condition index in [0, 1] (0 healthy, 1 failed).
    faults : tuple of FaultDegree
        The faults behind an advisory or no-go status, largest first: each at
        advisory level at least on its own (see :data:`LEVEL_NOTE`). Empty for
        a go test: "no fault".
    symptoms : dict
        ``{param: {"high": .., "low": ..}}`` after preprocessing.
    applied : tuple of str
        Preprocessing rules that fired.
    watch : tuple of FaultDegree
        Rules whose condition holds to a degree of at least
        :data:`WATCH_DEGREE` but below advisory level: not faults, tendencies
        to watch.
    candidates : tuple of CandidateSet
        The listed faults grouped by what the symptoms tell apart, best
        supported first (:mod:`condmon.diagnose.evidence`): a set of one fault
        is told from the others; a larger set is an ambiguity set, its faults
        equally likely (it may hold a rule below advisory level that the
        symptoms cannot exclude). Empty for a go test.
    undetermined : tuple of UnexplainedChange
        Clear symptoms (at least :func:`advisory_degree`) that no fault rule
        accounts for: "change detected in P (low), cause not determined".
        They never change the status.
    unseen : tuple of UnseenFault
        Faults the test cannot show: a symptom each of their rules needs is of
        a parameter with no value in this test (not identified by the record,
        held). "go" says nothing of them; they never change the status.
    calibrated : str
        How the calibrated change test governed the status, when it did
        (:func:`condmon.monitor.statistics.governed`); "" otherwise.
    """

    status: str
    condition: float
    faults: tuple[FaultDegree, ...]
    symptoms: dict[str, dict[str, float]] = field(default_factory=dict)
    applied: tuple[str, ...] = ()
    watch: tuple[FaultDegree, ...] = ()
    candidates: tuple[CandidateSet, ...] = ()
    undetermined: tuple[UnexplainedChange, ...] = ()
    calibrated: str = ""
    unseen: tuple[UnseenFault, ...] = ()

    @property
    def no_fault(self) -> bool:
        """True when no fault rule fired."""
        return not self.faults

    @property
    def ambiguous(self) -> bool:
        """True when the symptoms leave two faults or more that they cannot tell apart."""
        return any(c.ambiguous for c in self.candidates)

    @property
    def summary(self) -> str:
        """One line for the operator: one fault is named alone only when the
        symptoms tell it from the others; faults they cannot tell apart are
        named together as candidates; a clear change no rule explains is said
        to have no determined cause."""
        named = {n for c in self.candidates for n in c.faults}
        watched = [f for f in self.watch if f.name not in named]
        watch = ("; to watch: " + ", ".join(f"{f.name} ({f.degree:.2f})" for f in watched)
                 if watched else "")
        changes = "".join(f"; {c.text}" for c in self.undetermined)
        changes += f"; {self.calibrated}" if self.calibrated else ""
        if self.unseen:
            changes += "; not judged: " + ", ".join(u.text for u in self.unseen)
        if self.no_fault:
            return f"{self.status}: no fault{' named' if changes else ''}{changes}{watch}"
        if self.candidates:
            top = ("; " if self.ambiguous else ", ").join(c.text for c in self.candidates)
        else:
            top = ", ".join(f"{f.name} ({f.degree:.2f})" for f in self.faults)
        return f"{self.status}: {top}{changes}{watch}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"status": self.status, "condition": self.condition,
                "faults": [f.to_dict() for f in self.faults],
                "watch": [f.to_dict() for f in self.watch],
                "no_fault": self.no_fault, "summary": self.summary,
                "candidates": [c.to_dict() for c in self.candidates],
                "ambiguous": self.ambiguous,
                "undetermined": [c.to_dict() for c in self.undetermined],
                "unseen": [u.to_dict() for u in self.unseen],
                "calibrated": self.calibrated or None,
                "preprocessing_applied": list(self.applied)}


def _triangle(x: FloatArray, a: float, b: float, c: float) -> FloatArray:
    """Triangular membership of ``x`` (feet ``a``, ``c``, peak ``b``; ``a <= b <= c``),
    computed as scikit-fuzzy's ``trimf`` does, to the last bit."""
    y = np.zeros(x.size)
    if a != b:
        left = (a < x) & (x < b)
        y[left] = (x[left] - a) / float(b - a)
    if b != c:
        right = (b < x) & (x < c)
        y[right] = (c - x[right]) / float(c - b)
    y[x == b] = 1.0
    return y


def _mf(points: tuple[float, ...]) -> FloatArray:
    """A status set on the universe: a triangle (3 points) or a trapezoid (4),
    as scikit-fuzzy's ``trimf`` / ``trapmf`` (the points are validated
    non-decreasing when the rules are loaded)."""
    x = _UNIVERSE
    if len(points) == 3:
        return _triangle(x, *map(float, points))
    a, b, c, d = map(float, points)
    y = np.ones(x.size)
    low, high = x <= b, x >= c
    y[low] = _triangle(x[low], a, b, b)
    y[high] = _triangle(x[high], c, c, d)
    y[(x < a) | (x > d)] = 0.0
    return y


def _centroid(x: FloatArray, mf: FloatArray) -> float:
    """Centroid of the piecewise-linear area under ``mf``, as scikit-fuzzy's
    ``defuzz(x, mf, "centroid")`` computes it (the same terms, summed in the
    same order, so to the last bit). [same unit as x]"""
    x1, x2, y1, y2 = x[:-1], x[1:], mf[:-1], mf[1:]
    width = x2 - x1
    with np.errstate(invalid="ignore", divide="ignore"):
        moment = np.select(
            [y1 == y2, (y1 == 0.0) & (y2 != 0.0), (y2 == 0.0) & (y1 != 0.0)],
            [0.5 * (x1 + x2), 2.0 / 3.0 * width + x1, 1.0 / 3.0 * width + x1],
            2.0 / 3.0 * width * (y2 + 0.5 * y1) / (y1 + y2) + x1)
    area = np.select([y1 == y2, (y1 == 0.0) & (y2 != 0.0), (y2 == 0.0) & (y1 != 0.0)],
                     [width * y1, 0.5 * width * y2, 0.5 * width * y1],
                     0.5 * width * (y1 + y2))
    used = ~(((y1 == 0.0) & (y2 == 0.0)) | (x1 == x2))
    # cumsum adds left to right, as the reference's loop does (np.sum would not)
    moments = np.cumsum(np.where(used, moment * area, 0.0))
    areas = np.cumsum(np.where(used, area, 0.0))
    return float(moments[-1] / max(float(areas[-1]), float(np.finfo(float).eps)))


def _preprocess(high: dict[str, float], low: dict[str, float], rules: RuleBase
                ) -> tuple[dict[str, float], dict[str, float], list[str]]:
    applied = []
    high, low = dict(high), dict(low)
    for p in rules.preprocess:
        src = high if p.dominant.kind == "high" else low
        value = src[p.dominant.parameter]
        others = [v for k, v in high.items() if not (p.dominant.kind == "high"
                                                     and k == p.dominant.parameter)]
        if value > 0 and all(value > v for v in others):
            for a in p.clear:
                (high if a.kind == "high" else low)[a.parameter] = 0.0
            applied.append(p.name)
    return high, low, applied


def diagnose(symptoms: Mapping[str, Mapping[str, float]], rules: RuleBase | None = None,
             parameters: Sequence[str] | None = None, *,
             tolerance: float = AMBIGUITY_TOLERANCE) -> Diagnosis:
    """Diagnose one test from its symptoms.

    Parameters
    ----------
    symptoms : mapping
        ``{param: {"high": SymH, "low": SymL}}`` (e.g. ``Symptoms.to_dict()``).
        A parameter of an operating regime (``Tc@forward``) counts for its
        parameter (``Tc``): the largest degree over the test's regimes.
    rules : RuleBase, optional
        The shipped rule base if omitted.
    parameters : sequence of str, optional
        Every parameter the machine reports: the rules may name these, and one
        without a symptom (not identified by this test, or not in its
        baseline) counts as 0. Default: the rules must name only the
        symptoms' parameters.
    tolerance : float
        Degrees and symptom evidence closer than this do not tell two faults
        apart (:mod:`condmon.diagnose.evidence`). [-]

    Returns
    -------
    Diagnosis
        Never NaN: when no rule fires the answer is ``go`` with no faults.

    Example
    -------
    >>> zero = {"high": 0.0, "low": 0.0}
    >>> s = {p: dict(zero) for p in ("R", "L", "Ke", "Kt", "J", "D")}
    >>> diagnose(s).summary
    'go: no fault'
    >>> s["R"]["high"] = 1.0
    >>> diagnose(s).summary
    'no-go: winding resistance increase (1.00)'
    >>> s["R"]["high"], s["D"]["low"] = 0.0, 0.9
    >>> diagnose(s).summary
    'go: no fault named; change detected in D (low), cause not determined'
    """
    rb = rules if rules is not None else load_rules()
    high: dict[str, float] = {}
    low: dict[str, float] = {}
    for key, v in symptoms.items():
        p = split_key(key)[0]
        high[p] = max(high.get(p, 0.0), float(v["high"]))
        low[p] = max(low.get(p, 0.0), float(v["low"]))
    rb.check_parameters(list(parameters) if parameters is not None else list(high))
    unseen = unseen_faults(rb, rb.parameters() - set(high))
    for p in rb.parameters():
        high.setdefault(p, 0.0)
        low.setdefault(p, 0.0)
    high, low, applied = _preprocess(high, low, rb)
    degrees: dict[str, float] = {}
    meta: dict[str, tuple[str, str]] = {}
    for rule in rb.faults:
        d = float(evaluate(rule.condition, high, low))
        degrees[rule.name] = max(degrees.get(rule.name, 0.0), d)
        meta[rule.name] = (rule.severity, rule.advice)
    held = sorted((FaultDegree(n, round(d, 12), meta[n][0], meta[n][1], meta[n][0])
                   for n, d in degrees.items() if d > 0.0), key=lambda f: -f.degree)
    sets = tuple(_mf(p) for p in (rb.status.go, rb.status.advisory, rb.status.no_go))
    worst = max((f.degree for f in held), default=0.0)
    major = max((f.degree for f in held if f.severity == "major"), default=0.0)
    minor = max((f.degree for f in held if f.severity == "minor"), default=0.0)
    condition, status = _infer(sets, worst, major, minor)
    # Each fault's level is what it would give on its own, capped by the test's
    # status: the list then agrees with the status it explains.
    rank = {s: i for i, s in enumerate(STATUSES)}
    faults, watch = [], []
    for f in held:
        alone = _infer(sets, f.degree, f.degree if f.severity == "major" else 0.0,
                       f.degree if f.severity == "minor" else 0.0)[1]
        level = STATUSES[min(rank[alone], rank[status])]
        if level != "go":
            faults.append(dataclasses.replace(f, severity="major" if level == "no-go" else "minor"))
        elif f.degree >= WATCH_DEGREE:
            watch.append(f)
    if status != "go" and not faults:
        # several faults below advisory level each, together above it
        faults = [dataclasses.replace(f, severity="minor") for f in watch]
        watch = []
    sym = {p: {"high": high[p], "low": low[p]} for p in high}
    fired = {f.name: f.degree for f in held if f.degree >= WATCH_DEGREE}
    fired.update({f.name: f.degree for f in faults})
    candidates = candidate_sets(fired, [f.name for f in faults], rb, high, low, tolerance,
                                advisory_degree(rb))
    unexplained = unexplained_changes(degrees, rb, high, low, advisory_degree(rb))
    return Diagnosis(status, condition, tuple(faults), sym, tuple(applied), tuple(watch),
                     candidates, unexplained, unseen=unseen)


def _infer(sets: tuple[FloatArray, ...], worst: float, major: float, minor: float
           ) -> tuple[float, str]:
    """Mamdani inference over "condition": (centroid, status)."""
    go_mf, adv_mf, nogo_mf = sets
    agg = np.maximum.reduce([np.minimum(go_mf, 1.0 - worst), np.minimum(adv_mf, minor),
                             np.minimum(nogo_mf, major)])
    condition = _centroid(_UNIVERSE, agg)
    memberships = [float(np.interp(condition, _UNIVERSE, m)) for m in sets]
    return condition, STATUSES[int(np.argmax(memberships))]


def nogo_degree(rules: RuleBase | None = None) -> float:
    """The smallest degree of a single major fault at which a check turns
    no-go: where the status sets' inference (centroid of go, advisory and
    no-go) first gives no-go, found by bisection (inf: none does). [-]

    A parameter whose own symptom names a major fault turns a check no-go at
    this degree of its symptom, short of ``r2`` where the degree is 1
    (:class:`condmon.forecast.unit.NoGo`).

    Example
    -------
    >>> 0.6 < nogo_degree() < 0.8
    True
    """
    rb = rules or load_rules()
    return _nogo_degree(tuple(rb.status.go), tuple(rb.status.advisory), tuple(rb.status.no_go))


def advisory_degree(rules: RuleBase | None = None) -> float:
    """The smallest degree of a single major fault at which a check turns
    advisory (or worse): where the status sets' inference first leaves go,
    found by bisection (inf: none does). [-]

    A symptom this strong that no fault rule accounts for is a change whose
    cause is not determined (:attr:`Diagnosis.undetermined`).

    Example
    -------
    >>> 0.2 < advisory_degree() < 0.4
    True
    """
    rb = rules or load_rules()
    return _advisory_degree(tuple(rb.status.go), tuple(rb.status.advisory),
                            tuple(rb.status.no_go))


@functools.lru_cache(maxsize=32)
def _advisory_degree(*points: tuple[float, ...]) -> float:
    """:func:`advisory_degree` of the status sets' points (each diagnosis asks it)."""
    sets = tuple(_mf(p) for p in points)
    if _infer(sets, 1.0, 1.0, 0.0)[1] == "go":
        return math.inf
    lo, hi = 0.0, 1.0
    for _ in range(40):          # to 1e-12
        mid = 0.5 * (lo + hi)
        if _infer(sets, mid, mid, 0.0)[1] != "go":
            hi = mid
        else:
            lo = mid
    return hi


@functools.lru_cache(maxsize=32)
def _nogo_degree(*points: tuple[float, ...]) -> float:
    """:func:`nogo_degree` of the status sets' points (each forecast asks it)."""
    sets = tuple(_mf(p) for p in points)
    if _infer(sets, 1.0, 1.0, 0.0)[1] != "no-go":
        return math.inf
    lo, hi = 0.0, 1.0
    for _ in range(40):          # to 1e-12
        mid = 0.5 * (lo + hi)
        if _infer(sets, mid, mid, 0.0)[1] == "no-go":
            hi = mid
        else:
            lo = mid
    return hi


def single_faults(rules: RuleBase | None = None) -> dict[str, FaultDegree]:
    """The fault each parameter's symptom names on its own: ``{"high(D)":
    friction increase, "low(R)": ...}``, the rules (the major ones before the
    minor) that a degree of 1 on that symptom alone, every other 0, fires in
    full (``high(R) and not high(L)`` counts for ``high(R)``), after the
    rule base's preprocessing, as :func:`diagnose` takes it. Several such
    rules are one fault named "A or B": the symptom alone does not tell them
    apart (a friction fall: a leak or the drive train).

    Example
    -------
    >>> single_faults()["high(D)"].name, single_faults()["high(R)"].name
    ('friction increase', 'winding resistance increase')
    """
    return dict(_single_faults(rules or load_rules()))


@functools.lru_cache(maxsize=32)
def _single_faults(rb: RuleBase) -> tuple[tuple[str, FaultDegree], ...]:
    out = []
    for s in _symptoms(rb):
        fired = _fired(rb, [s])
        if fired:
            top = min(fired, key=lambda f: f.severity != "major")
            same = [f.name for f in fired if f.severity == top.severity]
            out.append((s, dataclasses.replace(top, name=" or ".join(same)) if len(same) > 1
                        else top))
    return tuple(out)


def _symptoms(rb: RuleBase) -> list[str]:
    return [f"{kind}({p})" for p in sorted(rb.parameters()) for kind in ("high", "low")]


def _fired(rb: RuleBase, on: Sequence[str]) -> list[FaultDegree]:
    """The rules a degree of 1 on the symptoms ``on`` (``"high(D)"``), every
    other 0, fires in full, after the rule base's preprocessing."""
    high = {q: 0.0 for q in rb.parameters()}
    low = dict(high)
    for s in on:
        kind, p = s[:-1].split("(")
        (high if kind == "high" else low)[p] = 1.0
    high, low, _ = _preprocess(high, low, rb)
    return [FaultDegree(r.name, 1.0, r.severity, r.advice, r.severity)
            for r in rb.faults if float(evaluate(r.condition, high, low)) >= 1.0 - 1e-12]


def joint_faults(rules: RuleBase | None = None) -> dict[str, tuple[FaultDegree, tuple[str, ...]]]:
    """The major faults a symptom names together with another, where it names
    none alone: ``{"low(Ke)": (magnet weakening, ("low(Kt)",)), ...}``. The
    rule fires in full on the two symptoms at 1 (every other 0) and on
    neither alone; a check turns no-go by it when the later of the two
    reaches the no-go degree (a rule's ``and`` is the minimum).

    Example
    -------
    >>> f, partners = joint_faults()["low(Ke)"]
    >>> f.name, partners
    ('magnet weakening', ('low(Kt)',))
    """
    return dict(_joint_faults(rules or load_rules()))


@functools.lru_cache(maxsize=32)
def _joint_faults(rb: RuleBase) -> tuple[tuple[str, tuple[FaultDegree, tuple[str, ...]]], ...]:
    symptoms = _symptoms(rb)
    alone = {s: _fired(rb, [s]) for s in symptoms}
    out = []
    for s in symptoms:
        if any(f.severity == "major" for f in alone[s]):
            continue            # a major fault of its own: single_faults
        for t in symptoms:
            if t == s or t.split("(")[1] == s.split("(")[1]:
                continue        # (high and low of one parameter cannot come together)
            named = {f.name for f in alone[s] + alone[t]}
            both = [f for f in _fired(rb, [s, t]) if f.severity == "major"
                    and f.name not in named]
            if both:
                out.append((s, (both[0], (t,))))
                break
    return tuple(out)
