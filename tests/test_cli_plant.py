"""The plant-model commands: simulate hst, isolate."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from condmon.cli.main import main


def test_simulate_then_isolate_with_healthy_records_and_plots(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "rv.csv"
    assert main(["simulate", "hst", "--out", str(rec), "--fault", "Rv=+40%@10s", "--seed", "3"]) == 0
    df = pd.read_csv(rec)
    assert list(df.columns)[:3] == ["t", "Ps", "omega_m"] and len(df) == 3001
    healthy = []
    for s in (1, 2):
        h = tmp_path / f"h{s}.parquet"
        assert main(["simulate", "hst", "--out", str(h), "--seed", str(s)]) == 0
        healthy += ["--healthy", str(h)]
    capsys.readouterr()
    assert main(["isolate", "hst", str(rec), *healthy, "--json", "--plots",
                 str(tmp_path / "plots"), "--workers", "1"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["detected"] and doc["isolated"] == ["Rv"]
    assert doc["estimates"]["Rv"] == pytest.approx(11.271 * 1.4, rel=0.03)
    assert doc["normalisation"]["source"] == "healthy records (2)"
    for name in ("residuals.png", "model-errors.png"):
        assert (tmp_path / "plots" / name).stat().st_size > 20_000
    assert main(["isolate", "hst", str(rec), "--workers", "1"]) == 0
    out = capsys.readouterr().out
    assert "fault isolated: Rv" in out and "Mb" in out


@pytest.mark.parametrize("args,message", [
    (["isolate", "hst", "{missing}"], "file not found"),
    (["isolate", "hst", "{nocol}"], "missing column 'omega_m'"),
    (["isolate", "hst", "{rec}", "--residuals", "mso"], "unknown --residuals 'mso'; allowed: simulation, structured"),
    (["isolate", "hsx", "{rec}"], "unknown model 'hsx'"),
    (["simulate", "hst", "--out", "{out}", "--fault", "Rx=+10%"], "no parameter 'Rx'"),
    (["simulate", "hst", "--out", "{bad_out}"], "unknown file type '.txt'"),
])
def test_bad_input_gives_one_line_and_status_2(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                               args: list[str], message: str) -> None:
    rec = tmp_path / "r.csv"
    main(["simulate", "hst", "--out", str(rec), "--duration", "2"])
    pd.read_csv(rec).drop(columns="omega_m").to_csv(tmp_path / "nocol.csv", index=False)
    paths = {"missing": tmp_path / "none.csv", "nocol": tmp_path / "nocol.csv", "rec": rec,
             "out": tmp_path / "o.csv", "bad_out": tmp_path / "o.txt"}
    capsys.readouterr()
    assert main([a.format(**{k: str(v) for k, v in paths.items()}) for a in args]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1 and "Traceback" not in err


def test_a_users_own_declaration_is_simulated_and_isolated(tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    from importlib import resources

    model = tmp_path / "my-hst.toml"
    model.write_text((resources.files("condmon") / "data" / "hst.toml").read_text()
                     .replace('name = "hst"', 'name = "my-hst"'))
    rec = tmp_path / "r.csv"
    assert main(["simulate", "plant", str(model), "--out", str(rec), "--fault", "Dm=+25%@10s"]) == 0
    capsys.readouterr()
    assert main(["isolate", str(model), str(rec), "--json", "--workers", "1"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["model"] == "my-hst" and doc["isolated"] == ["Dm"]


def test_isolations_are_kept_in_the_units_history(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    db = str(tmp_path / "h.db")
    healthy, faulty = tmp_path / "ok.csv", tmp_path / "rv.csv"
    assert main(["simulate", "hst", "--out", str(healthy), "--seed", "5"]) == 0
    assert main(["simulate", "hst", "--out", str(faulty), "--fault", "Rv=+40%@10s",
                 "--seed", "3"]) == 0
    for rec, date in ((healthy, "2026-04-01"), (faulty, "2026-04-08")):
        assert main(["isolate", "hst", str(rec), "--unit", "HST-1", "--db", db, "--date", date,
                     "--workers", "1"]) == 0
    assert "stored in the history of 'HST-1'" in capsys.readouterr().out
    # the same content again (as Parquet) is recognised, not stored twice
    copy = tmp_path / "rv.parquet"
    pd.read_csv(faulty).to_parquet(copy)
    assert main(["isolate", "hst", str(copy), "--unit", "HST-1", "--db", db, "--json",
                 "--workers", "1"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["stored"] is False and doc["isolation_id"] == 2 and doc["warning"] is None
    # the same record under another unit is stored, with a warning (tests had one)
    assert main(["isolate", "hst", str(faulty), "--unit", "HST-9", "--db", db, "--json",
                 "--workers", "1"]) == 0
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    assert doc["stored"] is True and doc["warning"] == (
        "the same record is also isolation i2 of 'HST-1'; is it filed under the right unit?")
    assert f"warning: {faulty}: the same record is also isolation i2 of 'HST-1'" in captured.err
    assert main(["history", "--unit", "HST-1", "--db", db, "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [(r["kind"], r["status"], r["isolated"]) for r in rows] == [
        ("isolation", "go", []), ("isolation", "no-go", ["Rv"])]
    assert rows[1]["Rv_change"] == pytest.approx(40, abs=3)
    assert rows[1]["test_date"].startswith("2026-04-08")
    assert main(["history", "--unit", "HST-1", "--db", db]) == 0
    assert "fault isolated: Rv" in capsys.readouterr().out
    assert main(["units", "--db", db, "--json"]) == 0
    unit = json.loads(capsys.readouterr().out)["units"][0]
    assert (unit["status"], unit["isolations"], unit["tests"]) == ("no-go", 2, 0)
    # a wrong isolation is excluded (kept, marked, audited) and included again
    assert main(["exclude", "i2", "--reason", "wrong unit's record", "--db", db]) == 0
    assert "isolation i2 excluded" in capsys.readouterr().out
    assert main(["units", "--db", db, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["units"][0]["status"] == "go"
    assert main(["history", "--unit", "HST-1", "--db", db, "--json"]) == 0
    assert [r["excluded"] for r in json.loads(capsys.readouterr().out)] == [False, True]
    assert main(["exclude", "i2", "--reason", "again", "--db", db]) == 2
    assert "already excluded (wrong unit's record)" in capsys.readouterr().err
    assert main(["include", "i2", "--db", db]) == 0
    assert "isolation i2 included" in capsys.readouterr().out
    assert main(["units", "--db", db, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["units"][0]["status"] == "no-go"
    assert main(["exclude", "x2", "--reason", "r", "--db", db]) == 2
    assert "not a test id (12 or #12) nor an isolation id (i3)" in capsys.readouterr().err
    assert main(["audit", "--unit", "HST-1", "--db", db, "--json"]) == 0
    actions = [r["action"] for r in json.loads(capsys.readouterr().out)["audit"]]
    assert actions[-2:] == ["isolation excluded", "isolation included"]
    # an actuator record offered to the HST unit is refused
    from condmon.simulate import simulate_actuator

    act = tmp_path / "a.csv"
    simulate_actuator(seed=1).to_csv(act, index=False)
    assert main(["baseline", "add", str(act), "--unit", "HST-1", "--db", db]) == 2
    assert "is monitored with plant model 'hst': its records are isolated" in capsys.readouterr().err


@pytest.mark.parametrize("order", [
    ["{rec}", "--healthy", "{h1}", "{h2}"],
    ["--healthy", "{h1}", "{h2}", "{rec}"],
    ["--healthy={h1}", "{h2}", "{rec}"],
    ["--healthy", "{h1}", "--healthy", "{h2}", "{rec}"],
])
def test_several_healthy_records_after_one_flag(
        order: list[str], tmp_path_factory: pytest.TempPathFactory,
        capsys: pytest.CaptureFixture[str]) -> None:
    """`--healthy a b` (a shell glob) reads both, wherever the record is."""
    root = tmp_path_factory.getbasetemp() / "several-healthy"
    files = {"rec": root / "rv.csv", "h1": root / "h1.csv", "h2": root / "h2.csv"}
    if not files["rec"].exists():
        root.mkdir(exist_ok=True)
        assert main(["simulate", "hst", "--out", str(files["rec"]), "--fault", "Rv=+40%@5s",
                     "--seed", "3", "--duration", "15"]) == 0
        for s in (1, 2):
            assert main(["simulate", "hst", "--out", str(files[f"h{s}"]), "--seed", str(s),
                         "--duration", "15"]) == 0
    capsys.readouterr()
    args = [a.format(**{k: str(v) for k, v in files.items()}) for a in order]
    assert main(["isolate", "hst", *args, "--json", "--workers", "1"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["normalisation"]["source"] == "healthy records (2)"
    assert doc["detected"] and "Rv" in doc["isolated"]  # the faulty record is the one read


def test_spreading_leaves_the_commands_own_words() -> None:
    from condmon.cli._options import spread_values

    greedy, flags = {"--healthy"}, {"--json"}
    assert spread_values(["hst", "r.csv"], greedy, flags, 2) == ["hst", "r.csv"]
    # one healthy record and the record after it: the record stays an argument
    assert spread_values(["hst", "--healthy", "a", "r.csv"], greedy, flags, 2) == [
        "hst", "--healthy", "a", "r.csv"]
    # a flag ends the values; an option's value is never taken
    assert spread_values(["hst", "--healthy", "a", "--json", "b", "r.csv"], greedy, flags,
                         2) == ["hst", "--healthy", "a", "--json", "b", "r.csv"]
    assert spread_values(["--workers", "2", "hst", "r.csv", "--healthy", "a", "b", "c"],
                         greedy, flags, 2) == ["--workers", "2", "hst", "r.csv", "--healthy",
                                               "a", "--healthy", "b", "--healthy", "c"]


def test_isolate_reads_a_record_as_the_rig_writes_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`simulate plant` writes a declaration's record as its [record] table says
    the rig writes it; `isolate` ignored that table, so the README's own pair
    failed for such a machine. It now reads records as `estimate` does."""
    hst = Path(__file__).resolve().parents[1] / "src" / "condmon" / "data" / "hst.toml"
    decl = tmp_path / "hst-rig.toml"
    decl.write_text(hst.read_text() + '\n[record]\nsample_rate = 100.0\n\n[record.columns]\n'
                    't = "n"\nPs = { column = "p_bar", scale = 1.0e5 }\n'
                    'omega_m = { column = "rpm", scale = 0.10471975511965977 }\n')
    rec = tmp_path / "rig.csv"
    assert main(["simulate", "plant", str(decl), "--out", str(rec), "--fault",
                 "Dm=-25%@10s", "--seed", "1"]) == 0
    assert rec.read_text().splitlines()[0].split(",")[:3] == ["n", "p_bar", "rpm"]
    capsys.readouterr()
    assert main(["isolate", str(decl), str(rec)]) == 0
    assert "fault isolated: Dm" in capsys.readouterr().out


def test_a_parameter_file_of_the_other_sign_or_beyond_the_declared_range_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`Rv = -5` was taken as the nominal value, and a healthy record then
    "had" a fault."""
    rec = tmp_path / "ok.csv"
    assert main(["simulate", "hst", "--out", str(rec), "--seed", "5"]) == 0
    p = tmp_path / "p.toml"
    for text, said in (("Rv = -5\n", "p.toml: Rv = -5 N m s/rad is not of the sign of its "
                                     "declared value 11.271 N m s/rad"),
                       ("Tld = 900\n", "p.toml: Tld = 900 N m lies outside its declared range "
                                       "[-450, 450] N m")):
        p.write_text(text)
        capsys.readouterr()
        assert main(["isolate", "hst", str(rec), "--params", str(p)]) == 2
        assert said in capsys.readouterr().err
    p.write_text("Rv = 12.0\n")
    assert main(["simulate", "hst", "--out", str(tmp_path / "b.csv"), "--params", str(p)]) == 0
