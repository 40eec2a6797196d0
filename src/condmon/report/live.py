"""The fleet page's live feed: unit statuses from the broker, pushed to browsers.

``condmon serve --mqtt HOST:PORT`` keeps a :class:`LiveFeed`: an MQTT client
(paho-mqtt) subscribed to ``condmon/+/status`` (each unit's last status,
retained by the broker, arrives at once; every change after it) and to
``condmon/+/samples`` (only the arrival time is noted, the payload is not
read). A unit silent for longer than ``stale_after`` seconds is ``stale``
until its samples arrive again. Every change is numbered; the page's
``/api/events`` streams them to the browser as server-sent events, and the
page redraws its table at once, without a reload.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from condmon.errors import ConfigError, DataError
from condmon.io.stream import StreamLimits, unit_of_topic
from condmon.store.states import STATUS_ORDER

__all__ = ["LiveFeed", "with_live"]

STATUS = "condmon/+/status"
SAMPLES = "condmon/+/samples"
#: A status message's statuses: the history's and the watcher's own.
STATUSES = frozenset(STATUS_ORDER) | {"baseline"}
KINDS = frozenset({"watching", "detected", "isolated", "checked", "baseline"})
MAX_REASON = 500  # characters of a status's reason kept


def valid_status(unit: str, doc: Any) -> dict[str, Any] | None:
    """A status message as the page may show it, or None when it is not one
    (another tool, or a hostile client, may publish anything retained).

    Example
    -------
    >>> valid_status("U1", {"unit": "U1", "status": 7}) is None
    True
    >>> valid_status("U1", {"unit": "U1", "status": "go", "t": 1e999})["t"] is None
    True
    """
    if not isinstance(doc, dict) or doc.get("unit") != unit:
        return None
    status, kind = doc.get("status"), doc.get("kind")
    if not isinstance(status, str) or status not in STATUSES or (
            kind is not None and (not isinstance(kind, str) or kind not in KINDS)):
        return None
    isolated = doc.get("isolated")
    if isolated is not None and not (isinstance(isolated, list) and len(isolated) <= 64
                                     and all(isinstance(p, str) for p in isolated)):
        return None
    reason, when, t = doc.get("reason"), doc.get("time"), doc.get("t")
    return {"unit": unit, "status": status,
            "time": when[:40] if isinstance(when, str) else None,
            "reason": reason[:MAX_REASON] if isinstance(reason, str) else "",
            "isolated": [p[:64] for p in isolated] if isolated else [],
            "kind": kind,
            "t": float(t) if isinstance(t, (int, float)) and not isinstance(t, bool)
            and abs(t) < 1e300 else None}


@dataclass
class LiveFeed:
    """Each unit's live status, from the broker.

    Parameters
    ----------
    broker : str
        ``HOST:PORT`` of the MQTT broker.
    stale_after : float
        A unit silent this long is stale. [s]
    log : callable
        Takes log lines (connection lost, back).

    Example
    -------
    >>> feed = LiveFeed.offline(stale_after=30.0)   # no broker: fed by hand
    >>> feed.take("condmon/U1/status", b'{"unit": "U1", "status": "no-go", "reason": "x"}')
    >>> feed.status("U1")["status"], feed.version
    ('no-go', 1)
    """

    broker: str
    stale_after: float = 30.0
    log: Callable[[str], None] = lambda line: None
    max_units: int = field(default_factory=lambda: StreamLimits.shipped().max_units)
    version: int = 0
    refused: int = 0
    _state: dict[str, dict[str, Any]] = field(default_factory=dict, repr=False)
    _seen: dict[str, float] = field(default_factory=dict, repr=False)
    _sampled: dict[str, float] = field(default_factory=dict, repr=False)   # wall clock [s]
    _started: float = field(default_factory=time.time, repr=False)         # wall clock [s]
    _changes: list[tuple[int, dict[str, Any]]] = field(default_factory=list, repr=False)
    _cond: threading.Condition = field(default_factory=threading.Condition, repr=False)
    _client: Any = field(default=None, repr=False)
    _halt: threading.Event = field(default_factory=threading.Event, repr=False)

    @classmethod
    def offline(cls, stale_after: float = 30.0) -> LiveFeed:
        """A feed with no broker (tests, or a page fed by :meth:`take`)."""
        return cls("", stale_after)

    def start(self) -> LiveFeed:
        """Connect (reconnecting with backoff when the broker is lost) and watch staleness."""
        import paho.mqtt.client as mqtt
        from paho.mqtt.enums import CallbackAPIVersion

        from condmon.io.stream import parse_broker

        host, port = parse_broker(self.broker)
        client = mqtt.Client(CallbackAPIVersion.VERSION2)
        client.reconnect_delay_set(1, 30)

        def on_connect(c: Any, userdata: Any, flags: Any, reason: Any, props: Any) -> None:
            c.subscribe([(STATUS, 1), (SAMPLES, 0)])
            self.log(f"live feed: connected to {host}:{port}")

        def on_disconnect(c: Any, userdata: Any, flags: Any, reason: Any, props: Any) -> None:
            if not self._halt.is_set():
                self.log(f"live feed: lost the broker {host}:{port} ({reason}); reconnecting")

        client.on_connect = on_connect
        client.on_disconnect = on_disconnect
        client.on_message = lambda c, userdata, msg: self.take(msg.topic, bytes(msg.payload))
        try:
            client.connect(host, port, keepalive=30)
        except OSError as exc:
            raise ConfigError(f"--mqtt {self.broker}: cannot reach the broker ({exc})") from None
        client.loop_start()
        self._client = client
        threading.Thread(target=self._watch_staleness, name="stale", daemon=True).start()
        return self

    def stop(self) -> None:
        """Disconnect."""
        self._halt.set()
        if self._client is not None:
            self._client.loop_stop()
            self._client.disconnect()

    def take(self, topic: str, payload: bytes) -> None:
        """One message from the broker (a status, or a chunk's arrival); one that
        is not a valid status of a valid unit name, or a new unit past
        ``max_units``, is refused and counted (said once per 1,000)."""
        parts = topic.split("/")
        if len(parts) != 3 or parts[2] not in ("samples", "status"):
            return
        unit, kind = parts[1], parts[2]
        try:
            unit_of_topic(f"condmon/{unit}/samples")
        except DataError:
            return self._refuse(f"topic {topic[:80]!r}: not a unit name")
        if unit not in self._seen and len(self._seen) >= self.max_units:
            return self._refuse(f"unit {unit!r}: the page follows {self.max_units} units "
                                "already ([stream] max_units)")
        if kind == "samples":
            self._seen[unit] = time.monotonic()
            self._sampled[unit] = time.time()
            last = self._state.get(unit)
            if last is not None and last.get("status") == "stale":
                self._change(unit, dict(last.get("was") or {"unit": unit, "status": "go"}))
            return
        try:
            doc = valid_status(unit, json.loads(payload))
        except (ValueError, RecursionError):
            doc = None
        if doc is None:
            return self._refuse(f"{topic[:80]}: not a status message of condmon watch")
        self._seen.setdefault(unit, time.monotonic())
        self._change(unit, doc)

    def _refuse(self, why: str) -> None:
        self.refused += 1
        if self.refused % 1000 == 1:
            self.log(f"live feed: refused {why}" + (f" ({self.refused} refused so far)"
                                                    if self.refused > 1 else ""))

    def status(self, unit: str) -> dict[str, Any] | None:
        """The unit's live status (None: never heard of)."""
        with self._cond:
            return dict(self._state[unit]) if unit in self._state else None

    def statuses(self) -> dict[str, dict[str, Any]]:
        """Every unit's live status."""
        with self._cond:
            return {u: dict(s) for u, s in self._state.items()}

    def changes(self, after: int, timeout: float) -> list[tuple[int, dict[str, Any]]]:
        """The changes numbered after ``after``, waiting up to ``timeout`` s for one."""
        with self._cond:
            if self.version <= after:
                self._cond.wait(timeout)
            return [(v, dict(d)) for v, d in self._changes if v > after]

    def _change(self, unit: str, doc: dict[str, Any]) -> None:
        with self._cond:
            self.version += 1
            self._state[unit] = doc
            self._changes.append((self.version, doc))
            del self._changes[:-1000]   # a browser further behind redraws the whole table
            self._cond.notify_all()

    def _watch_staleness(self) -> None:
        while not self._halt.wait(min(1.0, self.stale_after / 4)):
            self.mark_stale(time.monotonic())

    def _silent_since(self, unit: str) -> str:
        """Since when a unit sent no samples: its last sample's arrival, or,
        for a unit only its retained status was heard of, the page's start
        (the last sample before it is not known)."""
        if unit in self._sampled:
            return f"no samples since {_utc(self._sampled[unit])}"
        return (f"no samples since this page started at {_utc(self._started)} (the last "
                "one before is not known)")

    def mark_stale(self, now: float) -> None:
        """Mark units silent since before ``now - stale_after`` as stale."""
        for unit, seen in list(self._seen.items()):
            last = self._state.get(unit)
            if now - seen > self.stale_after and last is not None \
                    and last.get("status") != "stale":
                self._change(unit, {"unit": unit, "status": "stale", "was": last,
                                    "reason": f"{self._silent_since(unit)} (stale after "
                                              f"{self.stale_after:g} s); last: "
                                              f"{last.get('status')}",
                                    "time": None, "isolated": last.get("isolated"),
                                    "kind": "stale", "t": None})


def _utc(stamp: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(stamp))


def with_live(units: list[dict[str, Any]], live: LiveFeed | None) -> list[dict[str, Any]]:
    """Unit summaries (:meth:`HistoryStore.unit_summaries`) with each unit's live
    status, when the feed has one, over the history's latest.

    Example
    -------
    >>> feed = LiveFeed.offline()
    >>> feed.take("condmon/U1/status", b'{"unit": "U1", "status": "no-go", "reason": "r"}')
    >>> with_live([{"unit": "U1", "status": "go", "summary": "ok"}], feed)[0]["status"]
    'no-go'
    """
    if live is None:
        return units
    states = live.statuses()
    out = []
    for u in units:
        s = states.get(str(u["unit"]))
        if s is not None and s.get("status"):
            u = {**u, "status": s["status"], "summary": s.get("reason") or u.get("summary"),
                 "live": True}
        out.append(u)
    return out
