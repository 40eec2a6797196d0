"""Condition-monitoring figures on the simulated test-bed (nonlinear effects on).

    python benchmarks/bench_monitoring.py [--healthy 1000] [--seeds 20]

- false alarms: healthy tests against independent 5-test baselines;
- cross-coupling: mean estimated change of every parameter (D included) for the
  reference experiments' largest faults, against the true change;
- L +60 % with R +40 %: how often SymH(R) = 1 and SymH(L) = 1, the largest other symptom;
- time per `check` (estimate, symptoms, diagnosis, SQLite write).

Prints tables and writes results/monitoring.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time

import numpy as np

from _common import table, write_json
from condmon.workflows.demo import load_demo_config
from condmon.identify import estimate
from condmon.workflows.checks import check_test
from condmon.workflows.monitoring import add_baseline_tests
from condmon.simulate import load_actuator_rig, simulate_actuator
from condmon.store import open_store

PARAMS = ("R", "L", "Ke", "Kt", "J", "D")


def false_alarms(rig, n: int) -> dict[str, object]:  # type: ignore[no-untyped-def]
    per_baseline = 50
    statuses: list[str] = []
    times = []
    for u in range(max(1, n // per_baseline)):
        with open_store("sqlite://") as store:
            add_baseline_tests(store, "U", [simulate_actuator(rig, seed=100_000 + 100 * u + i)
                                            for i in range(5)])
            for t in range(per_baseline):
                rec = simulate_actuator(rig, seed=200_000 + 1000 * u + t)
                t0 = time.perf_counter()
                statuses.append(check_test(store, "U", rec).status)
                times.append(time.perf_counter() - t0)
    n_done = len(statuses)
    return {"tests": n_done, "baselines": n_done // per_baseline,
            "no_go": statuses.count("no-go"), "advisory": statuses.count("advisory"),
            "retest": statuses.count("retest"),
            "advisory_percent": 100 * statuses.count("advisory") / n_done,
            "check_ms_median": 1e3 * statistics.median(times)}


def cross_coupling(rig, seeds: int) -> list[dict[str, object]]:  # type: ignore[no-untyped-def]
    healthy = np.array([[estimate(simulate_actuator(rig, seed=s)).parameters[p] for p in PARAMS]
                        for s in range(700, 700 + seeds)])
    rows = []
    for faults in (["R=+20%"], ["R=+40%"], ["L=+20%", "R=+13%"], ["L=+50%", "R=+20%"],
                   ["D=*4", "coulomb_friction=*4"], ["D=*7", "coulomb_friction=*7"]):
        f_rig = rig.with_faults(faults)
        est = np.array([[estimate(simulate_actuator(f_rig, seed=s)).parameters[p] for p in PARAMS]
                        for s in range(900, 900 + seeds)])
        change = 100 * (est.mean(axis=0) / healthy.mean(axis=0) - 1)
        truth = np.array([100 * (f_rig.physical()[p] / rig.physical()[p] - 1) for p in PARAMS])
        changed = np.abs(truth) > 1e-9
        smallest = float(np.min(np.abs(truth[changed])))
        others = np.abs(change[~changed])
        core = [abs(change[i]) for i, p in enumerate(PARAMS) if not changed[i] and p != "D"]
        row: dict[str, object] = {"faults": " ".join(faults)}
        for i, p in enumerate(PARAMS):
            row[f"{p} %"] = float(change[i])
        row["worst/true"] = float(others.max() / smallest)
        row["worst/true excl. D"] = float(max(core) / smallest) if core else 0.0
        rows.append(row)
    return rows


def lr_symptoms(rig, seeds: int) -> dict[str, object]:  # type: ignore[no-untyped-def]
    exact_r = exact_l = 0
    r_high, others, r_change = [], [], []
    for s in range(seeds):
        with open_store("sqlite://") as store:
            add_baseline_tests(store, "U", [simulate_actuator(rig, seed=5000 + 10 * s + i)
                                            for i in range(5)])
            res = check_test(store, "U", simulate_actuator(
                rig.with_faults(["L=+60%", "R=+40%"]), seed=9000 + s))
        sym = res.symptoms
        exact_r += sym["R"]["high"] == 1.0
        exact_l += sym["L"]["high"] == 1.0
        r_high.append(sym["R"]["high"])
        r_change.append(res.percent_change["R"])
        others.append(max(v for p, d in sym.items() for k, v in d.items()
                          if not (k == "high" and p in ("R", "L"))))
    return {"seeds": seeds, "SymH_L_equals_1": exact_l, "SymH_R_equals_1": exact_r,
            "SymH_R_min": float(min(r_high)), "R_change_mean": float(np.mean(r_change)),
            "R_change_std": float(np.std(r_change, ddof=1)), "max_other_symptom": float(max(others))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--healthy", type=int, default=1000)
    ap.add_argument("--seeds", type=int, default=20)
    args = ap.parse_args()
    rig = dataclasses.replace(load_actuator_rig(), **load_demo_config().get("rig", {}))
    t0 = time.perf_counter()
    fa = false_alarms(rig, args.healthy)
    print(table([fa], "False alarms over healthy tests (independent 5-test baselines, 50 tests each)"))
    cc = cross_coupling(rig, args.seeds)
    print()
    print(table(cc, f"Mean estimated change [%] over {args.seeds} seeds, and the largest change of "
                    "an unchanged parameter over the smallest true change"))
    lr = lr_symptoms(rig, args.seeds)
    print()
    print(table([lr], "L +60 % with R +40 %: symptoms (SymH = 1 iff the measured change >= r2)"))
    path = write_json("monitoring", {"false_alarms": fa, "cross_coupling": cc,
                                     "L60_R40": lr, "seconds": time.perf_counter() - t0})
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
