"""A million tests: a check and the fleet page at 10,000 units x 100 tests.

    python benchmarks/bench_scale.py [--units 10000] [--tests 100] [--backends sqlite,postgresql]
                                     [--postgres URL] [--repeat 3]

One real unit is made first: 3 healthy tests stored, its baseline saved, 10
checks (simulated actuator records estimated and checked with ``check_test``).
Its rows (tests, estimates, symptoms, diagnoses, baseline, audit) are then
copied, with new ids, to every unit of the large history (the checks cycled
to ``--tests`` tests a unit; every 7th unit's latest check made no-go, every
11th advisory, so the filters have work) and of a small reference history
(100 units x 10 tests: one full page). The kept unit states are worked out once for each
(``HistoryStore.refresh_states``: the cost of an upgrade from schema v7).

Timed (best of ``--repeat``) on each back-end:
- ``check``: ``check_test`` of a new record on a unit with ``--tests`` tests,
  against the same on a unit of the reference history (10 tests). Target:
  within 1.5x. ``check (cold peers)``: the same right after every kept
  forecast was dropped (a forecast method change): a check fits no peer's
  wear (the peers not kept are left out of its prior, and it says so);
  target within 1.5x of the warm one. ``forecast (cold peers)``: ``condmon
  forecast`` of that unit then, which fits the peers' wear from their
  histories and keeps it (reported, no target).
- the fleet index ``/`` and ``/api/units`` (page 1, 100 units), a page deep
  in the fleet, a status filter, and a unit's page, each against the
  reference history. Target: <= 0.3 s a request, and flat. The unit page is
  timed warm (its figures already drawn for that state of its history) and,
  on a row of its own, cold (a unit not shown before: every figure drawn).

PostgreSQL: ``--postgres URL`` (a server whose databases this may create),
else ``CONDMON_TEST_POSTGRES_URL``, else a private server started with
``.ci/postgres.sh`` on port 55499 (stopped at the end).

Prints a table and writes results/scale.json.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse
import json
import subprocess
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from datetime import timedelta
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from _common import best_of, table, write_json
from condmon.report.web import create_app
from condmon.simulate import simulate_actuator
from condmon.store import open_store
from condmon.store import schema as S
from condmon.store.forecasts import FleetHistory
from condmon.store.kept import FORECAST_METHOD
from condmon.workflows.checks import check_test
from condmon.workflows.forecasting import forecast_unit
from condmon.workflows.monitoring import add_baseline_tests

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE_CHECKS = 10
CHUNK = 250   # units a transaction when copying


def template(db: str) -> dict[str, list[dict[str, Any]]]:
    """One real unit ``T`` (3 healthy tests, a baseline, 10 checks); its rows by
    table, and by table and test (``"<table>@<test id>"``) for copying."""
    with open_store(db) as store:
        add_baseline_tests(store, "T", [simulate_actuator(seed=s) for s in range(3)])
        for k in range(TEMPLATE_CHECKS):
            check_test(store, "T", simulate_actuator(seed=100 + k),
                       test_date=f"2026-01-{k + 2:02d}")
        with store.engine.connect() as c:
            rows = {t.name: [dict(r._mapping) for r in c.execute(sa.select(t))]
                    for t in (S.tests, S.estimates, S.symptoms, S.diagnoses,
                              S.diagnosis_faults, S.baselines, S.baseline_values)}
    for name in ("estimates", "symptoms", "diagnoses", "diagnosis_faults"):
        for t in rows["tests"]:
            rows[f"{name}@{t['id']}"] = [r for r in rows[name] if r["test_id"] == t["id"]]
    return rows


def _unit_rows(rows: dict[str, list[dict[str, Any]]], uid: int, n_tests: int,
               ids: dict[str, int], status: str | None) -> dict[str, list[dict[str, Any]]]:
    """The template's rows for unit ``uid``: new ids, checks cycled to ``n_tests`` tests."""
    base = [t for t in rows["tests"] if t["role"] == "baseline"]
    checks = [t for t in rows["tests"] if t["role"] == "check"]
    out: dict[str, list[dict[str, Any]]] = {k: [] for k in (*rows, "audit") if "@" not in k}
    remap: dict[int, int] = {}
    for b in rows["baselines"]:
        ids["baseline"] += 1
        remap_b = ids["baseline"]
    order = base + [checks[k % len(checks)] for k in range(max(0, n_tests - len(base)))]
    for k, t in enumerate(order):
        ids["test"] += 1
        tag = f"{uid:07d}{k:05d}"   # hashes stay 64 characters, as the columns hold
        new = {**t, "id": ids["test"], "unit_id": uid, "record_hash": t["record_hash"][:52] + tag,
               "file_hash": t["file_hash"][:52] + tag,
               "test_date": None if t["test_date"] is None else
               t["test_date"] + timedelta(days=k)}
        remap.setdefault(t["id"], new["id"])
        out["tests"].append(new)
        ids["audit"] += 1
        out["audit"].append({"id": ids["audit"], "at": t["created_at"], "actor": "bench",
                             "action": "test added", "unit_id": uid, "test_id": new["id"]})
        for e in rows[f"estimates@{t['id']}"]:
            out["estimates"].append({**e, "test_id": new["id"]})
        if t["role"] == "check":
            for name in ("symptoms", "diagnoses", "diagnosis_faults"):
                for s in rows[f"{name}@{t['id']}"]:
                    out[name].append({**s, "test_id": new["id"], "baseline_id": remap_b})
    if status is not None and out["diagnoses"]:
        out["diagnoses"][-1] = {**out["diagnoses"][-1], "status": status}
    for b in rows["baselines"]:
        out["baselines"].append({**b, "id": remap_b, "unit_id": uid,
                                 "test_ids": json.dumps([remap[i] for i in json.loads(
                                     b["test_ids"])])})
    out["baseline_values"] = [{**v, "baseline_id": remap_b} for v in rows["baseline_values"]]
    return out


def build(db: str, rows: dict[str, list[dict[str, Any]]], n_units: int, n_tests: int) -> float:
    """A history of ``n_units`` copies of the template unit; returns the seconds
    taken to work out the kept unit states."""
    with open_store(db) as store:
        t0 = rows["tests"][0]["created_at"]
        ids = {"test": 0, "baseline": 0, "audit": 0}
        for start in range(0, n_units, CHUNK):
            batch: dict[str, list[dict[str, Any]]] = {}
            units = []
            for u in range(start, min(n_units, start + CHUNK)):
                units.append({"id": u + 1, "name": f"EMA-{u:05d}", "model": "dc-motor",
                              "created_at": t0})
                status = "no-go" if u % 7 == 3 else "advisory" if u % 11 == 5 else None
                for k, v in _unit_rows(rows, u + 1, n_tests, ids, status).items():
                    batch.setdefault(k, []).extend(v)
            with store.engine.begin() as c:
                c.execute(S.units.insert(), units)
                for t in (S.tests, S.baselines, S.baseline_values, S.estimates, S.symptoms,
                          S.diagnoses, S.diagnosis_faults, S.audit):
                    if batch.get(t.name):
                        c.execute(t.insert(), batch[t.name])
            print(f"\r  {db.split('@')[-1]}: {min(n_units, start + CHUNK)}/{n_units} units",
                  end="", flush=True)
        print()
        if store.engine.dialect.name == "postgresql":   # ids given: the sequences move on
            with store.engine.begin() as c:
                for name in ("units", "tests", "baselines", "audit"):
                    c.exec_driver_sql(f"SELECT setval(pg_get_serial_sequence('{name}', 'id'), "
                                      f"(SELECT max(id) FROM {name}))")
        # the kept forecasts below are the current method's (else the first
        # check would drop them all: the cold path, timed on a row of its own)
        store.renew_forecasts(FORECAST_METHOD)
        start_s = time.perf_counter()
        store.refresh_states()
        took = time.perf_counter() - start_s
        # the degraded units' rates, kept as each one's own check keeps them (the
        # copies share one series: its rates, worked out once)
        degraded = sorted(store.units_with_status())
        if degraded:
            rates = FleetHistory(store).rates_of(degraded[0])
            marks = store.history_marks(degraded)
            store.keep_forecasts([(u, marks[u], 0, None, "copied", rates) for u in degraded])
        return took


def measure(db: str, n_units: int, repeat: int, seed0: int) -> dict[str, float]:
    """Seconds of a check and of the page's requests (best of ``repeat``)."""
    out = {}
    seeds = iter(range(seed0, seed0 + 10 * repeat))
    records = [simulate_actuator(seed=next(seeds)) for _ in range(2 * repeat + 1)]
    with open_store(db) as store:
        it = iter(records)
        check_test(store, "EMA-00000", next(it))   # the first of a process reads the model
        out["check"] = best_of(lambda: check_test(store, "EMA-00000", next(it)), repeat)
        # cold peers: every kept forecast and wear dropped (a forecast method
        # change); the next check leaves those peers out of its prior
        colds = []
        for _ in range(repeat):
            store.renew_forecasts(FORECAST_METHOD)
            t0 = time.perf_counter()
            check_test(store, "EMA-00000", next(it))
            colds.append(time.perf_counter() - t0)
        out["check (cold peers)"] = min(colds)
        # the peers' wear is fitted where a user asks for a forecast, and kept
        fits = []
        for _ in range(repeat):
            store.renew_forecasts(FORECAST_METHOD)
            t0 = time.perf_counter()
            forecast_unit(store, "EMA-00000")
            fits.append(time.perf_counter() - t0)
        out["forecast (cold peers)"] = min(fits)
    client = create_app(db).test_client()
    deep = max(1, n_units // 100 // 2)
    for name, url in (("index", "/"), ("api", "/api/units"),
                      ("index, middle page", f"/?page={deep}"),
                      ("api status=no-go", "/api/units?status=no-go"),
                      ("unit page", "/units/EMA-00001")):
        def get(u: str = url) -> None:
            resp = client.get(u)
            if resp.status_code != 200:
                raise SystemExit(f"GET {u}: {resp.status_code} {resp.get_data(as_text=True)}")
        get()   # the first request of a process reads the model files
        out[name] = best_of(get, repeat)
    # cold: a unit whose figures this process has not drawn yet (the warm row
    # above shows them from the figure cache)
    cold = []
    for k in range(repeat):
        t0 = time.perf_counter()
        resp = client.get(f"/units/EMA-{2 + k:05d}")
        cold.append(time.perf_counter() - t0)
        if resp.status_code != 200:
            raise SystemExit(f"GET /units/EMA-{2 + k:05d}: {resp.status_code}")
    out["unit page (cold)"] = min(cold)
    return out


@contextmanager
def postgres(given: str | None) -> Iterator[str]:
    """A PostgreSQL server URL: given, from the environment, or started here."""
    url = given or os.environ.get("CONDMON_TEST_POSTGRES_URL")
    if url:
        yield url
        return
    env = {**os.environ, "CONDMON_PGPORT": "55499"}
    subprocess.run(["bash", str(ROOT / ".ci/postgres.sh"), "start"], env=env, check=True,
                   stdout=subprocess.DEVNULL)
    try:
        yield "postgresql://postgres@127.0.0.1:55499/postgres"
    finally:
        subprocess.run(["bash", str(ROOT / ".ci/postgres.sh"), "stop"], env=env, check=False)


def _fresh_database(server: str, name: str) -> str:
    engine = sa.create_engine(server, isolation_level="AUTOCOMMIT")
    with engine.connect() as c:
        c.exec_driver_sql(f"DROP DATABASE IF EXISTS {name}")
        c.exec_driver_sql(f"CREATE DATABASE {name}")
    engine.dispose()
    return server.rsplit("/", 1)[0] + f"/{name}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=10_000)
    ap.add_argument("--tests", type=int, default=100)
    ap.add_argument("--backends", default="sqlite,postgresql")
    ap.add_argument("--postgres", default=None)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rows_out, doc = [], {"units": args.units, "tests_per_unit": args.tests, "backends": {}}
    with tempfile.TemporaryDirectory(prefix="condmon-scale-") as tmp:
        rows = template(str(Path(tmp) / "template.db"))
        for backend in args.backends.split(","):
            with (postgres(args.postgres) if backend == "postgresql"
                  else nullcontext("")) as server:
                if backend == "postgresql":
                    big, small = (_fresh_database(server, "condmon_scale_big"),
                                  _fresh_database(server, "condmon_scale_small"))
                else:
                    big, small = str(Path(tmp) / "big.db"), str(Path(tmp) / "small.db")
                t = time.perf_counter()
                states_big = build(big, rows, args.units, args.tests)
                built = time.perf_counter() - t
                states_small = build(small, rows, 100, 10)
                m_big = measure(big, args.units, args.repeat, 1000)
                m_small = measure(small, 100, args.repeat, 2000)
            doc["backends"][backend] = {"build_s": built, "states_s": states_big,
                                        "states_small_s": states_small,
                                        "large": m_big, "reference": m_small}
            for what in m_big:
                target = 1.5 if what.startswith("check") else 2.0
                rows_out.append({
                    "backend": backend, "what": what,
                    "large_s": m_big[what], "reference_s": m_small[what],
                    "ratio": m_big[what] / m_small[what],
                    "flat": "yes" if m_big[what] / m_small[what] <= target else "no",
                    "<=0.3s": "-" if what.startswith(("check", "forecast"))
                    or what.endswith("(cold)") else ("yes" if m_big[what] <= 0.3 else "no")})
            cold = [m["check (cold peers)"] / m["check"] for m in (m_big, m_small)]
            rows_out.append({"backend": backend, "what": "check: cold peers / warm (ratio)",
                             "large_s": cold[0], "reference_s": cold[1],
                             "ratio": cold[0] / cold[1],
                             "flat": "yes" if max(cold) <= 1.5 else "no", "<=0.3s": "-"})
            rows_out.append({"backend": backend, "what": "states (whole fleet, once)",
                             "large_s": states_big, "reference_s": states_small,
                             "ratio": states_big / max(states_small, 1e-9), "flat": "-",
                             "<=0.3s": "-"})
            print(table([r for r in rows_out if r["backend"] == backend], backend), flush=True)
    title = (f"{args.units} units x {args.tests} tests = {args.units * args.tests:,} tests "
             f"against 100 x 10 (best of {args.repeat}; flat: check <= 1.5x, pages <= 2x)")
    print(table(rows_out, title))
    write_json("scale", {**doc, "rows": rows_out})


if __name__ == "__main__":
    main()
