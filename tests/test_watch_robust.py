"""Live monitoring that no single message takes down and that loses nothing:
messages that once killed the watcher are refused in one line, generated
payloads never raise, the journal replays a test cut by a crash and stores it
once, a restarted watcher on a unit still faulty stores no second isolation,
and units and held samples are bounded."""

from __future__ import annotations

import dataclasses
import json
import re
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from condmon.errors import DataError
from condmon.io.digest import content_hash
from condmon.io.stream import StreamLimits, parse_chunk
from condmon.models.registry import load_plant_model
from condmon.simulate import simulate_actuator
from condmon.simulate.plant import simulate_plant
from condmon.store import open_store
from condmon.store.journal import StreamJournal
from condmon.workflows.live import _handle
from condmon.workflows.watch import Watcher
from condmon.workflows.watch_bounds import Bounds

from _broker import Broker, _client, broker, start_watch  # noqa: F401

HST = load_plant_model("hst")
TOPIC = "condmon/U1/samples"


def test_an_integer_beyond_float64_is_refused_in_one_line() -> None:
    with pytest.raises(DataError, match="column 'Ps' has a value beyond float64 at sample 1"):
        parse_chunk(TOPIC, b'{"t": [0, 0.01], "Ps": [1, 1' + b"0" * 400 + b"]}")


def test_zero_length_columns_are_refused_and_an_empty_end_closes() -> None:
    with pytest.raises(DataError, match="the columns hold no sample"):
        parse_chunk(TOPIC, b'{"t": [], "Ps": [], "omega_m": []}')
    assert parse_chunk(TOPIC, b'{"t": [], "end": true}').end


@pytest.fixture(scope="module")
def watchers(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Watcher]]:
    folder = tmp_path_factory.mktemp("prop")
    with open_store(str(folder / "p.db")) as store:
        yield {m: Watcher(store, model=m) for m in ("hst", "dc-motor")}


numbers = st.one_of(st.integers(min_value=-10**400, max_value=10**400),
                    st.floats(allow_nan=False, allow_infinity=False), st.booleans())
columns = st.dictionaries(st.sampled_from(["t", "Ps", "omega_m", "V", "I", "omega", "x", ""]),
                          st.lists(numbers, max_size=6), max_size=5)
json_values = st.recursive(st.none() | st.booleans() | st.integers() | st.floats()
                           | st.text(max_size=5),
                           lambda inner: st.lists(inner, max_size=3)
                           | st.dictionaries(st.text(max_size=3), inner, max_size=3),
                           max_leaves=10)


@settings(max_examples=150, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(model=st.sampled_from(["hst", "dc-motor"]),
       doc=st.one_of(columns.map(lambda c: {**c, "t": sorted(set(
           float(v) for v in c.get("t", []) if not isinstance(v, bool) and abs(v) < 1e300))}),
           columns, json_values),
       end=st.sampled_from([None, True, False, 1, "yes"]),
       raw=st.one_of(st.none(), st.binary(max_size=40)))
def test_no_payload_raises_out_of_the_handler(watchers: dict[str, Watcher], model: str,
                                              doc: Any, end: Any, raw: bytes | None) -> None:
    """Whatever a message holds, the handler refuses or takes it, counts it, and
    returns: it never raises."""
    if isinstance(doc, dict) and end is not None:
        doc = {**doc, "end": end}
    payload = raw if raw is not None else json.dumps(doc).encode()
    w = watchers[model]
    before = w.counters.received
    lines: list[str] = []
    _handle(w, [(TOPIC.replace("U1", f"{model}-U"), payload, None)], StreamLimits.shipped(),
            lines.append)
    assert w.counters.received == before + 1
    assert all("\n" not in ln for ln in lines)


def _chunks(record: pd.DataFrame, size: int) -> list[bytes]:
    return [json.dumps({c: record[c].iloc[k:k + size].tolist() for c in record.columns}).encode()
            for k in range(0, len(record), size)]


def _feed(w: Watcher, book: StreamJournal, topic: str, payloads: list[bytes]) -> None:
    """What the MQTT transport does: journal, then handle, then forget what is done."""
    refs = book.add([(topic, p) for p in payloads])
    _handle(w, [(topic, p, r) for p, r in zip(payloads, refs)], StreamLimits.shipped(),
            w.log)
    book.done(w.finished)
    w.finished.clear()


def test_a_test_cut_by_a_crash_is_replayed_from_the_journal_and_stored_once(
        tmp_path: Path) -> None:
    from condmon.workflows.monitoring import add_baseline_tests

    db = str(tmp_path / "j.db")
    with open_store(db) as store:
        add_baseline_tests(store, "EMA-1", [simulate_actuator(seed=s) for s in (1, 2, 3)])
    parts = _chunks(simulate_actuator(seed=9), 500) + [b'{"end": true}']
    topic = "condmon/EMA-1/samples"
    book = StreamJournal(tmp_path / "w.journal")
    with open_store(db) as store:
        first = Watcher(store, model="dc-motor")
        _feed(first, book, topic, parts[:5])   # then the process dies: nothing closed
        assert len(book) == 5
        second = Watcher(store, model="dc-motor")
        kept = list(book.pending())
        _handle(second, [(t, p, r) for r, t, p in kept], StreamLimits.shipped(), second.log)
        _feed(second, book, topic, parts[5:])
        assert second.counters.checks == 1 and len(book) == 0
        assert len(store.history("EMA-1")) == 4
        # a crash after the check was stored and before its rows went: replayed again
        third, lines = Watcher(store, model="dc-motor"), []
        third.publish = lambda ev: lines.append(ev.reason)
        _feed(third, book, topic, parts)
        assert len(store.history("EMA-1")) == 4
        assert any("already stored; not stored again" in ln for ln in lines), lines
        assert len(book) == 0


def _stream(w: Watcher, record: pd.DataFrame, unit: str, size: int = 50) -> list[Any]:
    events = []
    w.publish = events.append
    for p in _chunks(record, size):
        _handle(w, [(f"condmon/{unit}/samples", p, None)], StreamLimits.shipped(), w.log)
        w.poll()
    w.poll(wait=True)
    return events


def test_a_watcher_restarted_on_a_faulty_unit_stores_no_second_isolation(
        tmp_path: Path) -> None:
    """The issue's attack: a restart that receives the stream after the fault's
    onset detects it again at once, at another stream time."""
    rec = simulate_plant(HST, ["Rv=+40%@8s"], seed=51, duration=20.0)
    with open_store(str(tmp_path / "f.db")) as store:
        first = Watcher(store, model="hst", keep=5.0)
        ev = _stream(first, rec, "HST-K")
        assert [e.kind for e in ev].count("isolated") == 1
        kept = first.bounds.held["HST-K"]
        assert kept <= 6.0 * 100 * 8 * len(rec.columns), "the window is trimmed after it"
        lines: list[str] = []
        second = Watcher(store, model="hst", keep=5.0, log=lines.append)
        again = _stream(second, rec[rec["t"] >= 12.0], "HST-K")
        assert len(store.isolations("HST-K")) == 1
        said = [e for e in again if e.kind == "detected"]
        assert len(said) == 1 and "still there" in said[0].reason, [e.reason for e in again]
        assert not any(e.kind == "isolated" for e in again)
        # a healthy unit restarted mid-stream raises nothing
        calm = _stream(Watcher(store, model="hst"),
                       simulate_plant(HST, seed=52, duration=12.0).iloc[400:], "HST-H")
        assert [e.status for e in calm] == ["go"]


def test_units_past_the_limit_or_the_pattern_are_refused_in_one_line(tmp_path: Path) -> None:
    limits = dataclasses.replace(StreamLimits.shipped(), max_units=2)
    rec = simulate_plant(HST, seed=3, duration=1.0)
    lines: list[str] = []
    with open_store(str(tmp_path / "u.db")) as store:
        w = Watcher(store, model="hst", log=lines.append,
                    bounds=Bounds(limits, units=re.compile("HST-[0-9]+")))
        for unit in ("HST-1", "HST-2", "HST-3", "HST-4", "other"):
            _stream(w, rec, unit)
        assert store.units() == ["HST-1", "HST-2"]
    refusals = [ln for ln in lines if ln.startswith("refused:")]
    assert refusals[0] == ("refused: unit 'HST-3' is new and the watcher follows 2 units "
                           "already ([stream] max_units); its messages are refused")
    assert "'other' does not match --units 'HST-[0-9]+'" in " ".join(refusals)
    # one line per kind in 10 s, however many messages: counted, not flooded
    assert len(refusals) == 2 and w.counters.refused == 3 * len(_chunks(rec, 50))


def test_an_open_test_past_its_bytes_is_dropped_and_said(tmp_path: Path) -> None:
    limits = dataclasses.replace(StreamLimits.shipped(), unit_bytes=200_000)
    lines: list[str] = []
    with open_store(str(tmp_path / "b.db")) as store:
        w = Watcher(store, model="dc-motor", log=lines.append, bounds=Bounds(limits))
        _stream(w, simulate_actuator(seed=2), "EMA-1", size=500)
        assert w.bounds.total <= 200_000
    assert any("passes 200000 bytes with no {\"end\": true} ([stream] unit_bytes)" in ln
               for ln in lines), lines


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_a_stop_under_a_stream_loses_no_acknowledged_test(broker: Broker, tmp_path: Path,
                                                          how: signal.Signals) -> None:
    """dc-motor units send tests as chunks through mosquitto; the watcher is
    killed (SIGKILL) or stopped (SIGTERM) mid-stream and started again: every
    test sent is stored, once, whole. (With the acknowledgement at receipt, the
    SIGKILL lost the chunks waiting behind a check.)"""
    from condmon.workflows.monitoring import add_baseline_tests

    db = tmp_path / "k.db"
    units = [f"EMA-{i}" for i in range(3)]
    with open_store(str(db)) as store:
        for u in units:
            add_baseline_tests(store, u, [simulate_actuator(seed=s) for s in (1, 2, 3)])
    tests = {u: [simulate_actuator(seed=10 + 3 * i + k) for k in range(3)]
             for i, u in enumerate(units)}
    streams = {u: [_chunks(t, 250) + [b'{"end": true}'] for t in tests[u]] for u in units}

    def start() -> subprocess.Popen[str]:
        return start_watch(broker, db, "dc-motor", "kill-tests")

    def stored(n: int, timeout: float = 120.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with open_store(str(db)) as store:
                if sum(len(store.history(u)) for u in units) >= n:
                    return True
            time.sleep(0.2)
        return False

    def send(k: int, parts: slice) -> None:
        infos = [pub.publish(f"condmon/{u}/samples", p, qos=1)
                 for j in range(len(streams[units[0]][k]))[parts] for u in units
                 for p in [streams[u][k][j]]]
        for info in infos:
            info.wait_for_publish(30)

    watcher = start()
    pub = _client("tests-publisher")
    pub.connect("127.0.0.1", broker.port)  # type: ignore[attr-defined]
    pub.loop_start()  # type: ignore[attr-defined]
    send(0, slice(None))
    assert stored(3 * 4)  # warm: the first tests checked
    send(1, slice(None))
    send(2, slice(0, 6))  # these wait behind the second tests' checks
    time.sleep(0.15)
    watcher.send_signal(how)
    watcher.communicate(timeout=60)
    watcher = start()
    send(2, slice(6, None))
    pub.loop_stop()  # type: ignore[attr-defined]
    assert stored(3 * 6)
    watcher.send_signal(signal.SIGTERM)
    out, err = watcher.communicate(timeout=120)
    assert watcher.returncode == 0, err
    with open_store(str(db)) as store:
        for u in units:
            assert len(store.history(u)) == 6, (u, err[-2000:])
            for record in tests[u]:  # whole: the stored content is the record's
                assert store.find_test(u, content_hash(record)) is not None, (u, err[-2000:])


def test_a_long_chunk_among_many_short_ones_is_not_padded_to_all(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The flood's attack: one unit's long chunk stepped with many units' 2-sample
    chunks padded them all to its length (at 100,000 samples and 10,000 units,
    24 GB). Units are now stepped together only while padding stays within
    twice their samples, and a long chunk is stepped in pieces."""
    import condmon.workflows.watch_bounds as wb
    from condmon.diagnose.tracking import ModelTracker

    monkeypatch.setattr(wb, "PIECE", 1_000)  # 10,000 shipped: the same cut, 10 times smaller
    rec = simulate_plant(HST, seed=5, duration=30.0)
    long = json.dumps({c: rec[c].iloc[:2_500].tolist() for c in rec.columns}).encode()
    short = b'{"t": [0, 0.01], "Ps": [1e7, 1e7], "omega_m": [100, 100]}'
    padded: list[int] = []
    real = ModelTracker.feed

    def feed(self: ModelTracker, chunks: Any) -> Any:
        lengths = [len(c["t"]) for c in chunks.values()]
        padded.append(max(lengths) * len(lengths))
        assert max(lengths) * len(lengths) <= 2 * sum(lengths)
        return real(self, chunks)

    monkeypatch.setattr(ModelTracker, "feed", feed)
    with open_store(str(tmp_path / "pad.db")) as store:
        w = Watcher(store, model="hst")
        msgs = [("condmon/LONG/samples", long, None)] + [
            (f"condmon/S{i}/samples", short, None) for i in range(300)]
        _handle(w, msgs, StreamLimits.shipped(), w.log)
        assert w.counters.refused == 0 and w.counters.received == 301
        assert w._plants["LONG"].chunks[-1]["t"][-1] == rec["t"].iloc[2_499]
    assert sorted(padded) == [500, 600, 1_000, 1_000], padded


def test_a_stop_ends_a_long_batch_and_leaves_the_rest_in_the_journal(tmp_path: Path) -> None:
    rec = simulate_plant(HST, seed=6, duration=60.0)
    payloads = _chunks(rec, 1000)
    book = StreamJournal(tmp_path / "h.journal")
    with open_store(str(tmp_path / "h.db")) as store:
        w = Watcher(store, model="hst", keep=1e9)
        refs = book.add([("condmon/H/samples", p) for p in payloads])
        w.halt.set()
        _handle(w, [("condmon/H/samples", p, r) for p, r in zip(payloads, refs)],
                StreamLimits.shipped(), w.log)
        assert w.finished == [] and len(book) == len(payloads)   # nothing stepped, all kept
        again = Watcher(store, model="hst", keep=1e9)
        _handle(again, [(t, p, r) for r, t, p in book.pending()], StreamLimits.shipped(),
                again.log)
        assert again._plants["H"].chunks[-1]["t"][-1] == rec["t"].iloc[-1]


def test_a_full_queue_refuses_in_bytes_and_says_so_at_once(broker: Broker,
                                                           tmp_path: Path) -> None:
    """A flood of valid messages once reached 3 GB: the queue counted messages, not
    bytes. Past ``[stream] queue_bytes`` a message is refused, counted and said
    while the watch runs."""
    import threading

    from condmon.workflows.live import watch_mqtt

    limits = dataclasses.replace(StreamLimits.shipped(), queue_bytes=20_000)
    # refused once handled (no omega_m), so a handled message leaves the journal
    payload = json.dumps({"t": [0.0, 0.01], "Ps": [1e7] * 2, "pad": [0.0] * 2}
                         ).encode() + b" " * 4_000
    lines: list[str] = []
    stop = threading.Event()
    result: dict[str, Any] = {}

    class Slow(Watcher):
        def handle_many(self, chunks: Any) -> Any:
            time.sleep(1.0)  # busy: the flood piles up behind it
            return super().handle_many(chunks)

    def run() -> None:
        with open_store(str(tmp_path / "q.db")) as store:
            result["s"] = watch_mqtt(store, broker.address, watcher=Slow(store, model="hst"),
                                     stop=stop, log=lines.append, client_id="q-watch",
                                     limits=limits)

    th = threading.Thread(target=run, daemon=True)
    th.start()
    deadline = time.monotonic() + 60
    while not any("subscribed to" in ln for ln in lines) and time.monotonic() < deadline:
        time.sleep(0.02)
    pub = _client("q-pub")
    pub.connect("127.0.0.1", broker.port)  # type: ignore[attr-defined]
    pub.loop_start()  # type: ignore[attr-defined]
    for i in range(60):
        pub.publish(f"condmon/F{i}/samples", payload, qos=0)
    deadline = time.monotonic() + 30
    while not any("queue_bytes = 20000" in ln for ln in lines) and time.monotonic() < deadline:
        time.sleep(0.05)
    said = [ln for ln in lines if "queue_bytes = 20000" in ln]
    stop.set()
    th.join(60)
    pub.loop_stop()  # type: ignore[attr-defined]
    assert said and said[0].startswith("refused: a message on 'condmon/F"), lines
    summary = result["s"]
    assert summary.overflow > 0
    # each counted once: refused at the queue, handled, or journaled at the stop
    kept = StreamJournal(summary.journal)
    assert summary.overflow + summary.counters.received + len(kept) == 60
    kept.close()


def test_a_stream_in_model_columns_is_read_as_si_for_a_rig_layout_machine(
        tmp_path: Path) -> None:
    """A machine whose declaration reads its rig's files ([record]: other names,
    raw units) had its live tests refused in the documented format (model
    columns in SI): the file's mapping was applied to them."""
    from condmon.io.rig import rig_layout
    from condmon.io.stream import Chunk
    from condmon.workflows.monitoring import add_baseline_tests
    from condmon.workflows.records import EstimateOptions

    shipped = Path(__file__).resolve().parents[1] / "src" / "condmon" / "data"
    decl = tmp_path / "rig-motor.toml"
    text = (shipped / "dc-motor.toml").read_text().replace('rules = "', f'rules = "{shipped}/')
    text = text.replace('breakpoints = "', f'breakpoints = "{shipped}/')
    decl.write_text(text + '\n[record.columns]\nV = "volts"\nI = { column = "milliamps", '
                    'scale = 1.0e-3 }\nomega = { column = "rpm", scale = 0.10471975511965977 }\n')
    plant = load_plant_model(str(decl))
    rig = EstimateOptions(model=str(decl)).settings()
    with open_store(str(tmp_path / "h.db")) as store:
        files = []
        for s in (1, 2, 3):
            p = tmp_path / f"b{s}.csv"
            rig_layout(simulate_plant(plant, (), seed=s), rig).to_csv(p, index=False)
            files.append(p)
        assert add_baseline_tests(store, "M", files, EstimateOptions(model=str(decl))).baseline
        w, events = Watcher(store, model=str(decl)), []
        w.publish = events.append
        si = simulate_plant(plant, (), seed=7)
        cols = {c: si[c].to_numpy(dtype=np.float64) for c in ("t", "V", "I", "omega")}
        w.handle(Chunk("M", cols))
        w.handle(Chunk("M", {}, end=True))
        assert w.counters.checks == 1, [e.reason for e in events]
        assert events[-1].status == "go", events[-1].reason
