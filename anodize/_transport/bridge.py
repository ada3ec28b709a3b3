"""A channel from another process moved into a local queue by a thread, for a role that waits on several.

A role with parallel branches waits on whichever channel has a message first, through
its doorbell (:mod:`anodize._transport.inproc`). A link's reader cannot ring it, so a
*bridge* thread reads the link and puts what comes into a :class:`BridgeQueue`, ringing
the doorbell each time. The queue is bounded: when the role falls behind, the thread
stops reading, the link fills and its sender blocks (back pressure), as without a bridge.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from queue import Empty
from typing import Any

from .._session.channel import Corrupt

__all__ = ["BridgeQueue", "bridge", "BRIDGE_MESSAGES", "BRIDGE_BYTES"]

BRIDGE_MESSAGES = 256  # a bridged channel's queue holds at most this many messages...
BRIDGE_BYTES = 4 * 2**20  # ...and this many bytes of frames: then the link fills and its sender blocks


def bridge(source: Any, sender: str, receiver: str, ring: Callable[[str, str], None]
           ) -> tuple[BridgeQueue, threading.Thread]:
    """A queue fed from ``source`` (a link's reader) by a thread, not yet started, that rings
    ``ring(receiver, sender)`` after each item."""
    target = BridgeQueue()

    def pump() -> None:
        while True:
            try:
                item = source.get()
            except MemoryError:
                raise  # our group's own bound, not the sender's fault: the thread hook reports it
            except Exception as error:  # never die silently: the receiver must hear of it
                item = Corrupt(f"{type(error).__name__}: {error}")
                target.put(item)
                ring(receiver, sender)
                return
            if type(item) is tuple or isinstance(item, Corrupt):
                target.put_message(item, source.frame_size)  # waits while the queue is full
            else:
                target.put(item)  # a failure or STOP: never waits
            ring(receiver, sender)
            if type(item) is not tuple and not isinstance(item, Corrupt):
                return  # a failure or STOP ends the channel

    thread = threading.Thread(target=pump, name=f"anodize-bridge:{sender}->{receiver}", daemon=True)
    return target, thread


class BridgeQueue:
    """A bridged channel's local queue, bounded by message count and frame bytes.

    The bridge thread waits in :meth:`put_message` while the queue is full; signals
    (a failure, STOP, a corrupt frame) and what a receiver puts back go in with
    :meth:`put`, which never waits, so they always get through.

    Args:
        messages: at most this many messages wait...
        budget: ...holding at most this many bytes of frames (one bigger message may
            still wait alone).
    """

    def __init__(self, messages: int = BRIDGE_MESSAGES, budget: int = BRIDGE_BYTES) -> None:
        self._items: deque[tuple[object, int]] = deque()
        self._bytes = 0
        self._messages = messages
        self._budget = budget
        self._lock = threading.Lock()
        self._not_empty = threading.Condition(self._lock)
        self._not_full = threading.Condition(self._lock)

    def put_message(self, item: object, size: int) -> None:
        """Queue a message of ``size`` frame bytes, waiting for room."""
        with self._not_full:
            while self._items and (len(self._items) >= self._messages or self._bytes + size > self._budget):
                self._not_full.wait()
            self._items.append((item, size))
            self._bytes += size
            self._not_empty.notify()

    def put(self, item: object) -> None:
        """Queue a signal (or put one back): never waits."""
        with self._lock:
            self._items.append((item, 0))
            self._not_empty.notify()

    def get(self, *, timeout: float | None = None) -> object:
        """The next item, waiting up to ``timeout`` seconds (None: for ever).

        Raises:
            queue.Empty: nothing arrived in time.
        """
        with self._not_empty:
            if not self._not_empty.wait_for(lambda: self._items, timeout):
                raise Empty
            item, size = self._items.popleft()
            self._bytes -= size
            self._not_full.notify()
            return item

    def get_nowait(self) -> object:
        """The next item, without waiting.

        Raises:
            queue.Empty: nothing is waiting.
        """
        return self.get(timeout=0)

    def empty(self) -> bool:
        """Whether nothing is waiting."""
        return not self._items

    def qsize(self) -> int:
        """How many items wait."""
        return len(self._items)
