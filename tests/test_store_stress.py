"""Many writers at once, some killed: nothing reported as stored is lost or doubled.

A study of many processes (16 Python processes per back-end, each importing
pandas and SQLAlchemy and estimating its records): a minute of CPU over both
back-ends, a tenth of the default run's budget. It is marked slow and run by
``.ci/run`` (``pytest -m slow tests/test_store_stress.py``), with PostgreSQL."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from condmon.simulate import ActuatorRig, simulate_actuator
from condmon.store import open_store

pytestmark = pytest.mark.slow

WORKER = Path(__file__).with_name("_stress_worker.py")
N_PROCESSES = 8
N_RECORDS = 12


@pytest.fixture(scope="module")
def pool(tmp_path_factory: pytest.TempPathFactory, rig: ActuatorRig) -> list[str]:
    """12 records, and Parquet copies of 4 of them (the same tests in other files)."""
    d = tmp_path_factory.mktemp("pool")
    files = []
    for s in range(12):
        p = d / f"r{s}.csv"
        simulate_actuator(rig, seed=300 + s).to_csv(p, index=False)
        files.append(str(p))
    for s in range(4):
        q = d / f"r{s}.parquet"
        pd.read_csv(files[s]).to_parquet(q)
        files.append(str(q))
    return files


def _wait_all(procs: list[subprocess.Popen[str]], timeout: float) -> list[tuple[str, str]]:
    """Every process's output; all waited for (pipes closed) even when one times out,
    so nothing is left open for the next test."""
    try:
        return [p.communicate(timeout=timeout) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.communicate()


def test_eight_writers_with_kills(store_url: str, pool: list[str], tmp_path: Path) -> None:
    rng = random.Random(7)
    procs = []
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    for k in range(N_PROCESSES):
        # shared units (overlapping files) and a unit of the process's own
        plan = [(rng.choice(["EMA-A", "EMA-B", f"EMA-own-{k}"]), rng.choice(pool))
                for _ in range(N_RECORDS)]
        plan_file = tmp_path / f"plan{k}.json"
        plan_file.write_text(json.dumps(plan))
        procs.append(subprocess.Popen(
            [sys.executable, str(WORKER), store_url, str(plan_file)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env))
    # kill three of them at random moments while they write
    victims = rng.sample(range(N_PROCESSES), 3)
    for v in victims:
        time.sleep(rng.uniform(0.5, 3.0))
        procs[v].send_signal(signal.SIGKILL)
    outputs = _wait_all(procs, 300)
    reported: list[tuple[str, int]] = []
    killed = 0
    for k, (p, (out, err)) in enumerate(zip(procs, outputs)):
        assert "Traceback" not in err, err
        if k not in victims:
            assert p.returncode == 0, err
            assert err.strip() == "", err
        killed += p.returncode == -signal.SIGKILL
        assert not [line for line in out.splitlines() if line.startswith("ERROR")], out
        for line in out.splitlines():
            if line.startswith("STORED"):
                _, unit, tid = line.split()
                reported.append((unit, int(tid)))
    assert len(reported) >= N_RECORDS  # the survivors did store
    assert killed >= 1  # at least one writer died in the middle of its work
    with open_store(store_url) as store:
        assert store.integrity_problems() == []
        by_unit = {u: store.history(u) for u in store.units()}
        for unit, tid in reported:
            assert tid in by_unit[unit].index, (unit, tid)
        # exactly once: each test id reported by one process only, and no content twice
        assert len(set(reported)) == len(reported)
        for unit, hist in by_unit.items():
            assert len(hist) <= len(pool) - 4  # 12 distinct contents at most
            assert hist["role"].eq("baseline").all()


OPEN_AT = """
import sys, time
from condmon.store import open_store
start = float(sys.argv[2])
time.sleep(max(0.0, start - time.time()))
with open_store(sys.argv[1], timeout=60) as store:
    store.unit_id(f"U{sys.argv[3]}", create=True)
print("OK", flush=True)
"""


def test_first_use_of_an_empty_database_from_eight_processes(store_url: str) -> None:
    """Schema creation is serialised: every process starts, none fails."""
    import condmon.store  # noqa: F401  (warm the import cache before timing the start)

    start = time.time() + 4.0
    procs = [subprocess.Popen([sys.executable, "-c", OPEN_AT, store_url, str(start), str(k)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for k in range(N_PROCESSES)]
    results = _wait_all(procs, 120)
    assert all(p.returncode == 0 for p in procs), [e for _, e in results]
    assert all(o.strip() == "OK" and e.strip() == "" for o, e in results), results
    with open_store(store_url) as store:
        assert store.units() == [f"U{k}" for k in range(N_PROCESSES)]
        assert store.integrity_problems() == []
