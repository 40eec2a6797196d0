"""Start-up time of the command line against ``python -c "import numpy"``.

    python benchmarks/bench_startup.py [--runs 9]

Each command runs in a fresh process, ``--runs`` times, the commands taking
turns; the table gives the median wall time and its ratio to the numpy import
measured in the same run. Targets: ``condmon --help`` <= 2x, ``condmon estimate``
(a simulated actuator record) <= 5x, ``condmon check`` (one more actuator record
of a unit whose baseline is in a SQLite history, stored) <= 6x, ``condmon
isolate`` (a simulated HST record with a fault) <= 8x. The history and its
baseline are built in the temporary folder before timing; each check is of a
record not yet in it. The derived-structure cache is a fresh folder, filled by
one warm-up run (the first run of a declaration, which derives it, is shown
apart: "cold"). The processes may cache their bytecode, as a user's Python
does (``PYTHONDONTWRITEBYTECODE`` is dropped from their environment: with it,
every run compiled condmon's own modules again, about 0.1 s). Reference rows
give the import of the libraries each command cannot start without, in the
same run: the floor under its time. Prints the table and writes
results/startup.json.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import table, write_json

#: The libraries a command imports before any of its work (the floor under its time).
FLOORS = {"condmon --help": "typer, typer.rich_utils",
          "condmon estimate": "numpy, typer, pydantic, rich.table",
          "condmon check": "numpy, pandas, sqlalchemy, typer, pydantic, rich.table",
          "condmon isolate": "numpy, scipy.integrate, typer, pydantic, rich.table"}
TARGETS = {"condmon --help": 2.0, "condmon estimate": 5.0, "condmon check": 6.0,
           "condmon isolate": 8.0}


def _condmon() -> list[str]:
    """The console script beside this interpreter, else the module."""
    script = Path(sys.executable).with_name("condmon")
    if script.exists():
        return [str(script)]
    found = shutil.which("condmon")
    return [found] if found else [sys.executable, "-m", "condmon.cli.main"]


def _simulate(condmon: list[str], out: Path, seed: int, env: dict[str, str],
              *extra: str) -> Path:
    """Write a simulated record (``simulate actuator`` unless ``extra`` names
    another test-bed) and return its path."""
    bed = list(extra) or ["actuator"]
    subprocess.run([*condmon, "simulate", *bed[:1], "--out", str(out), "--seed", str(seed),
                    *bed[1:]], env=env, check=True, capture_output=True)
    return out


def _time(cmd: list[str], env: dict[str, str]) -> float:
    start = time.perf_counter()
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env,
                          check=False)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}): "
                         f"{done.stderr.decode(errors='replace')}")
    return elapsed


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--runs", type=int, default=9)
    args = ap.parse_args()
    condmon = _condmon()
    with tempfile.TemporaryDirectory(prefix="condmon-startup-") as tmp:
        work = Path(tmp)
        env = {**os.environ, "CONDMON_CACHE_DIR": str(work / "cache")}
        env.pop("PYTHONDONTWRITEBYTECODE", None)   # a user's Python caches bytecode
        act = _simulate(condmon, work / "actuator.csv", 1, env)
        hst = _simulate(condmon, work / "hst.csv", 1, env, "hst", "--fault", "Rv=+40%@10s")
        db = work / "history.db"
        healthy = [_simulate(condmon, work / f"healthy{s}.csv", s, env) for s in (2, 3, 4)]
        subprocess.run([*condmon, "baseline", "add", *map(str, healthy), "--unit", "u1",
                        "--db", str(db)], env=env, check=True, capture_output=True)
        # one record per check: a record already in the history is refused
        checked = iter([_simulate(condmon, work / f"check{s}.csv", s, env)
                        for s in range(10, 11 + args.runs)])
        commands = {
            'python -c "import numpy"': lambda: [sys.executable, "-c", "import numpy"],
            "condmon --help": lambda: [*condmon, "--help"],
            "condmon estimate": lambda: [*condmon, "estimate", str(act)],
            "condmon check": lambda: [*condmon, "check", str(next(checked)), "--unit", "u1",
                                      "--db", str(db)],
            "condmon isolate": lambda: [*condmon, "isolate", "hst", str(hst)],
            **{f'python -c "import {libs}"': (lambda libs=libs: [sys.executable, "-c",
                                                                 f"import {libs}"])
               for libs in FLOORS.values()},
        }
        cold = {name: _time(commands[name](),
                          {**env, "CONDMON_CACHE_DIR": str(work / f"cold{i}")})
                for i, name in enumerate(("condmon estimate", "condmon isolate"))}
        for cmd in commands.values():  # warm-up: caches, the OS's file cache
            _time(cmd(), env)
        times: dict[str, list[float]] = {name: [] for name in commands}
        for _ in range(args.runs):
            for name, cmd in commands.items():
                times[name].append(_time(cmd(), env))
    base = statistics.median(times['python -c "import numpy"'])
    rows, doc = [], {}
    for name, ts in times.items():
        med = statistics.median(ts)
        ratio = med / base
        target = TARGETS.get(name)
        met = None if target is None else bool(ratio <= target)
        rows.append({"command": name, "median s": med, "min s": min(ts), "x numpy": ratio,
                     "target": "" if target is None else f"<= {target:g}x",
                     "met": "" if met is None else ("yes" if met else "NO")})
        doc[name] = {"median_s": med, "min_s": min(ts), "runs_s": ts, "ratio": ratio,
                     "target_ratio": target, "target_met": met}
    for name, t in cold.items():
        rows.append({"command": f"{name} (cold cache)", "median s": t, "min s": t,
                     "x numpy": t / base, "target": "", "met": ""})
        doc[f"{name} (cold cache)"] = {"seconds": t, "ratio": t / base}
    print(table(rows, f"Start-up: wall time of fresh processes, median of {args.runs} runs, "
                      f"as a multiple of the numpy import ({os.cpu_count()} CPUs)"))
    print()
    for name, target in TARGETS.items():
        state = "met" if doc[name]["target_met"] else "NOT met"
        floor = doc[f'python -c "import {FLOORS[name]}"']["ratio"]
        doc[name]["floor_ratio"] = floor
        print(f"{name}: {doc[name]['ratio']:.1f}x numpy (target <= {target:g}x): {state}; "
              f"its libraries' import alone {floor:.1f}x")
    path = write_json("startup", {"runs": args.runs, "results": doc,
                                  "targets_met": all(doc[n]["target_met"] for n in TARGETS)})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
