"""A check's faults never contradict its own table of changes.

A named fault whose rule reads ``low(R)`` must come with R measured lower
than its baseline, over every rule base shipped; and an estimate that does
not measure its parameter (standard error above the value) is refused, not
diagnosed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from condmon.diagnose import diagnose
from condmon.diagnose.rules import Atom, Expr, RuleBase, load_rules
from condmon.models.plausibility import Bound, Plausibility
from condmon.monitor.baseline import Baseline
from condmon.monitor.fuzzy import MonitorConfig, compute_symptoms, symptom_degree

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "src" / "condmon" / "data"
RULE_FILES = (DATA / "rules.toml", DATA / "dc-motor-coulomb-rules.toml",
              ROOT / "examples" / "hydraulic-actuator" / "rotary-actuator-rules.toml")
RULES: tuple[RuleBase, ...] = tuple(load_rules(p) for p in RULE_FILES)


def _asserted(e: Expr, negated: bool = False) -> list[Atom]:
    """The atoms an expression asserts (not those under a ``not``)."""
    if isinstance(e, Atom):
        return [] if negated else [e]
    flip = negated != (e.op == "not")
    return [a for arg in e.args for a in _asserted(arg, flip)]


@st.composite
def checks(draw: st.DrawFn) -> tuple[RuleBase, Baseline, MonitorConfig, np.ndarray, np.ndarray]:
    rb = draw(st.sampled_from(RULES))
    names = tuple(sorted(rb.parameters()))
    n = len(names)
    floats = st.floats
    mean = np.array(draw(st.lists(floats(0.01, 100.0), min_size=n, max_size=n)))
    std = mean * np.array(draw(st.lists(floats(0.001, 0.3), min_size=n, max_size=n)))
    change = np.array(draw(st.lists(floats(-90.0, 90.0), min_size=n, max_size=n)))
    # standard errors from a hundredth of the value to a hundred times it
    rel_se = 10.0 ** np.array(draw(st.lists(floats(-2.0, 2.0), min_size=n, max_size=n)))
    r1 = np.array(draw(st.lists(floats(2.0, 40.0), min_size=n, max_size=n)))
    r2 = r1 + np.array(draw(st.lists(floats(1.0, 40.0), min_size=n, max_size=n)))
    k = draw(st.sampled_from((1.0, 2.0, 3.0)))
    tests = draw(st.integers(3, 40))
    values = mean * (1.0 + change / 100.0)
    cfg = MonitorConfig(dict(zip(names, r1)), dict(zip(names, r2)), k)
    return rb, Baseline(names, tuple(mean), tuple(std), tests), cfg, values, values * rel_se


@settings(max_examples=500, deadline=None, derandomize=True, database=None)
@given(checks())
def test_no_named_fault_contradicts_the_table(case: tuple) -> None:
    rb, baseline, cfg, values, ses = case
    sym = compute_symptoms(values, baseline, cfg, ses)
    row = sym.row(0)
    diag = diagnose(sym.to_dict(0), rb)
    for p, v in row.items():   # one direction at most, and the measured one
        assert not (v["high"] > 0 and v["percent_change"] <= 0), (p, v)
        assert not (v["low"] > 0 and v["percent_change"] >= 0), (p, v)
    rules = {f.name: f for f in rb.faults}
    named = {f.name for f in diag.faults} | {n for c in diag.candidates for n in c.faults}
    for name in named:
        for atom in _asserted(rules[name].condition):
            s = diag.symptoms[atom.parameter][atom.kind]
            if s > 0:
                change = row[atom.parameter]["percent_change"]
                assert (change > 0) == (atom.kind == "high"), (name, atom, change)


def test_a_band_reaching_both_ways_is_neither_high_nor_low() -> None:
    # the R: +7 % with a band of thousands of percent read high and low at once
    high, low = symptom_degree(7.0, 2 * 100 * 40.5 / 1.0, 15.0, 30.0)
    assert float(high) == 0.0 and float(low) == 0.0
    # a clear change with a band that stays on its side is still a symptom
    high, low = symptom_degree(45.0, 10.0, 15.0, 30.0)
    assert float(high) == 1.0 and float(low) == 0.0


def test_a_standard_error_above_the_value_is_not_a_measurement() -> None:
    p = Plausibility({"R": Bound((("gt", 0.0),)), "D": Bound((("ge", 0.0),))})
    why = p.check_precision({"R": 1.08, "D": 1e-6}, {"R": "ohm", "D": "N m s/rad"},
                            {"R": 40.5, "D": 1e-5})
    assert why is not None and "R = 1.08 ± 40.5 ohm" in why
    assert "D" not in why   # may be 0: an estimate consistent with 0 is a measurement of it
    assert p.check_precision({"R": 1.08}, {"R": "ohm"}, {"R": 0.5}) is None


@pytest.mark.parametrize("path", RULE_FILES, ids=lambda p: p.name)
def test_every_shipped_rule_base_is_covered(path: Path) -> None:
    assert load_rules(path).faults
