"""History figures: baseline flags, store overhead per check, concurrent writers.

    python benchmarks/bench_history.py [--baselines 100] [--postgres URL]

- flags on healthy baselines (false flags) and on baselines with one bad test
  among healthy ones (D x 7, R +40 %, a record in mA), for N = 3, 5, 10 tests
  (the paper-level rig, estimates computed once and reused);
- time per `check` split into estimation and the store (SQLite file; PostgreSQL
  when a URL is given);
- 8 processes writing 20 records each at once: records/s and waits.

Prints tables and writes results/history.json.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _common import table, write_json
from condmon.identify import estimate
from condmon.monitor.baseline import assess_baseline
from condmon.simulate import load_actuator_rig, simulate_actuator
from condmon.store import open_store
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import EstimateOptions, add_baseline_tests

PARAMS = ("R", "L", "Ke", "Kt", "J", "D")


def _estimates(rig, seeds: range, faults: list[str]) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    vals, ses = [], []
    for s in seeds:
        r = estimate(simulate_actuator(rig.with_faults(faults), seed=s))
        vals.append([r.parameters[p] for p in PARAMS])
        ses.append([r.std_errors[p] for p in PARAMS])
    return np.array(vals), np.array(ses)


def flags(rig, n_baselines: int) -> list[dict[str, object]]:  # type: ignore[no-untyped-def]
    pool_v, pool_s = _estimates(rig, range(5000, 5000 + n_baselines * 4), [])
    bad = {"D x 7": _estimates(rig, range(6000, 6000 + n_baselines), ["D=*7"]),
           "R +40 %": _estimates(rig, range(7000, 7000 + n_baselines), ["R=+40%"])}
    rng = np.random.default_rng(0)
    rows = []
    for n in (3, 5, 10):
        false = 0
        caught = {k: 0 for k in bad}
        named = {k: 0 for k in bad}
        for b in range(n_baselines):
            idx = rng.choice(len(pool_v), n, replace=False)
            ids = list(range(1, n + 1))
            if assess_baseline(pool_v[idx], pool_s[idx], ids, PARAMS):
                false += 1
            for k, (bv, bs) in bad.items():
                v, s = pool_v[idx].copy(), pool_s[idx].copy()
                v[-1], s[-1] = bv[b], bs[b]
                f = assess_baseline(v, s, ids, PARAMS)
                caught[k] += bool(f)
                named[k] += any(x["kind"] == "outlier" and x["tests"] == [n] for x in f)
        row: dict[str, object] = {"N": n, "false_flags_percent": 100 * false / n_baselines}
        for k in bad:
            row[f"{k} flagged %"] = 100 * caught[k] / n_baselines
            row[f"{k} named %"] = 100 * named[k] / n_baselines
        rows.append(row)
    return rows


def check_overhead(rig, db: str, n: int = 30) -> dict[str, object]:  # type: ignore[no-untyped-def]
    recs = [simulate_actuator(rig, seed=900 + s) for s in range(n + 5)]
    for i, r in enumerate(recs):
        r.attrs["source"] = f"r{i}.csv"
    opts = EstimateOptions(model="dc-motor")
    est = []
    for r in recs[5:]:
        t0 = time.perf_counter()
        opts.run(r)
        est.append(time.perf_counter() - t0)
    total = []
    with open_store(db) as store:
        add_baseline_tests(store, "U", recs[:5])
        for r in recs[5:]:
            t0 = time.perf_counter()
            check_test(store, "U", r)
            total.append(time.perf_counter() - t0)
    e, t = statistics.median(est), statistics.median(total)
    return {"estimate_ms": 1e3 * e, "check_ms": 1e3 * t, "store_ms": 1e3 * (t - e)}


def writers(rig, db: str, n_proc: int = 8, per: int = 20) -> dict[str, object]:  # type: ignore[no-untyped-def]
    worker = Path(__file__).parents[1] / "tests" / "_stress_worker.py"
    with tempfile.TemporaryDirectory() as d:
        files = []
        for s in range(n_proc * per // 2):
            p = Path(d) / f"r{s}.csv"
            simulate_actuator(rig, seed=1200 + s).to_csv(p, index=False)
            files.append(str(p))
        plans = []
        for k in range(n_proc):
            plan = [(f"EMA-{(k + i) % 4}", files[(k * 7 + i) % len(files)]) for i in range(per)]
            pf = Path(d) / f"plan{k}.json"
            pf.write_text(json.dumps(plan))
            plans.append(str(pf))
        env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
        t0 = time.perf_counter()
        procs = [subprocess.Popen([sys.executable, str(worker), db, p], env=env,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                 for p in plans]
        outs = [p.communicate() for p in procs]
        wall = time.perf_counter() - t0
    stored = sum(o.count("STORED") for o, _ in outs)
    dup = sum(o.count("DUPLICATE") for o, _ in outs)
    errors = sum(o.count("ERROR") for o, _ in outs) + sum("Traceback" in e for _, e in outs)
    with open_store(db) as store:
        problems = store.integrity_problems()
    return {"processes": n_proc, "records": n_proc * per, "stored": stored, "duplicates": dup,
            "errors": errors, "wall_s": wall, "records_per_s": n_proc * per / wall,
            "integrity_problems": len(problems)}


def _empty(url: str | None, file: Path) -> str:
    """An empty history: the server's ``url`` with condmon's tables dropped, else a
    new SQLite ``file``."""
    if not url:
        return str(file)
    import sqlalchemy as sa

    from condmon.store import schema
    from condmon.store.engine import database_url

    eng = sa.create_engine(database_url(url))
    schema.metadata.drop_all(eng)
    eng.dispose()
    return url


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baselines", type=int, default=100)
    ap.add_argument("--postgres", default=os.environ.get("CONDMON_TEST_POSTGRES_URL"))
    args = ap.parse_args()
    rig = load_actuator_rig()
    doc: dict[str, object] = {}
    doc["flags"] = rows = flags(rig, args.baselines)
    print(table(rows, "Baseline flags: false flags on healthy baselines; one bad test among "
                      "healthy ones flagged / named as the outlier"))
    backends = {"sqlite": None}
    if args.postgres:
        backends["postgresql"] = args.postgres
    over, conc = [], []
    for name, url in backends.items():
        with tempfile.TemporaryDirectory() as d:
            over.append({"backend": name, **check_overhead(rig, _empty(url, Path(d) / "h.db"))})
            conc.append({"backend": name, **writers(rig, _empty(url, Path(d) / "w.db"))})
    doc["check_overhead"], doc["writers"] = over, conc
    print(table(over, "Time per check (median): estimation and the store"))
    print(table(conc, "8 processes x 20 records at once"))
    write_json("history", doc)


if __name__ == "__main__":
    main()
