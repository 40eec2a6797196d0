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
