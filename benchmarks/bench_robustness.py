"""Robustness of the actuator estimate on a rig the built-in defaults do not cover.

The speed loop has no current feedback (``k_current = 0``) and the voltage
perturbation ``ud`` is band-limited to 100 Hz; sensor noise is at paper level.
For each Monte-Carlo record the estimate is made twice — closed-loop
instruments from ``yd, ud`` and the direct approach (``excitation=None``) — and
the outcome is counted: accepted, rejected with a reason, or an exception.
Accuracy of the accepted closed-loop estimates is compared with the
Cramér–Rao bound of the output-error model.

    python benchmarks/bench_robustness.py [--runs 100] [--name robustness]

Prints tables and writes results/<name>.json. Run it on an older checkout (with
``PYTHONPATH`` pointing at its ``src``) to measure the failure rate before a change.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import sys
import time
import warnings
from typing import Any

import numpy as np

from _common import oe_information, table, write_json
from condmon.identify import estimate
from condmon.models import PARAMETER_NAMES, DCMotorParameters, dc_motor_tf, tf_c2d
from condmon.models.dc_motor import dc_motor_from_discrete
from condmon.simulate import load_actuator_rig, simulate_actuator

CONFIGS: dict[str, dict[str, float]] = {
    "no current feedback, ud 100 Hz": {"k_current": 0.0, "ud_bandwidth": 100.0},
    "built-in defaults": {},
    "other motor": {"R": 0.4, "L": 0.4e-3, "Kt": 0.1, "J": 2e-4, "D": 5e-4,
                    "k_current": 0.0, "ud_bandwidth": 100.0},
    "Coulomb friction": {"coulomb_friction": 0.02, "k_current": 0.0, "ud_bandwidth": 100.0},
    "noise x2": {"noise_I": 0.7, "noise_omega": 4.0, "k_current": 0.0, "ud_bandwidth": 100.0},
}


def run_config(changes: dict[str, float], runs: int, seed0: int) -> dict[str, Any]:
    rig = dataclasses.replace(load_actuator_rig(), **changes)
    truth_p = DCMotorParameters(**rig.physical())
    truth = truth_p.as_array()
    gd = tf_c2d(dc_motor_tf(truth_p), rig.dt)
    theta_true = np.r_[gd.den[1:], gd.nums[0, 1:], gd.nums[1, 1:]]
    sigma = np.array([rig.noise_I, rig.noise_omega])
    outcomes: dict[str, collections.Counter[str]] = {
        "closed": collections.Counter(), "direct": collections.Counter()}
    values: dict[str, list[list[float]]] = {"closed": [], "direct": []}
    paths: dict[str, collections.Counter[str]] = {
        "closed": collections.Counter(), "direct": collections.Counter()}
    crb = []
    seconds = {"closed": 0.0, "direct": 0.0}
    for k in range(runs):
        rec = simulate_actuator(rig, seed=seed0 + k)
        for label, exc in (("closed", "auto"), ("direct", None)):
            t0 = time.perf_counter()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    res = estimate(rec, excitation=exc)
            except Exception as err:  # counted, this is what the benchmark measures
                outcomes[label][f"exception {type(err).__name__}"] += 1
                continue
            finally:
                seconds[label] += time.perf_counter() - t0
            if res.accepted:
                outcomes[label]["accepted"] += 1
                values[label].append([res.parameters[p] for p in PARAMETER_NAMES])
            else:
                outcomes[label]["rejected"] += 1
            paths[label][str(getattr(res.discrete, "path", res.method))] += 1
        info = oe_information(theta_true, rec["V"].to_numpy(), sigma)
        _, pcov = dc_motor_from_discrete(gd, np.linalg.inv(info), rig.gamma)
        crb.append(np.sqrt(np.diag(pcov)))
    crb_sd = np.mean(crb, axis=0)
    rows = []
    for label in ("closed", "direct"):
        arr = np.array(values[label]) if values[label] else np.empty((0, 6))
        for i, p in enumerate(PARAMETER_NAMES):
            if arr.shape[0] < 3:
                continue
            bias = float(np.mean(arr[:, i]) - truth[i])
            sd = float(np.std(arr[:, i], ddof=1))
            rows.append({"approach": label, "param": p, "bias%": 100 * bias / truth[i],
                         "|bias|/sd": abs(bias) / sd, "sd/CRB": sd / crb_sd[i]})
    return {
        "changes": changes, "runs": runs,
        "outcomes": {k: dict(v) for k, v in outcomes.items()},
        "estimate_rate": {k: outcomes[k]["accepted"] / runs for k in outcomes},
        "paths": {k: dict(v) for k, v in paths.items()},
        "ms_per_record": {k: 1000 * v / runs for k, v in seconds.items()},
        "accuracy": rows,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--name", default="robustness")
    args = ap.parse_args()
    t0 = time.perf_counter()
    doc: dict[str, Any] = {}
    summary = []
    for i, (title, changes) in enumerate(CONFIGS.items()):
        res = run_config(changes, args.runs, 20000 + 1000 * i)
        doc[title] = res
        for label in ("closed", "direct"):
            summary.append({"rig": title, "approach": label,
                            "accepted": res["outcomes"][label].get("accepted", 0),
                            "rejected": res["outcomes"][label].get("rejected", 0),
                            "exceptions": sum(v for k, v in res["outcomes"][label].items()
                                              if k.startswith("exception")),
                            "ms/record": res["ms_per_record"][label],
                            "paths": ", ".join(f"{k}: {v}" for k, v in res["paths"][label].items())})
        if res["accuracy"]:
            print(table(res["accuracy"], f"{title}: accepted estimates against truth and the CRB"))
            print()
    print(table(summary, f"Outcome of {args.runs} records per rig (paper-level noise)"))
    path = write_json(args.name, {"configs": doc, "seconds": time.perf_counter() - t0})
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
