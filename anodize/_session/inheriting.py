"""The hook of priority inheritance in a receive: lend the waiter's priority only when it blocks.

An endpoint whose network carries an inheritance table (``network.inheritance``, see
:mod:`anodize._isolation.inherit`) wraps each incoming channel whose sender could be
boosted in an :class:`InheritingChannel`. Its ``get`` first takes a message already there
without any scheduling call (the fast path costs one ``get_nowait``); only when nothing is
waiting does it enter the table's ``waiting`` context, which raises the sender's priority to
the waiter's for exactly as long as the blocking ``get`` lasts, whatever ends it (a message,
a timeout, a failure, a stop). A sender blocked on a full channel between threads is hooked
the same way through the channel's ``blocked`` attribute (:class:`anodize._transport.inproc.BoundedQueue`).

The endpoint (and the compiled core, which calls ``channel.get``) never knows: the wrapper is
a channel.
"""

from __future__ import annotations

import queue
from contextlib import AbstractContextManager
from typing import Any, Protocol

from .channel import Channel

__all__ = ["Lender", "InheritingChannel", "inheriting"]


class Lender(Protocol):
    """What the endpoint needs from an inheritance table."""

    def could_boost(self, waiter: str, target: str) -> bool:
        """Whether ``waiter`` waiting on ``target`` may ever raise ``target``'s priority."""

    def waiting(self, waiter: str, target: str) -> AbstractContextManager[None]:
        """While inside, ``target`` runs at least at ``waiter``'s priority."""


class InheritingChannel:
    """A channel whose blocking ``get`` lends the receiver's priority to the sender."""

    __slots__ = ("_lender", "_target", "_waiter", "channel")

    def __init__(self, channel: Channel, lender: Lender, waiter: str, target: str) -> None:
        self.channel = channel
        self._lender = lender
        self._waiter = waiter
        self._target = target

    def get(self, timeout: float | None = None) -> object:
        """The next item; while none is there, the sender runs at the receiver's priority.

        Raises:
            queue.Empty: nothing came within ``timeout`` seconds.
        """
        channel = self.channel
        try:
            return channel.get_nowait()  # the fast path: no scheduling call
        except queue.Empty:
            if timeout is not None and timeout <= 0:
                raise
        with self._lender.waiting(self._waiter, self._target):
            return channel.get(timeout=timeout)

    def get_nowait(self) -> object:
        return self.channel.get_nowait()

    def put(self, item: object) -> None:
        self.channel.put(item)

    def empty(self) -> bool:
        return self.channel.empty()

    def __getattr__(self, name: str) -> Any:  # take_ready, give_back, qsize...: the channel's own
        return getattr(self.channel, name)


def inheriting(lender: Lender | None, waiter: str, incoming: dict[str, Channel],
               outgoing: dict[str, Channel]) -> dict[str, Channel]:
    """``incoming`` with each channel whose sender could be boosted wrapped; senders' full-channel
    waits hooked on ``outgoing`` channels that offer a ``blocked`` attribute."""
    if lender is None:
        return incoming
    for peer, channel in outgoing.items():
        if hasattr(channel, "blocked") and lender.could_boost(waiter, peer):
            channel.blocked = _Lend(lender, waiter, peer)
    return {peer: InheritingChannel(channel, lender, waiter, peer) if lender.could_boost(waiter, peer)
            else channel for peer, channel in incoming.items()}


class _Lend:
    """``blocked()``: the context in which a sender waiting for room lends its priority."""

    __slots__ = ("_lender", "_target", "_waiter")

    def __init__(self, lender: Lender, waiter: str, target: str) -> None:
        self._lender = lender
        self._waiter = waiter
        self._target = target

    def __call__(self) -> AbstractContextManager[None]:
        return self._lender.waiting(self._waiter, self._target)
