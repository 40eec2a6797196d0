"""Webhook notifications: each event POSTed as JSON, with retries, never blocking the stream.

``condmon watch --notify URL`` hands every event to a :class:`Notifier`. The
stream only puts the event in a bounded queue (a full queue drops it and counts
it); one background thread posts, retrying a failed post (a connection error,
a timeout or a 5xx answer) with a doubling delay, and gives up after
``retries`` attempts, counting it (a 4xx answer is not retried). Each attempt
has a total deadline, ``timeout``, whatever the server does (one that trickles
a byte every few seconds is cut at it), so an event takes at most ``retries``
deadlines and the backoffs. A slow or dead webhook therefore never holds the
stream back, and never grows memory without limit. Every event is counted once:
posted, given up, dropped for a full queue, or left at the stop.

The URL is checked when the notifier is made. ``user:password@`` in it is sent
as HTTP basic authentication and shown as ``user:***@`` everywhere.
"""

from __future__ import annotations

import base64
import http.client
import json
import queue
import re
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from condmon.errors import ConfigError

__all__ = ["Notifier", "shown_url"]


def shown_url(url: str) -> str:
    """``url`` with its credentials hidden, for logs and summaries.

    Example
    -------
    >>> shown_url("https://ops:s3cret@hooks.example/x"), shown_url("http://token@h/x")
    ('https://ops:***@hooks.example/x', 'http://***@h/x')
    """
    from urllib.parse import urlsplit, urlunsplit

    try:
        parts = urlsplit(url)
    except ValueError:  # a broken address: hide whatever stands before an @
        return re.sub(r"//[^/@]*@", "//***@", url)
    if "@" not in parts.netloc:
        return url
    userinfo, _, where = parts.netloc.rpartition("@")
    user, colon, _ = userinfo.partition(":")
    return urlunsplit(parts._replace(netloc=f"{user + ':***' if colon else '***'}@{where}"))


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
        One attempt's total deadline. [s]
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
    left: int = 0
    _queue: queue.Queue[dict[str, Any] | None] = field(init=False, repr=False)
    _thread: threading.Thread = field(init=False, repr=False)
    _target: tuple[str, str, int, str, dict[str, str]] = field(init=False, repr=False)
    _quit: threading.Event = field(default_factory=threading.Event, repr=False)

    def __post_init__(self) -> None:
        from urllib.parse import unquote, urlsplit

        how = ("give an http:// or https:// URL with a host and, if any, a port number "
               "(http://host:port/path)")
        try:
            parts = urlsplit(self.url)
            port = parts.port
            host = parts.hostname
        except ValueError as exc:  # a port that is not a number, a broken [IPv6] address
            raise ConfigError(f"--notify {shown_url(self.url)!r}: {exc}; {how}") from None
        if parts.scheme not in ("http", "https") or not host:
            raise ConfigError(f"--notify {shown_url(self.url)!r}: {how}")
        headers = {"Content-Type": "application/json"}
        if parts.username is not None:
            pair = f"{unquote(parts.username)}:{unquote(parts.password or '')}"
            headers["Authorization"] = "Basic " + base64.b64encode(pair.encode()).decode()
        path = (parts.path or "/") + (f"?{parts.query}" if parts.query else "")
        self._target = (parts.scheme, host, port or (443 if parts.scheme == "https" else 80),
                        path, headers)
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
        """Post what is queued within ``wait`` seconds, then stop; the events still
        waiting then are counted in ``left``."""
        deadline = time.monotonic() + wait
        while not self._queue.empty() and time.monotonic() < deadline \
                and self._thread.is_alive():
            time.sleep(0.05)
        self._quit.set()  # the attempt under way ends at its deadline; no more begin
        while True:
            try:
                if self._queue.get_nowait() is not None:
                    self.left += 1
            except queue.Empty:
                break
        self._queue.put(None)
        self._thread.join(self.timeout + 1.0)

    def _run(self) -> None:
        while True:
            event = self._queue.get()
            if event is None:
                return
            if self._quit.is_set():
                self.left += 1
            elif self._post(event):
                self.sent += 1
            else:
                self.failed += 1
                self.log(f"webhook {shown_url(self.url)}: gave up on the event of "
                         f"{event.get('unit', '?')} after {self.retries} attempts")

    def _post(self, event: dict[str, Any]) -> bool:
        body = json.dumps(event).encode()
        delay = self.backoff
        for attempt in range(self.retries):
            status = self._attempt(body)
            if status is not None and status < 500:
                return status < 400  # a 4xx is the hook's refusal: sending again changes nothing
            if attempt + 1 < self.retries and not self._quit.wait(delay):
                delay *= 2
                continue
            break
        return False

    def _attempt(self, body: bytes) -> int | None:
        """One POST within ``timeout`` in all; its status (None: no answer).

        http.client's own timeout is per socket operation; a deadline timer
        shuts the socket down so a server that trickles bytes is cut too."""
        scheme, host, port, path, headers = self._target
        kind = http.client.HTTPSConnection if scheme == "https" else http.client.HTTPConnection
        conn = kind(host, port, timeout=self.timeout)
        timer = threading.Timer(self.timeout, _cut, args=(conn,))
        timer.start()
        try:
            conn.request("POST", path, body=body, headers=headers)
            resp = conn.getresponse()
            resp.read(65536)
            return int(resp.status)
        except (OSError, http.client.HTTPException, ValueError):
            return None
        finally:
            timer.cancel()
            conn.close()


def _cut(conn: http.client.HTTPConnection) -> None:
    """End an attempt past its deadline: shut its socket down (a blocked read returns)."""
    sock = conn.sock
    if sock is not None:
        try:
            sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
