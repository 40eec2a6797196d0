"""Time to estimate one 4 s, 1 kHz actuator record (two outputs) on one core.

    python benchmarks/bench_speed.py [--records 20] [--repeat 10]

Also times reading that record as CSV: condmon's reader (dialect sniffing,
decimal mark, exact digits) against pandas' C and pyarrow engines on the same
file. Prints tables and writes results/speed.json. Single-threaded BLAS is forced
before numpy loads, so the figure is per core.
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


def floor_ms(records, repeat: int) -> float:  # type: ignore[no-untyped-def]
    """The floor under an SRIV estimate [ms]: five passes of what every
    iteration must do (the six signals through a C filter, the normal
    equations, their solve), median over the records."""
    import numpy as np
    from scipy.signal import lfilter

    from condmon.identify._common import normal_equations, solve

    times = []
    for rec in records:
        sig0 = rec[["I", "omega", "V", "I", "omega", "V"]].to_numpy(dtype=float)
        den = np.array([1.0, -1.9, 0.9])
        for _ in range(repeat):
            t0 = time.perf_counter()
            for _pass in range(5):
                sig = lfilter([1.0], den, sig0, axis=0)
                R, r, _, _ = normal_equations(sig, 2, 2, np.ones(2))
                solve(R, r)
            times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


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
    for method, exc in (("sriv", "auto"), ("sriv", None), ("iv", "auto"), ("arx", "auto")):
        label = f"{method} ({'closed-loop instruments' if exc else 'direct'})"
        estimate(records[0], method=method, excitation=exc)  # warm-up
        times = []
        iters = []
        for rec in records:
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                res = estimate(rec, method=method, excitation=exc)
                times.append(time.perf_counter() - t0)
            iters.append(res.discrete.iterations)
        med = statistics.median(times) * 1e3
        p90 = sorted(times)[int(0.9 * len(times))] * 1e3
        rows.append({"estimator": label, "median ms": med, "p90 ms": p90,
                     "iterations (mean)": sum(iters) / len(iters)})
        doc[label] = {"median_ms": med, "p90_ms": p90, "n": len(times)}
    print(table(rows, f"Time per record (4000 samples, outputs I and omega, full pipeline: "
                      f"validation, estimate, fit, d2c, physical parameters with covariance); "
                      f"{args.records} records x {args.repeat}"))
    doc["floor_ms"] = floor_ms(records, args.repeat)
    print(f"\nfloor (5 passes of scipy's C filter over the 6 signals + normal equations + "
          f"solve): {doc['floor_ms']:.2f} ms; SRIV / floor: "
          f"{doc['sriv (closed-loop instruments)']['median_ms'] / doc['floor_ms']:.2f} "
          "(target <= 3)")
    doc["csv"] = read_times(records[0], args.repeat * 5)
    print()
    print(table([{"reader": k, "median ms": v, "ratio to pandas C": v / doc["csv"]["pandas C"]}
                 for k, v in doc["csv"].items()],
                f"Reading the record as CSV ({len(records[0])} rows, {records[0].shape[1]} columns)"))
    target = doc["sriv (closed-loop instruments)"]["median_ms"] <= 10.0
    print(f"\nmedian <= 10 ms (SRIV, closed-loop instruments): {target}")
    path = write_json("speed", {"results": doc, "target_met": target})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
