"""A client watching labels of a running system (``anodize echo|hz``): bounded, never waited for.

The threads that read the groups' taps hand a watcher each message of its labels
(:meth:`Watcher.offer`: a lock, never a wait); the watcher's own thread decodes them and
writes them to its client, one JSON line each, with a beat every :data:`BEAT_EVERY`
seconds saying how many were dropped. A client that reads slowly (or never) fills its
socket, then its watcher's queue of :data:`QUEUE` messages, whose OLDEST then go, counted:
it blocks nothing but its own thread.
"""

from __future__ import annotations

import json
import socket
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence

from .._isolation.sched import side_work_priority
from .._recording.encoding import SortCodec
from .summary import summarize
from .tap import WANT_MESSAGES

__all__ = ["Watcher", "QUEUE", "BEAT_EVERY"]

QUEUE = 1024       # messages a watcher holds for its client at most
BEAT_EVERY = 1.0   # seconds between two beats (the drop count; how a client knows the run lives)


class Watcher:
    """One client's watch of some labels: ``mode`` is :data:`~.tap.WANT_MESSAGES` (echo) or
    :data:`~.tap.WANT_TIMES` (hz).

    Attributes:
        dropped: messages that went unsent because the client was behind.
        sent: messages written to the client.
    """

    def __init__(self, sock: socket.socket, mode: int, names: Sequence[str], codecs: Sequence[SortCodec],
                 tap_losses: Callable[[], int]) -> None:
        self.sock = sock
        self.mode = mode
        self.names = names    # by label index: "Sender->Receiver:label"
        self.codecs = codecs  # by label index
        self._tap_losses = tap_losses  # what the groups' taps did not forward of these labels, so far
        self._queue: deque[tuple[int, int, bytes]] = deque()
        self._ready = threading.Condition()
        self.dropped = 0
        self.sent = 0
        self.closed = False

    def offer(self, index: int, stamp: int, data: bytes) -> None:
        """A message (``data`` empty: only its time) of a watched label; never waits for the client."""
        if self.mode == WANT_MESSAGES and not data:
            return  # a thinned message's time: for rates, not for echo
        with self._ready:
            if len(self._queue) >= QUEUE:
                self._queue.popleft()
                self.dropped += 1
            self._queue.append((index, stamp, data))
            self._ready.notify()

    def close(self) -> None:
        """Stop: the run is over, or the client went away."""
        with self._ready:
            self.closed = True
            self._ready.notify()

    def serve(self) -> None:
        """Write what comes to the client until it goes away or :meth:`close`; returns then."""
        side_work_priority()
        baseline = self._tap_losses()
        beat_at = time.monotonic() + BEAT_EVERY
        try:
            while True:
                with self._ready:
                    if not self._queue and not self.closed:
                        self._ready.wait(max(0.0, beat_at - time.monotonic()))
                    taken = list(self._queue)
                    self._queue.clear()
                    closed = self.closed
                lines = [self._line(index, stamp, data) for index, stamp, data in taken]
                if time.monotonic() >= beat_at or closed:
                    lost = self.dropped + max(0, self._tap_losses() - baseline)
                    lines.append(json.dumps({"beat": time.time_ns(), "dropped": lost, "ended": closed}))
                    beat_at = time.monotonic() + BEAT_EVERY
                if lines:
                    self.sock.sendall(("\n".join(lines) + "\n").encode())
                    self.sent += len(taken)
                if closed:
                    return
        except OSError:  # the client went away
            self.closed = True

    def _line(self, index: int, stamp: int, data: bytes) -> str:
        found: dict[str, object] = {"channel": self.names[index], "stamp": stamp}
        if self.mode == WANT_MESSAGES:
            try:
                found["message"] = summarize(self.codecs[index].decode(data))
            except Exception as error:  # what a group sent is not ours to trust: say so, go on
                found["error"] = f"{type(error).__name__}: {error}"
        return json.dumps(found, default=str)
