"""Routine records: the real hydraulic actuators of one test stand, and a simulated fleet with a group.

    python benchmarks/bench_routine.py [--fleets 3] [--units 20]

One line per acceptance figure of the routine-records work:

- every record of Act_1 (healthy) and Act_4 (seal defect) estimated with
  examples/hydraulic-actuator/ alone: accepted, regime, identifiable
  parameters, fit, physical bounds, time per record;
- baseline from Act_1's first 10 records (by the number after ``Base_000_``),
  then ``check --dry-run`` of every other record: Act_1 go, Act_4 advisory or
  no-go with a diagnosis naming the parameter;
- records cut to their hold: not identifiable, nothing trended;
- simulated fleets of DC-motor units with a +-5 % manufacturing spread in one
  group: healthy units' tests against the group (false flags), a new unit
  with R +20 % against the group, a unit whose own baseline is 4 between-unit
  standard deviations off (flagged in ``units``; other units flagged too).

Prints a table and writes results/routine.json. The actuator lines need
../shared/external/hydraulic_actuators beside the repository (skipped otherwise).
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import json
import re
import sys
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

from _common import table, write_json
from condmon.cli.main import main
from condmon.simulate import load_actuator_rig, simulate_actuator
from condmon.store import open_store
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import add_baseline_tests

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "external" / "hydraulic_actuators"
MODEL = str(ROOT / "examples" / "hydraulic-actuator" / "rotary-actuator.toml")


def _cli(*args: str) -> tuple[int, str]:
    buf = io.StringIO()
    with redirect_stdout(buf), redirect_stderr(io.StringIO()):
        code = main(list(args))
    return code, buf.getvalue()


def _files(actuator: str) -> list[str]:
    files = sorted(DATA.glob(f"{actuator}/*.txt"),
                   key=lambda p: int(re.search(r"_000_(\d+)_", p.name).group(1)))  # type: ignore[union-attr]
    return [str(p) for p in files]


def actuators(work: Path) -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    a1, a4 = _files("Act_1"), _files("Act_4")
    for name, files in (("Act_1", a1), ("Act_4", a4)):
        t0 = time.perf_counter()
        docs = []
        for f in files:
            code, text = _cli("estimate", f, "--model", MODEL, "--json")
            docs.append(json.loads(text) if code == 0 else {"accepted": False, "error": True})
        ms = 1e3 * (time.perf_counter() - t0) / len(files)
        ok = [d for d in docs if d.get("accepted")]
        bounds = sum(1 for d in ok if d["parameters"]["Tc"] < 0 or d["parameters"]["J"] <= 0)
        rows.append({"figure": f"estimate {name}: accepted", "value": f"{len(ok)}/{len(docs)}",
                     "target": "every file, no other option"})
        rows.append({"figure": f"estimate {name}: regimes (forward/reverse)",
                     "value": f"{sum(d['regime'] == 'forward' for d in ok)}/"
                              f"{sum(d['regime'] == 'reverse' for d in ok)}", "target": "-"})
        rows.append({"figure": f"estimate {name}: identified Tc only",
                     "value": f"{sum(d['identifiable'] == {'Tc': True, 'Dv': False, 'Tl': False, 'J': False} for d in ok)}/{len(ok)}",
                     "target": "-"})
        rows.append({"figure": f"estimate {name}: lowest fit [%]",
                     "value": round(min(d["fit_percent"] for d in ok), 2), "target": ">= 90"})
        rows.append({"figure": f"estimate {name}: bounds broken", "value": bounds, "target": 0})
        rows.append({"figure": f"estimate {name}: time per record [ms] (CLI, in-process)",
                     "value": round(ms, 1), "target": "-"})
    db = str(work / "act.db")
    _cli("baseline", "add", *a1[:10], "--unit", "Act_1", "--db", db, "--model", MODEL)
    for name, files, want in (("Act_1", a1[10:], ("go",)), ("Act_4", a4, ("advisory", "no-go"))):
        statuses, named = [], 0
        for f in files:
            code, text = _cli("check", f, "--unit", "Act_1", "--db", db, "--dry-run", "--json")
            doc = json.loads(text) if code == 0 else {"status": "error", "summary": ""}
            statuses.append(doc["status"])
            named += doc["status"] in ("advisory", "no-go") and "Tc" in doc["summary"]
        hit = sum(s in want for s in statuses)
        rows.append({"figure": f"check {name} against Act_1's first 10: {' or '.join(want)}",
                     "value": f"{hit}/{len(statuses)} ({100 * hit / len(statuses):.1f} %)",
                     "target": ">= 95 %"})
        if name == "Act_4":
            rows.append({"figure": "Act_4 flagged with a diagnosis naming Tc",
                         "value": f"{named}/{hit}", "target": "all"})
            counts = {s: statuses.count(s) for s in sorted(set(statuses))}
            rows.append({"figure": "Act_4 statuses", "value": counts, "target": "-"})
    retest = 0
    for k, f in enumerate(a1[20:30]):
        lines = Path(f).read_text().splitlines()
        hold = work / f"hold{k}.txt"
        hold.write_text("\n".join([lines[0], *lines[700:]]) + "\n")
        code, text = _cli("check", str(hold), "--unit", "Act_1", "--db", db, "--json")
        doc = json.loads(text) if code == 0 else {}
        retest += doc.get("status") == "retest" and str(doc.get("reason", "")).startswith(
            "not identifiable")
    with open_store(db) as store:
        trended = len(store.usable_tests("Act_1", role="check"))
    rows.append({"figure": "records cut to their hold: not identifiable (retest)",
                 "value": f"{retest}/10", "target": "all"})
    rows.append({"figure": "... of them trended", "value": trended, "target": 0})
    return rows


NAMES = ("R", "L", "Kt", "J", "D")


def fleet(seed: int, n_units: int) -> dict[str, int]:
    rng = np.random.default_rng(seed)
    base = load_actuator_rig()
    sigma = 0.05 / np.sqrt(3.0)

    def unit(**factor: float):  # type: ignore[no-untyped-def]
        f = {k: (1.0 + rng.uniform(-0.05, 0.05)) * factor.get(k, 1.0) for k in NAMES}
        return dataclasses.replace(base, **{k: getattr(base, k) * f[k] for k in NAMES})

    def records(rig, seeds):  # type: ignore[no-untyped-def]
        return [simulate_actuator(rig, seed=int(s)) for s in seeds]

    out = {"healthy_checks": 0, "healthy_flagged": 0, "r20_checks": 0, "r20_flagged": 0,
           "odd_flagged": 0, "others_flagged": 0}
    with open_store("sqlite://") as store:
        rigs = {f"U{i:02d}": unit() for i in range(n_units)}
        s0 = 100_000 * seed
        for j, (name, rig) in enumerate(rigs.items()):
            add_baseline_tests(store, name, records(rig, range(s0 + 10 * j, s0 + 10 * j + 3)),
                               group="g")
        for j, (name, rig) in enumerate(rigs.items()):
            for rec in records(rig, range(s0 + 5000 + 10 * j, s0 + 5002 + 10 * j)):
                res = check_test(store, name, rec, dry_run=True, against="g")
                out["healthy_checks"] += 1
                out["healthy_flagged"] += res.status != "go"
        worn = unit(R=1.2)
        for rec in records(worn, range(s0 + 9000, s0 + 9003)):
            res = check_test(store, "R20", rec, dry_run=True, group="g")
            out["r20_checks"] += 1
            out["r20_flagged"] += res.status in ("advisory", "no-go")
        odd = dataclasses.replace(unit(), R=base.R * (1 + 4 * sigma))
        add_baseline_tests(store, "ODD", records(odd, range(s0 + 9100, s0 + 9103)), group="g")
        rows = store.unit_summaries()
        out["odd_flagged"] = int(any(r["group_flags"] for r in rows if r["unit"] == "ODD"))
        out["others_flagged"] = sum(1 for r in rows if r["unit"] != "ODD" and r["group_flags"])
    return out


def main_bench() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fleets", type=int, default=3)
    ap.add_argument("--units", type=int, default=20)
    args = ap.parse_args()
    rows: list[dict[str, object]] = []
    if DATA.exists():
        with tempfile.TemporaryDirectory() as work:
            rows += actuators(Path(work))
    else:
        print(f"skipping the actuator records: {DATA} not found", file=sys.stderr)
    totals: dict[str, int] = {}
    t0 = time.perf_counter()
    for k in range(args.fleets):
        for key, v in fleet(k + 1, args.units).items():
            totals[key] = totals.get(key, 0) + v
    rows += [
        {"figure": f"fleet ({args.fleets} x {args.units} units): healthy tests vs group flagged",
         "value": f"{totals['healthy_flagged']}/{totals['healthy_checks']} "
                  f"({100 * totals['healthy_flagged'] / totals['healthy_checks']:.1f} %)",
         "target": "<= 2 %"},
        {"figure": "fleet: new unit with R +20 % vs group flagged",
         "value": f"{totals['r20_flagged']}/{totals['r20_checks']}", "target": "flagged"},
        {"figure": "fleet: unit 4 between-unit sigma off flagged in units",
         "value": f"{totals['odd_flagged']}/{args.fleets}", "target": "flagged"},
        {"figure": "fleet: other units flagged in units",
         "value": f"{totals['others_flagged']}/{args.fleets * args.units}", "target": "-"},
        {"figure": "fleet: time per fleet [s]",
         "value": round((time.perf_counter() - t0) / args.fleets, 1), "target": "-"},
    ]
    print(table(rows, "Routine records: real actuators, peer groups"))
    path = write_json("routine", {"rows": rows, "fleet_totals": totals,
                                  "fleets": args.fleets, "units": args.units})
    print(f"wrote {path}")


if __name__ == "__main__":
    main_bench()
