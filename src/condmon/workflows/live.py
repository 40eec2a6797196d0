"""``condmon watch`` over MQTT: the broker in, the watcher, events out.

paho-mqtt (the Eclipse client) does the protocol. The client subscribes to
``condmon/+/samples`` with QoS 1 under a fixed client id and a persistent
session, so a broker that keeps the session hands over what arrived while the
watcher was away, once; it reconnects with backoff (1 s to 30 s) and
resubscribes on every connection, and says so in the log. Messages go through
a bounded queue: when the watcher falls behind, new messages are dropped and
counted, never piled up. Every event is published retained (QoS 1) on
``condmon/<unit>/status``, so a client that subscribes later sees each unit's
last status at once.

SIGTERM or Ctrl-C stops the loop: the queue is drained, pending isolations
finish and are stored, and the function returns (the command exits 0).
"""

from __future__ import annotations

import json
import queue
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from condmon.errors import ConfigError, CondmonError
from condmon.io.stream import STATUS_TOPIC, StreamLimits, parse_broker, parse_chunk
from condmon.store.db import HistoryStore
from condmon.store.engine import StoreError
from condmon.workflows.watch import WatchCounters, WatchEvent, Watcher

__all__ = ["parse_broker", "LiveSummary", "watch_mqtt", "stop_on_signals", "restore_signals"]

SUBSCRIPTION = "condmon/+/samples"
BATCH = 2000  # messages handled together at most (one integration of many units)


@dataclass(frozen=True)
class LiveSummary:
    """How a watch ended.

    Attributes
    ----------
    counters : WatchCounters
    seconds : float
        How long it ran. [s]
    overflow : int
        Messages dropped because the queue was full.
    connections : int
        Connections made to the broker (1 + reconnections).
    """

    counters: WatchCounters
    seconds: float
    overflow: int
    connections: int


def watch_mqtt(store: HistoryStore, broker: str, *, model: str | None = None,
               watcher: Watcher | None = None, duration: float | None = None,
               stop: threading.Event | None = None, log: Callable[[str], None] = print,
               client_id: str | None = None, limits: StreamLimits | None = None,
               notify: Callable[[dict[str, Any]], object] | None = None,
               outbox: queue.Queue[WatchEvent] | None = None) -> LiveSummary:
    """Watch the units streaming to ``broker`` until stopped.

    Parameters
    ----------
    store : HistoryStore
    broker : str
        ``HOST:PORT`` of the MQTT broker.
    model : str, optional
        The model of units new to the history.
    watcher : Watcher, optional
        Default: one over ``store`` with ``model``.
    duration : float, optional
        Stop after this long (default: until SIGTERM, Ctrl-C or ``stop``). [s]
    stop : threading.Event, optional
        Set it to stop (from another thread).
    log : callable
        Takes each log line.
    client_id : str, optional
        The MQTT client id: the broker keeps a persistent session under it, and
        two clients with one id push each other off. Default: ``condmon-watch-``
        and a digest of the history's address, so one history has one session.
    limits : StreamLimits, optional
        Message and queue bounds (default: shipped).
    notify : callable, optional
        Also takes every event's JSON object (a :class:`~condmon.workflows.notify.
        Notifier`'s ``send``: it must not block).
    outbox : queue.Queue, optional
        Events made elsewhere (``watch FOLDER`` beside the stream) to publish too.

    Returns
    -------
    LiveSummary
    """
    import paho.mqtt.client as mqtt
    from paho.mqtt.enums import CallbackAPIVersion

    host, port = parse_broker(broker)
    if client_id is None:
        import hashlib

        client_id = "condmon-watch-" + hashlib.sha256(str(store.url).encode()).hexdigest()[:12]
    if not client_id.strip() or len(client_id) > 128:
        raise ConfigError(f"--client-id {client_id!r}: give a name of 1 to 128 characters "
                          "(the broker keeps this watcher's session under it)")
    lim = limits or StreamLimits.shipped()
    inbox: queue.Queue[tuple[str, bytes]] = queue.Queue(maxsize=lim.queue)
    state = {"overflow": 0, "connections": 0}
    halt = stop or threading.Event()

    client = mqtt.Client(CallbackAPIVersion.VERSION2, client_id=client_id,
                         clean_session=False)
    client.reconnect_delay_set(min_delay=1, max_delay=30)

    def on_connect(c: Any, userdata: Any, flags: Any, reason: Any, props: Any) -> None:
        if getattr(reason, "is_failure", False):
            log(f"broker {host}:{port} refused the connection: {reason}")
            return
        state["connections"] += 1
        c.subscribe(SUBSCRIPTION, qos=1)
        log(f"connected to {host}:{port}" + (" again" if state["connections"] > 1 else "")
            + f"; subscribed to {SUBSCRIPTION}")

    def on_disconnect(c: Any, userdata: Any, flags: Any, reason: Any, props: Any) -> None:
        if not halt.is_set():
            log(f"lost the broker {host}:{port} ({reason}); reconnecting")

    def on_message(c: Any, userdata: Any, msg: Any) -> None:
        try:
            inbox.put_nowait((msg.topic, msg.payload))
        except queue.Full:
            state["overflow"] += 1

    client.on_connect = on_connect
    client.on_disconnect = on_disconnect
    client.on_message = on_message

    def publish(event: WatchEvent) -> None:
        client.publish(STATUS_TOPIC.format(unit=event.unit), json.dumps(event.to_dict()),
                       qos=1, retain=True)
        if notify is not None:
            notify(event.to_dict())
        log(f"{event.unit}: {event.status}: {event.reason}")

    w = watcher or Watcher(store, model=model)
    w.publish = publish
    w.log = log
    try:
        client.connect(host, port, keepalive=30)
    except OSError as exc:
        raise ConfigError(f"--mqtt {broker}: cannot reach the broker at {host}:{port} "
                          f"({exc})") from None
    client.loop_start()
    previous = stop_on_signals(halt)
    started = time.monotonic()
    try:
        while not halt.is_set():
            if duration is not None and time.monotonic() - started >= duration:
                break
            while outbox is not None and not outbox.empty():
                publish(outbox.get_nowait())
            try:
                first = inbox.get(timeout=0.1)
            except queue.Empty:
                w.poll()
                continue
            _handle(w, [first, *_drain(inbox, BATCH)], lim, log)
            w.poll()
        # flush: what arrived before the stop is handled, pending isolations stored
        while messages := _drain(inbox, BATCH):
            _handle(w, messages, lim, log)
        w.close()
    finally:
        halt.set()  # a stop, not a lost broker
        restore_signals(previous)
        client.disconnect()
        client.loop_stop()
    counters = w.counters
    counters.dropped += state["overflow"]
    return LiveSummary(counters, time.monotonic() - started, state["overflow"],
                       state["connections"])


def _drain(inbox: queue.Queue[tuple[str, bytes]], most: int) -> list[tuple[str, bytes]]:
    """Up to ``most`` messages waiting in the queue (none: an empty list)."""
    out: list[tuple[str, bytes]] = []
    while len(out) < most:
        try:
            out.append(inbox.get_nowait())
        except queue.Empty:
            break
    return out


def _handle(w: Watcher, messages: list[tuple[str, bytes]], lim: StreamLimits,
            log: Callable[[str], None]) -> None:
    """Validate messages and hand the good ones to the watcher together."""
    chunks = []
    for topic, payload in messages:
        try:
            chunks.append(parse_chunk(topic, payload, lim))
        except CondmonError as exc:
            w.counters.received += 1
            w.counters.refused += 1
            log(f"refused: {exc}")
    try:
        w.handle_many(chunks)
    except StoreError:
        raise
    except CondmonError as exc:  # handled per unit inside; a last guard: the stream goes on
        log(f"refused: {exc}")


def stop_on_signals(halt: threading.Event) -> dict[int, Any]:
    """SIGTERM and SIGINT set ``halt`` (main thread only); the previous handlers."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    previous: dict[int, Any] = {}
    for sig in (signal.SIGTERM, signal.SIGINT):
        previous[sig] = signal.signal(sig, lambda signum, frame: halt.set())
    return previous


def restore_signals(previous: dict[int, Any]) -> None:
    """Put back the handlers :func:`stop_on_signals` replaced."""
    for sig, handler in previous.items():
        signal.signal(sig, handler)
