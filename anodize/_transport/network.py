"""The channels of one group's process, built from parts: local queues and one transport's links.

A group's process sees the same interface as the inproc transport
(:class:`~anodize._transport.inproc.InprocNetwork`): a channel per ordered pair with
``put``/``get``, doorbells, and what is known of failed roles. Channels inside the
group are queues; every channel to or from another group is a link made by the
transport's :class:`~anodize._transport.links.Links` (pipes or DDS topics). A local
role with parallel branches gets its links bridged into local queues
(:mod:`.bridge`), so it can wait on all of them at once.

Only the sending group writes a channel, so a receiver here learns of a remote
sender's failure from its link (a failure frame, end-of-file, a lost writer) or
from the supervisor (:meth:`GroupNetwork.note_failed`); a role here that fails has a
failure written after its last message on each of its links.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Mapping
from queue import SimpleQueue
from typing import Any

from .._session.channel import STOP, Channel, Doorbell, PeerFailure
from .bridge import bridge
from .codec import Codec
from .inproc import BoundedQueue
from .links import FailureWriter, Links

__all__ = ["GroupNetwork"]

_EOF_CAUSE_WAIT = 2.0  # seconds to wait for the supervisor's word on why a peer's process ended


class GroupNetwork:
    """The channels of one group's process.

    Args:
        local_roles: the roles running in this process.
        channels: every ordered pair the global type connects.
        links: the transport's links to other groups' processes.
        dead: roles whose group did not start with this one, with the reason; sending
            to them or receiving from them fails at once.
        codec_for: builds the codec of a linked channel (its payload classes and rings).
        doorbell_roles: local roles with parallel branches (their links are bridged).
        capacities: channels that hold at most so many messages (their senders wait).
    """

    def __init__(self, local_roles: Iterable[str], channels: Iterable[tuple[str, str]], links: Links,
                 dead: Mapping[str, str], codec_for: Callable[[tuple[str, str]], Codec],
                 doorbell_roles: Iterable[str] = (),
                 capacities: Mapping[tuple[str, str], int] | None = None) -> None:
        self.local_roles = local = frozenset(local_roles)
        self.links = links
        self.capacities = dict(capacities or {})
        channels = tuple(channels)
        self.queues: dict[tuple[str, str], Channel] = {
            pair: BoundedQueue(self.capacities[pair], self, *pair) if pair in self.capacities else SimpleQueue()
            for pair in channels if pair[0] in local and pair[1] in local}
        self.doorbells: dict[str, Doorbell] = {role: SimpleQueue() for role in doorbell_roles if role in local}
        self.failed: dict[str, str] = dict(dead)
        self.inheritance: Any = None  # the run's priority inheritance table, set by the group process
        self.stopping = False
        self.stopped: set[str] = set()  # never filled here: a group's process stops as a whole
        # Raised on any failure or stop: senders test this one flag on the fast path.
        self.alarm = bool(dead)
        self._lock = threading.Lock()
        self._stop_events: dict[str, threading.Event] = {}
        self._cause_arrived = threading.Condition()
        self.bridges: list[threading.Thread] = []
        self._linked_in: set[tuple[str, str]] = set()  # the links our roles read
        for sender, receiver in links.pairs(local, channels, dead):
            codec = codec_for((sender, receiver))
            if sender in local:
                self.queues[(sender, receiver)] = links.writer((sender, receiver), codec, self)
                continue
            self._linked_in.add((sender, receiver))
            if receiver in self.doorbells:
                reader = links.reader((sender, receiver), codec, self)
                self.queues[(sender, receiver)], thread = bridge(reader, sender, receiver, self.ring)
                self.bridges.append(thread)
            else:
                self.queues[(sender, receiver)] = links.reader((sender, receiver), codec, self)
        for sender, receiver in channels:  # channels from a peer that is not there
            if (sender, receiver) not in self.queues and receiver in local:
                gone: SimpleQueue[object] = SimpleQueue()
                gone.put(PeerFailure(sender, dead.get(sender, "not running")))
                self.queues[(sender, receiver)] = gone

    def start(self) -> None:
        """Start the bridges' threads (once every endpoint is built)."""
        for thread in self.bridges:
            thread.start()

    def close(self, linger: float = 2.0) -> None:
        """The process is ending: let the links flush what was written (bounded by ``linger`` seconds)."""
        self.links.close(linger)

    def ring(self, receiver: str, sender: str) -> None:
        """Tell ``receiver`` (if it waits on several channels) that ``sender`` put something."""
        doorbell = self.doorbells.get(receiver)
        if doorbell is not None:
            doorbell.put(sender)

    def stop_event_for(self, role: str) -> threading.Event:
        """Set when ``role`` must stop: sleeping roles wake on it."""
        with self._lock:
            event = self._stop_events.get(role)
            if event is None:
                event = self._stop_events[role] = threading.Event()
                if self.stopping:
                    event.set()
            return event

    # ---- failure and stop ------------------------------------------------------------------
    def fail(self, role: str, cause: str) -> None:
        """``role`` failed: tell its receivers (a local role), or just record it (a remote one)."""
        if role not in self.local_roles:
            self.note_failed(role, cause)
            return
        with self._lock:
            if role in self.failed:
                return
            self.failed[role] = cause
            self.alarm = True
        for (sender, receiver), channel in self.queues.items():
            if receiver == role and (sender, receiver) in self._linked_in:
                self.links.silence((sender, receiver))
            if sender != role:
                continue
            if isinstance(channel, FailureWriter):
                channel.put_failure(cause)
            else:
                channel.put(PeerFailure(role, cause))
                self.ring(receiver, sender)

    def note_failed(self, role: str, cause: str) -> None:
        """Record why a remote role failed (from its link or the supervisor), and wake its
        receivers here."""
        with self._cause_arrived:
            self.failed.setdefault(role, cause)
            self.alarm = True
            self._cause_arrived.notify_all()
        self.links.noted_failed(role)

    def wait_for_cause(self, role: str, default: str) -> str | None:
        """Why ``role`` failed; wait briefly for the supervisor to say, when its process died.

        Returns:
            The cause (``default`` if none arrived in time), or None when the run is
            stopping and ``role`` did not fail: its process ended with the run.
        """
        with self._cause_arrived:
            self._cause_arrived.wait_for(lambda: role in self.failed or self.stopping, timeout=_EOF_CAUSE_WAIT)
            # Read here, not by the caller: ``stopping`` changes from other threads, and
            # the caller has already seen it False before waiting.
            if self.stopping and role not in self.failed:
                return None
            return self.failed.get(role, default)

    def stop(self) -> None:
        """Wake every receiver of this process with STOP."""
        with self._cause_arrived:  # a receiver waiting to learn why a peer's process ended: the stop
            self.stopping = True
            self.alarm = True
            self._cause_arrived.notify_all()
        for role in self.local_roles:
            self.stop_event_for(role).set()
        self.links.wake()
        local = self.local_roles
        for (sender, receiver), channel in self.queues.items():
            # Channels inside this process, whatever wraps them (a bounded queue, a tap), and the
            # queues standing for peers that are not there; links are woken by the transport.
            if (sender in local and receiver in local) or isinstance(channel, SimpleQueue):
                channel.put(STOP)
                self.ring(receiver, sender)
