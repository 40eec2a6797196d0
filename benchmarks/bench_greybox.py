"""Grey-box estimation from declarations: parity, Coulomb friction, real data.

1. The DC motor through its declaration (symbolic coefficient map) against the
   closed-form map of the previous release: largest relative difference of the
   six parameters over Monte-Carlo records, and the time per record of both.
2. The DC motor with Coulomb friction on the nonlinear rig (the demo's): bias
   and spread of D with the linear model (Coulomb folded into D) and with the
   declared Coulomb model (output-error route), Tc with its standard error.
3. EMPS (real data, if present beside the repository): M, Fv, Fc, offset
   against the published values, time.

    python benchmarks/bench_greybox.py [--runs 30]

Prints tables and writes results/greybox.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from _common import table, write_json
from condmon.workflows.demo import load_demo_config
from condmon.identify import estimate
from condmon.models.dc_motor import dc_motor_from_discrete
from condmon.simulate import load_actuator_rig, simulate_actuator

ROOT = Path(__file__).parents[1]


def parity(runs: int) -> dict[str, Any]:
    worst, t_new, t_ref = 0.0, [], []
    for k in range(runs):
        rec = simulate_actuator(seed=3000 + k)
        t0 = time.perf_counter()
        res = estimate(rec)
        t_new.append(time.perf_counter() - t0)
        assert res.discrete is not None
        t0 = time.perf_counter()
        ref, _ = dc_motor_from_discrete(res.discrete.model, res.discrete.covariance, 0.95)
        t_ref.append(time.perf_counter() - t0)
        worst = max(worst, max(abs(res.parameters[p] / v - 1) for p, v in ref.as_dict().items()))
    return {"max_rel_difference": worst, "ms_per_record": 1000 * float(np.median(t_new)),
            "closed_form_map_ms": 1000 * float(np.median(t_ref))}


def coulomb(runs: int) -> dict[str, Any]:
    rig = dataclasses.replace(load_actuator_rig(), **load_demo_config().get("rig", {}))
    truth = {**rig.physical(), "Tc": rig.coulomb_friction}
    lin, oe, se, secs = [], [], [], []
    for k in range(runs):
        rec = simulate_actuator(rig, seed=4000 + k)
        a = estimate(rec)
        t0 = time.perf_counter()
        b = estimate(rec, model="dc-motor-coulomb")
        secs.append(time.perf_counter() - t0)
        if a.accepted:
            lin.append(a.parameters)
        if b.accepted:
            oe.append(b.parameters)
            se.append(b.std_errors)
    rows = []
    for label, vals in (("linear dc-motor", lin), ("dc-motor-coulomb (oe)", oe)):
        for p in ("R", "L", "Kt", "J", "D", "Tc"):
            if p not in vals[0]:
                continue
            x = np.array([v[p] for v in vals])
            rows.append({"model": label, "param": p, "accepted": len(vals),
                         "bias%": 100 * (x.mean() / truth[p] - 1),
                         "sd%": 100 * x.std(ddof=1) / truth[p],
                         "bias/(sd/sqrt n)": (x.mean() - truth[p]) / (x.std(ddof=1) / np.sqrt(len(x)))})
    mean_se_tc = float(np.mean([s["Tc"] for s in se])) if se else float("nan")
    return {"rows": rows, "truth": truth, "seconds_per_record_oe": float(np.median(secs)),
            "mean_reported_se_Tc_percent": 100 * mean_se_tc / truth["Tc"]}


def emps() -> dict[str, Any] | None:
    path = ROOT.parent / "shared" / "external" / "emps" / "DATA_EMPS.mat"
    if not path.exists():
        return None
    from condmon.io import read_record

    published = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}
    t0 = time.perf_counter()
    res = estimate(read_record(path), ROOT / "examples" / "emps" / "emps.toml")
    secs = time.perf_counter() - t0
    return {"seconds": secs, "accepted": res.accepted,
            "rows": [{"param": k, "estimate": res.parameters[k], "std_error": res.std_errors[k],
                      "published": v, "difference%": 100 * (res.parameters[k] / v - 1)}
                     for k, v in published.items()]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--runs", type=int, default=30)
    args = ap.parse_args()
    doc: dict[str, Any] = {"parity": parity(args.runs)}
    print(table([doc["parity"]], f"DC motor: declared route vs closed form, {args.runs} records"))
    doc["coulomb"] = coulomb(args.runs)
    print()
    print(table(doc["coulomb"]["rows"], f"Nonlinear rig (Coulomb {doc['coulomb']['truth']['Tc']} N m), "
                f"{args.runs} records; oe: {doc['coulomb']['seconds_per_record_oe']:.2f} s/record, "
                f"mean reported se(Tc) {doc['coulomb']['mean_reported_se_Tc_percent']:.1f} %"))
    doc["emps"] = emps()
    if doc["emps"] is not None:
        print()
        print(table(doc["emps"]["rows"], f"EMPS (real data), {doc['emps']['seconds']:.2f} s"))
    print(f"\nwrote {write_json('greybox', doc)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
