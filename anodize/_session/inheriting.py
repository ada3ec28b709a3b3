"""The hooks of priority inheritance in the wait paths: lend the waiter's priority only when it blocks.

An endpoint whose network carries an inheritance table (``network.inheritance``, see
:mod:`anodize._isolation.inherit`) hooks each channel on which it may wait for a role that
could be boosted:

- a channel that knows where it blocks declares a ``lend_while_empty`` attribute on its class
  (receiving) or ``lend_while_full`` (sending: a bounded queue between threads, a pipe between
  processes); the endpoint sets it to a :class:`Lend`, and the channel enters it only in its
  blocking branch. Declared on the class, so that a wrapper forwarding attributes (a channel
  tapped by a recording or the live view) is not taken for the channel it wraps;
- any other channel (a ``queue.SimpleQueue`` between threads) is listed in the endpoint's
  ``_lending`` table: its receive first takes a message already there (``get_nowait``, no
  scheduling call; the compiled core does this in C) and only when none is waiting enters
  the :class:`Lend` around the blocking ``get`` (:func:`get_lending`).

Whatever ends the wait (a message, a timeout, a failure, a stop), leaving the context takes
the priority back.
"""

from __future__ import annotations

import queue
from collections.abc import Iterable
from contextlib import AbstractContextManager
from typing import Any, Protocol

from .channel import Channel

__all__ = ["Lender", "Lend", "inheriting", "get_lending", "lend_to_any"]


class Lender(Protocol):
    """What the endpoint needs from an inheritance table."""

    def could_boost(self, waiter: str, target: str) -> bool:
        """Whether ``waiter`` waiting on ``target`` may ever raise ``target``'s priority."""

    def join(self, role: str) -> None:
        """The calling thread plays ``role`` too (a parallel branch's thread)."""

    def waiting(self, waiter: str, *targets: str) -> AbstractContextManager[None]:
        """While inside, each of ``targets`` runs at least at ``waiter``'s priority."""


class Lend:
    """``lend()``: the context in which ``waiter``, blocked on ``targets``, lends them its priority."""

    __slots__ = ("_lender", "targets", "waiter")

    def __init__(self, lender: Lender, waiter: str, *targets: str) -> None:
        self._lender = lender
        self.waiter = waiter
        self.targets = targets

    def __call__(self) -> AbstractContextManager[None]:
        return self._lender.waiting(self.waiter, *self.targets)


def inheriting(lender: Lender | None, waiter: str, incoming: dict[str, Channel],
               outgoing: dict[str, Channel]) -> dict[str, Lend]:
    """Hook ``waiter``'s channels (see the module docstring); returns the incoming channels
    whose receive the endpoint itself must lend around (peer -> :class:`Lend`)."""
    if lender is None:
        return {}
    lending = {}
    hooked: Any  # a channel whose class declares the hook
    for peer, channel in incoming.items():
        if lender.could_boost(waiter, peer):
            if hasattr(type(channel), "lend_while_empty"):
                hooked = channel
                hooked.lend_while_empty = Lend(lender, waiter, peer)
            else:
                lending[peer] = Lend(lender, waiter, peer)
    for peer, channel in outgoing.items():
        if hasattr(type(channel), "lend_while_full") and lender.could_boost(waiter, peer):
            hooked = channel
            hooked.lend_while_full = Lend(lender, waiter, peer)
    return lending


def get_lending(channel: Channel, timeout: float | None, lend: Lend) -> object:
    """``channel.get(timeout=timeout)``, lending the receiver's priority only if it must wait.

    Raises:
        queue.Empty: nothing came within ``timeout`` seconds.
    """
    try:
        return channel.get_nowait()  # the fast path: no scheduling call
    except queue.Empty:
        if timeout is not None and timeout <= 0:
            raise
    with lend():
        return channel.get(timeout=timeout)


def lend_to_any(lender: Lender | None, waiter: str, peers: Iterable[str]) -> Lend | None:
    """The :class:`Lend` for a wait on whichever of ``peers`` sends first (``recv_any``), or None
    when none of them could be boosted."""
    if lender is None:
        return None
    targets = [peer for peer in peers if lender.could_boost(waiter, peer)]
    return Lend(lender, waiter, *targets) if targets else None
