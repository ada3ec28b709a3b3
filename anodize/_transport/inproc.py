"""Channels between threads of one process: one ``queue.SimpleQueue`` per ordered pair.

Failure and stop are delivered *through* the channels, as signals put after
everything already sent (:mod:`anodize._session.channel`), so a receiver sees
every message its peer sent before it failed, then the failure: nothing is
dropped and nobody waits forever. Messages travel as plain ``(label, payload)``
tuples. Roles with parallel branches also get a *doorbell*: each message into
them rings it with the sender's name, so one thread can wait on whichever
channel has a message first. A channel given a *capacity* is a
:class:`BoundedQueue`: its sender waits while that many messages wait in it.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from contextlib import AbstractContextManager, nullcontext
from queue import Empty, SimpleQueue
from typing import Any, Protocol

from .._session.channel import STOP, Channel, Doorbell, PeerFailure
from ..errors import PeerFailedError, RoleStopped

__all__ = ["InprocNetwork", "BoundedQueue"]

_LOOK = 0.05  # seconds between a waiting sender's looks at stops and failures


class _Watched(Protocol):
    """What a waiting sender looks at: whether the run, or its own role, stops, and who failed."""

    stopping: bool
    stopped: set[str]
    failed: dict[str, str]


class BoundedQueue:
    """A channel between threads that holds at most ``capacity`` messages: a sender waits while
    it is full (back pressure, bounded memory), and stops waiting when the run stops or its
    receiver fails. Signals (a failure, STOP) never wait and do not count."""

    # Priority inheritance (anodize._session.inheriting): set by the endpoints, entered only
    # in the blocking branches of put and get.
    lend_while_full: Callable[[], AbstractContextManager[None]] | None = None
    lend_while_empty: Callable[[], AbstractContextManager[None]] | None = None

    def __init__(self, capacity: int, network: _Watched, sender: str, receiver: str) -> None:
        self.capacity = capacity
        self._network = network
        self._sender = sender
        self._receiver = receiver
        self._items: deque[object] = deque()
        self._messages = 0
        self._changed = threading.Condition()

    def put(self, item: object) -> None:
        """Add ``item``; a message waits for room first.

        Raises:
            RoleStopped: the sender was told to stop while it waited.
            PeerFailedError: the receiver failed while the sender waited.
        """
        with self._changed:
            if type(item) is tuple:
                if self._messages >= self.capacity:
                    with self.lend_while_full() if self.lend_while_full is not None else nullcontext():
                        while self._messages >= self.capacity:
                            self._check_waiting()
                            self._changed.wait(_LOOK)
                self._messages += 1
            self._items.append(item)
            self._changed.notify_all()

    def _check_waiting(self) -> None:
        network = self._network
        if network.stopping or self._sender in network.stopped:
            raise RoleStopped(f"interrupted sending to {self._receiver} (its channel is full: "
                              f"{self.capacity} messages wait)")
        cause = network.failed.get(self._receiver)
        if cause is not None:
            raise PeerFailedError(self._sender, self._receiver, cause)

    def get(self, timeout: float | None = None) -> object:
        """The oldest item.

        Raises:
            queue.Empty: nothing came within ``timeout`` seconds.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._changed:
            if not self._items:
                if timeout is not None and timeout <= 0:
                    raise Empty
                with self.lend_while_empty() if self.lend_while_empty is not None else nullcontext():
                    while not self._items:
                        left = None if deadline is None else deadline - time.monotonic()
                        if left is not None and left <= 0:
                            raise Empty
                        self._changed.wait(left)
            item = self._items.popleft()
            if type(item) is tuple:
                self._messages -= 1
            self._changed.notify_all()
            return item

    def get_nowait(self) -> object:
        return self.get(timeout=0)

    def empty(self) -> bool:
        return not self._items

    def qsize(self) -> int:
        """The messages waiting (signals not counted)."""
        return self._messages


class InprocNetwork:
    """The channels of one run (or of the groups restarted together), and what is
    known about failed roles.

    Args:
        channels: the ordered pairs of roles that talk.
        doorbell_roles: roles with parallel branches (see the module docstring).
        dead: roles that are not there for these channels (their group did not start
            with this batch), with the reason: receiving from them or sending to them
            fails at once.
        capacities: channels that hold at most so many messages (their senders wait).
    """

    def __init__(self, channels: Iterable[tuple[str, str]], doorbell_roles: Iterable[str] = (),
                 dead: Mapping[str, str] | None = None,
                 capacities: Mapping[tuple[str, str], int] | None = None) -> None:
        capacities = capacities or {}
        self.queues: dict[tuple[str, str], Channel] = {
            pair: BoundedQueue(capacities[pair], self, *pair) if pair in capacities else SimpleQueue()
            for pair in channels}
        self.doorbells: dict[str, Doorbell] = {role: SimpleQueue() for role in doorbell_roles}
        self.failed: dict[str, str] = {}
        self.inheritance: Any = None  # the run's priority inheritance table, set by the runner
        self.stopping = False
        self.stopped: set[str] = set()  # roles told to stop on their own (their group stops)
        self._stop_events: dict[str, threading.Event] = {}
        # Raised on any failure or stop: senders test this one flag on the fast path.
        self.alarm = False
        self._lock = threading.Lock()
        for role, cause in (dead or {}).items():
            self.failed[role] = cause
            self.alarm = True
            for (sender, _), queue in self.queues.items():
                if sender == role:
                    queue.put(PeerFailure(role, cause))

    def stop_event_for(self, role: str) -> threading.Event:
        """Set when ``role`` must stop: sleeping roles wake on it."""
        with self._lock:
            event = self._stop_events.get(role)
            if event is None:
                event = self._stop_events[role] = threading.Event()
                if self.stopping or role in self.stopped:
                    event.set()
            return event

    def fail(self, role: str, cause: str) -> None:
        """Tell every role that receives from ``role`` that it failed."""
        with self._lock:
            if role in self.failed:
                return
            self.failed[role] = cause
            self.alarm = True
        for (sender, receiver), queue in self.queues.items():
            if sender == role:
                queue.put(PeerFailure(role, cause))
                self.ring(receiver, sender)

    def stop(self) -> None:
        """Wake every waiting receiver with STOP."""
        self.stop_roles({receiver for _, receiver in self.queues} | set(self._stop_events), everyone=True)

    def stop_roles(self, roles: Iterable[str], everyone: bool = False) -> None:
        """Stop ``roles`` only: each gets ``RoleStopped`` at its next send, receive or sleep."""
        roles = set(roles)
        with self._lock:
            self.stopped |= roles
            self.stopping = self.stopping or everyone
            self.alarm = True
            events = [self._stop_events.setdefault(role, threading.Event()) for role in roles]
        for event in events:
            event.set()
        for (sender, receiver), queue in self.queues.items():
            if receiver in roles:
                queue.put(STOP)
                self.ring(receiver, sender)

    def ring(self, receiver: str, sender: str) -> None:
        doorbell = self.doorbells.get(receiver)
        if doorbell is not None:
            doorbell.put(sender)
