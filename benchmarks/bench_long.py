"""Long records: time per sample and peak memory of an estimate as the record grows.

    python benchmarks/bench_long.py [--durations 400,3600] [--repeat 2]

Simulated actuator records at 1 kHz (the built-in closed-loop test, longer),
written as Parquet in a temporary folder. For each duration, in a fresh
process each time (so one run's heap does not hide another's):
- the estimate alone (``condmon.estimate`` on the loaded record): seconds and
  microseconds per sample, best of ``--repeat``;
- ``condmon estimate FILE`` from the command line, the record limit raised
  with ``CONDMON_MAX_SAMPLES``: wall seconds and the process's peak resident
  memory (``ru_maxrss`` of the child).
Targets: per-sample time at the longest within 1.2x of the shortest; the
command's peak at an hour <= 1 GB (10^9 bytes, 953.7 MiB). Prints a table and writes results/long.json.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import table, write_json

_MAKE = """
import dataclasses, sys
from condmon.simulate import load_actuator_rig, simulate_actuator
rig = dataclasses.replace(load_actuator_rig(), duration=float(sys.argv[1]))
simulate_actuator(rig, seed=1).to_parquet(sys.argv[2])
"""

_ESTIMATE = """
import json, os, sys, time
os.environ["CONDMON_MAX_SAMPLES"] = "100000000"
from condmon.io import read_record
from condmon.identify import estimate
rec = read_record(sys.argv[1])
best = float("inf")
for _ in range(int(sys.argv[2])):
    t0 = time.perf_counter()
    res = estimate(rec)
    best = min(best, time.perf_counter() - t0)
print(json.dumps({"seconds": best, "samples": len(rec), "R": res.parameters["R"],
                  "R_se": res.std_errors["R"]}))
"""


#: The command line, run as ``condmon`` runs, reporting its own peak resident
#: memory as it exits (a child's ``ru_maxrss`` seen from here is the largest of
#: every child so far, the simulations' included).
_CLI = """
import atexit, resource, sys
atexit.register(lambda: sys.stderr.write(
    "MAXRSS %d\\n" % resource.getrusage(resource.RUSAGE_SELF).ru_maxrss))
from condmon.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


def _child(args: list[str], env: dict[str, str]) -> tuple[str, float, float]:
    """stdout, wall seconds and the child's own peak resident memory [MiB]."""
    t0 = time.perf_counter()
    out = subprocess.run(args, capture_output=True, text=True, env=env, check=True)
    wall = time.perf_counter() - t0
    peak = [int(line.split()[1]) for line in out.stderr.splitlines()
            if line.startswith("MAXRSS ")]
    return out.stdout, wall, (peak[-1] / 1024 if peak else float("nan"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--durations", default="400,3600")
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    durations = sorted(float(d) for d in args.durations.split(","))
    cli = [sys.executable, "-c", _CLI]
    env = {**os.environ, "CONDMON_MAX_SAMPLES": "100000000", "OPENBLAS_NUM_THREADS": "1"}
    rows, doc = [], {}
    with tempfile.TemporaryDirectory(prefix="condmon-long-") as tmp:
        for dur in durations:   # shortest first: each child's peak is then its own
            path = Path(tmp) / f"record-{dur:.0f}s.parquet"
            subprocess.run([sys.executable, "-c", _MAKE, str(dur), str(path)], check=True,
                           env=env)
            out, _, _ = _child([sys.executable, "-c", _ESTIMATE, str(path), str(args.repeat)],
                               env)
            est = json.loads(out)
            _, wall, peak = _child([*cli, "estimate", str(path)], env)
            per = est["seconds"] / est["samples"] * 1e6
            doc[f"{dur:.0f}"] = {**est, "us_per_sample": per, "cli_seconds": wall,
                                 "cli_peak_mib": peak,
                                 "file_mib": path.stat().st_size / 2**20}
            rows.append({"duration s": dur, "samples": est["samples"],
                         "estimate s": est["seconds"], "us/sample": per,
                         "CLI s": wall, "CLI peak MiB": peak})
    first, last = doc[f"{durations[0]:.0f}"], doc[f"{durations[-1]:.0f}"]
    ratio = last["us_per_sample"] / first["us_per_sample"]
    print(table(rows, "Estimate of a long 1 kHz actuator record (Parquet), time and memory"))
    print(f"\nper sample, {durations[-1]:.0f} s against {durations[0]:.0f} s: {ratio:.2f} "
          f"(target <= 1.2: {ratio <= 1.2}); CLI peak at {durations[-1]:.0f} s: "
          f"{last['cli_peak_mib']:.0f} MiB = {last['cli_peak_mib'] * 2**20 / 1e6:.0f} MB "
          f"(target <= 1000 MB: {last['cli_peak_mib'] * 2**20 <= 1e9})")
    path = write_json("long", {"runs": doc, "per_sample_ratio": ratio})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
