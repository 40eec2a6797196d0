"""The live benchmark's fault run and load runs (see bench_live.py).

- **Fault run.** HST units (some with a fault) and dc-motor units (tests sent
  as chunks) stream through mosquitto at a set rate to ``condmon watch``, run as
  a command the way a supervisor runs it; SIGTERMs, SIGKILLs and broker
  restarts hit at random moments, and the watcher is started again after each.
  Counted from the history at the end: every dc-motor test sent must be stored
  whole (its content hash) and once; every faulty HST unit isolated once and no
  healthy one; no tracker may see a gap (a gap is a lost chunk).
- **Memory under floods.** Peak RSS of the watcher under valid 3.4 MB chunks,
  dc-motor streams that never end, and 30,000 new unit names.
- **The page under load.** ``GET /`` with 100 live-event clients connected.
- **Idle folder watch.** CPU of a watch over 30,000 files with nothing new
  (once its local cluster, idle for 60 s, is closed; that cluster's processes
  are counted too).
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from condmon.io.digest import content_hash
from condmon.models.registry import load_plant_model
from condmon.simulate import simulate_actuator
from condmon.simulate.plant import simulate_plant
from condmon.store import open_store

HST = load_plant_model("hst")
FAULTS = ("Rv=+40%@{t:.1f}s", "Dm=-25%@{t:.1f}s", "Tld=+60@{t:.1f}s")


def _client(cid: str, port: int) -> Any:
    import paho.mqtt.client as mqtt
    from paho.mqtt.enums import CallbackAPIVersion

    c = mqtt.Client(CallbackAPIVersion.VERSION2, client_id=cid, clean_session=False)
    c.reconnect_delay_set(0.2, 2)
    c.connect("127.0.0.1", port)
    c.loop_start()
    return c


def _plan(rng: np.random.Generator, messages: int, rate: float, hst_units: int,
          dc_units: int, faults: int) -> tuple[list[tuple[float, str, bytes]], dict[str, Any]]:
    """Messages in the order and at the times they are sent, and the truth."""
    seconds = messages / rate
    hst_share = hst_units * 10.0 * seconds   # 0.1 s chunks at 100 Hz
    faulty = set(rng.choice(hst_units, size=faults, replace=False).tolist())
    plan: list[tuple[float, str, bytes]] = []
    truth: dict[str, Any] = {"faulty": [], "healthy": [], "tests": {}}
    for i in range(hst_units):
        unit = f"HST-{i}"
        spec = ([FAULTS[i % 3].format(t=float(rng.uniform(3.0, 6.0)))] if i in faulty else [])
        rec = simulate_plant(HST, spec, seed=1000 + i, duration=seconds)
        truth["faulty" if spec else "healthy"].append(unit)
        for k in range(0, len(rec) - 1, 10):
            part = rec.iloc[k:k + 10]
            plan.append((k / 100.0, f"condmon/{unit}/samples", json.dumps(
                {c: part[c].tolist() for c in part.columns}).encode()))
    per_unit = max(11, int((messages - hst_share) / max(dc_units, 1)))
    for j in range(dc_units):
        unit = f"EMA-{j}"
        truth["tests"][unit] = []
        msgs: list[bytes] = []
        for k in range(per_unit // 11):
            rec = simulate_actuator(seed=500 + 37 * j + k)
            truth["tests"][unit].append(content_hash(rec))
            msgs += [json.dumps({c: rec[c].iloc[s:s + 400].tolist() for c in rec.columns}
                                ).encode() for s in range(0, len(rec), 400)]
            msgs.append(b'{"end": true}')
        for n, m in enumerate(msgs):
            plan.append((seconds * n / len(msgs), f"condmon/{unit}/samples", m))
    plan.sort(key=lambda item: item[0])
    return plan, truth


def fault_run(broker_cls: Any, *, messages: int = 6000, rate: float = 400.0,
              hst_units: int = 35, dc_units: int = 6, faults: int = 10, sigterms: int = 5,
              sigkills: int = 5, restarts: int = 2, seed: int = 7,
              log: Any = print) -> dict[str, Any]:
    rng = np.random.default_rng(seed)
    folder = Path(tempfile.mkdtemp(prefix="chaos-"))
    # the broker keeps what it holds for an absent watcher without a cap (its
    # default, 1,000 a client, would drop messages in a 3 s restart at 400/s)
    broker = broker_cls(folder, extra="max_queued_messages 0\n")
    db = folder / "chaos.db"
    plan, truth = _plan(rng, messages, rate, hst_units, dc_units, faults)
    with open_store(str(db)) as store:
        from condmon.workflows.monitoring import add_baseline_tests

        for j in range(dc_units):
            add_baseline_tests(store, f"EMA-{j}", [simulate_actuator(seed=s)
                                                   for s in (1 + j, 11 + j, 21 + j)])
    logs: list[str] = []

    def start() -> subprocess.Popen[str]:
        proc = subprocess.Popen([sys.executable, "-m", "condmon.cli.main", "watch", "--mqtt",
                                 broker.address, "--db", str(db), "--model", "hst",
                                 "--client-id", "chaos"], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        assert proc.stderr is not None
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            line = proc.stderr.readline()
            logs.append(line)
            if "subscribed to" in line or (not line and proc.poll() is not None):
                break
        _drain(proc, logs)
        return proc

    def finish(proc: subprocess.Popen[str]) -> None:
        proc.wait(timeout=300)

    watcher = start()
    seconds = plan[-1][0] + 0.1
    moments = sorted(rng.uniform(1.0, seconds + 20.0, size=sigterms + sigkills + restarts))
    kinds = ["term"] * sigterms + ["kill"] * sigkills + ["broker"] * restarts
    random.Random(seed).shuffle(kinds)
    infos: list[Any] = []
    pub = _client("chaos-pub", broker.port)

    def publish() -> None:
        t0 = time.monotonic()
        for at, topic, payload in plan:
            time.sleep(max(0.0, t0 + at - time.monotonic()))
            info = pub.publish(topic, payload, qos=1)
            while info.rc != 0:  # the broker is restarting: the source waits and sends again
                time.sleep(0.05)
                info = pub.publish(topic, payload, qos=1)
            infos.append((topic, payload, info))

    sender = threading.Thread(target=publish, daemon=True)
    t0 = time.monotonic()
    sender.start()
    done: list[tuple[float, str]] = []
    for when, kind in zip(moments, kinds):
        time.sleep(max(0.0, t0 + when - time.monotonic()))
        if kind == "broker":
            broker.kill()
            broker.start()
        else:
            watcher.send_signal(signal.SIGTERM if kind == "term" else signal.SIGKILL)
            finish(watcher)
            watcher = start()
        done.append((round(time.monotonic() - t0, 2), kind))
    sender.join()
    resent = 0
    for topic, payload, info in infos:  # a publication the broker never acknowledged is sent again
        try:
            info.wait_for_publish(30)
            published = info.is_published()
        except (RuntimeError, ValueError):
            published = False
        if not published:
            resent += 1
            pub.publish(topic, payload, qos=1).wait_for_publish(30)
    expected = sum(len(v) for v in truth["tests"].values())
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        with open_store(str(db)) as store:
            tests = sum(len(store.history(u)) - 3 for u in truth["tests"])
            isolated = sum(len(store.isolations(u)) > 0 for u in truth["faulty"])
        if tests >= expected and isolated >= len(truth["faulty"]):
            break
        time.sleep(1.0)
    watcher.send_signal(signal.SIGTERM)
    finish(watcher)
    pub.loop_stop()
    broker.kill()
    whole = duplicated = extra = 0
    with open_store(str(db)) as store:
        for unit, hashes in truth["tests"].items():
            found = [store.find_test(unit, h) for h in hashes]
            whole += sum(f is not None for f in found)
            extra += len(store.history(unit)) - 3 - sum(f is not None for f in found)
        iso = {u: len(store.isolations(u)) for u in truth["faulty"] + truth["healthy"]}
    duplicated = sum(max(0, n - 1) for n in iso.values())
    gaps = sum("a gap of" in ln or "clock went back" in ln for ln in logs)
    return {"messages": len(plan), "rate_per_s": rate, "seconds": round(seconds, 1),
            "disruptions": " ".join(f"{k}@{t:g}" for t, k in done),
            "republished": resent, "tests_sent": expected, "tests_stored_whole": whole,
            "tests_not_whole": expected - whole, "tests_extra_or_partial": extra,
            "faulty_units": len(truth["faulty"]),
            "faulty_isolated": sum(iso[u] > 0 for u in truth["faulty"]),
            "isolations_stored_twice": duplicated,
            "healthy_isolated": sum(iso[u] > 0 for u in truth["healthy"]),
            "tracker_gaps": gaps,
            "replays": sum("replaying" in ln for ln in logs)}


def flood(broker_cls: Any, *, seconds: float = 60.0, names: int = 30_000) -> dict[str, Any]:
    """Peak RSS of ``condmon watch`` (a child of its own, measured by wait4)
    under three floods at once: valid 3.4 MB HST chunks, dc-motor tests that
    never end, and new unit names."""
    folder = Path(tempfile.mkdtemp(prefix="flood-"))
    broker = broker_cls(folder)
    db = folder / "flood.db"
    with open_store(str(db)) as store:
        for u in range(10):
            store.unit_id(f"EMA-{u}", create=True, model="dc-motor")
    proc = subprocess.Popen(
        [sys.executable, "-m", "condmon.cli.main", "watch", "--mqtt", broker.address,
         "--db", str(db), "--model", "hst", "--client-id", "flood"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    _drain(proc, lines)
    peak = {"kB": 0.0}

    def sample() -> None:
        while proc.poll() is None:
            peak["kB"] = max(peak["kB"], _hwm(proc.pid))
            time.sleep(0.5)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    time.sleep(8.0)
    pub = _client("flood-pub", broker.port)
    rec = simulate_plant(HST, seed=5, duration=1000.0)
    big = json.dumps({c: rec[c].iloc[:100_000].tolist() for c in rec.columns}).encode()
    dc = simulate_actuator(seed=3)
    t0 = time.monotonic()
    sent = {"big": 0, "dc": 0, "names": 0}
    k = 0
    while time.monotonic() - t0 < seconds:
        if k % 20 == 0:  # one a second: each is 1,000 s of a unit's samples to step
            pub.publish(f"condmon/BIG-{k // 20}/samples", big, qos=1)
            sent["big"] += 1
        chunk = json.dumps({c: (dc[c] + 4.0 * k if c == "t" else dc[c]).tolist()
                            for c in dc.columns}).encode()   # the test goes on, never ending
        for u in range(10):
            pub.publish(f"condmon/EMA-{u}/samples", chunk, qos=1)
            sent["dc"] += 1
        for _ in range(500):
            if sent["names"] < names:
                pub.publish(f"condmon/N{sent['names']}/samples", b'{"t": [0, 0.01], '
                            b'"Ps": [1e7, 1e7], "omega_m": [100, 100]}', qos=0)
                sent["names"] += 1
        k += 1
        time.sleep(0.05)
    pub.loop_stop()
    proc.send_signal(signal.SIGTERM)
    stopping = time.monotonic()
    out = proc.communicate(timeout=600)[0]
    stopped = time.monotonic() - stopping
    sampler.join()
    broker.kill()
    return {"seconds": seconds, "big_chunks": sent["big"], "dc_chunks": sent["dc"],
            "unit_names": sent["names"], "peak_rss_MB": round(peak["kB"] / 1024.0, 1),
            "sigterm_to_exit_s": round(stopped, 1),
            "refusal_lines": sum(ln.startswith("refused") for ln in lines),
            "summary": out.strip().splitlines()[-1] if out.strip() else ""}


def page_under_load(clients: int = 100, units: int = 200) -> dict[str, Any]:
    """``GET /`` through ``condmon serve --mqtt`` with ``clients`` event streams open."""
    import http.client
    import socket

    folder = Path(tempfile.mkdtemp(prefix="page-"))
    db = folder / "p.db"
    with open_store(str(db)) as store:
        for i in range(units):
            store.unit_id(f"U{i}", create=True, model="hst")
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from _broker import Broker

    broker = Broker(folder)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-m", "condmon.cli.main", "serve", "--db", str(db),
                             "--port", str(port), "--mqtt", broker.address],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            break
        except OSError:
            time.sleep(0.1)
    streams = []
    refused = 0
    for _ in range(clients):
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
        c.request("GET", "/api/events")
        r = c.getresponse()
        if r.status == 200:
            streams.append((c, r))
        else:
            refused += 1
            c.close()
    times = []
    for _ in range(10):
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
        t = time.perf_counter()
        c.request("GET", "/")
        r = c.getresponse()
        r.read()
        times.append(time.perf_counter() - t)
        c.close()
    for c, _ in streams:
        c.close()
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=30)
    broker.kill()
    return {"event_clients": clients, "streaming": len(streams), "turned_away": refused,
            "units": units, "GET_/_median_s": round(float(np.median(times)), 3),
            "GET_/_max_s": round(max(times), 3)}


def idle_folder(files: int = 30_000, units: int = 100, seconds: float = 20.0) -> dict[str, Any]:
    """CPU of ``condmon watch FOLDER`` over ``files`` files already handed over
    (they are notes, refused once by the fleet run), nothing new arriving."""
    folder = Path(tempfile.mkdtemp(prefix="idle-"))
    inbox = folder / "inbox"
    for u in range(units):
        (inbox / f"U{u}").mkdir(parents=True)
        for k in range(files // units):
            (inbox / f"U{u}" / f"n{k}.txt").write_text("x")
    proc = subprocess.Popen([sys.executable, "-m", "condmon.cli.main", "watch", str(inbox),
                             "--db", str(folder / "i.db"), "--complete", "rename"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True)
    # the first fleet run refuses every note once: wait until it is over (5 s
    # spent under 10 % of a core), at most 10 minutes
    deadline, last = time.monotonic() + 600, _cpu(proc.pid)
    while time.monotonic() < deadline:
        time.sleep(5.0)
        now = _cpu(proc.pid)
        if now - last < 0.5:
            break
        last = now
    kids = _children(proc.pid)
    deadline = time.monotonic() + 120   # the watch closes its cluster after 60 s idle
    while kids and time.monotonic() < deadline:
        time.sleep(2.0)
        kids = _children(proc.pid)
    before = _cpu(proc.pid), sum(_cpu(k) for k in kids)
    time.sleep(seconds)
    after = _cpu(proc.pid), sum(_cpu(k) for k in kids)
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=120)
    return {"files": files, "units": units, "idle_s": seconds,
            "cpu_percent_of_a_core": round(100.0 * (after[0] - before[0]) / seconds, 2),
            "its_cluster_percent": round(100.0 * (after[1] - before[1]) / seconds, 2),
            "cluster_processes": len(kids)}


def _drain(proc: subprocess.Popen[str], into: list[str]) -> None:
    """Read a child's log lines as they come (a full pipe would stop the child)."""
    def run() -> None:
        assert proc.stderr is not None
        for line in proc.stderr:
            into.append(line.rstrip("\n"))

    threading.Thread(target=run, daemon=True).start()


def _hwm(pid: int) -> float:
    """Peak resident memory of a live process so far (VmHWM). [kB]"""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return float(line.split()[1])
    except OSError:
        pass
    return 0.0


def _children(pid: int) -> list[int]:
    """Every process ``pid`` started, and theirs (the fleet run's local cluster)."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            kids = [int(k) for k in (task / "children").read_text().split()]
        except OSError:
            continue
        for k in kids:
            out += [k, *_children(k)]
    return out


def _cpu(pid: int) -> float:
    """User + system CPU of a process so far (0 once gone). [s]"""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
