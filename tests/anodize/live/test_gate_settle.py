"""Before the live view stops the SDK's server, the gate waits until the server has stopped sending.

The SDK drops what it has queued for a client and not yet written when its server stops;
its writer is side work, which a busy machine may run late. ``SubprotocolGate.settle``
waits (bounded) until the server behind has sent its clients nothing for a while, counted
from the call: what the view handed over last is written out first.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Iterator

from anodize._live.gate import SUBPROTOCOL, SubprotocolGate

CHUNKS = 10
HEAD = (f"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Protocol: {SUBPROTOCOL}\r\n\r\n").encode()


class TrickleServer:
    """A backend that answers a request head with :data:`CHUNKS` chunks, ``every`` seconds apart."""

    def __init__(self, every: float) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.address = ("127.0.0.1", int(self.listener.getsockname()[1]))
        self.every = every
        self.sent = 0
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        connection, _ = self.listener.accept()
        with connection:
            head = b""
            while b"\r\n\r\n" not in head:
                head += connection.recv(4096)
            for _ in range(CHUNKS):
                connection.sendall(b"x" * 100)
                self.sent += 1
                time.sleep(self.every)
            time.sleep(30.0)  # holds the connection open: the relay is still there when the test settles

    def close(self) -> None:
        self.listener.close()


@contextlib.contextmanager
def _gate(client: bool) -> Iterator[tuple[TrickleServer, SubprotocolGate]]:
    """A gate before a trickling server; with ``client``, one connected whose first bytes came."""
    server = TrickleServer(every=0.02)
    gate = SubprotocolGate("127.0.0.1", 0, server.address, lambda *_: None, lambda: None)
    try:
        if not client:
            yield server, gate
            return
        with socket.create_connection(("127.0.0.1", gate.port), timeout=10.0) as connection:
            connection.sendall(HEAD)
            assert connection.recv(100)  # the server has begun; it sends for about 0.2 s more
            yield server, gate
    finally:
        gate.close(drain=0.0)
        server.close()


def test_settle_waits_until_the_server_has_sent_its_clients_everything() -> None:
    with _gate(client=True) as (server, gate):
        gate.settle(quiet=2.0, limit=30.0)  # 2 s: a busy machine may run the server's thread late
        assert server.sent == CHUNKS  # settle returned only once the server had stopped sending


def test_settle_is_bounded_by_its_limit() -> None:
    with _gate(client=True) as (_, gate):
        began = time.monotonic()
        gate.settle(quiet=60.0, limit=0.5)  # never 60 s quiet after the call: the limit ends the wait
        assert time.monotonic() - began < 30.0


def test_settle_does_not_wait_without_a_client() -> None:
    with _gate(client=False) as (_, gate):
        began = time.monotonic()
        gate.settle(quiet=30.0, limit=60.0)
        assert time.monotonic() - began < 30.0  # nobody to write to: it returns at once
