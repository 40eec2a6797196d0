"""Webhook notifications: each event POSTed as JSON, with retries, never blocking the stream.

``condmon watch --notify URL`` hands every event to a :class:`Notifier`. The
stream only puts the event in a bounded queue (a full queue drops it and counts
it); one background thread posts, retrying a failed post (a connection error,
a timeout or a 5xx answer) with a doubling delay, and gives up after
``retries`` attempts, counting it (a 4xx answer is not retried). A slow or dead webhook therefore never holds
the stream back, and never grows memory without limit.
"""

from __future__ import annotations

import json
import queue
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from condmon.errors import ConfigError

__all__ = ["Notifier"]


@dataclass
class Notifier:
    """POST events to ``url`` from a background thread.

    Parameters
    ----------
    url : str
        The webhook (``http://`` or ``https://``).
    maxsize : int
        Events waiting at most; beyond, new ones are dropped and counted.
    retries : int
        Attempts per event.
    timeout : float
        Per attempt. [s]
    backoff : float
        Delay before the second attempt, doubled each time after. [s]
    log : callable
        Takes a line for each event given up.

    Example
    -------
    >>> n = Notifier("http://127.0.0.1:9/hook", retries=1, timeout=0.2)  # nobody listens
    >>> n.send({"unit": "U1", "status": "no-go"})
    True
    >>> n.close(); (n.sent, n.failed)
    (0, 1)
    """

    url: str
    maxsize: int = 1000
    retries: int = 3
    timeout: float = 5.0
    backoff: float = 0.5
    log: Callable[[str], None] = lambda line: None
    sent: int = 0
    failed: int = 0
    dropped: int = 0
    _queue: queue.Queue[dict[str, Any] | None] = field(init=False, repr=False)
    _thread: threading.Thread = field(init=False, repr=False)

    def __post_init__(self) -> None:
        from urllib.parse import urlsplit

        parts = urlsplit(self.url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ConfigError(f"--notify {self.url!r}: give an http:// or https:// URL with "
                              "a host (http://host:port/path)")
        self._queue = queue.Queue(maxsize=self.maxsize)
        self._thread = threading.Thread(target=self._run, name="notify", daemon=True)
        self._thread.start()

    def send(self, event: dict[str, Any]) -> bool:
        """Queue one event; False (and counted) when the queue is full."""
        try:
            self._queue.put_nowait(event)
            return True
        except queue.Full:
            self.dropped += 1
            return False

    def close(self, wait: float = 30.0) -> None:
        """Post what is queued (within ``wait`` seconds), then stop."""
        try:
            self._queue.put(None, timeout=wait)
        except queue.Full:
            return
        self._thread.join(wait)

    def _run(self) -> None:
        while True:
            event = self._queue.get()
            if event is None:
                return
            if self._post(event):
                self.sent += 1
            else:
                self.failed += 1
                self.log(f"webhook {self.url}: gave up on the event of "
                         f"{event.get('unit', '?')} after {self.retries} attempts")

    def _post(self, event: dict[str, Any]) -> bool:
        body = json.dumps(event).encode()
        delay = self.backoff
        for attempt in range(self.retries):
            req = urllib.request.Request(self.url, data=body, method="POST",
                                         headers={"Content-Type": "application/json"})
            try:
                with urllib.request.urlopen(req, timeout=self.timeout) as resp:  # noqa: S310
                    if resp.status < 500:
                        return True
            except urllib.error.HTTPError as exc:
                if exc.code < 500:
                    return False  # the hook refused the event: sending it again changes nothing
            except (urllib.error.URLError, OSError, TimeoutError):
                pass
            if attempt + 1 < self.retries:
                time.sleep(delay)
                delay *= 2
        return False
