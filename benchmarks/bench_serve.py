"""The fleet page at fleet scale: `condmon units` and `condmon serve`'s index over many units.

    python benchmarks/bench_serve.py [--units 1000] [--repeat 3]

Builds a synthetic history (SQL inserts, no estimation: every unit has 3
baseline tests, a baseline and 2 checks; every tenth a pending baseline of 2
tests, every twentieth an isolation), then times ``unit_summaries`` (what
``condmon units`` reads), the index page and ``/api/units``, and counts the
SQL statements each one issues. The units' kept states are worked out once
after the inserts (``HistoryStore.refresh_states``), as the store's own writes keep them.

Prints a table and writes results/serve.json.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from _common import best_of, table, write_json
from condmon.report.web import create_app
from condmon.store import open_store
from condmon.store import schema as S


def synthetic_history(db: str, n_units: int) -> None:
    """A history of ``n_units`` actuators written with plain SQL inserts."""
    t0 = datetime(2026, 1, 1, tzinfo=timezone.utc)
    with open_store(db) as store:
        engine = store.engine
        with engine.begin() as c:
            c.execute(S.units.insert(), [
                {"id": u + 1, "name": f"EMA-{u:04d}", "model": "dc-motor", "created_at": t0}
                for u in range(n_units)])
            tests: list[dict[str, Any]] = []
            baselines: list[dict[str, Any]] = []
            diagnoses: list[dict[str, Any]] = []
            isolations: list[dict[str, Any]] = []
            tid = 0
            for u in range(n_units):
                pending = u % 10 == 9
                ids = []
                for k in range(2 if pending else 5):
                    tid += 1
                    role = "baseline" if k < 3 else "check"
                    tests.append({"id": tid, "unit_id": u + 1, "created_at": t0,
                                  "test_date": t0 + timedelta(days=k), "source": f"r{k}.csv",
                                  "file_hash": f"{tid:064x}", "role": role, "accepted": True,
                                  "reason": None, "fit_percent": 95.0, "fits": "{}",
                                  "method": "ls", "closed_loop": False, "constants": "{}",
                                  "record_hash": f"{tid:064x}"})
                    ids.append(tid)
                if not pending:
                    baselines.append({"id": len(baselines) + 1, "unit_id": u + 1,
                                      "created_at": t0, "n": 3, "test_ids": json.dumps(ids[:3]),
                                      "flags": "[]" if u % 7 else '[{"message": "x"}]'})
                    for check in ids[3:]:
                        diagnoses.append({"test_id": check, "baseline_id": len(baselines),
                                          "status": "go" if u % 3 else "no-go",
                                          "condition": 0.0, "summary": "no fault"})
                if u % 20 == 0:
                    isolations.append({"unit_id": u + 1, "created_at": t0,
                                       "test_date": t0 + timedelta(days=9), "source": "i.csv",
                                       "file_hash": "0" * 64, "record_hash": "0" * 64,
                                       "model": "hst", "detected": True, "decided": True,
                                       "statement": "Rv", "suspects": "[]", "isolated": "[]",
                                       "result": "{}"})
            c.execute(S.tests.insert(), tests)
            c.execute(S.baselines.insert(), baselines)
            c.execute(S.diagnoses.insert(), diagnoses)
            if isolations:
                c.execute(S.isolations.insert(), isolations)
        store.refresh_states()   # as the store keeps them when it writes the rows itself


def _statements(engine: sa.Engine, fn: Any) -> int:
    count = [0]

    def tick(*_: Any) -> None:
        count[0] += 1

    sa.event.listen(engine, "before_cursor_execute", tick)
    try:
        fn()
    finally:
        sa.event.remove(engine, "before_cursor_execute", tick)
    return count[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        db = str(Path(tmp) / "fleet.db")
        synthetic_history(db, args.units)
        client = create_app(db).test_client()
        with open_store(db, create=False) as store:
            queries = _statements(store.engine, store.unit_summaries)
            rows.append({"what": "unit_summaries", "units": args.units, "statements": queries,
                         "seconds": best_of(store.unit_summaries, args.repeat)})
        for path in ("/", "/api/units"):
            rows.append({"what": f"GET {path}", "units": args.units, "statements": queries,
                         "seconds": best_of(lambda p=path: client.get(p), args.repeat)})
    print(table(rows, f"fleet page over {args.units} units (best of {args.repeat})"))
    write_json("serve", {"rows": rows})


if __name__ == "__main__":
    main()
