"""Fleet runs on dask.distributed: records per second against workers, and the
engine's cost per record against a plain loop over the same worker function.

    python benchmarks/bench_fleet.py [--units 12] [--records 5] [--repeat 3]
                                     [--sizes 1000,10000] [--backends sqlite,postgresql]

The workload is the estimate of actuator records (4 s at 1 kHz, the built-in
test), ``units`` x ``records`` of them, the first three of each unit building
its baseline and the others checked against it, every result written to a
fresh SQLite history. Each timed run uses a local cluster already started and
warmed up (its workers have imported condmon and estimated one record), so
the figure is the steady rate; the cluster's start-up is reported apart.
The machine's load before each run is recorded: a second core busy with other
work makes the 2-worker figure meaningless. Prints tables and writes
results/fleet.json. Then, for each of ``--sizes`` (records, 5 per unit), whole
fleet runs on 1 and 2 workers into a new history on each of ``--backends``
(PostgreSQL: a private server this script starts on a spare port, as
``.ci/postgres.sh`` does for the tests, and stops), with records/s, the SQL
statements per record and the engine's start. Target: on the estimate workload (the records through the
engine), 2 workers >= 1.6 x 1 worker; the whole fleet run's ratio is printed
beside it with the client's own CPU per record (its writes and, for a local
cluster, the scheduler), which on a 2-core machine shares the second core with
the 1-worker run already.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import contextlib  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
from collections.abc import Iterator  # noqa: E402
from pathlib import Path  # noqa: E402

import psutil  # noqa: E402

from _common import table, write_json  # noqa: E402
from condmon.workflows.fleet import (  # noqa: E402
    RecordTask, _run_tasks, local_cluster, process_record, run_fleet,
)
from condmon.workflows.inbox import SimulatedUnit, simulated_inbox  # noqa: E402


def _load() -> dict[str, float]:
    """Load average (1 min) and the busiest core's use over half a second [%]."""
    per_core = psutil.cpu_percent(interval=0.5, percpu=True)
    return {"loadavg_1min": os.getloadavg()[0], "busiest_core_percent": max(per_core),
            "idlest_core_percent": min(per_core)}


@contextlib.contextmanager
def private_postgres(port: int) -> Iterator[str]:
    """A PostgreSQL server of this run alone (``.ci/postgres.sh`` on ``port``);
    its URL. Stopped, and its folder removed, at the end."""
    script = Path(__file__).resolve().parent.parent / ".ci" / "postgres.sh"
    env = {**os.environ, "CONDMON_PGPORT": str(port),
           "CONDMON_PGDATA": f"/tmp/condmon-bench-pg-{port}"}
    subprocess.run(["bash", str(script), "start"], env=env, check=True,
                   stdout=subprocess.DEVNULL)
    try:
        yield f"postgresql://postgres@127.0.0.1:{port}/postgres"
    finally:
        subprocess.run(["bash", str(script), "stop"], env=env, check=False)


def _new_database(server: str, name: str) -> str:
    """A new, empty database on the server; its URL."""
    import sqlalchemy as sa

    engine = sa.create_engine(server.replace("postgresql://", "postgresql+psycopg://", 1),
                              isolation_level="AUTOCOMMIT")
    with engine.connect() as conn:
        conn.exec_driver_sql(f"DROP DATABASE IF EXISTS {name}")
        conn.exec_driver_sql(f"CREATE DATABASE {name}")
    engine.dispose()
    return server.rsplit("/", 1)[0] + f"/{name}"


@contextlib.contextmanager
def _statements() -> Iterator[list[int]]:
    """The SQL statements this process issues meanwhile (an executemany counts once)."""
    import sqlalchemy as sa

    n = [0]

    def count(*args: object) -> None:
        n[0] += 1

    sa.event.listen(sa.Engine, "before_cursor_execute", count)
    try:
        yield n
    finally:
        sa.event.remove(sa.Engine, "before_cursor_execute", count)


def scale(work: Path, clients: dict[int, object], sizes: list[int], backends: list[str],
          port: int) -> list[dict[str, object]]:
    """Whole fleet runs of ``sizes`` records on 1 and 2 workers into new histories."""
    rows: list[dict[str, object]] = []
    with contextlib.ExitStack() as stack:
        server = (stack.enter_context(private_postgres(port)) if "postgresql" in backends
                  else None)
        for size in sizes:
            t0 = time.perf_counter()
            inbox = work / f"inbox-{size}"
            simulated_inbox(inbox, [SimulatedUnit(f"U{i + 1:05d}", records=5,
                                                  fault="D=*7" if i % 4 == 3 else None)
                                    for i in range(size // 5)], seed=7000)
            print(f"{size} records written in {time.perf_counter() - t0:.0f} s")
            for backend in backends:
                for workers, client in clients.items():
                    name = f"w{workers}_{size}"
                    db = (str(work / f"{name}.db") if backend == "sqlite" else
                          _new_database(str(server), name))
                    load = _load()
                    address = str(client.scheduler.address)  # type: ignore[attr-defined]
                    with _statements() as n:
                        t0 = time.perf_counter()
                        res = run_fleet(inbox, db, scheduler=address)
                        took = time.perf_counter() - t0
                    assert res.stored + res.count("rejected") == size, res.to_dict()["stored"]
                    rows.append({"records": size, "backend": backend, "workers": workers,
                                 "records/s": size / took, "seconds": took,
                                 "statements/record": n[0] / size,
                                 "connect s": res.engine_start,
                                 "load 1 min": load["loadavg_1min"],
                                 "idlest core %": load["idlest_core_percent"]})
                    print(table(rows[-1:], ""))
            shutil.rmtree(inbox, ignore_errors=True)
    return rows


def _warm(path: str) -> float:
    """Import and estimate once in a worker (the first record pays the imports)."""
    t0 = time.perf_counter()
    process_record(RecordTask("warm", path, "estimate", "dc-motor"))
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--units", type=int, default=12)
    ap.add_argument("--records", type=int, default=5, help="records per unit")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per worker count")
    ap.add_argument("--sizes", default="1000,10000",
                    help="records of the whole-run scale study (comma-separated; '' for none)")
    ap.add_argument("--backends", default="sqlite,postgresql")
    ap.add_argument("--pg-port", type=int, default=55490,
                    help="port of the private PostgreSQL server")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench-fleet-"))
    units = [SimulatedUnit(f"EMA-{i + 1:02d}", records=args.records,
                           fault="D=*7" if i % 4 == 3 else None) for i in range(args.units)]
    files = simulated_inbox(work / "inbox", units, seed=1000)
    n = sum(len(v) for v in files.values())
    tasks = [RecordTask(u, str(p), "estimate", "dc-motor") for u, ps in files.items() for p in ps]
    print(f"{n} actuator records in {args.units} units; cores: {os.cpu_count()}")

    # both clusters up at once (idle workers cost nothing); the runs alternate
    # between the plain loop, 1 worker and 2 workers, so a load that comes and
    # goes touches each alike; each figure is the best of its repeats
    _warm(tasks[0].path)
    loop_s, loads = [], []
    times: dict[int, list[float]] = {1: [], 2: []}
    engine: dict[int, list[float]] = {1: [], 2: []}
    compute: dict[int, list[float]] = {1: [], 2: []}
    client_cpu: dict[int, list[float]] = {1: [], 2: []}
    starts: dict[int, float] = {}
    with contextlib.ExitStack() as stack:
        clients = {}
        for workers in (1, 2):
            t0 = time.perf_counter()
            clients[workers] = stack.enter_context(local_cluster(workers))
            starts[workers] = time.perf_counter() - t0
            clients[workers].run(_warm, tasks[0].path)
        for rep in range(args.repeat):
            loads.append(_load())
            t0 = time.perf_counter()
            for t in tasks:
                out = process_record(t)
                assert out.error is None, out.error
            loop_s.append(time.perf_counter() - t0)
            for workers, client in clients.items():
                # the engine alone: the same tasks through dask, nothing written
                t0 = time.perf_counter()
                outs = list(_run_tasks(client, tasks))
                engine[workers].append(time.perf_counter() - t0)
                compute[workers].append(sum(o.seconds for o in outs))
                assert all(o.error is None for o in outs)
                address = str(client.scheduler.address)  # type: ignore[union-attr]
                t0, c0 = time.perf_counter(), time.process_time()
                res = run_fleet(work / "inbox", work / f"w{workers}-{rep}.db", scheduler=address)
                times[workers].append(time.perf_counter() - t0)
                # this process: the client's writes, and the local cluster's scheduler
                client_cpu[workers].append(time.process_time() - c0)
                assert res.stored == n, res.to_dict()["stored"]
        sizes = [int(x) for x in args.sizes.split(",") if x.strip()]
        scaled = scale(work, clients, sizes, args.backends.split(","), args.pg_port)
    rate = {w: n / min(times[w]) for w in (1, 2)}
    engine_rate = {w: n / min(engine[w]) for w in (1, 2)}
    rows = [{"workers": w, "estimate rec/s": engine_rate[w], "fleet run rec/s": rate[w],
             "fleet median s": statistics.median(times[w]),
             "worker compute s": min(compute[w]),
             "client CPU ms/rec": 1e3 * min(client_cpu[w]) / n,
             "cluster start s": starts[w]} for w in (1, 2)]
    print(table(rows, f"{n} records, best of {args.repeat}: estimated on the engine alone, "
                      "and the whole fleet run (estimate, check, store)"))
    ratio = engine_rate[2] / engine_rate[1]
    fleet_ratio = rate[2] / rate[1]
    overhead_ms = 1e3 * (min(engine[1]) - min(loop_s)) / n
    print(table([
        {"path": "plain loop (in process)", "ms/record": 1e3 * min(loop_s) / n},
        {"path": "dask, 1 worker, engine only", "ms/record": 1e3 * min(engine[1]) / n},
        {"path": "  of which in the worker function",
         "ms/record": 1e3 * min(compute[1]) / n},
        {"path": "fleet run, 1 worker (+ store)", "ms/record": 1e3 / rate[1]},
    ], "Time per record"))
    load1 = statistics.mean(x["loadavg_1min"] for x in loads)
    idle = min(x["idlest_core_percent"] for x in loads)
    # the load average counts this benchmark's own runs; the least busy core's use
    # over the half second before a run (nothing of ours running) tells other work
    busy = idle > 30
    cores = os.cpu_count() or 1
    print(f"\nestimate workload, 2 workers / 1 worker: {ratio:.2f} (target >= 1.6: "
          f"{ratio >= 1.6}); engine overhead {overhead_ms:+.1f} ms/record; before the runs: "
          f"load average {load1:.2f}, least busy core {idle:.0f} % -> second core "
          f"{'BUSY with other work' if busy else 'free'}")
    print(f"whole fleet run, 2 workers / 1 worker: {fleet_ratio:.2f}; the client (writes, "
          f"and the local scheduler) uses {1e3 * min(client_cpu[2]) / n:.1f} ms of CPU per "
          f"record beside the workers' {1e3 * min(compute[1]) / n:.1f} ms"
          + (f": on {cores} cores the 1-worker run already has the client on the second "
             "core" if cores <= 2 else ""))
    if scaled:
        print(table(scaled, "Whole fleet runs into a new history (one run each; 5 records "
                           "per unit)"))
        for size in sizes:
            for backend in args.backends.split(","):
                got = {r["workers"]: r["records/s"] for r in scaled
                       if r["records"] == size and r["backend"] == backend}
                if len(got) == 2:
                    print(f"{size} records, {backend}: 2 workers / 1 worker "
                          f"{float(got[2]) / float(got[1]):.2f}")
    doc = {"records": n, "units": args.units, "repeat": args.repeat, "scale": scaled,
           "plain_loop_seconds": loop_s,
           "runs": {str(w): {"seconds": times[w], "records_per_s": rate[w],
                             "engine_only_seconds": engine[w],
                             "engine_records_per_s": engine_rate[w],
                             "worker_compute_seconds": compute[w],
                             "client_cpu_seconds": client_cpu[w],
                             "cluster_start_seconds": starts[w]} for w in (1, 2)},
           "ratio_2_to_1": ratio, "fleet_run_ratio_2_to_1": fleet_ratio,
           "engine_overhead_ms_per_record": overhead_ms,
           "target_met": ratio >= 1.6, "load_before": loads, "second_core_busy": busy}
    shutil.rmtree(work, ignore_errors=True)
    path = write_json("fleet", doc)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
