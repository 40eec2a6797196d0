"""Live monitoring: online tracking cost, detection latency and broker throughput.

    python benchmarks/bench_live.py [--units 10 100 1000] [--seconds 10]

- **Online residual tracking of the HST** (no broker): N units at 100 Hz fed to
  one :class:`~condmon.diagnose.tracking.ModelTracker` in chunks of one second;
  CPU per unit-second of data, how many units one core sustains in real time,
  and memory per unit (the tracker's arrays, by tracemalloc). Goal: one
  unit-second in <= 1 ms of CPU (>= 1,000 units on one core).
- **Latency through a real broker** (Debian's mosquitto on a loopback port): a
  faulty unit streamed in real time in 0.1 s chunks; from the publication of
  the chunk holding the detection sample to the detection event received on
  ``condmon/<unit>/status`` (median, 99th percentile over repeats). The
  detection itself comes the persistence time (0.5 s) after the residual left
  its band, so onset-to-event is persistence + this latency. Goal: <= 100 ms.
- **Throughput through the broker**: many units' chunks published as fast as
  possible; chunks/s and samples/s handled by ``watch`` (each message journaled
  before it is acknowledged).
- **Fault run** (``_live_chaos.py``): 6,000 messages at 400 msg/s, 10 faulty
  HST units among 35 and 6 dc-motor units sending tests as chunks; 5 SIGTERMs,
  5 SIGKILLs and 2 broker restarts at random moments. Goal: every test stored
  whole and once, every fault isolated once, no tracker gap (0 messages lost
  past the acknowledgement, 0 stored twice).
- **Floods**: peak RSS of ``watch`` under 3.4 MB chunks, endless dc-motor tests
  and 30,000 new unit names. Goal: <= 1 GB.
- **The page under load**: ``GET /`` with 100 event clients. Goal: <= 1 s.
- **Idle folder watch** over 30,000 files. Goal: <= 5 % of a core.

    python benchmarks/bench_live.py --part faults flood page folder

Prints tables, the machine's load, and writes results/live.json.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import threading
import time
import tracemalloc
from pathlib import Path

import numpy as np


from _common import table, write_json

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from condmon.diagnose.residuals import DetectionSettings  # noqa: E402
from condmon.diagnose.tracking import ModelTracker  # noqa: E402
from condmon.models.registry import load_plant_model  # noqa: E402
from condmon.simulate.plant import simulate_plant  # noqa: E402
from condmon.store import open_store  # noqa: E402
from condmon.workflows.live import watch_mqtt  # noqa: E402

HST = load_plant_model("hst")


def tracking(units: int, seconds: int) -> dict[str, float]:
    rec = simulate_plant(HST, seed=1, duration=float(seconds))
    cols = {c: rec[c].to_numpy() for c in rec.columns}
    tracemalloc.start()
    tr = ModelTracker(HST, DetectionSettings())
    names = [f"U{i}" for i in range(units)]
    tr.feed({n: {c: v[:100] for c, v in cols.items()} for n in names})  # warm: every unit known
    held = tracemalloc.get_traced_memory()[0]
    tracemalloc.stop()
    cpu = time.process_time()
    wall = time.perf_counter()
    for k in range(100, len(rec) - 1, 100):
        tr.feed({n: {c: v[k:k + 100] for c, v in cols.items()} for n in names})
    cpu = time.process_time() - cpu
    wall = time.perf_counter() - wall
    unit_seconds = units * (len(rec) - 101) / 100.0
    per = cpu / unit_seconds
    return {"units": units, "cpu_ms_per_unit_s": 1e3 * per, "units_real_time_one_core": 1.0 / per,
            "wall_s": wall, "kB_per_unit": held / units / 1024.0}


def watcher_memory(units: int) -> dict[str, float]:
    """Memory a watcher holds per plant unit once its kept window is full."""
    from condmon.io.stream import Chunk
    from condmon.workflows.watch import Watcher

    rec = simulate_plant(HST, seed=3, duration=70.0)
    cols = {c: rec[c].to_numpy() for c in rec.columns}
    db = tempfile.mktemp(suffix=".db")
    with open_store(db) as store:
        w = Watcher(store, model="hst")
        tracemalloc.start()
        base = tracemalloc.get_traced_memory()[0]
        for k in range(0, len(rec) - 1, 100):
            w.handle_many([Chunk(f"M{i}", {c: v[k:k + 100].copy() for c, v in cols.items()})
                           for i in range(units)])
        held = tracemalloc.get_traced_memory()[0] - base
        tracemalloc.stop()
        w.close()
    return {"units": units, "kept_s": w.keep, "kB_per_unit": held / units / 1024.0}


class _Events:
    def __init__(self, port: int) -> None:
        import paho.mqtt.client as mqtt
        from paho.mqtt.enums import CallbackAPIVersion

        self.got: list[tuple[float, dict]] = []
        self.client = mqtt.Client(CallbackAPIVersion.VERSION2, client_id="bench-listen")
        self.client.on_message = lambda c, u, m: self.got.append(
            (time.perf_counter(), json.loads(m.payload)))
        self.client.connect("127.0.0.1", port)
        self.client.subscribe("condmon/+/status", qos=1)
        self.client.loop_start()


def _publisher(port: int):  # type: ignore[no-untyped-def]
    import paho.mqtt.client as mqtt
    from paho.mqtt.enums import CallbackAPIVersion

    pub = mqtt.Client(CallbackAPIVersion.VERSION2, client_id="bench-pub")
    pub.connect("127.0.0.1", port)
    pub.loop_start()
    return pub


def latency(broker, repeats: int) -> dict[str, float]:  # type: ignore[no-untyped-def]
    samples = []
    for r in range(repeats):
        unit = f"LAT-{r}"
        rec = simulate_plant(HST, ["Rv=+40%@3s"], seed=100 + r, duration=5.0)
        events = _Events(broker.port)
        stop = threading.Event()
        db = tempfile.mktemp(suffix=".db")
        th = threading.Thread(target=lambda: _watch(db, broker, stop, f"lat-{r}"), daemon=True)
        th.start()
        time.sleep(1.0)
        pub = _publisher(broker.port)
        sent: dict[float, float] = {}
        t0 = time.perf_counter()
        for k in range(0, len(rec), 10):      # 0.1 s chunks, in real time
            part = rec.iloc[k:k + 10]
            due = t0 + k / 100.0
            time.sleep(max(0.0, due - time.perf_counter()))
            pub.publish(f"condmon/{unit}/samples",
                        json.dumps({c: part[c].tolist() for c in part.columns}), qos=1)
            sent[float(part["t"].iloc[-1])] = time.perf_counter()
        deadline = time.perf_counter() + 10
        mine = lambda: [(at, e) for at, e in events.got  # noqa: E731
                        if e.get("kind") == "detected" and e.get("unit") == unit]
        while time.perf_counter() < deadline and not mine():
            time.sleep(0.01)
        got = mine()[0]
        when = min(t for t in sent if t >= got[1]["t"] - 1e-9)   # the chunk holding it
        samples.append(got[0] - sent[when])
        stop.set()
        th.join(30)
        pub.loop_stop()
        events.client.loop_stop()
    ordered = sorted(samples)
    return {"repeats": repeats, "median_ms": 1e3 * statistics.median(ordered),
            "p99_ms": 1e3 * ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]}


def _watch(db: str, broker, stop: threading.Event, cid: str,  # type: ignore[no-untyped-def]
           out: dict | None = None) -> None:
    from condmon.workflows.watch import Watcher

    with open_store(db) as store:
        w = Watcher(store, model="hst")
        if out is not None:
            out["watcher"] = w
        s = watch_mqtt(store, broker.address, watcher=w, stop=stop, log=lambda line: None,
                       client_id=cid)
    if out is not None:
        out["summary"] = s


def throughput(broker, units: int, seconds: int) -> dict[str, float]:  # type: ignore[no-untyped-def]
    rec = simulate_plant(HST, seed=2, duration=float(seconds))
    payloads = [json.dumps({c: rec[c].iloc[k:k + 100].tolist() for c in rec.columns})
                for k in range(0, len(rec) - 1, 100)]
    stop, out = threading.Event(), {}
    db = tempfile.mktemp(suffix=".db")
    th = threading.Thread(target=lambda: _watch(db, broker, stop, "tp", out), daemon=True)
    th.start()
    time.sleep(1.0)
    pub = _publisher(broker.port)
    total = len(payloads) * units
    t0 = time.perf_counter()
    for p in payloads:
        for u in range(units):
            pub.publish(f"condmon/TP-{u}/samples", p, qos=1)
    while time.perf_counter() - t0 < 300 and out["watcher"].counters.received < total:
        time.sleep(0.01)
    spent = time.perf_counter() - t0
    stop.set()
    th.join(120)
    pub.loop_stop()
    c = out["summary"].counters
    return {"units": units, "chunks": c.received, "samples": c.samples,
            "chunks_per_s": c.received / spent, "samples_per_s": c.samples / spent,
            "dropped": c.dropped}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--units", type=int, nargs="+", default=[10, 100, 1000])
    ap.add_argument("--seconds", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=5)
    parts = ("tracking", "latency", "throughput", "faults", "flood", "page", "folder")
    ap.add_argument("--part", nargs="+", choices=parts, default=list(parts))
    args = ap.parse_args()
    doc: dict = {}
    if "tracking" in args.part:
        rows = [tracking(n, args.seconds) for n in args.units]
        print(table(rows, "Online residual tracking of the HST (100 Hz, 1 s chunks, one core)"))
        mem = watcher_memory(100)
        print(table([mem], "A watcher's memory per plant unit (its model, detector and kept "
                           "window)"))
        doc.update(tracking=rows, watcher_memory=mem)
    from _broker import Broker

    import _live_chaos as chaos

    def broker_run(fn, *a):  # type: ignore[no-untyped-def]
        folder = Path(tempfile.mkdtemp())
        broker = Broker.__new__(Broker)
        try:
            Broker.__init__(broker, folder)
        except BaseException as exc:  # pytest.skip when mosquitto is missing
            print(f"no broker: {exc}")
            return None
        try:
            return fn(broker, *a)
        finally:
            broker.kill()

    if "latency" in args.part:
        doc["latency"] = lat = broker_run(latency, args.repeats)
        print(table([lat], "Detection latency through mosquitto (chunk published -> event)"))
    if "throughput" in args.part:
        doc["throughput"] = tp = broker_run(throughput, 50, args.seconds)
        print(table([tp], "Throughput through mosquitto (50 units, 1 s chunks)"))
    if "faults" in args.part:
        doc["faults"] = f = chaos.fault_run(Broker)
        print(table([{k: v for k, v in f.items() if k != "disruptions"}],
                    "Fault run: 5 SIGTERM, 5 SIGKILL, 2 broker restarts under a stream"))
        print(f"disruptions (s after the stream started): {f['disruptions']}")
    if "flood" in args.part:
        doc["flood"] = fl = chaos.flood(Broker)
        print(table([{k: v for k, v in fl.items() if k != "summary"}],
                    "Floods: peak RSS of condmon watch"))
        print(fl["summary"])
    if "page" in args.part:
        doc["page"] = pg = chaos.page_under_load()
        print(table([pg], "The fleet page with 100 event clients connected"))
    if "folder" in args.part:
        doc["folder"] = fo = chaos.idle_folder()
        print(table([fo], "An idle folder watch over 30,000 files"))
    path = write_json("live", doc)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
