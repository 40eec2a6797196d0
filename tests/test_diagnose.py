"""Fuzzy fault diagnoser: rule parsing, preprocessing, inference, status."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from condmon.diagnose import diagnose, load_rules, parse_condition
from condmon.errors import ConfigError

PARAMS = ("R", "L", "Ke", "Kt", "J", "D")


def sym(**high_low: tuple[float, float]) -> dict[str, dict[str, float]]:
    out = {p: {"high": 0.0, "low": 0.0} for p in PARAMS}
    for p, (h, lo) in high_low.items():
        out[p] = {"high": h, "low": lo}
    return out


def test_no_rule_fires_means_go_and_no_fault() -> None:
    d = diagnose(sym())
    assert d.status == "go" and d.no_fault and d.faults == ()
    assert d.summary == "go: no fault" and np.isfinite(d.condition)


@pytest.mark.parametrize("symptoms,fault", [
    (sym(D=(1.0, 0.0)), "friction increase"),
    (sym(R=(1.0, 0.0)), "winding resistance increase"),
    (sym(R=(1.0, 0.0), L=(1.0, 0.0)), "winding fault"),
    (sym(L=(0.0, 1.0), R=(0.0, 1.0)), "shorted winding"),
    (sym(Ke=(0.0, 1.0), Kt=(0.0, 1.0)), "magnet weakening"),
    (sym(J=(1.0, 0.0)), "mechanical inertia change"),
])
def test_each_initial_rule(symptoms: dict[str, dict[str, float]], fault: str) -> None:
    d = diagnose(symptoms)
    assert d.faults[0].name == fault and d.faults[0].degree == 1.0
    assert d.faults[0].advice


def test_major_fault_at_full_degree_is_no_go_minor_is_advisory() -> None:
    assert diagnose(sym(R=(1.0, 0.0))).status == "no-go"
    assert diagnose(sym(J=(1.0, 0.0))).status == "advisory"


def test_status_rises_monotonically_with_fault_degree() -> None:
    order = {"go": 0, "advisory": 1, "no-go": 2}
    levels = [order[diagnose(sym(D=(d, 0.0))).status] for d in np.linspace(0, 1, 21)]
    assert levels == sorted(levels) and levels[0] == 0 and levels[-1] == 2
    conds = [diagnose(sym(D=(d, 0.0))).condition for d in np.linspace(0, 1, 21)]
    assert all(b >= a for a, b in zip(conds, conds[1:]))


def test_bias_compensation_clears_ke_kt_j_when_friction_dominates() -> None:
    """The reference's friction case: SymH(D)=1, SymH(J)=0.94354, SymH(Ke,Kt)=0.069729."""
    d = diagnose(sym(D=(1.0, 0.0), J=(0.94354, 0.0), Ke=(0.069729, 0.0), Kt=(0.069729, 0.0)))
    assert d.applied == ("bias compensation",)
    assert [f.name for f in d.faults] == ["friction increase"]
    assert d.symptoms["J"]["high"] == 0.0 and d.symptoms["Ke"]["high"] == 0.0


def test_bias_compensation_does_not_fire_when_another_symptom_dominates() -> None:
    d = diagnose(sym(D=(0.5, 0.0), J=(0.9, 0.0)))
    assert d.applied == ()
    assert {f.name for f in d.faults} == {"friction increase", "mechanical inertia change"}


def test_condition_parser() -> None:
    e = parse_condition("(high(R) or low(L)) and not high(J)")
    from condmon.diagnose.rules import evaluate

    v = evaluate(e, {"R": np.array([0.7]), "L": np.array([0.0]), "J": np.array([0.2])},
                 {"R": np.array([0.0]), "L": np.array([0.4]), "J": np.array([0.0])})
    assert float(v[0]) == pytest.approx(0.7)


@pytest.mark.parametrize("text,message", [
    ("high(R) and", "ends early"),
    ("higher(R)", "expected high\\(P\\), low\\(P\\)"),
    ("high(R) high(L)", "unexpected 'high'"),
    ("high R", "expected '\\('"),
    ("high(R) & low(L)", "cannot read condition"),
])
def test_bad_conditions_are_explained(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_condition(text)


def test_user_rule_file(tmp_path: Path) -> None:
    p = tmp_path / "rules.toml"
    p.write_text('''
[[fault]]
name = "overheating"
if = "high(R) and low(Ke)"
severity = "minor"
advice = "Let it cool."
[status]
go = [0.0, 0.0, 0.25, 0.5]
advisory = [0.25, 0.5, 0.75]
no_go = [0.5, 0.75, 1.0, 1.0]
''')
    rb = load_rules(p)
    d = diagnose(sym(R=(0.8, 0.0), Ke=(0.0, 0.6)), rb)
    assert d.status == "go"  # a minor fault raises an advisory only once well established
    assert d.no_fault and d.summary == "go: no fault; to watch: overheating (0.60)"
    assert d.watch[0].name == "overheating" and d.watch[0].degree == pytest.approx(0.6)
    d = diagnose(sym(R=(0.9, 0.0), Ke=(0.0, 0.8)), rb)
    assert d.status == "advisory" and [f.name for f in d.faults] == ["overheating"]
    assert d.faults[0].severity == "minor" and not d.watch


@pytest.mark.parametrize("body,message", [
    ('[[fault]]\nname="x"\nif="high(R)"\nseverity="huge"\nadvice="a"\n', "severity 'huge'; allowed: major, minor"),
    ('[[fault]]\nname="x"\nif="high(R"\nseverity="major"\nadvice="a"\n', r"\(x\).*ends early"),
    ('[[fault]]\nname="x"\nseverity="major"\nadvice="a"\n', "has no 'if'"),
    ('', "no \\[\\[fault\\]\\] rules"),
    # one name is one fault: a second rule of it with another severity was merged
    # and its severity taken (a 7x friction check turned advisory, not no-go)
    ('[[fault]]\nname="wear"\nif="high(D)"\nseverity="major"\nadvice="a"\n'
     '[[fault]]\nname="wear"\nif="high(R)"\nseverity="minor"\nadvice="a"\n',
     r"\[\[fault\]\] #2 \(wear\): another rule of this name has another severity"),
    ('[[fault]]\nname="wear"\nif="high(D)"\nseverity="major"\nadvice="a"\n'
     '[[fault]]\nname="wear"\nif="high(R)"\nseverity="major"\nadvice="b"\n',
     r"another rule of this name has another advice"),
])
def test_bad_rule_files_are_explained(tmp_path: Path, body: str, message: str) -> None:
    p = tmp_path / "r.toml"
    p.write_text(body + '[status]\ngo=[0,0,0.25,0.5]\nadvisory=[0.25,0.5,0.75]\nno_go=[0.5,0.75,1,1]\n')
    with pytest.raises(ConfigError, match=message):
        load_rules(p)


def test_rules_of_one_name_with_one_severity_and_advice_are_one_fault(tmp_path: Path) -> None:
    p = tmp_path / "r.toml"
    p.write_text('[[fault]]\nname="wear"\nif="high(D)"\nseverity="major"\nadvice="a"\n'
                 '[[fault]]\nname="wear"\nif="high(R) and not high(L)"\nseverity="major"\n'
                 'advice="a"\n[status]\ngo=[0,0,0.25,0.5]\nadvisory=[0.25,0.5,0.75]\n'
                 'no_go=[0.5,0.75,1,1]\n')
    d = diagnose(sym(R=(1.0, 0.0)), load_rules(p))
    assert d.status == "no-go" and [f.name for f in d.faults] == ["wear"]


def test_rules_about_unknown_parameters_are_refused(tmp_path: Path) -> None:
    p = tmp_path / "r.toml"
    p.write_text('[[fault]]\nname="x"\nif="high(Q)"\nseverity="major"\nadvice="a"\n'
                 '[status]\ngo=[0,0,0.25,0.5]\nadvisory=[0.25,0.5,0.75]\nno_go=[0.5,0.75,1,1]\n')
    with pytest.raises(ConfigError, match=r"unknown parameter\(s\) \['Q'\]"):
        diagnose(sym(), load_rules(p))


@pytest.mark.parametrize("degree", [0.0, 0.001, 0.004, 0.1, 0.2, 0.3, 0.45, 0.6, 0.75, 0.8, 0.9,
                                    1.0])
@pytest.mark.parametrize("second", [0.0, 0.5, 0.9])
def test_listed_faults_agree_with_the_status(degree: float, second: float) -> None:
    """A go test lists no fault, an advisory test no major one, a no-go test a
    major one, and no listed fault or tendency reads 0.00."""
    d = diagnose(sym(R=(degree, 0.0), J=(second, 0.0)))
    if d.status == "go":
        assert d.faults == ()
    if d.status in ("go", "advisory"):
        assert all(f.severity == "minor" for f in d.faults)
    else:
        assert any(f.severity == "major" for f in d.faults)
    for f in (*d.faults, *d.watch):
        assert f"{f.degree:.2f}" != "0.00"
    assert not {f.name for f in d.faults} & {f.name for f in d.watch}
    # the rule's own severity is kept
    assert all(f.rule_severity in ("major", "minor") for f in (*d.faults, *d.watch))


# --- the status sets and the defuzzification: numpy, the reference's figures ------


@pytest.mark.parametrize("points", [
    (0.0, 0.0, 0.25, 0.5), (0.25, 0.5, 0.75), (0.5, 0.75, 1.0, 1.0), (0.0, 0.0, 0.0),
    (1.0, 1.0, 1.0), (0.1, 0.1, 0.9), (0.2, 0.2, 0.2, 0.7), (0.0, 0.3, 0.3, 1.0),
    (0.0, 0.5, 1.0), (0.333, 0.5, 0.5, 0.5),
])
def test_status_sets_are_scikit_fuzzys_to_the_bit(points: tuple[float, ...]) -> None:
    fuzz = pytest.importorskip("skfuzzy")
    from condmon.diagnose.diagnoser import _UNIVERSE, _mf

    ref = (fuzz.trimf if len(points) == 3 else fuzz.trapmf)(_UNIVERSE, list(points))
    assert np.array_equal(_mf(points), ref)


def test_centroid_is_scikit_fuzzys_to_the_bit() -> None:
    fuzz = pytest.importorskip("skfuzzy")
    from condmon.diagnose.diagnoser import _UNIVERSE, _centroid, _mf

    sets = [_mf(p) for p in ((0.0, 0.0, 0.25, 0.5), (0.25, 0.5, 0.75), (0.5, 0.75, 1.0, 1.0))]
    rng = np.random.default_rng(7)
    cuts = [(1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (0.3, 0.7, 0.0),
            *(tuple(rng.uniform(0.0, 1.0, 3)) for _ in range(40))]
    for go, adv, nogo in cuts:
        agg = np.maximum.reduce([np.minimum(sets[0], go), np.minimum(sets[1], adv),
                                 np.minimum(sets[2], nogo)])
        assert _centroid(_UNIVERSE, agg) == float(fuzz.defuzz(_UNIVERSE, agg, "centroid"))
    ragged = rng.uniform(0.0, 1.0, _UNIVERSE.size) * (rng.uniform(size=_UNIVERSE.size) > 0.3)
    assert _centroid(_UNIVERSE, ragged) == float(fuzz.defuzz(_UNIVERSE, ragged, "centroid"))



def test_a_fault_whose_symptom_has_no_value_is_not_judged_and_said() -> None:
    """A parameter held (not identified by the record) has no symptom: its
    faults cannot show, and a "go" must not read as their absence."""
    zero = {"high": 0.0, "low": 0.0}
    every = ("R", "L", "Ke", "Kt", "J", "D")
    full = diagnose({p: dict(zero) for p in every}, parameters=every)
    assert full.unseen == () and full.summary == "go: no fault"
    without_d = diagnose({p: dict(zero) for p in every if p != "D"}, parameters=every)
    assert without_d.status == "go"
    assert [(u.fault, u.parameters) for u in without_d.unseen] == [("friction increase", ("D",))]
    assert without_d.summary.endswith("not judged: friction increase (no judged value of D)")
    assert without_d.to_dict()["unseen"][0]["fault"] == "friction increase"
    # a rule that only needs L to be low-free still shows; those needing L do not
    without_l = diagnose({p: dict(zero) for p in every if p != "L"}, parameters=every)
    assert [u.fault for u in without_l.unseen] == ["winding fault", "shorted winding"]
    # a symptom of a judged parameter still names its fault beside the unseen one
    hot = {p: dict(zero) for p in every if p != "D"}
    hot["R"]["high"] = 1.0
    named = diagnose(hot, parameters=every)
    assert named.status == "no-go" and named.faults[0].name == "winding resistance increase"
    assert [u.fault for u in named.unseen] == ["friction increase"]


_STATUS = """[status]
go = [0.0, 0.0, 0.25, 0.5]
advisory = [0.25, 0.5, 0.75]
no_go = [0.5, 0.75, 1.0, 1.0]
"""


def test_a_rule_that_can_fire_on_a_judged_parameter_sees_its_fault(tmp_path: Path) -> None:
    """``high(Tc) or high(b)`` with Tc held: b alone fires it, so the fault is
    judged (it was reported "not judged" beside the same fault named at no-go).
    ``high(Tc) and high(b)`` cannot fire without Tc: not judged."""
    path = tmp_path / "rules.toml"
    path.write_text(_STATUS + """
[[fault]]
name = "friction increase"
if = "high(Tc) or high(b)"
severity = "major"
advice = "check the bearings"

[[fault]]
name = "seized"
if = "high(Tc) and high(b)"
severity = "major"
advice = "stop"
""")
    rules = load_rules(path)
    quiet = diagnose({"b": {"high": 0.0, "low": 0.0}}, rules, parameters=("Tc", "b"))
    assert [u.fault for u in quiet.unseen] == ["seized"]
    hot = diagnose({"b": {"high": 1.0, "low": 0.0}}, rules, parameters=("Tc", "b"))
    assert hot.faults[0].name == "friction increase"
    assert [u.fault for u in hot.unseen] == ["seized"]


def test_breakpoints_of_a_parameter_the_model_does_not_have_are_refused(tmp_path: Path) -> None:
    """`d = {r1 = 30, r2 = 60}` for D was ignored, D judged by the scatter's
    default with nothing said; a rules file of unknown names was refused."""
    from condmon.models.registry import get_model
    from condmon.monitor import load_monitor_config
    from condmon.monitor.baseline import make_baseline
    from condmon.workflows.monitoring import monitoring_of

    machine = get_model("dc-motor")
    baseline = make_baseline([{p: 1.0 + 0.01 * i for p in machine.monitored} for i in range(3)])
    p = tmp_path / "m.toml"
    p.write_text("k = 2.0\n[breakpoints]\nR = { r1 = 20.0, r2 = 40.0 }\n"
                 "d = { r1 = 30.0, r2 = 60.0 }\n")
    with pytest.raises(ConfigError, match=r"m\.toml: breakpoints or spreads name unknown "
                                          r"parameter\(s\) \['d'\]; the parameters of model "
                                          r"'dc-motor' are R, L, Ke, Kt, J, D"):
        monitoring_of(machine, baseline, load_monitor_config(p))
    p.write_text("k = 2.0\n[breakpoints]\nR = { r1 = 20.0, r2 = 40.0 }\n"
                 "[between_units]\nX = 10.0\n")
    with pytest.raises(ConfigError, match=r"unknown parameter\(s\) \['X'\]"):
        monitoring_of(machine, baseline, load_monitor_config(p))
    p.write_text("k = 2.0\n[breakpoints]\nR = { r1 = 20.0, r2 = 40.0 }\n")
    cfg, _ = monitoring_of(machine, baseline, load_monitor_config(p))
    assert cfg.r1 == {"R": 20.0}


def test_one_reason_for_several_parameters_is_said_once() -> None:
    from condmon.cli.check import folded_judgement

    lines = ["R: no spread between units is stated", "Tc@forward: judged against oil",
             "L: no spread between units is stated", "vib1@forward: judged against oil",
             "Ke: the declared r1 20 % lies inside the healthy scatter"]
    assert folded_judgement(lines) == [
        "R, L: no spread between units is stated",
        "Tc@forward, vib1@forward: judged against oil",
        "Ke: the declared r1 20 % lies inside the healthy scatter"]


def test_a_rules_file_without_status_takes_the_shipped_one_and_a_partial_one_is_named(
        tmp_path: Path) -> None:
    """A rules file names faults; without [status] it took 15 estimates to fail
    with "[status] has no 'go'". Left out, the shipped membership functions serve;
    a partial one is refused with the form it takes."""
    fault = '[[fault]]\nname = "leak"\nif = "low(p)"\nseverity = "major"\nadvice = "look"\n'
    path = tmp_path / "rules.toml"
    path.write_text(fault)
    assert load_rules(path).status == load_rules().status
    path.write_text(fault + "[status]\ngo = [0.0, 0.0, 0.25, 0.5]\n")
    with pytest.raises(ConfigError, match=r"rules.toml: \[status\] has no 'advisory'; it takes "
                                          r"three membership functions"):
        load_rules(path)
