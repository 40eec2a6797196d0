"""Output an engineer need not second-guess: boundaries are not refused by rounding,
a baseline add that adds nothing says so (every table: tests/test_tables.py)."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from condmon.cli.main import main
from condmon.simulate import load_actuator_rig, simulate_actuator


def test_a_sample_interval_on_the_model_s_bound_is_accepted(tmp_path: Path) -> None:
    """500 Hz: dt = 0.002 s +- 2e-16, the dc-motor model's limit is 0.002 s."""
    rig = dataclasses.replace(load_actuator_rig(), sample_rate=500.0)
    rec = simulate_actuator(rig, seed=3)
    rec["t"] = pd.Series(range(len(rec))) * (1 / 500.0)
    path = tmp_path / "r500.csv"
    rec.to_csv(path, index=False)
    assert main(["estimate", str(path)]) == 0


def test_a_baseline_add_that_adds_nothing_exits_1(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "noisy.csv"
    rig = dataclasses.replace(load_actuator_rig(), noise_I=5.0, noise_omega=40.0)
    simulate_actuator(rig, seed=4).to_csv(path, index=False)
    db = str(tmp_path / "h.db")
    assert main(["baseline", "add", str(path), "--unit", "E9", "--db", db]) == 1
    err = capsys.readouterr().err
    assert "stored" in err and "no test accepted: 0 of 1 record(s)" in err


def test_an_estimate_beyond_a_bound_by_a_few_errors_is_said() -> None:
    from condmon.identify import estimate

    res = estimate(simulate_actuator(seed=2), "dc-motor-coulomb")  # a rig without Coulomb
    tc, se = res.parameters["Tc"], res.std_errors["Tc"]
    assert res.accepted and abs(tc) < 3 * se
    assert any(n.startswith("Tc = ") and ("consistent with 0" in n or "cannot tell" in n)
               for n in res.notes)


def test_a_truncated_tdms_file_is_said_to_be_truncated(tmp_path: Path) -> None:
    import numpy as np
    from nptdms import ChannelObject, TdmsWriter

    from condmon.errors import DataError
    from condmon.io import read_record

    full = tmp_path / "full.tdms"
    with TdmsWriter(full) as w:
        w.write_segment([ChannelObject("rig", c, np.arange(10000.0), {"wf_increment": 1e-3})
                         for c in ("V", "I", "omega")])
    data = full.read_bytes()
    cut = tmp_path / "cut.tdms"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match="cut.tdms: the file is truncated: its channels hold"):
        read_record(cut)


@pytest.mark.tables
def test_a_row_that_cannot_be_read_does_not_take_the_history_down(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import json
    import sqlite3

    from condmon.report.web import create_app

    files = []
    for k in range(4):
        path = tmp_path / f"r{k}.csv"
        simulate_actuator(seed=k + 1).to_csv(path, index=False)
        files.append(str(path))
    db = str(tmp_path / "h.db")
    assert main(["baseline", "add", *files[:3], "--unit", "E1", "--db", db]) == 0
    assert main(["check", files[3], "--unit", "E1", "--db", db]) == 0
    assert main(["baseline", "add", *files[:3], "--unit", "E2", "--db", db]) == 0
    con = sqlite3.connect(db)  # a row written by hand, or by another tool
    con.execute("UPDATE tests SET test_date = 'garbage', fit_percent = 'abc' WHERE id = 4")
    con.execute("UPDATE estimates SET value = 'n/a' WHERE test_id = 4 AND parameter = 'R'")
    con.commit()
    con.close()
    capsys.readouterr()
    for args in (["history", "--unit", "E1"], ["units"], ["history", "--unit", "E1", "--json"],
                 ["report", "--out", str(tmp_path / "rep")]):
        assert main([*args, "--db", db]) == 0, args
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    client = create_app(db).test_client()
    for url in ("/", "/api/units", "/units/E1", "/units/E2", "/api/units/E1"):
        assert client.get(url).status_code == 200, url
    doc = json.loads(client.get("/api/units/E1").data)
    assert doc["tests"][3]["fit_percent"] is None


def test_the_numbers_a_user_reads_carry_their_units(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """What simulate says it wrote, and the bracketed units of --help (the tables'
    units: tests/test_tables.py)."""
    assert main(["simulate", "actuator", "--out", str(tmp_path / "a.csv"),
                 "--fault", "R=+40%"]) == 0
    assert "R=1.4 ohm" in capsys.readouterr().err.replace("\n", " ")
    assert main(["simulate", "hst", "--out", str(tmp_path / "h.csv"),
                 "--fault", "Tld=+20@10s"]) == 0
    assert "Tld=20 N m at 10 s" in capsys.readouterr().err.replace("\n", " ")
    # a unit in brackets in an option's help is shown, not taken for markup
    assert main(["serve", "--help"]) == 0
    assert "often [s]" in " ".join(capsys.readouterr().out.split())


def _commands(group: Any, path: tuple[str, ...] = ()) -> list[tuple[tuple[str, ...], Any]]:
    out = [(path, group)]
    for name, cmd in getattr(group, "commands", {}).items():
        out += _commands(cmd, (*path, name))
    return out


def test_help_is_whole_sentences_with_its_units(capsys: pytest.CaptureFixture[str],
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    import typer

    from condmon.cli.main import app

    monkeypatch.setenv("COLUMNS", "250")
    for path, cmd in _commands(typer.main.get_command(app)):
        capsys.readouterr()
        assert main([*path, "--help"]) == 0
        text = capsys.readouterr().out
        flat = " ".join(re.sub(r"[│╭╮╰╯─]", " ", text).split())
        # every sentence of the command's own help and of each option's is there whole
        for param in cmd.params:
            for unit in re.findall(r"\[[^\]]*\]", getattr(param, "help", None) or ""):
                assert unit in flat, (path, param.name, unit)
        for name, sub in getattr(cmd, "commands", {}).items():
            row = next(line for line in text.splitlines() if line.startswith(f"│ {name} "))
            assert row.rstrip(" │").endswith("."), (path, name, row)
            first = (sub.help or "").split("\n\n")[0]
            assert " ".join(first.split()) in flat, (path, name)
