"""Simulation-error estimation and validation on real benchmarks, against peers.

1. Cascaded tanks (Schoukens, Mattsson, Wigren, Noël 2016), through the CLI as a
   user runs it: ``condmon estimate`` on the estimation part, ``condmon validate``
   on the validation part (the benchmark's rule: the estimated initial state; and
   the first-sample and fitted starts beside it). Peers on the same data, in the
   same run: SIPPY's OE and ARX (linear, orders 2/2/1, simulated on the validation
   input), a straight line (the static affine map from pump voltage to level), and
   the published validation RMSEs (Forgione & Piga 2021, Eur. J. Control 59,
   table "CTS"). Ratios are peer RMSE over condmon's.
2. EMPS (Janot, Gautier, Brunot 2019): the simulation-error route against the
   inverse-model route and the published values, each difference in combined
   standard errors; beside them the benchmark's own method, the closed loop
   simulated with its sampled controller (``_emps_closed_loop.py``).

    python benchmarks/bench_simulation.py [--data ../shared/external]

Prints tables, with the machine's load, and writes results/simulation.json.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from _common import table, write_json
from _emps_closed_loop import closed_loop_fit

ROOT = Path(__file__).parents[1]
TANKS_MODEL = ROOT / "examples" / "cascaded-tanks" / "cascaded-tanks.toml"
EMPS_MODEL = ROOT / "examples" / "emps" / "emps.toml"
PUBLISHED_CTS = {"best linear approximation": 0.75, "Volterra": 0.54,
                 "nonlinear state space": 0.34, "neural state space": 0.33,
                 "grey box with the physical overflow": 0.18}
PUBLISHED_EMPS = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}


def condmon(*args: str) -> tuple[dict[str, Any], float]:
    """Run the CLI with ``--json``; (document, wall seconds)."""
    t0 = time.perf_counter()
    out = subprocess.run(["condmon", *args, "--json"], capture_output=True, text=True,
                         check=False)
    elapsed = time.perf_counter() - t0
    if out.returncode != 0:
        raise SystemExit(f"condmon {' '.join(args)} failed: {out.stderr.strip()}")
    return json.loads(out.stdout), elapsed


def sippy_rmse(u_est: np.ndarray, y_est: np.ndarray, u_val: np.ndarray, y_val: np.ndarray,
               method: str) -> float:
    """Validation simulation RMSE of a SIPPY linear model (deviations from the
    estimation part's means, simulated from rest on the validation input)."""
    from scipy.signal import lfilter
    from sippy_unipi import system_identification

    mu, my = u_est.mean(), y_est.mean()
    kw = {"ARX_orders": [2, 2, 1]} if method == "ARX" else {"OE_orders": [2, 2, 1]}
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        m = system_identification(y_est - my, u_est - mu, method, tsample=4.0, **kw)
    num = np.ravel(np.asarray(m.NUMERATOR, dtype=float))
    den = np.ravel(np.asarray(m.DENOMINATOR, dtype=float))
    sim = lfilter(num, den, u_val - mu) + my
    return float(np.sqrt(np.mean((sim - y_val) ** 2)))


def tanks(data: Path) -> dict[str, Any]:
    csv = data / "cascaded_tanks" / "dataBenchmark.csv"
    with tempfile.TemporaryDirectory() as tmp:
        est_path = Path(tmp) / "est.json"
        est, t_est = condmon("estimate", str(csv), "--model", str(TANKS_MODEL),
                             "--columns", "u=uEst,y=yEst")
        est_path.write_text(json.dumps(est))
        runs = {}
        for rule in ("estimated", "first-sample", "fit"):
            doc, t_val = condmon("validate", str(csv), "--model", str(TANKS_MODEL),
                                 "--columns", "u=uVal,y=yVal", "--params", str(est_path),
                                 "--initial", rule, "--figure", str(Path(tmp) / f"{rule}.png"))
            runs[rule] = {"rmse": doc["rmse"]["y"], "fit_percent": doc["fit_percent"]["y"],
                          "seconds": t_val}
    frame = pd.read_csv(csv)
    u_est, y_est = frame["uEst"].to_numpy(), frame["yEst"].to_numpy()
    u_val, y_val = frame["uVal"].to_numpy(), frame["yVal"].to_numpy()
    ours = runs["estimated"]["rmse"]
    peers: dict[str, float] = {}
    try:
        for method in ("OE", "ARX"):
            peers[f"SIPPY {method} (2,2,1)"] = sippy_rmse(u_est, y_est, u_val, y_val, method)
    except ImportError:
        print("SIPPY is not installed (pip install '.[bench]'): its rows are left out")
    slope, intercept = np.polyfit(u_est, y_est, 1)
    peers["straight line (static y = a u + b)"] = float(
        np.sqrt(np.mean((slope * u_val + intercept - y_val) ** 2)))
    peers.update({f"published: {k}": v for k, v in PUBLISHED_CTS.items()})
    rows = [{"model": "condmon (estimated initial state, the rule)", "rmse_V": ours,
             "ratio_to_condmon": 1.0}]
    rows += [{"model": f"condmon (--initial {r})", "rmse_V": runs[r]["rmse"],
              "ratio_to_condmon": runs[r]["rmse"] / ours} for r in ("first-sample", "fit")]
    rows += [{"model": k, "rmse_V": v, "ratio_to_condmon": v / ours} for k, v in peers.items()]
    print(table(rows, "Cascaded tanks: validation simulation RMSE [V] (target <= 0.25)"))
    params = {k: (v, est["std_errors"].get(k)) for k, v in est["parameters"].items()}
    print(f"estimate {t_est:.1f} s wall, validate {runs['estimated']['seconds']:.1f} s; "
          f"every parameter with a standard error: "
          f"{all(se is not None and np.isfinite(se) for _, se in params.values())}")
    return {"estimate_seconds": t_est, "validation": runs, "peers_rmse": peers,
            "parameters": params, "initial_states": est.get("initial_states"), "rows": rows}


def emps(data: Path) -> dict[str, Any]:
    mat = data / "emps" / "DATA_EMPS.mat"
    inv, t_inv = condmon("estimate", str(mat), "--model", str(EMPS_MODEL))
    sim, t_sim = condmon("estimate", str(mat), "--model", str(EMPS_MODEL), "--route",
                         "simulation")
    t0 = time.perf_counter()
    loop = closed_loop_fit(mat, inv["parameters"])
    t_loop = time.perf_counter() - t0
    rows = []
    for k, pub in PUBLISHED_EMPS.items():
        a, sa = inv["parameters"][k], inv["std_errors"][k]
        b, sb = sim["parameters"][k], sim["std_errors"][k]
        c, sc = loop["parameters"][k], loop["std_errors"][k]
        rows.append({"parameter": k, "inverse": a, "se_inverse": sa, "simulation": b,
                     "se_simulation": sb, "published": pub,
                     "difference_in_combined_se": abs(a - b) / float(np.hypot(sa, sb)),
                     "simulation_vs_published_percent": 100 * (b / pub - 1),
                     "closed_loop": c, "se_closed_loop": sc,
                     "closed_loop_vs_inverse_in_combined_se": abs(a - c) / float(np.hypot(sa, sc))})
    print(table(rows, "EMPS: simulation-error route against the inverse route, and the closed "
                      "loop simulated (the benchmark's method, a reference outside condmon)"))
    print(f"closed loop: controller output missed by {loop['vir_rms']:.4f} V RMS, "
          f"{loop['simulations']} simulations, {t_loop:.1f} s")
    print(f"inverse {t_inv:.1f} s, simulation {t_sim:.1f} s wall; simulation notes:")
    for note in sim["notes"]:
        print(f"  - {note}")
    return {"inverse_seconds": t_inv, "simulation_seconds": t_sim, "rows": rows,
            "simulation_notes": sim["notes"], "closed_loop": loop,
            "closed_loop_seconds": t_loop}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "external")
    args = ap.parse_args()
    doc: dict[str, Any] = {}
    if (args.data / "cascaded_tanks" / "dataBenchmark.csv").exists():
        doc["cascaded_tanks"] = tanks(args.data)
    else:
        print(f"no cascaded tanks data under {args.data}: left out")
    if (args.data / "emps" / "DATA_EMPS.mat").exists():
        doc["emps"] = emps(args.data)
    else:
        print(f"no EMPS data under {args.data}: left out")
    print(f"wrote {write_json('simulation', doc)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
