"""condmon against SIPPY (OE and ARX) on the same actuator records.

    pip install '.[bench]'
    python benchmarks/bench_peers.py [--records 20]

SIPPY estimates each output separately (no common denominator), so the
physical parameters of its models are read this way: each SISO model is
converted to continuous time with condmon's exact ZOH inverse, the two
continuous denominators are averaged, and the current numerator (b1, b0) and
speed numerator (c0) are taken from their own models. The order convention is
the same for both tools (two poles, numerators with one sample of delay:
SIPPY's ``nk = 0``). Accuracy is the RMS relative error of each parameter over
the records; time is per record (both outputs). Prints ratios and writes
results/peers.json.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # both tools on one core

import argparse
import contextlib
import io
import statistics
import sys
import time
import warnings

import numpy as np

from _common import table, write_json
from condmon.identify import estimate
from condmon.models import PARAMETER_NAMES, DiscreteTF, tf_d2c
from condmon.models.dc_motor import _coefficients_to_physical
from condmon.simulate import load_actuator_rig, simulate_actuator


def sippy_physical(rec, method: str, gamma: float) -> tuple[np.ndarray, float]:  # type: ignore[no-untyped-def]
    from sippy_unipi import system_identification

    u = rec["V"].to_numpy()
    conts = []
    t0 = time.perf_counter()
    for out in ("I", "omega"):
        kw = {"ARX_orders": [2, 2, 0]} if method == "ARX" else {"OE_orders": [2, 2, 0]}
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            m = system_identification(rec[out].to_numpy(), u, method, tsample=1e-3, **kw)
        num = np.ravel(np.asarray(m.NUMERATOR, dtype=float))
        den = np.ravel(np.asarray(m.DENOMINATOR, dtype=float))
        conts.append((num, den))
    elapsed = time.perf_counter() - t0
    cs = []
    for num, den in conts:
        g = tf_d2c(DiscreteTF(den, np.r_[0.0, num][None, :], 1e-3))
        cs.append(g)
    a1 = 0.5 * (cs[0].den[1] + cs[1].den[1])
    a0 = 0.5 * (cs[0].den[2] + cs[1].den[2])
    b1, b0 = cs[0].nums[0, 1], cs[0].nums[0, 2]
    c0 = cs[1].nums[0, 2]
    return _coefficients_to_physical(a1, a0, b1, b0, c0, gamma), elapsed


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--records", type=int, default=20)
    args = ap.parse_args()
    try:
        import sippy_unipi  # noqa: F401
    except ImportError:
        print("SIPPY is not installed: pip install '.[bench]'")
        return 1
    rig = load_actuator_rig()
    truth = np.array([rig.physical()[p] for p in PARAMETER_NAMES])
    est: dict[str, list[np.ndarray]] = {"condmon SRIV": [], "SIPPY OE": [], "SIPPY ARX": []}
    times: dict[str, list[float]] = {k: [] for k in est}
    failures: dict[str, list[str]] = {k: [] for k in est}
    estimate(simulate_actuator(rig, seed=1))  # warm-up
    for s in range(args.records):
        rec = simulate_actuator(rig, seed=2000 + s)
        t0 = time.perf_counter()
        res = estimate(rec)
        times["condmon SRIV"].append(time.perf_counter() - t0)
        est["condmon SRIV"].append(np.array([res.parameters[p] for p in PARAMETER_NAMES]))
        for method in ("OE", "ARX"):
            try:
                vals, el = sippy_physical(rec, method, rig.gamma)
            except Exception as err:  # a peer failing is a result too
                failures[f"SIPPY {method}"].append(f"record {s}: {err}")
                continue
            est[f"SIPPY {method}"].append(vals)
            times[f"SIPPY {method}"].append(el)
    rms = {k: np.sqrt(np.mean((np.array(v) / truth - 1) ** 2, axis=0)) * 100 for k, v in est.items() if v}
    tmed = {k: statistics.median(v) * 1e3 for k, v in times.items() if v}
    rows = []
    for k in est:
        if k not in rms:
            rows.append({"tool": k, "records": 0, **{f"{p} rms%": float("nan") for p in PARAMETER_NAMES},
                         "ms/record": float("nan")})
            continue
        row: dict[str, object] = {"tool": k, "records": len(est[k])}
        for i, p in enumerate(PARAMETER_NAMES):
            row[f"{p} rms%"] = float(rms[k][i])
        row["ms/record"] = tmed[k]
        rows.append(row)
    print(table(rows, f"Accuracy (RMS relative error, %) and time, {args.records} paper-level records"))
    for k, fails in failures.items():
        if fails:
            print(f"{k}: no physical parameters on {len(fails)}/{args.records} records "
                  f"(first: {fails[0]})")
    ratio_rows = []
    base = "condmon SRIV"
    for k in rms:
        if k == base:
            continue
        r: dict[str, object] = {"peer / condmon": k}
        for i, p in enumerate(PARAMETER_NAMES):
            r[f"{p} err ratio"] = float(rms[k][i] / rms[base][i])
        r["time ratio"] = tmed[k] / tmed[base]
        ratio_rows.append(r)
    print()
    print(table(ratio_rows, "Ratios (peer / condmon; > 1 means condmon is better or faster)"))
    path = write_json("peers", {
        "records": args.records,
        "rms_percent": {k: dict(zip(PARAMETER_NAMES, map(float, v))) for k, v in rms.items()},
        "median_ms": tmed, "ratios": ratio_rows,
        "failures": {k: len(v) for k, v in failures.items()},
        "failure_examples": {k: v[:3] for k, v in failures.items()}})
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
