"""The command line: a thin layer; clear one-line errors with exit status 2."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from _tables import row
from condmon.cli.main import main
from condmon.simulate import ActuatorRig, load_actuator_rig, simulate_actuator

if TYPE_CHECKING:
    from conftest import DemoRun


@pytest.mark.tables
def test_demo_writes_history_and_report(demo_run: DemoRun,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    """``condmon demo`` (run once for the run, :func:`conftest.demo_run`): its tables,
    its report and a history the other commands read."""
    out = demo_run.printed
    assert "friction increase" in out and "winding fault" in out and "Rlkgm=-50%@10s" in out
    # each experiment's row: its status and the changes [%] of R, L and D
    for label, status, changed, percent in (("friction x7", "no-go", 2, 600),
                                            ("R +40 %", "no-go", 0, 40),
                                            ("L +50 %, R +20 %", "no-go", 1, 50)):
        changes = [int(c) for c in row(out, label, status).split("  ")[-3:]]
        assert changes[changed] == pytest.approx(percent, rel=0.25), label
    for fault, name, truth in (("Rv=+25%@10s", "Rv", 14.089), ("Tld=+20@10s", "Tld", 20.0)):
        detected = row(out, fault).split("  ", 1)[1]
        found = re.fullmatch(r"\d+\.\d\d s  (\w+)  (\S+) \((\S+)\) (\S.*)", detected)
        assert found is not None and found[1] == name, fault     # the estimate with its unit
        assert float(found[2]) == pytest.approx(float(found[3]), rel=0.02)
        assert float(found[3]) == pytest.approx(truth, rel=1e-3)
    row(out, "Rlkgp=+50%@10s", "no", "—", "—")  # too small to see
    assert (demo_run.folder / "index.html").exists()
    assert (demo_run.folder / "EMA-friction-trends.png").stat().st_size > 10_000
    assert main(["history", "--unit", "EMA-resistance", "--db", str(demo_run.folder / "condmon.db")]) == 0
    assert "winding resistance" in capsys.readouterr().out


def _healthy_files(tmp_path: Path, n: int, seed0: int = 0) -> list[str]:
    files = []
    for s in range(n):
        p = tmp_path / f"h{seed0 + s}.csv"
        simulate_actuator(seed=seed0 + s).to_csv(p, index=False)
        files.append(str(p))
    return files


@pytest.mark.tables
def test_baseline_check_history_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = str(tmp_path / "h.db")
    files = _healthy_files(tmp_path, 5)
    assert main(["baseline", "add", *files[:2], "--unit", "U1", "--db", db]) == 0
    assert "needs at least 3" in capsys.readouterr().out
    assert main(["baseline", "add", *files, "--unit", "U1", "--db", db]) == 0
    captured = capsys.readouterr()
    assert "baseline of 'U1' from 5 accepted healthy tests" in captured.out.replace("\n", " ")
    assert captured.err.count("already in the history") == 2
    faulty = tmp_path / "f.csv"
    simulate_actuator(load_actuator_rig(faults=["R=+40%"]), seed=77).to_csv(faulty, index=False)
    assert main(["check", str(faulty), "--unit", "U1", "--db", db, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    for key in ("status", "fit_percent", "accepted", "parameters", "percent_change", "symptoms", "faults"):
        assert key in doc
    assert doc["status"] == "no-go" and doc["accepted"] is True
    assert doc["faults"][0]["name"] == "winding resistance increase"
    assert set(doc["faults"][0]) >= {"name", "degree", "advice"}
    assert set(doc["symptoms"]["R"]) == {"high", "low"} and doc["symptoms"]["R"]["high"] > 0.8
    assert doc["percent_change"]["R"] == pytest.approx(40, abs=4)
    assert main(["check", str(faulty), "--unit", "U1", "--db", db]) == 2
    assert "already in the history" in capsys.readouterr().err
    assert main(["history", "--unit", "U1", "--db", db]) == 0
    assert "no-go" in capsys.readouterr().out
    assert main(["report", "--unit", "U1", "--db", db, "--out", str(tmp_path / "rep")]) == 0
    page = (tmp_path / "rep" / "U1.html").read_text()
    assert "winding resistance increase" in page and "U1-trends.png" in page


def test_check_without_baseline_is_explained(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from condmon.store import open_store

    f = _healthy_files(tmp_path, 1)[0]
    assert main(["check", f, "--unit", "new", "--db", str(tmp_path / "x.db")]) == 2
    assert "no history database there" in capsys.readouterr().err
    open_store(str(tmp_path / "x.db")).close()  # an existing, empty history
    assert main(["check", f, "--unit", "new", "--db", str(tmp_path / "x.db")]) == 2
    err = capsys.readouterr().err.replace("\n", " ")
    assert "unknown unit 'new'" in err and "units: none yet" in err
    assert "a new unit starts with its healthy tests: condmon baseline add REC... --unit new" in err
    # a unit with too few healthy tests is told how many it has
    assert main(["baseline", "add", f, "--unit", "new", "--db", str(tmp_path / "x.db")]) == 0
    capsys.readouterr()
    assert main(["check", f, "--unit", "new", "--db", str(tmp_path / "x.db")]) == 2
    err = capsys.readouterr().err.replace("\n", " ")
    assert "has 1 accepted healthy test(s); a baseline needs at least 3" in err


def test_simulate_then_estimate_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "r.csv"
    assert main(["simulate", "actuator", "--out", str(rec), "--fault", "R=+40%", "--seed", "2"]) == 0
    capsys.readouterr()
    assert main(["estimate", str(rec), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["parameters"]["R"] == pytest.approx(1.4, rel=0.05)
    assert doc["accepted"] is True and doc["closed_loop_instruments"] is True
    assert set(doc["fits"]) == {"I", "omega"}
    assert main(["estimate", str(rec), "--json", "--excitation", "none", "--method", "iv"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["closed_loop_instruments"] is False and doc["method"] == "iv"


def test_output_into_a_pipe_is_not_folded(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """Into a pipe (no terminal, no COLUMNS) a line is whole and a wide table
    keeps its rows on one line each; COLUMNS still sets the width."""
    monkeypatch.delenv("COLUMNS", raising=False)
    rec = tmp_path / "r.csv"
    assert main(["simulate", "actuator", "--out", str(rec), "--seed", "2"]) == 0
    line = capsys.readouterr().err.strip()      # the note goes to stderr
    assert "\n" not in line and line.endswith("D=0.0001 N m s/rad)"), line
    assert main(["estimate", str(rec)]) == 0
    rows = [v for v in capsys.readouterr().out.splitlines() if v.startswith("│ Kt ")]
    assert len(rows) == 1 and "N m/A" in rows[0]
    monkeypatch.setenv("COLUMNS", "40")
    assert main(["simulate", "actuator", "--out", str(rec), "--seed", "3"]) == 0
    assert max(len(v) for v in capsys.readouterr().err.splitlines()) <= 40


def test_a_relative_fault_on_an_effect_that_is_off_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The default rig has no Coulomb friction: ``*1.5`` of it would silently do
    nothing, so it is refused; given a value, the note shows it."""
    rec = tmp_path / "r.csv"
    assert main(["simulate", "actuator", "--out", str(rec), "--fault",
                 "coulomb_friction=*1.5"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: fault coulomb_friction=*1.5: coulomb_friction is 0 on this "
                          "rig (off)") and err.count("\n") == 1 and not rec.exists()
    assert main(["simulate", "actuator", "--out", str(rec), "--fault",
                 "coulomb_friction=0.002"]) == 0
    assert capsys.readouterr().err.rstrip().endswith("coulomb_friction=0.002 N m)")


def test_units_fits_a_narrow_terminal(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """At 70 columns the units table keeps every line within them, its counts,
    dates and statuses whole; the long record name is cut, the unit's name
    folded (never cut). At 60 the record's column is left out, and a line says
    so."""
    from condmon.store import open_store
    from condmon.workflows.monitoring import add_baseline_tests

    db = str(tmp_path / "h.db")
    name = "a-rather-long-unit-name-on-line-A-042"
    with open_store(db) as store:
        recs = [simulate_actuator(seed=k) for k in (1, 2, 3)]
        for k, r in enumerate(recs):
            r.attrs["source"] = f"a_long_record_file_name_from_the_test_stand_{k}.csv"
        add_baseline_tests(store, name, recs, group="line-A")
    for width in (70, 60):
        monkeypatch.setenv("COLUMNS", str(width))
        assert main(["units", "--db", db]) == 0
        text = capsys.readouterr().out
        lines = text.splitlines()
        assert max(len(v.rstrip()) for v in lines) <= width
        body = lines[next(k for k, v in enumerate(lines) if "───" in v) + 1:]
        first = body[0]
        assert " 3 " in first and "baseline" in first and "2026-" in first
        assert "".join(v.split()[0] for v in body if v.strip() and not v.startswith("latest"))\
            .startswith(name)
        if width == 70:
            assert "a_lo" in first and "…" in first and "left out" not in text
        else:
            assert "a_lo" not in text and " ".join(text.split()).count(
                "latest: left out, the terminal is 60 columns wide") == 1


def test_history_in_a_narrow_terminal_says_which_parameters_it_leaves_out(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
        ) -> None:
    """At 50 columns the history leaves out the parameters that moved least,
    keeps the one that moved (friction), and names those it left out."""
    from condmon.store import open_store
    from condmon.workflows.checks import check_test
    from condmon.workflows.monitoring import add_baseline_tests

    db = str(tmp_path / "h.db")
    with open_store(db) as store:
        add_baseline_tests(store, "U", [simulate_actuator(seed=k) for k in (1, 2, 3)])
        check_test(store, "U", simulate_actuator(load_actuator_rig(faults=["D=*3"]), seed=9))
    monkeypatch.setenv("COLUMNS", "50")
    assert main(["history", "--unit", "U", "--db", db]) == 0
    text = capsys.readouterr().out
    lines = text.splitlines()
    assert max(len(v.rstrip()) for v in lines) <= 50
    header = next(v for v in lines if v.strip().startswith("#")).split()
    gone = next(v for v in lines if ": left out (they moved least)" in v).split(":")[0]
    assert header[-1] == "D" and gone and not set(gone.split(", ")) & set(header)
    assert set(gone.split(", ")) | (set(header) - {"#", "source", "fit", "%", "status"}) \
        == {"R", "L", "Kt", "J", "D"}


def test_parquet_and_column_mapping(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "r.parquet"
    simulate_actuator(seed=1).rename(columns={"V": "volts"}).to_parquet(rec)
    assert main(["estimate", str(rec), "--columns", "V=volts"]) == 0
    assert "accepted" in capsys.readouterr().out


def test_rejected_fit_exits_zero(rig: ActuatorRig, tmp_path: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    noisy = dataclasses.replace(rig, noise_I=2.0, noise_omega=10.0)
    rec = tmp_path / "bad.csv"
    simulate_actuator(noisy, seed=0).to_csv(rec, index=False)
    assert main(["estimate", str(rec), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["accepted"] is False and doc["fit_percent"] < 90


@pytest.mark.parametrize("args,message", [
    (["estimate", "missing.csv"], "missing.csv: file not found"),
    (["estimate", "{rec}", "--method", "bogus"], "unknown --method 'bogus'; allowed: sriv, oe, iv, arx"),
    (["estimate", "{rec}", "--columns", "V=watts"], "column mapping names ['watts'] not in the file"),
    (["estimate", "{rec}", "--excitation", "xx"], "missing column(s) 'xx'"),
    (["simulate", "actuator", "--out", "{tmp}/x.csv", "--fault", "R+4"], "cannot read fault 'R+4'"),
])
def test_bad_input_is_one_line_exit_2(args: list[str], message: str, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "r.csv"
    simulate_actuator(seed=0).to_csv(rec, index=False)
    argv = [a.format(rec=rec, tmp=tmp_path) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err.replace("\n", "")
    assert "Traceback" not in err and err.strip().startswith("error:")


def test_a_value_near_the_float_limit_is_one_line_without_a_numpy_warning(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """1e300 in a column overflowed the record's fingerprint first, printing
    numpy's "overflow encountered in square" above the error."""
    frame = simulate_actuator(seed=0)
    frame.loc[1234, "omega"] = 1e300
    rec = tmp_path / "huge.csv"
    frame.to_csv(rec, index=False)
    assert main(["estimate", str(rec)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "overflow" not in err, err
    assert "column 'omega' has 1 value(s) beyond 1e+15 in magnitude (row 1234" in err


def test_a_method_written_in_capitals_is_taken(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "r.csv"
    simulate_actuator(seed=0).to_csv(rec, index=False)
    assert main(["estimate", str(rec), "--method", "SRIV", "--json"]) == 0
    upper = json.loads(capsys.readouterr().out)
    assert main(["estimate", str(rec), "--json"]) == 0
    assert upper["parameters"] == json.loads(capsys.readouterr().out)["parameters"]


def test_an_arx_fit_without_physical_parameters_names_its_bias_and_the_method_without_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """ARX on the built-in test puts a pole on the negative real axis: its
    reason said to sample faster or lower the order, neither of which helps."""
    rec = tmp_path / "r.csv"
    simulate_actuator(seed=1).to_csv(rec, index=False)
    assert main(["estimate", str(rec), "--method", "arx", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["accepted"] is False
    assert "negative real axis" in doc["reason"]
    assert "(ARX) is biased by output noise: --method sriv estimates" in doc["reason"]
    assert main(["estimate", str(rec), "--method", "sriv", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["accepted"] is True


def test_a_voltage_in_millivolts_is_named_not_called_unexcited(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """V read 1000x too large: every unknown was "not excited", and nothing
    pointed at the column (a current in mA was already named)."""
    frame = simulate_actuator(seed=1)
    frame["V"] *= 1000.0
    rec = tmp_path / "mv.csv"
    frame.to_csv(rec, index=False)
    assert main(["estimate", str(rec), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["accepted"] is False and doc["reason"].startswith("not identifiable")
    assert doc["reason"].endswith("column 'V' (drive voltage) in mV? (converted to V, the "
                                  "record's estimate is accepted)")


def test_a_baseline_add_that_fails_on_a_record_says_what_it_stored(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A bad third file ended the command with its own error only, while the
    two before it were stored: the user could not tell."""
    db = str(tmp_path / "h.db")
    files = _healthy_files(tmp_path, 2)
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    assert main(["baseline", "add", *files, str(empty), "--unit", "U", "--db", db]) == 2
    assert capsys.readouterr().err.strip() == f"error: {empty}: the file is empty"
    assert not Path(db).exists()   # told before anything was estimated
    frame = simulate_actuator(seed=9)
    frame.loc[100, "I"] = float("nan")
    bad = tmp_path / "nan.csv"
    frame.to_csv(bad, index=False)
    assert main(["baseline", "add", *files, str(bad), "--unit", "U", "--db", db]) == 2
    err = capsys.readouterr().err.replace("\n", "")
    assert "column 'I'" in err and "(record 3 of 3; the 2 record(s) before it are stored as " \
        "tests of 'U' (" in err and "the stored ones are skipped)" in err
    assert main(["history", "--unit", "U", "--db", db, "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == 2
    assert main(["baseline", "add", str(bad), *files, "--unit", "U", "--db", db]) == 2
    assert "(record 1 of 3; nothing was stored)" in capsys.readouterr().err.replace("\n", "")


def test_a_check_whose_record_leaves_a_parameter_held_says_which_faults_it_cannot_see(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Basic IV does not identify D on the built-in test (its relative standard
    error would be 150 %): D is held at nominal, a 7x friction fault goes into
    the other parameters, and the check said "go: no fault". It still is go,
    but it now says that friction is not judged."""
    db = str(tmp_path / "h.db")
    files = _healthy_files(tmp_path, 4, seed0=11)
    assert main(["baseline", "add", *files, "--unit", "M", "--db", db, "--method", "iv"]) == 0
    worn = tmp_path / "worn.csv"
    simulate_actuator(load_actuator_rig(faults=["D=*7"]), seed=2).to_csv(worn, index=False)
    capsys.readouterr()
    assert main(["check", str(worn), "--unit", "M", "--db", db, "--method", "iv", "--json",
                 "--dry-run"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert "D" in doc["held"] and "D" not in doc["percent_change"]
    assert doc["unseen"] == [{"fault": "friction increase", "parameters": ["D"],
                              "text": "friction increase (no judged value of D)"}]
    assert "not judged: friction increase (no judged value of D)" in doc["summary"]
    assert main(["check", str(worn), "--unit", "M", "--db", db, "--method", "iv",
                 "--dry-run"]) == 0
    out = capsys.readouterr().out.replace("\n", " ")
    assert "1 fault(s) not judged" in out and "not judged by this test" in out
    (tmp_path / "more").mkdir()
    healthy = _healthy_files(tmp_path / "more", 1, seed0=40)[0]
    assert main(["check", healthy, "--unit", "M", "--db", db, "--method", "iv", "--json",
                 "--dry-run"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["status"] == "go"


def test_usage_error_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["estimate"]) == 2


@pytest.mark.parametrize("args,message", [
    (["check", "r.csv", "--unit", "U", "--alpha", "abc"],
     "error: Invalid value for '--alpha': Input should be a valid number"),
    (["forecast", "--unit", "U", "--horizon", "abc"], "error: Invalid value for '--horizon'"),
    (["check"], "error: Missing argument 'records'. (`condmon check --help` lists the options)"),
    (["nosuch"], "error: No such command 'nosuch'."),
])
def test_a_usage_error_is_one_line(args: list[str], message: str,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(message) and len(err.splitlines()) == 1, err


def test_help_and_a_bare_command_still_help(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0 and "Commands" in capsys.readouterr().out
    assert main([]) == 2 and "Commands" in capsys.readouterr().out
    assert main(["simulate"]) == 2 and "actuator" in capsys.readouterr().out


def test_units_of_a_history_without_units_says_so(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    from condmon.store import open_store

    db = str(tmp_path / "h.db")
    open_store(db).close()
    assert main(["units", "--db", db]) == 0
    assert "no units in" in capsys.readouterr().out


def test_the_route_option_lists_every_route_and_rules_name_their_default(
        capsys: pytest.CaptureFixture[str]) -> None:
    """--route left out `steady`, and check --rules said "the shipped one" for a
    model's own rule base."""
    from condmon.models.machine import ROUTES

    for command in (["estimate"], ["check"], ["baseline", "add"]):
        assert main([*command, "--help"]) == 0
        text = " ".join(re.sub(r"[│╭╮╰╯─]", " ", capsys.readouterr().out).split())
        listed = re.search(r"Estimation route: ([a-z, ]+?) \(", text)
        assert listed is not None, text
        assert set(re.split(r", | or ", listed.group(1))) == set(ROUTES), listed.group(1)
    assert main(["check", "--help"]) == 0
    text = " ".join(re.sub(r"[│╭╮╰╯─]", " ", capsys.readouterr().out).split())
    assert "the shipped one" not in text and "the model's own" in text


def test_help_lists_every_command_in_workflow_order(capsys: pytest.CaptureFixture[str]) -> None:
    """--help listed the commands in the order they happened to be registered."""
    from condmon.cli.main import WORKFLOW, app

    assert main(["--help"]) == 0
    shown = re.findall(r"^│ ([a-z]+) ", capsys.readouterr().out, flags=re.M)
    assert shown == list(WORKFLOW)
    import typer.main

    assert set(typer.main.get_command(app).commands) == set(WORKFLOW)  # type: ignore[attr-defined]


def test_the_notebook_history_takes_one_record_as_well_as_a_list(tmp_path: Path) -> None:
    """`History.baseline_add("U", "rec.csv")` read the path letter by letter
    ("r: file not found")."""
    import condmon

    files = _healthy_files(tmp_path, 3)
    with condmon.History(tmp_path / "h.db") as h:
        one = h.baseline_add("U", files[0])
        assert [t.source for t in one.tests] == [files[0]] and one.baseline is None
        frame = simulate_actuator(seed=7)
        assert len(h.baseline_add("U", frame).tests) == 1
        done = h.baseline_add("U", files[1:])
        assert done.baseline is not None and done.baseline.n == 4
        doc = json.loads(json.dumps(done.to_dict()))   # JSON-ready, as a check's is
        assert [t["test_id"] for t in doc["tests"]] == [3, 4]
        assert doc["baseline"]["n"] == 4 and doc["message"] == done.message


def test_the_notebook_history_s_errors_name_its_arguments_not_options(tmp_path: Path) -> None:
    """A notebook user was told `--against 'nobody'` and `give --unit NAME`: the
    shared workflows quote the CLI's options. The History's errors name the
    method's arguments; the error keeps its type."""
    import condmon

    files = _healthy_files(tmp_path, 3)
    with condmon.History(tmp_path / "h.db") as h:
        h.baseline_add("U", files)
        with pytest.raises(condmon.DataError, match=r"^against='nobody': no such unit or group"):
            h.check("U", files[0], against="nobody", dry_run=True)
        with pytest.raises(condmon.DataError, match=r"^horizon must be a finite number > 0"):
            h.forecast("U", horizon=-1.0)
        with pytest.raises(condmon.ConfigError, match=r"needs a reason \(reason=TEXT\)"):
            h.exclude(1, "")
        with pytest.raises(condmon.DataError, match=r"^test_date: 'yesterday' is not a date"):
            h.check("U", files[0], test_date="yesterday", dry_run=True)
    with pytest.raises(condmon.DataError, match=r"no such unit or group") as info:
        from condmon.store import open_store
        from condmon.workflows.checks import check_test
        from condmon.workflows.records import EstimateOptions

        with open_store(str(tmp_path / "h.db")) as store:   # the CLI's path keeps its option
            check_test(store, "U", files[0], EstimateOptions(), against="nobody", dry_run=True)
    assert str(info.value).startswith("--against 'nobody'")


def test_a_check_against_the_unit_itself_is_refused(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """`--against U --unit U` silently used U's own baseline: most likely the
    peer's name was mistyped."""
    db = str(tmp_path / "h.db")
    files = _healthy_files(tmp_path, 4)
    assert main(["baseline", "add", *files[:3], "--unit", "U", "--db", db]) == 0
    capsys.readouterr()
    assert main(["check", files[3], "--unit", "U", "--against", "U", "--db", db]) == 2
    assert capsys.readouterr().err.strip() == (
        "error: --against U: that is the unit itself; a check is judged against the unit's "
        "own baseline without --against")
    assert main(["check", files[3], "--unit", "U", "--db", db, "--dry-run"]) == 0


def test_model_given_as_an_option_where_it_is_the_first_argument(
        capsys: pytest.CaptureFixture[str]) -> None:
    """`estimate REC --model M` but `isolate M REC`: `isolate REC --model hst`
    answered "No such option: --model (Possible options: --date, --help)"."""
    assert main(["isolate", "rec.csv", "--model", "hst"]) == 2
    assert capsys.readouterr().err == ("error: condmon isolate takes the model as its first "
                                       "argument, not --model: condmon isolate MODEL RECORD\n")
    assert main(["simulate", "plant", "--model", "hst", "--out", "x.csv"]) == 2
    assert "condmon simulate plant MODEL" in capsys.readouterr().err


def test_a_warning_shown_on_stderr_is_also_in_the_json(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """A ``--json`` reader that keeps only stdout loses no warning: a saturating
    drive is warned of on stderr and listed under ``warnings``; a clean record's
    document has no such key (the list is per command)."""
    import warnings

    import numpy as np
    import pandas as pd

    rec = tmp_path / "r.csv"
    assert main(["simulate", "actuator", "--out", str(rec), "--seed", "2"]) == 0
    df = pd.read_csv(rec)
    lo, hi = np.percentile(df["V"], [6.0, 94.0])
    clipped = tmp_path / "clipped.csv"
    df.assign(V=df["V"].clip(lo, hi)).to_csv(clipped, index=False)
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        assert main(["estimate", str(clipped), "--json"]) == 0
        captured = capsys.readouterr()
        assert main(["estimate", str(rec), "--json"]) == 0
        clean = json.loads(capsys.readouterr().out)
    doc = json.loads(captured.out)
    assert "the drive saturates" in captured.err
    assert len(doc["warnings"]) == 1 and "the drive saturates" in doc["warnings"][0]
    assert "warnings" not in clean


def test_version_is_printed(capsys: pytest.CaptureFixture[str]) -> None:
    """`condmon --version` says the installed version and exits 0 (it had been
    an unknown option)."""
    import condmon

    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"condmon {condmon.__version__}"
