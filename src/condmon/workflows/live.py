"""``condmon watch`` over MQTT: the broker in, the watcher, events out.

paho-mqtt (the Eclipse client) does the protocol. The client subscribes to
``condmon/+/samples`` with QoS 1 under a fixed client id and a persistent
session, so a broker that keeps the session hands over what arrived while the
watcher was away, once; it reconnects with backoff (1 s to 30 s) and
resubscribes on every connection, and says so in the log.

**At least once in, once stored.** A message is acknowledged to the broker
(paho's manual acknowledgement) only once it is written to the watcher's
journal (:mod:`condmon.store.journal`); until then the broker keeps it and
sends it again after a stop, a crash or a lost connection. A start replays the
journal before it takes new messages. A test is stored once (its content hash),
and an isolation once (its unit and the stream time of its detection), so a
replay stores nothing twice. Messages wait in a queue bounded in bytes
(``[stream] queue_bytes``); past it a message is refused, counted and said.

Every event is published retained (QoS 1) on ``condmon/<unit>/status``, so a
client that subscribes later sees each unit's last status at once.

SIGTERM or Ctrl-C stops the loop: no message is taken after it, messages not
yet journaled are left to the broker (not acknowledged), running isolations
finish and are stored, and the client disconnects (the command exits 0).
"""

from __future__ import annotations

import json
import queue
import signal
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

from condmon.errors import ConfigError, CondmonError
from condmon.io.stream import STATUS_TOPIC, StreamLimits, parse_broker, parse_chunk
from condmon.store.db import HistoryStore
from condmon.store.engine import StoreError
from condmon.store.journal import StreamJournal, default_journal
from condmon.workflows.watch import WatchCounters, WatchEvent, Watcher

__all__ = ["parse_broker", "LiveSummary", "watch_mqtt", "stop_on_signals", "restore_signals"]

T = TypeVar("T")
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
    replayed : int
        Messages replayed from the journal at the start.
    journal : str
        The journal file.
    """

    counters: WatchCounters
    seconds: float
    overflow: int
    connections: int
    replayed: int = 0
    journal: str = ""


def watch_mqtt(store: HistoryStore, broker: str, *, model: str | None = None,
               watcher: Watcher | None = None, duration: float | None = None,
               stop: threading.Event | None = None, log: Callable[[str], None] = print,
               client_id: str | None = None, limits: StreamLimits | None = None,
               notify: Callable[[dict[str, Any]], object] | None = None,
               outbox: queue.Queue[WatchEvent] | None = None,
               journal: str | Path | None = None) -> LiveSummary:
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
    journal : str or Path, optional
        The journal file (default: :func:`~condmon.store.journal.default_journal`
        of the history and the client id).

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
    book = StreamJournal(journal if journal is not None
                         else default_journal(str(store.url), client_id))
    inbox: queue.Queue[_Message] = queue.Queue()
    state = {"overflow": 0, "connections": 0, "bytes": 0, "held": 0}
    said = [-1e9]  # when the last line about a full queue was said [s, monotonic]
    count = threading.Lock()  # "bytes" is counted up by paho's thread, down by this one
    halt = stop or threading.Event()

    client = mqtt.Client(CallbackAPIVersion.VERSION2, client_id=client_id,
                         clean_session=False, manual_ack=True)
    client.reconnect_delay_set(min_delay=1, max_delay=30)

    def on_connect(c: Any, userdata: Any, flags: Any, reason: Any, props: Any) -> None:
        if getattr(reason, "is_failure", False):
            log(f"broker {host}:{port} refused the connection: {reason}")
            return
        state["connections"] += 1
        c.subscribe(SUBSCRIPTION, qos=1)

    def on_subscribe(c: Any, userdata: Any, mid: Any, reasons: Any, props: Any) -> None:
        # said once the broker has granted it: a test sent from then on reaches this
        # watcher (said at the request, a sender started at that line could lose its
        # first messages to a subscription the broker had not made yet)
        if any(getattr(r, "is_failure", False) for r in reasons):
            log(f"broker {host}:{port} refused the subscription to {SUBSCRIPTION}: {reasons}")
            return
        log(f"connected to {host}:{port}" + (" again" if state["connections"] > 1 else "")
            + f"; subscribed to {SUBSCRIPTION}")

    def on_disconnect(c: Any, userdata: Any, flags: Any, reason: Any, props: Any) -> None:
        if not halt.is_set():
            log(f"lost the broker {host}:{port} ({reason}); reconnecting")

    def on_message(c: Any, userdata: Any, msg: Any) -> None:
        size = len(msg.payload)
        with count:  # what waits to be journaled or handled
            full = state["bytes"] + size > lim.queue_bytes or state["held"] >= lim.queue
            state["bytes"] += 0 if full else size
            state["held"] += 0 if full else 1
        if full:
            state["overflow"] += 1  # refused: acknowledged, so the broker does not resend it
            c.ack(msg.mid, msg.qos)
            if time.monotonic() - said[0] >= 10.0:
                said[0] = time.monotonic()
                log(f"refused: a message on {msg.topic[:80]!r}: {state['held']} messages of "
                    f"{state['bytes']} bytes wait already ([stream] queue_bytes = "
                    f"{lim.queue_bytes}, queue = {lim.queue}); {state['overflow']} refused so far")
            return
        inbox.put(_Message(state["connections"], msg.mid, msg.qos, msg.topic, msg.payload))

    client.on_connect = on_connect
    client.on_subscribe = on_subscribe
    client.on_disconnect = on_disconnect
    client.on_message = on_message

    def publish(event: WatchEvent) -> None:
        client.publish(STATUS_TOPIC.format(unit=event.unit), json.dumps(event.to_dict()),
                       qos=1, retain=True)
        if notify is not None:
            notify(event.to_dict())
        log(f"{event.unit}: {event.status}: {event.reason}")

    w = watcher or Watcher(store, model=model)
    w.halt = halt  # a stop ends a long batch within one step; the journal keeps the rest
    w.publish = publish
    w.log = log
    try:
        client.connect(host, port, keepalive=30)
    except OSError as exc:
        raise ConfigError(f"--mqtt {broker}: cannot reach the broker at {host}:{port} "
                          f"({exc})") from None
    ready: queue.Queue[tuple[str, bytes, int]] = queue.Queue()
    taking = threading.Event()  # set: the journal thread stops taking messages
    failed: list[BaseException] = []

    def release(payloads: list[bytes]) -> None:
        with count:
            state["bytes"] -= sum(len(p) for p in payloads)
            state["held"] -= len(payloads)

    def journal_loop() -> None:
        """Journal and acknowledge messages as they come, while the main thread
        steps the ones before: the broker's window of unacknowledged messages
        (20 by mosquitto's default) keeps moving, and the main thread takes
        many units' chunks in one step. At the stop, what waits is journaled
        too (what it holds is kept; what comes after is left to the broker)."""
        while True:
            stopping = taking.is_set()
            try:
                first = [inbox.get(timeout=0.1)] if not stopping else []
            except queue.Empty:
                continue
            batch = [*first, *_drain(inbox, inbox.qsize() if stopping else BATCH)]
            # a message of an earlier connection is not acknowledged: the broker
            # sends it again on this one (persistent session), and that copy is taken
            old = [m for m in batch if m.connection != state["connections"]]
            release([m.payload for m in old])
            batch = [m for m in batch if m.connection == state["connections"]]
            try:
                refs = book.add([(m.topic, m.payload) for m in batch])
            except CondmonError as exc:  # not acknowledged: the broker keeps them
                failed.append(exc)
                halt.set()
                return
            for m in batch:
                client.ack(m.mid, m.qos)
            for m, ref in zip(batch, refs):
                ready.put((m.topic, m.payload, ref))
            if stopping:
                return

    client.loop_start()
    previous = stop_on_signals(halt)
    started = time.monotonic()
    replayed = 0
    try:
        kept = list(book.pending())
        if kept:
            log(f"replaying {len(kept)} messages kept in the journal {book.path}")
        for k in range(0, len(kept), BATCH):
            _handle(w, [(topic, payload, ref) for ref, topic, payload in kept[k:k + BATCH]],
                    lim, log)
            book.done(_taken(w.finished))
            replayed += len(kept[k:k + BATCH])
        del kept
        journaling = threading.Thread(target=journal_loop, name="journal", daemon=True)
        journaling.start()
        while not halt.is_set():
            if duration is not None and time.monotonic() - started >= duration:
                break
            while outbox is not None and not outbox.empty():
                publish(outbox.get_nowait())
            try:
                first = ready.get(timeout=0.1)
            except queue.Empty:
                w.poll()
                book.done(_taken(w.finished))
                continue
            batch = [first, *_drain(ready, BATCH)]
            _handle(w, batch, lim, log)
            release([p for _, p, _ in batch])
            w.poll()
            book.done(_taken(w.finished))
        # the stop: nothing more is taken; what was journaled and not handled stays
        # in the journal, what was not journaled stays with the broker
        taking.set()
        journaling.join()
        w.close()
        book.done(_taken(w.finished))
        if failed:
            raise failed[0]
    finally:
        taking.set()
        halt.set()  # a stop, not a lost broker
        restore_signals(previous)
        client.disconnect()
        client.loop_stop()
        left = len(book)
        book.close()
    if left:
        log(f"{left} messages kept in the journal {book.path} for the next start "
            "(open tests and kept windows)")
    counters = w.counters
    counters.dropped += state["overflow"]
    return LiveSummary(counters, time.monotonic() - started, state["overflow"],
                       state["connections"], replayed, str(book.path))


@dataclass(frozen=True)
class _Message:
    """A message as received: its connection (acknowledged on that one only)."""

    connection: int
    mid: int
    qos: int
    topic: str
    payload: bytes


def _taken(finished: list[int]) -> list[int]:
    """Empty ``finished`` into a new list."""
    out = list(finished)
    finished.clear()
    return out


def _drain(inbox: queue.Queue[T], most: int) -> list[T]:
    """Up to ``most`` messages waiting in the queue (none: an empty list)."""
    out: list[T] = []
    while len(out) < most:
        try:
            out.append(inbox.get_nowait())
        except queue.Empty:
            break
    return out


def _handle(w: Watcher, messages: Sequence[tuple[str, bytes, int | None]], lim: StreamLimits,
            log: Callable[[str], None]) -> None:
    """Validate messages and hand the good ones to the watcher together; a
    message refused is done with (its journal row goes)."""
    chunks = []
    for topic, payload, ref in messages:
        try:
            chunks.append(replace(parse_chunk(topic, payload, lim), ref=ref))
        except Exception as exc:  # one message never takes the watcher down
            w.counters.received += 1
            w.counters.refused += 1
            log(f"refused: {exc}" if isinstance(exc, CondmonError) else
                f"refused: a message on {topic[:80]!r}: {type(exc).__name__}")
            if ref is not None:
                w.finished.append(ref)
    try:
        w.handle_many(chunks)
    except StoreError:
        raise
    except Exception as exc:  # handled per chunk inside; a last guard: the stream goes on
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
