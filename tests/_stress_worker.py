"""One writer of the store stress test: adds its planned records, reporting each.

Usage: python _stress_worker.py DB PLAN.json
Prints ``STORED unit test_id`` after each test is committed (flushed at once),
``DUPLICATE unit test_id`` when the record was already there, and on a
condmon error ``ERROR message`` (one line) and goes on.
"""

from __future__ import annotations

import json
import sys


def main() -> None:
    db, plan_file = sys.argv[1], sys.argv[2]
    from condmon.errors import CondmonError
    from condmon.store import open_store
    from condmon.workflows.monitoring import add_baseline_tests

    plan = json.loads(open(plan_file).read())
    try:
        store = open_store(db, timeout=60)
    except CondmonError as err:
        print(f"ERROR {err}", flush=True)
        return
    with store:
        for unit, path in plan:
            try:
                res = add_baseline_tests(store, unit, [path])
            except CondmonError as err:
                print(f"ERROR {err}", flush=True)
                continue
            for t in res.tests:
                what = "DUPLICATE" if t.duplicate else "STORED"
                print(f"{what} {unit} {t.test_id}", flush=True)


if __name__ == "__main__":
    main()
