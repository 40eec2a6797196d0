"""Routine records: judgements on real hydraulic actuators and a simulated fleet, as a new user gets them.

    python benchmarks/bench_routine.py                        # the units beside the repository
    python benchmarks/bench_routine.py --data DIR --healthy Act_3 Act_5 \\
        --peer Act_3=Act_5 --fault Act_6=Act_2:gear           # other units of the stand

Everything runs through the CLI, in-process, with examples/hydraulic-actuator/
as it is (nothing edited per unit) and the baselines its README tells a new
user to build:

- **own baseline** (each ``--healthy`` unit): ``baseline add`` of one cycle in
  two of the unit's records (records 4k and 4k + 1 in file-number order: one
  stroke each way, across the session's conditions), the tests its warnings
  name excluded (as it advises), then ``check`` of the others, stored; counts of go / advisory / no-go / not judged, the warnings
  ``baseline add`` printed, and what ``forecast`` says of each parameter;
- **against a healthy peer** (``--peer UNIT=REF``, both healthy, same load):
  ``check --against REF --dry-run`` of every record of UNIT;
- **faults** (``--fault UNIT=REF:KEYWORD``): ``check --against REF
  --dry-run`` of every record; flagged, the first named fault containing
  KEYWORD, and the checks that name the seal alone;
- **a simulated fleet** of DC-motor units (±5 % manufacturing spread, 2 %
  record-to-record scatter of every parameter): false flags of healthy
  checks against their own baselines, trust warnings at ``baseline add`` and
  ``check``, a new unit whose R is 20 % above the model's nominal flagged
  against the group.

Prints a table (with the machine's load) and writes results/routine.json.
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
from collections import Counter
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from typing import Any

import numpy as np

from _common import table, write_json
from condmon.cli.main import main
from condmon.monitor.baseline_checks import is_warning
from condmon.simulate import load_actuator_rig, simulate_actuator
from condmon.store import open_store
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import add_baseline_tests

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "external" / "hydraulic_actuators"
MODEL = str(ROOT / "examples" / "hydraulic-actuator" / "rotary-actuator.toml")
STATUSES = ("go", "advisory", "no-go", "not judged", "retest")


def _cli(*args: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main(list(args))
    return code, out.getvalue(), err.getvalue()


def _files(data: Path, unit: str) -> list[str]:
    """A unit's records in the stand's order: the number after ``<Kind>_000_`` in
    their names (``Base_000_12_...``, ``Leak_000_12_...``); names written another
    way, in natural order (their numbers compared as numbers)."""
    def key(p: Path) -> tuple[int, list[Any]]:
        m = re.search(r"^[A-Za-z]+_\d+_(\d+)_", p.name)
        if m:
            return 0, [int(m.group(1))]
        return 1, [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)]

    files = sorted(data.glob(f"{unit}/*.txt"), key=key)
    if not files:
        raise SystemExit(f"{data / unit}: no *.txt records")
    return [str(p) for p in files]


def _halves(files: list[str]) -> tuple[list[str], list[str]]:
    """The README's baseline (records 4k, 4k + 1) and the records to check."""
    return ([f for k, f in enumerate(files) if k % 4 in (0, 1)],
            [f for k, f in enumerate(files) if k % 4 in (2, 3)])


def _tests(files: list[str]) -> tuple[list[list[str]], int]:
    """The tests ``files`` make (in order) under the declaration's ``[estimation]
    cycle``, as ``baseline add`` makes them (one record each without a cycle),
    and how many records no cycle took."""
    from condmon.workflows.cycles import cycles_of
    from condmon.workflows.records import Cycle, EstimateOptions

    tests, left = cycles_of(EstimateOptions(model=MODEL), files)
    return [[str(r) for r in t.records] if isinstance(t, Cycle) else [str(t)]
            for t in tests], len(left)


def _share(counts: Counter[str], total: int) -> str:
    return ", ".join(f"{s} {counts[s]} ({100 * counts[s] / total:.0f} %)"
                     for s in STATUSES if counts[s]) or "-"


def _baseline(data: Path, unit: str, db: str) -> tuple[list[str], list[str]]:
    """The README's baseline of ``unit``, its advice followed (the tests a
    warning names are excluded: an outlier, a warm-up to leave out); the
    warnings ("warning:" lines)."""
    base, rest = _halves(_files(data, unit))
    code, _, err = _cli("baseline", "add", *base, "--unit", unit, "--db", db, "--model", MODEL)
    if code != 0:
        raise SystemExit(f"baseline add {unit} failed: {err.strip()}")
    with open_store(db) as store:
        latest = store.latest_baseline(unit)
        named = sorted({int(t) for f in (latest.flags if latest else ())
                        if is_warning(f) for t in f.get("tests", [])})
    for tid in named:
        _cli("exclude", str(tid), "--db", db, "--reason", "named by baseline add's warning")
    return rest, [line for line in err.splitlines() if line.startswith("warning:")]


def own(data: Path, unit: str, work: Path) -> tuple[list[dict[str, object]], dict[str, object]]:
    db = str(work / f"own-{unit}.db")
    rest, warned = _baseline(data, unit, db)
    counts: Counter[str] = Counter()
    reasons: Counter[str] = Counter()
    tests, left = _tests(rest)
    for f in tests:
        code, text, err = _cli("check", *f, "--unit", unit, "--db", db, "--json")
        doc = json.loads(text) if code == 0 else {"status": "error", "summary": err.strip()}
        counts[doc["status"]] += 1
        if doc["status"] != "go":
            reasons[str(doc["summary"])[:90]] += 1
    code, text, _ = _cli("forecast", "--unit", unit, "--db", db, "--json")
    fc = json.loads(text) if code == 0 else {"parameters": []}
    trends = [p["parameter"] for p in fc.get("parameters", []) if p.get("trend")]
    n = sum(counts.values())
    rows = [
        {"figure": f"{unit}: its other {len(rest)} records, {n} cycles, against its "
                   f"baseline (README's, {len(_halves(_files(data, unit))[0])} records)",
         "value": _share(counts, n),
         "target": "no-go <= 2 %, advisory <= 10 %"},
        {"figure": f"{unit}: records to check that no cycle took", "value": left,
         "target": "-"},
        {"figure": f"{unit}: warnings at baseline add", "value": len(warned), "target": "-"},
        {"figure": f"{unit}: forecast, parameters with a trend", "value": trends or "none",
         "target": "none"},
    ]
    return rows, {"unit": unit, "counts": dict(counts), "left_out": left, "warnings": warned,
                  "reasons": dict(reasons.most_common(5)), "trending": trends}


def against(data: Path, unit: str, ref: str, work: Path, keyword: str | None
            ) -> tuple[list[dict[str, object]], dict[str, object]]:
    db = str(work / f"peer-{unit}-{ref}.db")
    _baseline(data, ref, db)
    counts: Counter[str] = Counter()
    first_right = seal_alone = 0
    tests, left = _tests(_files(data, unit))
    for f in tests:
        code, text, err = _cli("check", *f, "--unit", unit, "--db", db, "--against", ref,
                               "--model", MODEL, "--dry-run", "--json")
        doc = json.loads(text) if code == 0 else {"status": "error", "candidates": []}
        counts[doc["status"]] += 1
        named = [n for c in doc.get("candidates", []) for n in c.get("faults", [])]
        if keyword is not None and named and keyword in named[0]:
            first_right += 1
        if named and all("seal" in n for n in named):
            seal_alone += 1
    n = sum(counts.values())
    flagged = counts["advisory"] + counts["no-go"]
    rows = [{"figure": f"{unit}: records no cycle took", "value": left, "target": "-"}]
    if keyword is None:
        rows += [{"figure": f"{unit} (healthy) against {ref}", "value": _share(counts, n),
                  "target": "no-go <= 2 %, advisory <= 10 %"}]
    else:
        rows += [
            {"figure": f"{unit} ({keyword}) against {ref}: flagged",
             "value": f"{flagged}/{n} ({100 * flagged / n:.0f} %); {_share(counts, n)}",
             "target": ">= 90 %"},
            {"figure": f"{unit}: '{keyword}' first in the named set",
             "value": f"{first_right}/{n} ({100 * first_right / n:.0f} %)",
             "target": ">= 75 % (gear), seal first (seal)"},
            {"figure": f"{unit}: the seal named alone", "value": seal_alone,
             "target": "0 (gear)"},
        ]
    return rows, {"unit": unit, "against": ref, "truth": keyword, "counts": dict(counts),
                  "left_out": left,
                  "first_right": first_right, "seal_alone": seal_alone}


NAMES = ("R", "L", "Kt", "J", "D")


def fleet(seed: int, n_units: int, n_base: int = 10, n_checks: int = 5) -> dict[str, int]:
    """Units of a ±5 % spread whose every record scatters 2 % about the unit's own
    values, in one group: healthy checks against their own baselines and against
    the group, trust warnings, and a new unit with R +20 % against the group."""
    rng = np.random.default_rng(seed)
    rig0 = load_actuator_rig()

    def unit(**factor: float):  # type: ignore[no-untyped-def]
        f = {k: (1.0 + rng.uniform(-0.05, 0.05)) * factor.get(k, 1.0) for k in NAMES}
        return dataclasses.replace(rig0, **{k: getattr(rig0, k) * f[k] for k in NAMES})

    def records(rig, n):  # type: ignore[no-untyped-def]
        out = []
        for _ in range(n):
            scatter = {k: getattr(rig, k) * (1.0 + 0.02 * rng.standard_normal()) for k in NAMES}
            out.append(simulate_actuator(dataclasses.replace(rig, **scatter),
                                         seed=int(rng.integers(1 << 30))))
        return out

    out: Counter[str] = Counter()
    with open_store("sqlite://") as store:
        rigs = {f"U{j:02d}": unit() for j in range(n_units)}
        warned: set[str] = set()
        for name, rig in rigs.items():
            added = add_baseline_tests(store, name, records(rig, n_base), group="g")
            if any(is_warning(f) for f in added.flags):
                warned.add(name)
        for name, rig in rigs.items():
            for rec in records(rig, n_checks):
                for how, kw in (("own", {}), ("group", {"against": "g"})):
                    res = check_test(store, name, rec, dry_run=True, **kw)  # type: ignore[arg-type]
                    out[f"{how}_checks"] += 1
                    out[f"{how}_flagged"] += res.status != "go"
                    if any(is_warning(f) for f in res.baseline_flags):
                        warned.add(name)
        out["trust_warnings"] = len(warned)
        worn = dataclasses.replace(unit(), R=rig0.R * 1.2)   # R 20 % above the model's nominal
        for rec in records(worn, 10):
            res = check_test(store, "R20", rec, dry_run=True, group="g")
            out["r20_checks"] += 1
            out["r20_flagged"] += res.status in ("advisory", "no-go")
    return dict(out)


def _load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "unknown"


def main_bench() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--healthy", nargs="*", default=["Act_1", "Act_2"])
    ap.add_argument("--peer", nargs="*", default=[], help="UNIT=REF, both healthy, one load")
    ap.add_argument("--fault", nargs="*", default=["Act_4=Act_1:seal"],
                    help="UNIT=REF:KEYWORD of the fault's name")
    ap.add_argument("--fleets", type=int, default=2)
    ap.add_argument("--units", type=int, default=10)
    args = ap.parse_args()
    print(f"load average before: {_load()}", file=sys.stderr)
    rows: list[dict[str, object]] = []
    detail: dict[str, object] = {"own": [], "peers": [], "faults": []}
    t0 = time.perf_counter()
    if args.data.exists():
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            for unit in args.healthy:
                r, d = own(args.data, unit, work)
                rows += r
                detail["own"].append(d)  # type: ignore[attr-defined]
            for spec in args.peer:
                unit, ref = spec.split("=")
                r, d = against(args.data, unit, ref, work, None)
                rows += r
                detail["peers"].append(d)  # type: ignore[attr-defined]
            for spec in args.fault:
                unit, rest = spec.split("=")
                ref, keyword = rest.split(":")
                r, d = against(args.data, unit, ref, work, keyword)
                rows += r
                detail["faults"].append(d)  # type: ignore[attr-defined]
    else:
        print(f"skipping the actuator records: {args.data} not found", file=sys.stderr)
    t1 = time.perf_counter()
    totals: Counter[str] = Counter()
    for k in range(args.fleets):
        totals.update(fleet(k + 1, args.units))
    own_n, grp_n = max(totals["own_checks"], 1), max(totals["group_checks"], 1)
    rows += [] if not args.fleets else [
        {"figure": f"fleet ({args.fleets} x {args.units} DC-motor units, ±5 % spread, 2 % "
                   "scatter): healthy checks flagged, own baseline",
         "value": f"{totals['own_flagged']}/{own_n} ({100 * totals['own_flagged'] / own_n:.1f} %)",
         "target": "<= 1 %"},
        {"figure": "fleet: healthy checks flagged, against the group",
         "value": f"{totals['group_flagged']}/{grp_n} "
                  f"({100 * totals['group_flagged'] / grp_n:.1f} %)", "target": "<= 1 %"},
        {"figure": "fleet: units with a trust warning at baseline add or check",
         "value": totals["trust_warnings"], "target": 0},
        {"figure": "fleet: new unit with R +20 % against the group flagged",
         "value": f"{totals['r20_flagged']}/{totals['r20_checks']}", "target": ">= 95 %"},
    ]
    rows += [
        {"figure": "time: actuators / fleet [s]",
         "value": f"{t1 - t0:.0f} / {time.perf_counter() - t1:.0f}", "target": "-"},
    ]
    print(table(rows, f"Routine records: judgements (load average {_load()})"))
    path = write_json("routine", {"rows": rows, "detail": detail, "fleet_totals": dict(totals),
                                  "fleets": args.fleets, "units": args.units,
                                  "load_average": _load()})
    print(f"wrote {path}")


if __name__ == "__main__":
    main_bench()
