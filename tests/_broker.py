"""A real MQTT broker for the live-monitoring tests (Debian's mosquitto,
started on a loopback port), a listener of the status events, a publisher of
records as chunks, and the wait for a `condmon watch` child to connect."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest


def _mosquitto() -> str | None:
    for exe in ("/usr/sbin/mosquitto", shutil.which("mosquitto")):
        if exe and os.access(exe, os.X_OK):
            return exe
    return None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Broker:
    """A mosquitto process on a loopback port, its sessions persisted in ``folder``."""

    def __init__(self, folder: Path, extra: str = "") -> None:
        exe = _mosquitto()
        if exe is None:
            why = ("no MQTT broker: needs Debian's mosquitto (apt-get install mosquitto; "
                   ".ci/broker.sh installs it)")
            if os.environ.get("CONDMON_REQUIRE_BROKER"):
                pytest.fail(why)
            pytest.skip(why)
        self.exe, self.folder, self.port = exe, folder, _free_port()
        self.conf = folder / "mosquitto.conf"
        store = folder / "broker-store"
        store.mkdir()
        # started as root, mosquitto would drop to its own user, which cannot
        # reach a private temporary folder: it stays the user that started it
        user = "user root\n" if os.geteuid() == 0 else ""
        self.conf.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous true\n"
                             f"persistence true\npersistence_location {store}/\n"
                             f"autosave_interval 1\n{user}{extra}")
        self.proc: subprocess.Popen[bytes] | None = None
        self.start()

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def start(self) -> None:
        self.proc = subprocess.Popen([self.exe, "-c", str(self.conf)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                return
            except OSError:
                time.sleep(0.05)
        raise RuntimeError("mosquitto did not start")

    def kill(self) -> None:
        if self.proc is not None:
            self.proc.send_signal(signal.SIGTERM)  # saves its sessions, as a restart does
            self.proc.wait(10)
            self.proc = None


@pytest.fixture
def broker(tmp_path: Path) -> Iterator[Broker]:
    b = Broker(tmp_path)
    yield b
    b.kill()


def _client(client_id: str) -> object:
    import paho.mqtt.client as mqtt
    from paho.mqtt.enums import CallbackAPIVersion

    return mqtt.Client(CallbackAPIVersion.VERSION2, client_id=client_id)


class Listener:
    """Collects the status events of every unit."""

    def __init__(self, broker: Broker, name: str = "listener") -> None:
        self.events: list[dict] = []
        self.client = _client(name)
        self.client.on_message = lambda c, u, m: self.events.append(json.loads(m.payload))
        self.client.connect("127.0.0.1", broker.port)
        self.client.subscribe("condmon/+/status", qos=1)
        self.client.loop_start()

    def wait(self, predicate, timeout: float = 90.0) -> bool:  # type: ignore[no-untyped-def]
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate(self.events):
                return True
            time.sleep(0.1)
        return False

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()


def _publish_records(broker: Broker, records: dict[str, pd.DataFrame], chunk: int = 50,
                     extra: list[tuple[str, bytes]] = ()) -> None:  # type: ignore[assignment]
    pub = _client("publisher")
    pub.connect("127.0.0.1", broker.port)
    pub.loop_start()
    n = max(len(r) for r in records.values())
    infos = []
    for topic, payload in extra:
        infos.append(pub.publish(topic, payload, qos=1))
    for k in range(0, n, chunk):
        for unit, rec in records.items():
            part = rec.iloc[k:k + chunk]
            if len(part):
                infos.append(pub.publish(f"condmon/{unit}/samples", json.dumps(
                    {c: part[c].tolist() for c in part.columns}), qos=1))
    for info in infos:
        info.wait_for_publish(30)
    pub.loop_stop()
    pub.disconnect()


def _connected(proc: subprocess.Popen[str], timeout: float = 60.0) -> None:
    """Wait until a `condmon watch` child has subscribed (its first log line)."""
    assert proc.stderr is not None
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if "subscribed to" in line:
            return
        if not line and proc.poll() is not None:
            break
    pytest.fail(f"condmon watch did not connect: {proc.stderr.read()}")




def start_watch(broker: Broker, db: Path, model: str, client_id: str) -> subprocess.Popen[str]:
    """`condmon watch --mqtt` as a child process, once it has subscribed."""
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "condmon.cli.main", "watch", "--mqtt",
                             broker.address, "--db", str(db), "--model", model,
                             "--client-id", client_id],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _connected(proc)
    return proc
