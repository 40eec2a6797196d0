"""The webhook notifier against servers and URLs that once broke it: a port
that is not a number, a broken IPv6 address, a server that trickles a byte
every few seconds, one that never answers, and credentials in the URL."""

from __future__ import annotations

import base64
import socket
import threading
import time
from collections.abc import Iterator

import pytest

from condmon.errors import ConfigError
from condmon.workflows.notify import Notifier, shown_url


@pytest.mark.parametrize("url,why", [
    ("http://127.0.0.1:http/hook", "Port could not be cast to integer value"),
    ("http://[::1/hook", "Invalid IPv6 URL"),
    ("ftp://host/hook", "give an http:// or https:// URL"),
    ("http:///hook", "give an http:// or https:// URL"),
])
def test_a_url_that_cannot_be_posted_to_is_refused_at_start(url: str, why: str) -> None:
    with pytest.raises(ConfigError, match=why):
        Notifier(url)


class _Server:
    """A TCP server that reads a request and then does ``behaviour``."""

    def __init__(self, behaviour: str) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(64)
        self.url = f"http://127.0.0.1:{self.sock.getsockname()[1]}/hook"
        self.requests: list[bytes] = []
        self.behaviour = behaviour
        self.halt = threading.Event()
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while not self.halt.is_set():
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            threading.Thread(target=self._one, args=(conn,), daemon=True).start()

    def _one(self, conn: socket.socket) -> None:
        with conn:
            conn.settimeout(5)
            try:
                self.requests.append(conn.recv(65536))
                if self.behaviour == "trickle":  # a status line, one byte every 0.4 s
                    for byte in b"HTTP/1.1 200 OK\r\nContent-Length: 0\r\n\r\n":
                        if self.halt.wait(0.4):
                            return
                        conn.sendall(bytes([byte]))
                elif self.behaviour == "silent":
                    self.halt.wait(30)
                else:
                    conn.sendall(b"HTTP/1.1 200 OK\r\nContent-Length: 0\r\n\r\n")
            except OSError:
                pass

    def close(self) -> None:
        self.halt.set()
        self.sock.close()


@pytest.fixture
def server(request: pytest.FixtureRequest) -> Iterator[_Server]:
    s = _Server(request.param)
    yield s
    s.close()


@pytest.mark.parametrize("server", ["trickle"], indirect=True)
def test_a_server_that_trickles_is_cut_at_the_deadline(server: _Server) -> None:
    n = Notifier(server.url, retries=1, timeout=0.5, backoff=0.05)
    started = time.monotonic()
    n.send({"unit": "U1"})
    n.close(wait=5)
    # a byte every 0.4 s kept the old per-read timeout (0.5 s) from ever firing
    assert time.monotonic() - started < 3.0
    assert (n.sent, n.failed, n.left) == (0, 1, 0)


@pytest.mark.parametrize("server", ["silent"], indirect=True)
def test_every_event_is_counted_when_the_server_never_answers(server: _Server) -> None:
    n = Notifier(server.url, retries=2, timeout=0.2, backoff=0.05)
    for i in range(50):
        n.send({"unit": f"U{i}"})
    n.close(wait=1.0)
    assert n.sent + n.failed + n.dropped + n.left == 50
    assert n.left > 0 and n.failed >= 1


@pytest.mark.parametrize("server", ["answer"], indirect=True)
def test_credentials_are_sent_as_basic_auth_and_never_shown(server: _Server) -> None:
    url = server.url.replace("http://", "http://ops:s3cret@")
    lines: list[str] = []
    n = Notifier(url, log=lines.append)
    n.send({"unit": "U1"})
    n.close()
    assert n.sent == 1
    expected = base64.b64encode(b"ops:s3cret").decode()
    assert f"Authorization: Basic {expected}".encode() in server.requests[0]
    assert shown_url(url) == server.url.replace("http://", "http://ops:***@")
    with pytest.raises(ConfigError) as err:
        Notifier("http://ops:s3cret@[::1/hook")
    assert "s3cret" not in str(err.value)
