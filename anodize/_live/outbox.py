"""What the live view's server has taken from the groups and not yet handed to Foxglove.

The threads that read the groups' taps put messages here and never wait; one thread of
the server, at the side-work priority, takes them out and hands them to the
Foxglove SDK (which gives each client its own bounded queue). The outbox is bounded in
bytes: a large message (an image) waits in its label's one slot, where a newer one
replaces it; small ones wait in one queue. When the bound is reached the OLDEST message
goes: a live view shows the present, and a stale image or pose is worth less than the
one that replaces it. Every message that goes is counted, per label. (The batch the publisher has taken
and is handing on is outside the bound: the server holds at most twice it.)
"""

from __future__ import annotations

import threading
from collections import deque

__all__ = ["Outbox", "OUTBOX_BYTES"]

OUTBOX_BYTES = 32 * 2**20  # bytes the server holds for Foxglove at most, whatever the clients do


class Outbox:
    """A bounded, never-waiting hand-over of ``(label index, time, bytes)``.

    Attributes:
        dropped: label index -> messages that went unshown because the outbox was full.
        peak: the most bytes it ever held.
    """

    def __init__(self, limit: int = OUTBOX_BYTES, large: int = 4096) -> None:
        self.limit = limit
        self.large = large
        self._small: deque[tuple[int, int, bytes]] = deque()
        self._slots: dict[int, tuple[int, bytes]] = {}  # a large message per label: the newest
        self._bytes = 0
        self._ready = threading.Condition()
        self.dropped: dict[int, int] = {}
        self.peak = 0
        self._closed = False

    @property
    def held(self) -> int:
        """The bytes waiting now."""
        return self._bytes

    def put(self, index: int, stamp: int, data: bytes) -> None:
        """Leave a message for the publisher: O(1), never blocks for long (a lock, never a wait)."""
        with self._ready:
            if len(data) > self.large:
                older = self._slots.pop(index, None)
                if older is not None:
                    self._drop(index, len(older[1]))
                self._slots[index] = (stamp, data)
            else:
                self._small.append((index, stamp, data))
            self._bytes += len(data)
            while self._bytes > self.limit:
                self._drop_oldest()
            self.peak = max(self.peak, self._bytes)
            self._ready.notify()

    def _drop_oldest(self) -> None:
        if self._small:
            index, _, data = self._small.popleft()
        else:  # only large ones left: the oldest of them
            index = min(self._slots, key=lambda i: self._slots[i][0])
            data = self._slots.pop(index)[1]
        self._drop(index, len(data))

    def _drop(self, index: int, size: int) -> None:
        self.dropped[index] = self.dropped.get(index, 0) + 1
        self._bytes -= size

    def take(self, timeout: float) -> list[tuple[int, int, bytes]]:
        """Everything waiting (small ones first, in order), after waiting at most ``timeout``
        seconds for something to come; empty once closed and drained."""
        with self._ready:
            if not self._small and not self._slots and not self._closed:
                self._ready.wait(timeout)
            taken = list(self._small)
            taken.extend((index, stamp, data) for index, (stamp, data) in self._slots.items())
            self._small.clear()
            self._slots.clear()
            self._bytes = 0
            return taken

    def close(self) -> None:
        """Wake the publisher for the last time."""
        with self._ready:
            self._closed = True
            self._ready.notify_all()

    @property
    def closed(self) -> bool:
        return self._closed
