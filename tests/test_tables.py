"""Every table the command line prints, read back at 80 columns: each row shows the
values that were computed (the command's --json twin, the store, the simulated
truth) with their units, and nothing is cut off.

These run on the oldest and the newest versions pyproject allows (`pytest -m
tables` selects them with the other table tests; `.ci/pandas-range.sh`).
"""

from __future__ import annotations

import contextlib
import io
import json
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from _strokes import STROKE_DECLARATION as DECLARATION, write_stroke
from _tables import flat, row
from condmon.cli._console import fmt, id_runs
from condmon.cli.main import main

pytestmark = pytest.mark.tables

#: The estimated parameters of the dc-motor model, in the history's column order
#: (Ke = gamma Kt is derived, so it has no column).
MOTOR = ("R", "L", "Kt", "J", "D")
#: Every parameter of the dc-motor model with its unit, in the model's order.
UNITS = {"R": "ohm", "L": "H", "Ke": "V s/rad", "Kt": "N m/A", "J": "kg m^2", "D": "N m s/rad"}
#: The rig's truth (condmon simulate actuator) and the HST's nominal Rv.
TRUTH = {"R": 1.0, "L": 1.2e-3, "Kt": 0.05, "J": 5e-5}
RV = 11.271


@dataclass
class History:
    """A history made through the command line, and what its commands printed."""

    db: str
    folder: Path
    printed: dict[str, str] = field(default_factory=dict)

    def run(self, key: str | None, *args: str) -> str:
        """Run ``condmon ARGS`` (status 0); its standard output, kept under ``key``."""
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            assert main(list(args)) == 0, args
        if key is not None:
            self.printed[key] = buf.getvalue()
        return buf.getvalue()


@contextlib.contextmanager
def _terminal() -> Iterator[None]:
    """An 80-column terminal and a fixed actor for the audit trail."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("COLUMNS", "80")
        mp.setenv("CONDMON_ACTOR", "tester")
        yield


@pytest.fixture(autouse=True)
def _eighty_columns() -> Iterator[None]:
    with _terminal():
        yield


@pytest.fixture(scope="module")
def history(tmp_path_factory: pytest.TempPathFactory) -> History:
    """Unit E1: a baseline of 3 tests, a healthy check, a check with R +40 %, test #2
    excluded; unit H1: an isolation of Rv +40 %."""
    folder = tmp_path_factory.mktemp("tables")
    made = History(str(folder / "h.db"), folder)
    with _terminal():
        files = []
        for k, fault in enumerate([None, None, None, None, "R=+40%"]):
            path = folder / f"r{k}.csv"
            made.run(None, "simulate", "actuator", "--out", str(path), "--seed", str(k + 1),
                     *(["--fault", fault] if fault else []))
            files.append(str(path))
        made.run("baseline add", "baseline", "add", *files[:3], "--unit", "E1", "--db", made.db)
        made.run("check go", "check", files[3], "--unit", "E1", "--db", made.db)
        made.run("check no-go", "check", files[4], "--unit", "E1", "--db", made.db)
        made.run(None, "exclude", "2", "--reason", "a wrong record", "--db", made.db)
        hst = folder / "hst.csv"
        made.run(None, "simulate", "hst", "--out", str(hst), "--fault", "Rv=+40%@10s")
        made.run("isolate", "isolate", "hst", str(hst), "--unit", "H1", "--db", made.db)
    return made


def _json(made: History, *args: str) -> Any:
    return json.loads(made.run(None, *args, "--json"))


def _minute(iso: str) -> str:
    """``2026-03-01 14:30`` of ``2026-03-01T14:30:05.1Z``."""
    return iso.replace("T", " ")[:16]


def _change(value: float | None) -> str:
    return "" if value is None else f"{value:+.1f}"


# --- the tables of one record --------------------------------------------------------------

def test_estimate_table(history: History) -> None:
    record = str(history.folder / "r0.csv")
    doc = _json(history, "estimate", record)
    out = history.run(None, "estimate", record)
    for p, value in doc["parameters"].items():
        row(out, p, fmt(value), fmt(doc["std_errors"][p]), doc["units"][p], "record")
    for p, truth in TRUTH.items():
        assert doc["parameters"][p] == pytest.approx(truth, rel=0.05), p
    assert "r0.csv — dc-motor, SRIV, closed-loop instruments" in flat(out)
    assert (f"fit {doc['fit_percent']:.1f} % (100 R²; I {doc['fits']['I']:.1f} %, omega "
            f"{doc['fits']['omega']:.1f} %) — accepted (threshold 90 %)") in flat(out)


def test_baseline_add_table(history: History) -> None:
    out = history.printed["baseline add"]
    (doc,) = _json(history, "baseline", "list", "--unit", "E1", "--db", history.db)["baselines"]
    assert "Baseline of E1 (N = 3)" in out and doc["n"] == 3
    assert list(doc["mean"]) == list(UNITS)
    for p, unit in UNITS.items():
        mean, sd = doc["mean"][p], doc["std"][p]
        row(out, p, fmt(mean), fmt(sd), unit, f"{100 * sd / abs(mean):.2f}")
    assert doc["mean"]["R"] == pytest.approx(TRUTH["R"], rel=0.05)


@pytest.mark.parametrize("key,test_id,status", [("check go", 4, "go"),
                                                ("check no-go", 5, "no-go")])
def test_check_table(history: History, key: str, test_id: int, status: str) -> None:
    out = history.printed[key]
    rows = _json(history, "history", "--unit", "E1", "--db", history.db)
    r = {d["test_id"]: d for d in rows}[test_id]
    assert r["status"] == status
    assert re.search(rf"E1 — \S*r{test_id - 1}\.csv: {status}\s+\(fit {r['fit_percent']:.1f} "
                     rf"%, test #{test_id}\)", flat(out))
    for p, unit in UNITS.items():
        row(out, p, fmt(r[p]), unit, f"{r[f'{p}_change']:+.1f}", f"{r[f'{p}_high']:.2f}",
            f"{r[f'{p}_low']:.2f}")
    if status == "no-go":
        assert r["R_change"] == pytest.approx(40, abs=4) and r["R_high"] > 0.8
        assert "winding resistance increase — degree 1.00 (major" in flat(out)
    else:
        assert "no fault" in out


def test_isolate_tables(history: History) -> None:
    from condmon.models.registry import load_plant_model

    out = history.printed["isolate"]
    iso = _json(history, "history", "--unit", "H1", "--db", history.db)[0]
    plant = {p.name: p for p in load_plant_model("hst").parameters}
    # the fault signature matrix, one row per suspect, then the suspects' table
    row(out, "fault", "r_Ps", "r_omega_m", "Mb", "Ib")
    units = {"Rv": "N m s/rad", "Dm": "m^3/rad", "Dp": "m^3/rad", "Tld": "N m",
             "Rlkgm": "N s/m^5", "Rlkgp": "N s/m^5"}
    assert sorted(iso["suspects"]) == sorted(units)
    for p in iso["suspects"]:
        row(out, p, "1", "1", "1", "0")
        assert plant[p].unit == units[p]
        change = iso[f"{p}_change"]
        shown = ("" if change is None else "ran away" if abs(change) >= 1e4
                 else f"{change:+.1f}")
        value = "ran away" if shown == "ran away" else fmt(iso[p])   # never 2.7e+56
        line = row(out, *[c for c in (p, value, fmt(plant[p].value), units[p], shown) if c])
        assert line.endswith("rejected" if iso[f"{p}_rejected"] else f"{iso[f'{p}_error']:.2f}")
    assert iso["Rv"] == pytest.approx(1.4 * RV, rel=0.03) and plant["Rv"].value == RV
    assert f"detected at {iso['detection_time']:.2f} s" in out
    assert "fault isolated: Rv" in out
    assert "isolation i1 stored in the history of 'H1'" in flat(out)


# --- the tables of a history ---------------------------------------------------------------

def test_history_table_of_tests(history: History) -> None:
    rows = _json(history, "history", "--unit", "E1", "--db", history.db)
    out = history.run(None, "history", "--unit", "E1", "--db", history.db)
    row(out, "#", "source", "fit %", "status", *MOTOR)
    assert [r["status"] for r in rows] == ["baseline", "excluded", "baseline", "go", "no-go"]
    for r in rows:
        changes = [] if r["excluded"] else [_change(r[f"{p}_change"]) for p in MOTOR]
        line = row(out, str(r["test_id"]), Path(r["source"]).name, f"{r['fit_percent']:.1f}",
                   r["status"], *[c for c in changes if c])
        assert bool(re.search(r"[+-]\d", line)) == (r["role"] == "check" and not r["excluded"])
    assert "#2 excluded: a wrong record" in out
    assert "#5 no-go: winding resistance increase (1.00)" in out
    assert "baseline 'default' v1 (N = 3): #1-#3" in out


def test_history_table_of_isolations(history: History) -> None:
    iso = _json(history, "history", "--unit", "H1", "--db", history.db)[0]
    out = history.run(None, "history", "--unit", "H1", "--db", history.db)
    row(out, "#", "date", "source", "status", "detected", "isolated")
    row(out, "i1", _minute(iso["date"]), "hst.csv", iso["status"],
        f"{iso['detection_time']:.2f} s", "Rv")
    assert "i1 fault isolated: Rv" in out


def test_units_table(history: History) -> None:
    units = _json(history, "units", "--db", history.db)["units"]
    out = history.run(None, "units", "--db", history.db)
    row(out, "unit", "model", "tests", "latest", "date", "status")
    assert [(u["unit"], u["status"]) for u in units] == [("E1", "no-go"), ("H1", "no-go")]
    for u in units:
        count = str(u["tests"]) if not u["isolations"] else f"{u['isolations']} iso"
        row(out, u["unit"], u["model"], count, Path(u["latest_source"]).name,
            u["latest_date"][:10], u["status"])
    # by urgency: the "no-go in" column, "—" for a unit that cannot be forecast
    assert [u["forecast"] for u in units] == [None, None]
    assert units[0]["forecast_reason"] == (  # test #2 excluded
        "no baseline: 2 usable healthy test(s), a baseline needs 3")
    assert units[1]["forecast_reason"].startswith(  # H1: isolations only
        "its records are isolated against a plant model")
    out = history.run(None, "units", "--db", history.db, "--sort", "forecast")
    row(out, "unit", "model", "tests", "latest", "date", "status", "no-go in")
    for u in units:
        count = str(u["tests"]) if not u["isolations"] else f"{u['isolations']} iso"
        row(out, u["unit"], u["model"], count, Path(u["latest_source"]).name,
            u["latest_date"][:10], u["status"], "—")


@pytest.mark.parametrize("unit", [None, "E1", "H1"])
def test_audit_table(history: History, unit: str | None) -> None:
    args = ["audit", "--db", history.db, *(["--unit", unit] if unit else [])]
    trail = _json(history, *args)["audit"]
    out = history.run(None, *args)
    assert f"Audittrailof{unit or history.db}" in "".join(out.split())
    row(out, "at (UTC)", "who", "action", "unit", "test", "reason")
    assert trail and all(unit in (None, r["unit"]) for r in trail)
    for r in trail:
        ref = (f"i{r['isolation_id']}" if r["isolation_id"] is not None
               else "" if r["test_id"] is None else f"#{r['test_id']}")
        row(out, *[c for c in (_minute(r["at"]), r["actor"], r["action"], r["unit"], ref,
                               r["reason"]) if c])
    actions = [r["action"] for r in trail]
    if unit != "H1":
        assert "test excluded" in actions
        row(out, "test excluded", "E1", "#2", "a wrong record")
    if unit != "E1":
        row(out, "isolation added", "H1", "i1")


def test_baseline_list_table(history: History) -> None:
    doc = _json(history, "baseline", "list", "--unit", "E1", "--db", history.db)
    out = history.run(None, "baseline", "list", "--unit", "E1", "--db", history.db)
    row(out, "name", "v", "created", "N", "tests", "flags", "reason")
    (b,) = doc["baselines"]
    row(out, "*", b["name"], str(b["version"]), _minute(b["created_at"]), str(b["n"]),
        id_runs(b["test_ids"]), b["reason"])
    assert f"{b['name']} v{b['version']}: mean ± standard deviation of its tests" in out
    for p, unit in UNITS.items():
        assert f"\n  {p}: {fmt(b['mean'][p])} ± {fmt(b['std'][p])} {unit}\n" in out


def test_dates_groups_and_regimes_get_their_columns(tmp_path: Path) -> None:
    """A unit of a group, with dated tests, monitored per operating regime: the history
    and units tables gain date, group and regime columns."""
    made = History(str(tmp_path / "h.db"), tmp_path)
    strokes = [str(write_stroke(tmp_path / f"s{k}.txt", 1.0 if k % 2 == 0 else -1.0, seed=k))
               for k in range(6)]
    worn = str(write_stroke(tmp_path / "worn.txt", 1.0, seed=9, friction={"Tc": 60.0}))
    made.run(None, "baseline", "add", *strokes, "--unit", "A1", "--db", made.db, "--model",
             str(DECLARATION), "--group", "stand-2", "--date", "2026-03-01")
    made.run(None, "check", worn, "--unit", "A1", "--db", made.db, "--date", "2026-03-09T10:00")
    rows = _json(made, "history", "--unit", "A1", "--db", made.db)
    out = made.run(None, "history", "--unit", "A1", "--db", made.db)
    row(out, "#", "date", "source", "regime", "fit %", "status", "Tc")
    assert [r["regime"] for r in rows] == ["forward", "reverse"] * 3 + ["forward"]
    for r in rows:
        row(out, str(r["test_id"]), r["test_date"][:10], Path(r["source"]).name, r["regime"],
            f"{r['fit_percent']:.1f}", r["status"],
            *[c for c in [_change(r.get(f"Tc@{r['regime']}_change"))] if c])
    assert rows[-1]["status"] == "no-go" and rows[-1]["Tc@forward_change"] > 20
    (u,) = _json(made, "units", "--db", made.db)["units"]
    out = made.run(None, "units", "--db", made.db)
    row(out, "unit", "model", "group", "tests", "latest", "regime", "date", "status")
    row(out, "A1", Path(u["model"]).name, "stand-2", "7", "worn.txt", "forward", "2026-03-09",
        "no-go")


def test_the_oldest_versions_ci_installs_are_the_floors() -> None:
    """.ci/lowest.txt pins each dependency at the floor pyproject.toml declares."""
    import tomllib

    root = Path(__file__).resolve().parents[1]
    project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    floors = {}
    for spec in [*project["dependencies"], *project["optional-dependencies"]["postgres"]]:
        found = re.fullmatch(r"([\w-]+)(?:\[\w+\])?>=([\d.]+)", spec)
        assert found is not None, f"{spec}: a floor (>=) and nothing else"
        floors[found[1].lower()] = found[2]
    floors["psycopg-binary"] = floors["psycopg"]  # psycopg[binary]
    pins = dict(line.lower().split("==") for line in (root / ".ci" / "lowest.txt").read_text()
                .splitlines() if line.strip() and not line.startswith("#"))

    def numbers(v: str) -> tuple[int, ...]:
        return tuple(int(x) for x in (v.split(".") + ["0", "0"])[:3])

    assert {k: numbers(v) for k, v in pins.items()} == {k: numbers(v) for k, v in floors.items()}
