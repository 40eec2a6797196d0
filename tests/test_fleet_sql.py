"""A fleet run's cost to the database: SQL statements per record, on SQLite and
PostgreSQL, on a dask.distributed cluster started here and reached by address."""

from __future__ import annotations

import collections
import contextlib
import io
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import sqlalchemy as sa

from condmon.cli.main import main
from condmon.store import open_store
from condmon.workflows.fleet import run_fleet
from condmon.workflows.inbox import SimulatedUnit, simulated_inbox

#: Statements a fleet run may issue per record it offers (schema, reads, writes).
MAX_PER_RECORD = 4

UNITS = [SimulatedUnit("EMA-1", records=7), SimulatedUnit("EMA-2", records=7),
         SimulatedUnit("EMA-3", records=7, fault="D=*7", fault_from=5),
         SimulatedUnit("EMA-4", records=7)]


@pytest.fixture(scope="module")
def cluster() -> Iterator[str]:
    """A dask.distributed LocalCluster of one worker process; its scheduler's address."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,  # type: ignore[no-untyped-call]
                      dashboard_address=":0") as local:
        yield str(local.scheduler_address)


@pytest.fixture(scope="module")
def inbox(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[Path]]:
    """4 actuator units x 7 records (EMA-3: friction x7 from its 5th) and one
    HST record with a fault; the first 5 of each unit are the first run's."""
    root = tmp_path_factory.mktemp("fleet-sql") / "inbox"
    files = simulated_inbox(root, UNITS, seed=700)
    files.update(simulated_inbox(root, [SimulatedUnit("HST-1", "hst", records=1,
                                                      fault="Dm=-25%@5s", fault_from=1,
                                                      duration=16)], seed=200))
    return {u: [Path(p) for p in ps] for u, ps in files.items()}


@contextlib.contextmanager
def statements() -> Iterator[collections.Counter[str]]:
    """SQL statements issued by every engine of this process meanwhile, by their
    first word (an executemany counts once: one round trip, one statement)."""
    counts: collections.Counter[str] = collections.Counter()

    def count(conn: Any, cursor: Any, statement: str, *args: Any) -> None:
        counts[statement.split(None, 1)[0].upper()] += 1

    sa.event.listen(sa.Engine, "before_cursor_execute", count)
    try:
        yield counts
    finally:
        sa.event.remove(sa.Engine, "before_cursor_execute", count)


def test_a_fleet_run_issues_few_statements_per_record(
        inbox: dict[str, list[Path]], cluster: str, store_url: str, tmp_path: Path) -> None:
    """A run into an empty history (baselines built, checks evaluated, an isolation),
    then one of new records into it (checks against the stored baselines): at
    most 4 statements per record each, every record stored and audited."""
    first = [p for u, ps in inbox.items() for p in ps[:5]]
    with statements() as counts:
        open_store(store_url).close()
    print(f"\nan empty history: {sum(counts.values())} statements (the schema, once)")
    with statements() as counts:
        res = run_fleet(inbox["EMA-1"][0].parent.parent, store_url, scheduler=cluster,
                        files=first)
    n = len(first)
    per_record = sum(counts.values()) / n
    print(f"first run, {n} records: {per_record:.2f} statements/record {dict(counts)}")
    assert (res.stored, res.skipped, res.count("rejected"), res.count("refused")) == (n, 0, 0, 0)
    assert res.engine == cluster and res.workers == 1 and res.engine_start > 0
    assert per_record <= MAX_PER_RECORD, dict(counts)
    # one savepoint per batch (a batch: 20 records, or 2 s of them), not one per record
    assert counts["SAVEPOINT"] == counts["RELEASE"] <= n / 20 + res.seconds / 2 + 1

    by_file = {Path(r.file).name: r for r in res.records if r.unit == "EMA-3"}
    assert [by_file[f"rec-0{i}.csv"].status for i in range(1, 6)] == [
        "baseline", "baseline", "baseline", "go", "no-go"]
    assert "friction" in str(by_file["rec-05.csv"].reason)

    later = [p for u, ps in inbox.items() for p in ps[5:]]
    with statements() as counts:
        again = run_fleet(inbox["EMA-1"][0].parent.parent, store_url, scheduler=cluster,
                          files=later)
    per_record = sum(counts.values()) / len(later)
    print(f"second run, {len(later)} new records: {per_record:.2f} statements/record "
          f"{dict(counts)}")
    assert again.stored == len(later) == 8
    assert per_record <= MAX_PER_RECORD, dict(counts)
    assert {r.status for r in again.records if r.unit == "EMA-3"} == {"no-go"}
    assert {r.status for r in again.records if r.unit != "EMA-3"} == {"go"}

    with open_store(store_url, create=False) as store:
        assert store.integrity_problems() == []
        actions = collections.Counter(store.audit()["action"])
        assert actions == {"unit created": 5, "test added": 28, "baseline saved": 4,
                           "isolation added": 1}
        hist = store.history("EMA-3")
        assert list(hist["status"]) == ["baseline"] * 3 + ["go"] + ["no-go"] * 3
        assert [r.test_id for r in res.records if r.unit == "EMA-3"] == list(hist.index[:5])


def test_the_engine_start_is_in_the_summary(inbox: dict[str, list[Path]], cluster: str,
                                            tmp_path: Path) -> None:
    """Connecting to a running cluster is reported in the JSON and in the printed
    summary, beside the run's time."""
    root = inbox["EMA-1"][0].parent.parent
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["fleet", "run", str(root), "--db", str(tmp_path / "a.db"),
                     "--scheduler", cluster, "--json"]) == 0
    doc = json.loads(buf.getvalue())
    assert doc["engine"] == cluster and 0 < doc["engine_start_seconds"] < doc["seconds"]
    assert doc["stored"] == 29
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["fleet", "run", str(root), "--db", str(tmp_path / "b.db"),
                     "--scheduler", cluster]) == 0
    assert f"connected to {cluster} in " in " ".join(buf.getvalue().split())


def test_a_batch_that_cannot_be_written_names_its_record_and_keeps_the_ones_before(
        store_url: str, rig: Any) -> None:
    """One test of a batch clashes with a stored one (the same file in the unit):
    the batch is written record by record, the one at fault is named, the
    records before it are kept and nothing after it is written."""
    from condmon.identify import estimate
    from condmon.simulate import simulate_actuator
    from condmon.store.bulk import BulkWriteError, BulkWriter

    res = [estimate(simulate_actuator(rig, seed=s), source=f"rec{s}.csv") for s in range(4)]
    with open_store(store_url) as store:
        uid = store.unit_id("EMA-1", create=True)
        store.add_test("EMA-1", res[3], role="baseline", digest="c9", file_digest="f9")
        writer = BulkWriter()
        for k, (content, file) in enumerate([("c0", "f0"), ("c1", "f9"), ("c2", "f2")]):
            writer.record(f"rec{k}.csv")
            writer.add_test(uid, res[k], role="baseline", digest=content, file_digest=file)
        with store.batch():
            with pytest.raises(BulkWriteError, match=r"^rec1\.csv: ") as err:
                store.write_bulk(writer)
        assert err.value.written == 1 and "\n" not in str(err.value)
        assert list(store.history("EMA-1")["source"]) == ["rec3.csv", "rec0.csv"]
        assert collections.Counter(store.audit()["action"])["test added"] == 2
