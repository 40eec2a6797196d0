"""Live monitoring through a real MQTT broker (Debian's mosquitto, started here):
plant-model units tracked online, detected, isolated and stored; a healthy
stream raises nothing; malformed messages are refused and the stream goes on;
a dc-motor test sent as chunks is checked as by `condmon check`; the last
status of each unit is retained on the broker."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from condmon.models.registry import load_plant_model
from condmon.simulate.plant import simulate_plant
from condmon.store import open_store
from condmon.workflows.live import watch_mqtt

from _broker import (Broker, Listener, _client, _connected, _free_port,  # noqa: F401
                     _publish_records, broker, start_watch)

HST = load_plant_model("hst")


def _watch_in_thread(db: str, broker: Broker, stop: threading.Event, lines: list[str],
                     model: str = "hst") -> tuple[threading.Thread, dict]:
    result: dict = {}

    def run() -> None:
        with open_store(db) as store:
            result["summary"] = watch_mqtt(store, broker.address, model=model, stop=stop,
                                           log=lines.append, client_id="test-watch")

    th = threading.Thread(target=run, daemon=True)
    th.start()
    deadline = time.monotonic() + 60
    while not any("subscribed to" in ln for ln in lines) and time.monotonic() < deadline:
        time.sleep(0.02)  # published before the watcher subscribes, a chunk would be lost
    return th, result


FAULTS = {"HST-RV": ("Rv=+40%@8s", 8.0, {"Rv", "Tld"}),
          "HST-DM": ("Dm=-25%@6s", 6.0, {"Dm"}),
          "HST-TLD": ("Tld=+60@9s", 9.0, {"Rv", "Tld"})}


def test_plant_units_are_tracked_detected_isolated_and_stored(
        broker: Broker, tmp_path: Path) -> None:
    """20 HST units at 100 Hz through a real broker, replayed faster than real
    time: the three faulty ones detected within persistence + 0.5 s of onset,
    isolated to their parameter or its documented ambiguity set (one operating
    point after the fault cannot tell a viscous load Rv from a load torque Tld),
    and stored; the 17 healthy ones raise nothing."""
    records = {f"HST-{i}": simulate_plant(HST, seed=10 + i, duration=20.0) for i in range(17)}
    for k, (unit, (fault, _, _)) in enumerate(FAULTS.items()):
        records[unit] = simulate_plant(HST, [fault], seed=40 + k, duration=20.0)
    db = str(tmp_path / "live.db")
    listen = Listener(broker)
    stop, lines = threading.Event(), []
    th, result = _watch_in_thread(db, broker, stop, lines)
    bad = [("condmon/HST-0/samples", b"not json"),
           ("condmon/HST-0/samples", b'{"t": [0, 0.01], "Ps": [1.0]}'),
           ("condmon/HST-0/samples", b'{"Ps": [1.0, 2.0]}'),
           ("condmon/HST-0/samples", b'{"t": [0, 0.01], "Ps": [1.0, NaN]}'),
           ("condmon/bad unit!/samples", b'{"t": [0]}')]
    _publish_records(broker, records, extra=bad)
    assert listen.wait(lambda ev: sum(e["kind"] == "isolated" for e in ev) == 3), lines
    time.sleep(1.0)
    stop.set()
    th.join(60)
    listen.close()
    summary = result["summary"]
    events = listen.events
    for unit, (_, onset, allowed) in FAULTS.items():
        faulty = [e for e in events if e["unit"] == unit]
        detected = next(e for e in faulty if e["kind"] == "detected")
        assert onset < detected["t"] <= onset + 0.5 + 0.5, (unit, detected)
        isolated = next(e for e in faulty if e["kind"] == "isolated")
        truth = unit.split("-")[1].capitalize() if unit != "HST-TLD" else "Tld"
        assert truth in isolated["isolated"] and set(isolated["isolated"]) <= allowed, isolated
    for unit in (f"HST-{i}" for i in range(17)):  # the healthy units raise nothing
        assert [e["status"] for e in events if e["unit"] == unit] == ["go"], unit
    with open_store(db) as store:
        assert all(len(store.isolations(u)) == 1 for u in FAULTS)
        assert all(len(store.isolations(f"HST-{i}")) == 0 for i in range(17))
    c = summary.counters
    assert c.detections == 3 and c.isolations == 3
    # the four malformed messages and the bad topic: refused in one line each
    refused = [ln for ln in lines if ln.startswith("refused")]
    assert c.refused == 5 and len(refused) == 5, refused
    assert sum("unit 'HST-0' (topic condmon/HST-0/samples)" in ln for ln in refused) == 4
    assert "topic 'condmon/bad unit!/samples' is not condmon/<unit>/samples" in refused[-1]
    assert c.samples == sum(len(r) for r in records.values())
    # the last status of every unit is retained: a late subscriber sees it at once
    late = Listener(broker, "late")
    assert late.wait(lambda ev: {e["unit"] for e in ev} >= set(records), timeout=5)
    last = {e["unit"]: e for e in late.events}
    late.close()
    assert last["HST-RV"]["kind"] == "isolated" and last["HST-0"]["status"] == "go"


def test_a_dc_motor_test_sent_as_chunks_is_checked_as_by_check(
        broker: Broker, tmp_path: Path) -> None:
    from condmon.simulate import simulate_actuator
    from condmon.workflows.checks import check_test
    from condmon.workflows.monitoring import add_baseline_tests

    db = str(tmp_path / "dc.db")
    with open_store(db) as store:
        add_baseline_tests(store, "EMA-1", [simulate_actuator(seed=s) for s in (1, 2, 3)])
    shutil.copy(db, tmp_path / "ref.db")
    test = simulate_actuator(seed=9)
    with open_store(str(tmp_path / "ref.db")) as store:
        ref = check_test(store, "EMA-1", test.copy())
    listen = Listener(broker)
    stop, lines = threading.Event(), []
    th, _ = _watch_in_thread(db, broker, stop, lines, model="dc-motor")
    time.sleep(1.0)
    _publish_records(broker, {"EMA-1": test}, chunk=500,
                     extra=[])
    pub = _client("ender")
    pub.connect("127.0.0.1", broker.port)
    pub.loop_start()
    pub.publish("condmon/EMA-1/samples", b'{"end": true}', qos=1).wait_for_publish(10)
    pub.loop_stop()
    assert listen.wait(lambda ev: any(e["kind"] == "checked" for e in ev)), lines
    stop.set()
    th.join(60)
    listen.close()
    checked = next(e for e in listen.events if e["kind"] == "checked")
    assert checked["status"] == ref.status
    with open_store(db) as live, open_store(str(tmp_path / "ref.db")) as offline:
        a, b = live.history("EMA-1"), offline.history("EMA-1")
        assert len(a) == len(b) == 4
        for p in ("R", "L", "Kt", "J", "D"):
            assert a[p].iloc[-1] == pytest.approx(b[p].iloc[-1], rel=1e-9), p


def test_the_command_stops_on_sigterm_and_says_what_it_saw(
        broker: Broker, tmp_path: Path) -> None:
    db = tmp_path / "cmd.db"
    proc = subprocess.Popen([sys.executable, "-m", "condmon.cli.main", "watch", "--mqtt",
                             broker.address, "--db", str(db), "--model", "hst"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    listen = Listener(broker)
    _connected(proc)
    _publish_records(broker, {"HST-9": simulate_plant(HST, seed=4, duration=3.0)})
    assert listen.wait(lambda ev: any(e["unit"] == "HST-9" for e in ev), timeout=30)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    listen.close()
    assert proc.returncode == 0, err
    assert "301 samples" in out and "0 refused" in out, out


def test_a_dropped_file_gets_the_fleet_run_result(tmp_path: Path) -> None:
    """Files dropped in a watched inbox, one by one, end as `fleet run` leaves them."""
    from condmon.simulate import simulate_actuator
    from condmon.workflows.fleet import run_fleet
    from condmon.workflows.watch_folder import watch_folder

    inbox, staging = tmp_path / "inbox", tmp_path / "staging"
    (inbox / "EMA-1").mkdir(parents=True)
    staging.mkdir()
    files = []
    for i, seed in enumerate((1, 2, 3, 9)):
        f = staging / f"test-{i + 1}.csv"
        simulate_actuator(seed=seed).to_csv(f, index=False)
        files.append(f)
    stop, lines, events = threading.Event(), [], []
    db = str(tmp_path / "watched.db")
    result: dict = {}
    th = threading.Thread(target=lambda: result.update(summary=watch_folder(
        inbox, db, settle=0.5, poll=0.2, stop=stop, log=lines.append,
        publish=events.append)), daemon=True)
    th.start()
    for f in files:  # written elsewhere, renamed into place: complete at once
        os.replace(f, inbox / "EMA-1" / f.name)
        time.sleep(1.0)
    deadline = time.monotonic() + 120
    while len(events) < 4 and time.monotonic() < deadline:
        time.sleep(0.2)
    stop.set()
    th.join(120)
    assert result["summary"].files == 4 and result["summary"].stored == 4, lines
    ref = run_fleet(inbox, str(tmp_path / "fleet.db"), workers=1)
    assert ref.stored == 4
    with open_store(db) as a, open_store(str(tmp_path / "fleet.db")) as b:
        ha, hb = a.history("EMA-1"), b.history("EMA-1")
        assert list(ha["status"]) == list(hb["status"])
        for p in ("R", "L", "Kt", "J", "D"):
            assert ha[p].to_numpy() == pytest.approx(hb[p].to_numpy(), rel=1e-9), p
    assert [e.unit for e in events] == ["EMA-1"] * 4
    # running the fleet again over the watched history stores nothing new
    assert run_fleet(inbox, db, workers=1).stored == 0


def test_the_broker_restarted_mid_stream_loses_nothing(broker: Broker, tmp_path: Path) -> None:
    records = {"HST-A": simulate_plant(HST, seed=21, duration=20.0),
               "HST-B": simulate_plant(HST, ["Rv=+40%@12s"], seed=22, duration=20.0)}
    db = str(tmp_path / "restart.db")
    stop, lines = threading.Event(), []
    th, result = _watch_in_thread(db, broker, stop, lines)
    time.sleep(1.0)
    first = {u: r.iloc[:900] for u, r in records.items()}
    second = {u: r.iloc[900:] for u, r in records.items()}
    _publish_records(broker, first)
    time.sleep(1.0)
    broker.kill()           # stopped mid-stream ...
    time.sleep(2.0)
    broker.start()          # ... and back on the same port with its saved sessions
    _publish_records(broker, second)
    listen = Listener(broker)
    assert listen.wait(lambda ev: any(e["kind"] == "isolated" for e in ev)), lines
    time.sleep(1.0)
    stop.set()
    th.join(60)
    listen.close()
    summary = result["summary"]
    assert summary.connections >= 2
    assert any("again" in ln for ln in lines) and any("lost the broker" in ln for ln in lines)
    assert summary.counters.samples == sum(len(r) for r in records.values())  # nothing lost
    assert summary.counters.dropped == 0
    with open_store(db) as store:
        assert len(store.isolations("HST-B")) == 1 and len(store.isolations("HST-A")) == 0


class _Hook:
    """A local webhook: answers 500 to the first post, then 200 after a delay."""

    def __init__(self, delay: float = 0.0) -> None:
        import http.server

        self.posts: list[dict] = []
        hook = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802
                body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
                hook.posts.append(body)
                if len(hook.posts) == 1:
                    self.send_response(500)
                else:
                    time.sleep(delay)
                    self.send_response(200)
                self.end_headers()

            def log_message(self, *args: object) -> None:
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/hook"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def test_events_are_posted_with_retries_and_a_slow_hook_never_holds_the_stream(
        broker: Broker, tmp_path: Path) -> None:
    from condmon.workflows.notify import Notifier

    hook = _Hook(delay=1.5)   # each post takes 1.5 s to answer
    notifier = Notifier(hook.url, backoff=0.1)
    records = {f"HST-{i}": simulate_plant(HST, seed=30 + i, duration=4.0) for i in range(3)}
    stop, lines = threading.Event(), []
    result: dict = {}
    from condmon.workflows.watch import Watcher

    def run() -> None:
        with open_store(str(tmp_path / "n.db")) as store:
            result["watcher"] = Watcher(store, model="hst")
            result["summary"] = watch_mqtt(store, broker.address, watcher=result["watcher"],
                                           stop=stop, log=lines.append,
                                           client_id="notify-watch", notify=notifier.send)

    th = threading.Thread(target=run, daemon=True)
    th.start()
    deadline = time.monotonic() + 60
    while not any("subscribed to" in ln for ln in lines) and time.monotonic() < deadline:
        time.sleep(0.02)
    started = time.monotonic()
    _publish_records(broker, records)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if (sum(ln.endswith("the stream") for ln in lines) == 3
                and result["watcher"].counters.samples == 3 * 401):
            break
        time.sleep(0.05)
    handled = time.monotonic() - started
    stop.set()
    th.join(30)
    assert result["summary"].counters.samples == 3 * 401
    # three events at 1.5 s a post (one retried): the stream did not wait for them
    assert handled < 3.0, handled
    notifier.close()
    hook.close()
    assert notifier.sent == 3 and notifier.failed == 0
    assert len(hook.posts) == 4  # the first was answered 500 and posted again
    assert {p["unit"] for p in hook.posts} == set(records)
    assert all(p["status"] == "go" and p["kind"] == "watching" for p in hook.posts)


def test_the_fleet_page_shows_a_status_change_live(broker: Broker, tmp_path: Path) -> None:
    """`serve --mqtt`: a status published by the watcher reaches the open page
    without a reload (server-sent events), and a silent unit turns stale."""
    import re
    import tempfile

    exe = os.environ.get("CONDMON_CHROMIUM") or shutil.which("chromium")
    try:
        from playwright.sync_api import expect, sync_playwright
    except ImportError:
        exe = None
    if exe is None:
        why = "no browser: needs Debian's chromium and playwright (.ci/browser.sh)"
        if os.environ.get("CONDMON_REQUIRE_BROWSER") == "1":
            pytest.fail(why)
        pytest.skip(why)
    db = tmp_path / "page.db"
    with open_store(str(db)) as store:
        store.unit_id("HST-L", create=True, model="hst")
    proc = subprocess.Popen([sys.executable, "-m", "condmon.cli.main", "serve", "--db", str(db),
                             "--port", "0", "--refresh", "0", "--mqtt", broker.address,
                             "--stale-after", "5"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    url = re.search(r"(http://127\.0\.0\.1:\d+/)", proc.stdout.readline()).group(1)  # type: ignore[union-attr]
    pub = _client("page-pub")
    pub.connect("127.0.0.1", broker.port)
    pub.loop_start()
    profile = tempfile.mkdtemp(prefix="condmon-chromium-")
    try:
        with sync_playwright() as pw:
            ctx = pw.chromium.launch_persistent_context(
                profile, executable_path=exe, headless=True,
                args=["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                      "--no-first-run", "--disable-component-update", "--disable-sync"])
            page = ctx.new_page()
            page.set_default_timeout(15_000)
            page.goto(url)
            row = page.locator('tr[data-unit="HST-L"]')
            expect(row).to_have_attribute("data-status", "none")
            page.evaluate("window.__same_page = true")
            pub.publish("condmon/HST-L/samples", b'{"t": [0, 0.01], "Ps": [0, 0], '
                        b'"omega_m": [0, 0]}', qos=1).wait_for_publish(5)
            pub.publish("condmon/HST-L/status", json.dumps(
                {"unit": "HST-L", "status": "no-go", "time": "2026-11-24T12:00:00+00:00",
                 "reason": "fault detected at t = 8.53 s", "isolated": [], "kind": "detected",
                 "t": 8.53}), qos=1, retain=True).wait_for_publish(5)
            expect(row).to_have_attribute("data-status", "no-go")
            expect(row).to_contain_text("fault detected at t = 8.53 s")
            expect(page.locator('[data-count="no-go"]')).to_have_text("1")  # the tally too
            expect(page.locator('[data-count="none"]')).to_have_count(0)
            assert page.evaluate("window.__same_page === true")  # no reload
            expect(row).to_have_attribute("data-status", "stale", timeout=15_000)
            expect(row).to_contain_text("no samples since")
            pub.publish("condmon/HST-L/samples", b'{"t": [1, 1.01], "Ps": [0, 0], '
                        b'"omega_m": [0, 0]}', qos=1).wait_for_publish(5)
            expect(row).to_have_attribute("data-status", "no-go")
            assert page.evaluate("window.__same_page === true")
            page.screenshot(path=str(tmp_path / "live.png"))
            ctx.close()
    finally:
        pub.loop_stop()
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=20)
        shutil.rmtree(profile, ignore_errors=True)


def test_after_a_sigkill_a_restart_stores_no_event_twice(broker: Broker, tmp_path: Path) -> None:
    """The watcher killed (SIGKILL) after it stored an isolation; the restarted
    one is sent the stream again from t = 5 s (what a source re-sends): it
    detects the same fault and stores nothing twice."""
    db = tmp_path / "kill.db"
    rec = simulate_plant(HST, ["Rv=+40%@8s"], seed=51, duration=16.0)

    def start() -> subprocess.Popen[str]:
        return start_watch(broker, db, "hst", "kill-watch")

    listen = Listener(broker)
    first = start()
    _publish_records(broker, {"HST-K": rec})
    assert listen.wait(lambda ev: any(e["kind"] == "isolated" for e in ev), timeout=90)
    first.kill()
    first.communicate(timeout=20)
    listen.events.clear()
    second = start()
    _publish_records(broker, {"HST-K": rec.iloc[500:]})
    assert listen.wait(lambda ev: any(e["kind"] == "isolated" for e in ev), timeout=90)
    second.send_signal(signal.SIGTERM)
    out, err = second.communicate(timeout=60)
    listen.close()
    again = next(e for e in listen.events if e["kind"] == "isolated")
    assert "already stored" in again["reason"], again
    assert "already; not stored again" in err
    with open_store(str(db)) as store:
        assert len(store.isolations("HST-K")) == 1


def test_events_made_beside_the_stream_are_published_too(broker: Broker, tmp_path: Path) -> None:
    """`watch FOLDER --mqtt`: a dropped file's event goes out on condmon/<unit>/status."""
    import queue as _queue

    from condmon.workflows.watch import WatchEvent

    outbox: _queue.Queue[WatchEvent] = _queue.Queue()
    listen = Listener(broker)
    stop, lines, result = threading.Event(), [], {}

    def run() -> None:
        with open_store(str(tmp_path / "o.db")) as store:
            result["s"] = watch_mqtt(store, broker.address, stop=stop, log=lines.append,
                                     outbox=outbox)

    th = threading.Thread(target=run, daemon=True)
    th.start()
    outbox.put(WatchEvent("EMA-3", "no-go", "2026-11-24T00:00:00+00:00",
                          "test-4.csv: stored", (), "checked"))
    assert listen.wait(lambda ev: any(e["unit"] == "EMA-3" for e in ev), timeout=30), lines
    stop.set()
    th.join(30)
    listen.close()
    assert next(e for e in listen.events if e["unit"] == "EMA-3")["status"] == "no-go"


def test_an_unreachable_broker_is_one_line_and_makes_no_history(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from condmon.cli.main import main

    db = tmp_path / "none.db"
    capsys.readouterr()
    assert main(["watch", "--mqtt", f"127.0.0.1:{_free_port()}", "--db", str(db)]) == 2
    err = capsys.readouterr().err
    assert "cannot reach the broker at 127.0.0.1:" in err and len(err.strip().splitlines()) == 1
    assert not db.exists()
