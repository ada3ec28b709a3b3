"""Channels between threads of one process: one ``queue.SimpleQueue`` per ordered pair.

Failure and stop are delivered *through* the channels, as signals put after
everything already sent (:mod:`anodize.session.channel`), so a receiver sees
every message its peer sent before it failed, then the failure: nothing is
dropped and nobody waits forever. Messages travel as plain ``(label, payload)``
tuples. Roles with parallel branches also get a *doorbell*: each message into
them rings it with the sender's name, so one thread can wait on whichever
channel has a message first.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Mapping
from queue import SimpleQueue

from ..session.channel import STOP, Channel, Doorbell, PeerFailure

__all__ = ["InprocNetwork"]


class InprocNetwork:
    """The channels of one run (or of the groups restarted together), and what is
    known about failed roles.

    Args:
        channels: the ordered pairs of roles that talk.
        doorbell_roles: roles with parallel branches (see the module docstring).
        dead: roles that are not there for these channels (their group did not start
            with this batch), with the reason: receiving from them or sending to them
            fails at once.
    """

    def __init__(self, channels: Iterable[tuple[str, str]], doorbell_roles: Iterable[str] = (),
                 dead: Mapping[str, str] | None = None) -> None:
        self.queues: dict[tuple[str, str], Channel] = {pair: SimpleQueue() for pair in channels}
        self.doorbells: dict[str, Doorbell] = {role: SimpleQueue() for role in doorbell_roles}
        self.failed: dict[str, str] = {}
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
