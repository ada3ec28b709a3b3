"""The live view's front door: a client must offer the WebSocket subprotocol the server speaks.

Foxglove's SDK serves its WebSocket protocol under the subprotocol ``foxglove.sdk.v1``
(``Sec-WebSocket-Protocol``) and drops any other handshake with a bare "handshake failed",
logged once per attempt; the Foxglove app retries, so a client that offers another
subprotocol (``foxglove.websocket.v1``, the older protocol's name) fills the run's output and
learns nothing. The gate listens on the live view's port in front of the SDK's server (which
listens on the loopback only) and reads each connection's HTTP request head: a WebSocket
handshake offering :data:`SUBPROTOCOL` is handed to the SDK unchanged and then relayed both
ways; anything else is answered ``400 Bad Request`` with a body naming the subprotocol it
needs, and reported once per client (``on_refused``).
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from .._isolation.sched import start_side_work_thread

__all__ = ["SUBPROTOCOL", "Handshake", "SubprotocolGate", "describe_offer", "parse_head", "refusal"]

SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk 0.30's server accepts, and nothing else
HEAD_LIMIT = 16 * 1024  # bytes of request head read before a connection is refused as no handshake
HEAD_TIMEOUT = 5.0  # seconds a client may take to send its request head
CHUNK = 256 * 1024  # bytes relayed per read
DRAIN = 1.0  # seconds a closing gate lets its relays copy what the server sent last
QUIET = 0.2  # seconds the server must have sent its clients nothing before it is stopped (see settle)
SETTLE_LIMIT = 2.0  # seconds settle waits at most, however busy the server stays


@dataclass(frozen=True)
class Handshake:
    """What a connection's request head asks for."""

    websocket: bool  # an ``Upgrade: websocket`` request
    offered: tuple[str, ...]  # the subprotocols it offers, in its order

    @property
    def accepted(self) -> bool:
        """Whether the SDK's server will take it."""
        return self.websocket and SUBPROTOCOL in self.offered


def parse_head(head: bytes) -> Handshake:
    """The handshake an HTTP request head (up to its blank line) asks for; header names in any case."""
    websocket = False
    offered: list[str] = []
    for line in head.decode("latin-1").split("\r\n")[1:]:
        name, colon, value = line.partition(":")
        if not colon:
            continue
        name = name.strip().lower()
        if name == "upgrade":
            websocket = websocket or "websocket" in value.lower()
        elif name == "sec-websocket-protocol":
            offered.extend(p.strip() for p in value.split(",") if p.strip())
    return Handshake(websocket, tuple(offered))


def describe_offer(handshake: Handshake) -> str:
    """``the WebSocket subprotocol X``, ``no WebSocket subprotocol`` or ``a plain HTTP request``."""
    if not handshake.websocket:
        return "a plain HTTP request (no WebSocket handshake)"
    if not handshake.offered:
        return "no WebSocket subprotocol"
    plural = "s" if len(handshake.offered) > 1 else ""
    return f"the WebSocket subprotocol{plural} {', '.join(handshake.offered)}"


def refusal(handshake: Handshake) -> bytes:
    """The HTTP response to a connection the SDK would drop: 400, and a body that says why."""
    body = (f"This is anodize's live view for the Foxglove app. It speaks the WebSocket subprotocol {SUBPROTOCOL} "
            f"(Sec-WebSocket-Protocol: {SUBPROTOCOL}); the client offered {describe_offer(handshake)}. Connect with "
            f"a Foxglove app or client that offers {SUBPROTOCOL}.\n").encode()
    head = ("HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain; charset=utf-8\r\n"
            f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n").encode()
    return head + body


class SubprotocolGate:
    """Listens on ``host:port`` and relays the accepted handshakes to the server on ``backend``.

    Args:
        host, port: where the live view serves (0: any free port; see ``port``).
        backend: the SDK server's ``(host, port)``.
        on_refused: called with the client's address and its handshake for each refused one.
        lower: called first in each of the gate's threads (side work: below every group).

    Raises:
        OSError: the address cannot be had.
    """

    def __init__(self, host: str, port: int, backend: tuple[str, int],
                 on_refused: Callable[[str, Handshake], None], lower: Callable[[], None]) -> None:
        self._listener = socket.create_server((host, port))
        self.port: int = self._listener.getsockname()[1]
        self._backend = backend
        self._on_refused = on_refused
        self._lower = lower
        self._lock = threading.Lock()
        self._drained = threading.Condition(self._lock)
        self._open: set[socket.socket] = set()
        self._closed = False
        self._last_out = 0.0  # time.monotonic() when a relay last copied the server's bytes to a client
        threading.Thread(target=self._accept_loop, name="anodize-live-gate", daemon=True).start()

    def settle(self, quiet: float = QUIET, limit: float = SETTLE_LIMIT) -> None:
        """Wait until the server behind has sent its clients nothing for ``quiet`` seconds since this
        call (at most ``limit``); no wait without a client.

        The SDK's server drops what it has queued for a client and not yet written when it is
        stopped, and its writer is side work that a busy machine may not have run yet: the
        view settles the gate after handing over its last messages and before it stops the server.
        """
        with self._lock:
            relaying = bool(self._open)
        if not relaying:
            return
        start = time.monotonic()
        while (now := time.monotonic()) - start < limit:
            idle = now - max(start, self._last_out)
            if idle >= quiet:
                return
            time.sleep(min(quiet - idle, limit - (now - start)))

    def close(self, drain: float = DRAIN) -> None:
        """Stop listening, let the relays copy what is in flight (up to ``drain`` seconds: the
        server behind is stopped first, so each relay meets its end), then end the rest."""
        with self._lock:
            self._closed = True
        with contextlib.suppress(OSError):
            self._listener.shutdown(socket.SHUT_RDWR)
        self._listener.close()
        deadline = time.monotonic() + drain
        with self._drained:
            while self._open and time.monotonic() < deadline:
                self._drained.wait(max(0.0, deadline - time.monotonic()))
            open_ = list(self._open)
        for sock in open_:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)

    def _keep(self, sock: socket.socket) -> bool:
        with self._lock:
            if not self._closed:
                self._open.add(sock)
            return not self._closed

    def _drop(self, sock: socket.socket) -> None:
        with self._lock:
            self._open.discard(sock)
            self._drained.notify_all()
        sock.close()

    def _accept_loop(self) -> None:
        self._lower()
        while True:
            try:
                client, address = self._listener.accept()
            except OSError:  # closed
                return
            start_side_work_thread(self._serve, "anodize-live-gate-client", (client, str(address[0])))

    def _serve(self, client: socket.socket, address: str) -> None:
        self._lower()
        if not self._keep(client):
            client.close()
            return
        server: socket.socket | None = None
        relaying = False
        try:
            head = _read_head(client)
            if head is None:
                return
            handshake = parse_head(head)
            if not handshake.accepted:
                with contextlib.suppress(OSError):
                    client.sendall(refusal(handshake))
                self._on_refused(address, handshake)
                return
            server = socket.create_connection(self._backend, timeout=HEAD_TIMEOUT)
            server.settimeout(None)
            client.settimeout(None)
            if not self._keep(server):
                return
            start_side_work_thread(self._relay, "anodize-live-gate-relay", (server, client, b"", True))
            relaying = True
        except OSError:  # the client went away, or the SDK's server is gone (the view is closing)
            return
        finally:
            if not relaying:
                if server is not None:
                    self._drop(server)
                self._drop(client)
        self._relay(client, server, head)

    def _relay(self, source: socket.socket, sink: socket.socket, first: bytes, to_client: bool = False) -> None:
        """Copy ``source`` to ``sink`` until either ends; then end both (the other relay stops too)."""
        self._lower()
        try:
            if first:
                sink.sendall(first)
            while data := source.recv(CHUNK):
                sink.sendall(data)
                if to_client:
                    self._last_out = time.monotonic()
        except OSError:
            pass
        finally:
            for sock in (source, sink):
                with contextlib.suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
            self._drop(source)


def _read_head(client: socket.socket) -> bytes | None:
    """The bytes of the request up to and including its blank line (with anything read past it),
    or None when the client sends none within ``HEAD_TIMEOUT`` or ``HEAD_LIMIT``."""
    client.settimeout(HEAD_TIMEOUT)
    head = b""
    while b"\r\n\r\n" not in head:
        if len(head) >= HEAD_LIMIT:
            return None
        try:
            data = client.recv(HEAD_LIMIT)
        except OSError:
            return None
        if not data:
            return None
        head += data
    return head
