"""Honest diagnoses: ambiguity sets, changes no rule explains, and what a rule
base can tell apart (``condmon rules check``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from condmon.cli.main import main
from condmon.diagnose import diagnose, load_rules
from condmon.diagnose.diagnoser import advisory_degree
from condmon.diagnose.rules import RuleBase
from condmon.diagnose.structure_rules import check_model_rules, check_rules

STATUS = ('[status]\ngo = [0.0, 0.0, 0.25, 0.5]\nadvisory = [0.25, 0.5, 0.75]\n'
          'no_go = [0.5, 0.75, 1.0, 1.0]\n')
DC = ("R", "L", "Ke", "Kt", "J", "D")


def rules(tmp_path: Path, *faults: tuple[str, str, str]) -> RuleBase:
    body = "".join(f'[[fault]]\nname = "{n}"\nif = "{c}"\nseverity = "{s}"\nadvice = "x"\n'
                   for n, c, s in faults)
    p = tmp_path / "rules.toml"
    p.write_text(body + STATUS)
    return load_rules(p)


def sym(params: tuple[str, ...] = ("Tc", "vib"), **high_low: tuple[float, float]
        ) -> dict[str, dict[str, float]]:
    out = {p: {"high": 0.0, "low": 0.0} for p in params}
    for p, (h, lo) in high_low.items():
        out[p] = {"high": h, "low": lo}
    return out


@pytest.fixture
def same(tmp_path: Path) -> RuleBase:
    """low(Tc) names two faults: nothing tells them apart."""
    return rules(tmp_path, ("seal wear", "low(Tc)", "major"),
                 ("load decoupled", "low(Tc)", "major"), ("vibration", "high(vib)", "minor"))


@pytest.fixture
def told(tmp_path: Path) -> RuleBase:
    """A vibration symptom tells them apart."""
    return rules(tmp_path, ("seal wear", "low(Tc) and not high(vib)", "major"),
                 ("load decoupled", "low(Tc) and high(vib)", "major"))


# --- the rule base's structure ------------------------------------------------------


def test_one_symptom_naming_two_faults_is_indistinguishable(same: RuleBase) -> None:
    check = check_rules(same, ["Tc", "vib"])
    assert check.indistinguishable == (("seal wear", "load decoupled"),)
    assert not check.ok and check.never_told_apart == () and check.unknown == ()


def test_a_discriminating_symptom_makes_them_distinguishable(told: RuleBase) -> None:
    check = check_rules(told, ["Tc", "vib"])
    assert check.indistinguishable == () and check.never_told_apart == ()
    assert check.ok


def test_a_narrower_rule_is_never_told_from_a_wider_one(tmp_path: Path) -> None:
    rb = rules(tmp_path, ("seal wear", "low(Tc)", "major"),
               ("load decoupled", "low(Tc) and high(vib)", "major"),
               ("impossible", "high(vib) and low(vib)", "minor"))
    check = check_rules(rb, ["Tc", "vib"])
    assert check.never_told_apart == (("load decoupled", "seal wear"),)
    assert check.never_fire == ("impossible",) and check.indistinguishable == ()


def test_the_parameters_the_rules_and_the_model_name(same: RuleBase) -> None:
    check = check_rules(same, ["Tc", "vib@forward", "J"])
    assert check.unnamed == ("J",) and check.unknown == ()
    check = check_rules(same, ["Tc"])
    assert check.unknown == ("vib",)
    assert "low(vib)" in check_rules(same, ["Tc", "vib"]).alone_unnamed


def test_or_of_the_same_patterns_is_indistinguishable(tmp_path: Path) -> None:
    """Conditions written differently but firing on the same patterns."""
    rb = rules(tmp_path, ("a", "high(R) or low(R)", "minor"),
               ("b", "not (not high(R) and not low(R))", "minor"))
    assert check_rules(rb, ["R"]).indistinguishable == (("a", "b"),)


def test_the_shipped_and_example_rules_tell_every_fault_apart() -> None:
    for model in ("dc-motor", "dc-motor-coulomb", "examples/emps/emps.toml"):
        check = check_model_rules(model)
        assert check.ok, (model, check.findings())
    # the actuator's friction alone cannot tell a leak from the drive train, and says so
    rotary = check_model_rules("examples/hydraulic-actuator/rotary-actuator.toml")
    assert [f[0] for f in rotary.findings()] == ["never told apart", "not named"]
    assert "internal leakage" in rotary.findings()[0][1]
    assert "drive train" in rotary.findings()[0][1]
    # a fall of D names no fault: the diagnosis says so
    assert "low(D)" in check_model_rules("dc-motor").alone_unnamed


def test_preprocessing_is_applied_to_the_patterns() -> None:
    """Crisp patterns after bias compensation: with J high, D high does not
    exceed it, so inertia change fires wherever J is high."""
    from condmon.diagnose.structure_rules import firing_patterns

    fired = firing_patterns(load_rules(), ["mechanical inertia change"], ["D", "J"])
    # patterns: D in (low, none, high) x J in (low, none, high)
    assert fired.astype(int).tolist() == [[0, 0, 1, 0, 0, 1, 0, 0, 1]]


# --- the diagnosis -------------------------------------------------------------------


def test_a_symptom_naming_two_faults_names_both_as_candidates(same: RuleBase) -> None:
    d = diagnose(sym(Tc=(0.0, 1.0)), same)
    assert [c.faults for c in d.candidates] == [("seal wear", "load decoupled")]
    assert d.ambiguous and d.status == "no-go"
    assert d.summary == ("no-go: candidates: seal wear, load decoupled (1.00), the symptoms "
                         "do not tell them apart")
    doc = d.to_dict()
    assert doc["ambiguous"] and doc["candidates"][0]["faults"] == ["seal wear", "load decoupled"]
    assert json.loads(json.dumps(doc))["undetermined"] == []


def test_the_discriminating_symptom_names_one(told: RuleBase) -> None:
    d = diagnose(sym(Tc=(0.0, 1.0), vib=(1.0, 0.0)), told)
    assert [c.faults for c in d.candidates] == [("load decoupled",)]
    assert d.summary == "no-go: load decoupled (1.00)" and not d.ambiguous
    d = diagnose(sym(Tc=(0.0, 1.0)), told)
    assert [c.faults for c in d.candidates] == [("seal wear",)]


def test_a_symptom_half_way_tells_nothing(told: RuleBase) -> None:
    """vib at 0.5 is as much high as not: both rules hold to 0.5."""
    d = diagnose(sym(Tc=(0.0, 1.0), vib=(0.5, 0.0)), told)
    assert [c.faults for c in d.candidates] == [("seal wear", "load decoupled")]
    d = diagnose(sym(Tc=(0.0, 1.0), vib=(0.7, 0.0)), told)
    assert [c.faults for c in d.candidates] == [("load decoupled",), ("seal wear",)]


def test_a_symptom_only_one_rule_explains_ranks_it_first(tmp_path: Path) -> None:
    """Both hold to 1: high(vib) is explained by one only, which comes first
    though declared second; with vib absent nothing tells them apart."""
    rb = rules(tmp_path, ("seal wear", "low(Tc)", "major"),
               ("load decoupled", "low(Tc) and high(vib)", "major"))
    d = diagnose(sym(Tc=(0.0, 1.0), vib=(1.0, 0.0)), rb)
    assert [c.faults for c in d.candidates] == [("load decoupled",), ("seal wear",)]
    assert d.summary == "no-go: load decoupled (1.00), seal wear (1.00)"
    rb = rules(tmp_path, ("seal wear", "low(Tc)", "major"),
               ("load decoupled", "low(Tc) or high(vib)", "major"))
    assert diagnose(sym(Tc=(0.0, 1.0)), rb).ambiguous


def test_a_weaker_rule_the_symptoms_cannot_exclude_is_a_candidate(same: RuleBase,
                                                                 tmp_path: Path) -> None:
    rb = rules(tmp_path, ("seal wear", "low(Tc)", "major"),
               ("load decoupled", "low(Tc)", "minor"))
    d = diagnose(sym(Tc=(0.0, 0.5)), rb)
    assert d.status == "advisory" and [f.name for f in d.faults] == ["seal wear"]
    assert [c.faults for c in d.candidates] == [("seal wear", "load decoupled")]
    assert "to watch" not in d.summary


def test_separate_symptoms_are_separate_faults() -> None:
    d = diagnose(sym(DC, D=(1.0, 0.0), R=(1.0, 0.0)))
    assert [c.faults for c in d.candidates] == [("friction increase",),
                                                ("winding resistance increase",)]
    assert d.summary == "no-go: friction increase (1.00), winding resistance increase (1.00)"


def test_healthy_has_no_candidates_and_no_change() -> None:
    d = diagnose(sym(DC))
    assert d.candidates == () and d.undetermined == () and not d.ambiguous
    assert d.summary == "go: no fault"


def test_a_change_no_rule_names_is_said_undetermined() -> None:
    d = diagnose(sym(DC, D=(0.0, 0.9)))
    assert d.status == "go" and d.faults == ()
    assert [(u.parameter, u.kind) for u in d.undetermined] == [("D", "low")]
    assert d.summary == "go: no fault named; change detected in D (low), cause not determined"
    assert d.to_dict()["undetermined"][0]["direction"] == "low"


def test_a_rule_needing_an_absent_symptom_leaves_the_change_undetermined() -> None:
    """Magnet weakening needs low(Ke) and low(Kt): low(Ke) alone is a change of
    no determined cause; with low(Kt) too it is the fault."""
    d = diagnose(sym(DC, Ke=(0.0, 1.0), Kt=(0.0, 0.1)))
    assert [(u.parameter, u.kind) for u in d.undetermined] == [("Ke", "low")]
    assert "change detected in Ke (low), cause not determined" in d.summary
    d = diagnose(sym(DC, Ke=(0.0, 1.0), Kt=(0.0, 1.0)))
    assert d.undetermined == () and d.summary == "no-go: magnet weakening (1.00)"


def test_a_weak_symptom_is_not_a_change(told: RuleBase) -> None:
    weak = 0.9 * advisory_degree(told)
    d = diagnose(sym(vib=(weak, 0.0)), told)
    assert d.undetermined == () and d.summary == "go: no fault"
    assert diagnose(sym(vib=(1.0, 0.0)), told).undetermined[0].parameter == "vib"


def test_a_minor_rule_naming_the_symptom_accounts_for_it() -> None:
    """high(J) at 0.5 is the inertia change to watch, not an unexplained change."""
    d = diagnose(sym(DC, J=(0.5, 0.0)))
    assert d.status == "go" and d.undetermined == ()
    assert d.summary == "go: no fault; to watch: mechanical inertia change (0.50)"


def test_a_cleared_symptom_is_not_a_change() -> None:
    """Bias compensation clears high(J) when friction dominates."""
    d = diagnose(sym(DC, D=(1.0, 0.0), J=(0.9, 0.0), Ke=(0.5, 0.0)))
    assert d.applied == ("bias compensation",) and d.undetermined == ()


@pytest.mark.parametrize("seed", range(30))
def test_the_status_and_faults_do_not_depend_on_the_tolerance(seed: int) -> None:
    rng = np.random.default_rng(seed)
    s = {p: {"high": float(h), "low": float(lo)} for p, h, lo in
         zip(DC, rng.uniform(size=6) * (rng.uniform(size=6) < 0.4),
             rng.uniform(size=6) * (rng.uniform(size=6) < 0.3))}
    a, b = diagnose(s, tolerance=0.0), diagnose(s, tolerance=0.5)
    assert (a.status, a.condition, a.faults, a.watch) == (b.status, b.condition, b.faults, b.watch)
    for d in (a, b):
        assert sorted(n for c in d.candidates for n in c.faults
                      if n in {f.name for f in d.faults}) == sorted(f.name for f in d.faults)
        assert (d.candidates == ()) == (d.status == "go")


def test_regime_symptoms_count_for_their_parameter(same: RuleBase) -> None:
    s = {"Tc@forward": {"high": 0.0, "low": 1.0}, "Tc@reverse": {"high": 0.0, "low": 0.2},
         "vib": {"high": 0.0, "low": 0.0}}
    assert diagnose(s, same).ambiguous


# --- the command line -----------------------------------------------------------------


def test_rules_check_of_a_shipped_model(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["rules", "check", "dc-motor"]) == 0
    text = capsys.readouterr().out
    assert "fine" in text and "low(D)" in text
    assert main(["rules", "check", "dc-motor", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["ok"] and doc["indistinguishable"] == [] and doc["model"] == "dc-motor"


def test_rules_check_of_a_model_diagnosed_by_isolation_says_so(
        capsys: pytest.CaptureFixture[str]) -> None:
    """It printed "0 faults over " and then "fine"."""
    assert main(["rules", "check", "hst"]) == 2
    assert capsys.readouterr().err.strip() == (
        "error: model 'hst' reports no parameters or features, so no fault rule names them: "
        "its faults are isolated from residuals (condmon isolate RECORD --model hst)")


def test_rules_check_lists_what_cannot_be_told_apart(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / "r.toml"
    p.write_text('[[fault]]\nname = "seal wear"\nif = "high(D)"\nseverity = "major"\n'
                 'advice = "x"\n[[fault]]\nname = "load decoupled"\nif = "high(D)"\n'
                 'severity = "minor"\nadvice = "y"\n[[fault]]\nname = "q"\nif = "high(Q)"\n'
                 'severity = "minor"\nadvice = "z"\n' + STATUS)
    assert main(["rules", "check", "dc-motor", "--rules", str(p), "--json"]) == 1
    doc = json.loads(capsys.readouterr().out)
    assert doc["indistinguishable"] == [["seal wear", "load decoupled"]]
    assert doc["unknown"] == ["Q"] and doc["unnamed"] == ["R", "L", "Ke", "Kt", "J"]
    assert main(["rules", "check", "dc-motor", "--rules", str(p)]) == 1
    text = capsys.readouterr().out
    assert "indistinguishable" in text and "seal wear, load decoupled" in text


def test_rules_check_of_an_unknown_model_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["rules", "check", "no-such-model"]) == 2
    got = capsys.readouterr()
    assert got.out == "" and len(got.err.strip().splitlines()) == 1
    assert "unknown model 'no-such-model'" in got.err
