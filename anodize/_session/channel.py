"""What an endpoint needs from a transport: channels, and the signals that travel in them.

A transport gives each ordered pair of connected roles a FIFO channel. Besides
messages (plain ``(label, payload)`` tuples) a channel may carry three signals,
put after everything sent before them so that nothing is overtaken:

- :class:`PeerFailure`: the sending role failed (and why);
- :data:`STOP`: the run, or the receiver's group, is stopping;
- :class:`Corrupt`: a frame from another process that did not decode (the sender
  is to blame).

Transports import this module; the endpoint never imports a transport.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Protocol

__all__ = ["PeerFailure", "STOP", "Corrupt", "Channel", "Doorbell", "Network"]


@dataclass(frozen=True, slots=True)
class PeerFailure:
    """Signal: the sending role failed; ``cause`` says how."""

    peer: str
    cause: str


class _Stop:
    __slots__ = ()

    def __repr__(self) -> str:
        return "STOP"


STOP = _Stop()


class Corrupt:
    """Signal: a frame from another process that did not decode; the sender is to blame."""

    __slots__ = ("reason",)

    def __init__(self, reason: str) -> None:
        self.reason = reason


class Channel(Protocol):
    """One direction between two roles (a ``queue.SimpleQueue`` satisfies it).

    The sending role only puts; the receiving role gets, and puts signals back
    (see :class:`PeerFailure`) so that later receives see them too.
    """

    def put(self, item: object) -> None: ...

    def get(self, *, timeout: float | None = None) -> object:
        """The next item, waiting up to ``timeout`` seconds (None: for ever).

        Raises:
            queue.Empty: nothing arrived in time.
        """

    def get_nowait(self) -> object:
        """The next item, without waiting.

        Raises:
            queue.Empty: nothing is waiting.
        """

    def empty(self) -> bool: ...


class Doorbell(Protocol):
    """The rings of a role with parallel branches: each names a peer that put a message
    into one of its channels (a ``queue.SimpleQueue[str]`` satisfies it)."""

    def put(self, sender: str) -> None: ...

    def get(self, *, timeout: float | None = None) -> str:
        """The next ring, waiting up to ``timeout`` seconds (None: for ever).

        Raises:
            queue.Empty: no ring in time.
        """

    def get_nowait(self) -> str:
        """The next ring, without waiting.

        Raises:
            queue.Empty: no ring is waiting.
        """

    def qsize(self) -> int: ...


class Network(Protocol):
    """The channels of one run as an endpoint sees them, and what is known of failures."""

    queues: dict[tuple[str, str], Channel]
    doorbells: dict[str, Doorbell]
    failed: dict[str, str]
    alarm: bool  # raised on any failure or stop: the senders' fast path tests only this

    def stop_event_for(self, role: str) -> threading.Event:
        """Set once ``role`` must stop."""

    def ring(self, receiver: str, sender: str) -> None:
        """Tell ``receiver`` (if it waits on several channels) that ``sender`` put something."""
