"""Time to estimate one 4 s, 1 kHz actuator record (two outputs) on one core.

    python benchmarks/bench_speed.py [--records 20] [--repeat 10]

Also times reading that record as CSV: condmon's reader (dialect sniffing,
decimal mark, exact digits) against pandas' C and pyarrow engines on the same
file. Prints tables and writes results/speed.json. Single-threaded BLAS is forced
before numpy loads, so the figure is per core.

The floor (five passes of what every SRIV iteration must do) is timed right
after each SRIV estimate, on the same record, so that their ratio sees the same
state of the machine; the ratio of the medians and that of the fastest runs
are both printed. Targets: median <= 10 ms and <= 3x the floor.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from _common import table, write_json  # noqa: E402
from condmon.identify import estimate  # noqa: E402
from condmon.simulate import simulate_actuator  # noqa: E402


def floor_pass(rec):  # type: ignore[no-untyped-def]
    """A function running, on one record, the floor under an SRIV estimate:
    five passes of what every iteration must do (the six signals through
    scipy's C filter, the normal equations, their solve)."""
    import numpy as np
    from scipy.signal import lfilter

    from condmon.identify._common import normal_equations, solve

    sig0 = rec[["I", "omega", "V", "I", "omega", "V"]].to_numpy(dtype=float)
    den = np.array([1.0, -1.9, 0.9])

    def run() -> None:
        for _pass in range(5):
            sig = lfilter([1.0], den, sig0, axis=0)
            R, r, _ = normal_equations(sig, 2, 2, np.ones(2))
            solve(R, r)
    return run


def read_times(record, repeat: int) -> dict[str, float]:  # type: ignore[no-untyped-def]
    """Median time [ms] to read ``record`` written as CSV, per reader."""
    import pandas as pd

    from condmon.io.delimited import read_delimited

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "record.csv"
        record.to_csv(path, index=False)
        readers = {"condmon": lambda: read_delimited(path),
                   "pandas C": lambda: pd.read_csv(path),
                   "pandas pyarrow": lambda: pd.read_csv(path, engine="pyarrow")}
        out = {}
        for name, fn in readers.items():
            fn()
            times = []
            for _ in range(repeat):
                t0 = time.perf_counter()
                fn()
                times.append(time.perf_counter() - t0)
            out[name] = statistics.median(times) * 1e3
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--records", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=10)
    args = ap.parse_args()
    records = [simulate_actuator(seed=s) for s in range(args.records)]
    rows = []
    doc = {}
    floor_times: list[float] = []
    for method, exc in (("sriv", "auto"), ("sriv", None), ("iv", "auto"), ("arx", "auto")):
        label = f"{method} ({'closed-loop instruments' if exc else 'direct'})"
        with_floor = method == "sriv" and exc == "auto"
        estimate(records[0], method=method, excitation=exc)  # warm-up
        times = []
        iters = []
        for rec in records:
            floor = floor_pass(rec)
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                res = estimate(rec, method=method, excitation=exc)
                times.append(time.perf_counter() - t0)
                if with_floor:   # interleaved: the ratio sees the same machine
                    t0 = time.perf_counter()
                    floor()
                    floor_times.append(time.perf_counter() - t0)
            iters.append(res.discrete.iterations)
        med = statistics.median(times) * 1e3
        p90 = sorted(times)[int(0.9 * len(times))] * 1e3
        rows.append({"estimator": label, "median ms": med, "p90 ms": p90,
                     "iterations (mean)": sum(iters) / len(iters)})
        doc[label] = {"median_ms": med, "p90_ms": p90, "min_ms": min(times) * 1e3,
                      "n": len(times), "iterations_mean": sum(iters) / len(iters)}
    print(table(rows, f"Time per record (4000 samples, outputs I and omega, full pipeline: "
                      f"validation, estimate, fit, d2c, physical parameters with covariance); "
                      f"{args.records} records x {args.repeat}"))
    doc["floor_ms"] = statistics.median(floor_times) * 1e3
    sriv = doc["sriv (closed-loop instruments)"]
    ratio = sriv["median_ms"] / doc["floor_ms"]
    doc["sriv_over_floor"] = ratio
    doc["floor_min_ms"] = min(floor_times) * 1e3
    best = sriv["min_ms"] / doc["floor_min_ms"]
    doc["sriv_over_floor_best"] = best
    print(f"\nfloor (5 passes of scipy's C filter over the 6 signals + normal equations + "
          f"solve, timed after each SRIV estimate): {doc['floor_ms']:.2f} ms; SRIV / floor: "
          f"{ratio:.2f} (target <= 3); fastest of each: {sriv['min_ms']:.2f} "
          f"/ {doc['floor_min_ms']:.2f} ms = {best:.2f}")
    doc["csv"] = read_times(records[0], args.repeat * 5)
    print()
    print(table([{"reader": k, "median ms": v, "ratio to pandas C": v / doc["csv"]["pandas C"]}
                 for k, v in doc["csv"].items()],
                f"Reading the record as CSV ({len(records[0])} rows, {records[0].shape[1]} columns)"))
    target = sriv["median_ms"] <= 10.0 and ratio <= 3.0
    print(f"\nmedian <= 10 ms and <= 3x the floor (SRIV, closed-loop instruments): {target}")
    path = write_json("speed", {"results": doc, "target_met": target})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
