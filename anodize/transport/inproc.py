"""Channels between threads of one process: one ``queue.SimpleQueue`` per ordered pair.

Failure and stop are delivered *through* the channels, as sentinels put after
everything already sent, so a receiver sees every message its peer sent before
it failed, then the failure: nothing is dropped and nobody waits forever.
Messages travel as plain ``(label, payload)`` tuples. Roles with parallel
branches also get a *doorbell*: each message into them
rings it with the sender's name, so one thread can wait on whichever channel
has a message first.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable
from dataclasses import dataclass
from queue import SimpleQueue

__all__ = ["PeerFailure", "STOP", "InprocNetwork"]


@dataclass(frozen=True, slots=True)
class PeerFailure:
    """Sentinel: the sending role failed; ``cause`` says how."""

    peer: str
    cause: str


class _Stop:
    __slots__ = ()

    def __repr__(self) -> str:
        return "STOP"


STOP = _Stop()


class InprocNetwork:
    """The channels of one run, and what is known about failed roles."""

    def __init__(self, channels: Iterable[tuple[str, str]], doorbell_roles: Iterable[str] = ()) -> None:
        self.queues: dict[tuple[str, str], SimpleQueue[object]] = {
            pair: SimpleQueue() for pair in channels}
        self.doorbells: dict[str, SimpleQueue[str]] = {role: SimpleQueue() for role in doorbell_roles}
        self.failed: dict[str, str] = {}
        self.stopping = False
        self.stop_event = threading.Event()  # set with ``stopping``: sleeping roles wake on it
        # Raised on any failure or stop: senders test this one flag on the fast path.
        self.alarm = False
        self._lock = threading.Lock()

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
        self.stopping = True
        self.alarm = True
        self.stop_event.set()
        for (sender, receiver), queue in self.queues.items():
            queue.put(STOP)
            self.ring(receiver, sender)

    def ring(self, receiver: str, sender: str) -> None:
        doorbell = self.doorbells.get(receiver)
        if doorbell is not None:
            doorbell.put(sender)
