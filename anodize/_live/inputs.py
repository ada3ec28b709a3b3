"""What live-view clients publish, for the roles that send on the same channels.

A Foxglove client may publish on a channel's topic (``/joy`` from a joystick panel);
the supervisor checks each message against the label's type and hands it to the group
whose role sends that label. The role itself decides what to do with it: it reads the
latest one with :func:`client_input` and still sends through its monitored endpoint,
so what a client publishes enters the protocol only as the role's own message.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

from .._recording.encoding import SortCodec
from .._session.endpoint import Endpoint
from .._session.payloads import validator_for
from .plan import LiveLabel

__all__ = ["ClientInput", "ClientMessage", "client_input"]


@dataclass(frozen=True)
class ClientMessage:
    """One message a client published: the payload (a value of the label's sort) and when it came."""

    payload: object
    arrived: float  # time.monotonic() in this process


class ClientInput:
    """The messages clients publish on one label's topic, as its sender's role sees them.

    Attributes:
        label: the channel label, with its topic.
        received: client messages taken so far.
        rejected: client messages that were not values of the label's sort (dropped).
    """

    def __init__(self, label: LiveLabel, codec: SortCodec) -> None:
        self.label = label
        self._codec = codec
        self._check = validator_for(label.sort)
        self._latest: ClientMessage | None = None
        self.received = 0
        self.rejected = 0

    def latest(self, max_age: float | None = None) -> object | None:
        """The payload of the newest client message, or None if there is none (no younger
        than ``max_age`` seconds, if given)."""
        found = self._latest
        if found is None or (max_age is not None and time.monotonic() - found.arrived > max_age):
            return None
        return found.payload

    def deliver(self, data: bytes) -> str | None:
        """Take a client's message (CDR); returns why it was rejected, or None."""
        try:
            payload = self._codec.decode(data)
        except Exception as error:  # whatever a client sends, it must not reach the role
            self.rejected += 1
            return f"{type(error).__name__}: {error}"
        reason = self._check(payload)
        if reason is not None:
            self.rejected += 1
            return reason
        self._latest = ClientMessage(payload, time.monotonic())
        self.received += 1
        return None


_lock = threading.Lock()
_inputs: dict[tuple[str, str, str], ClientInput] = {}  # (sender, receiver, label) in this process


def client_input(ep: Endpoint, to: str, label: str) -> ClientInput | None:
    """The client messages for ``ep``'s role's label ``label`` to ``to``; None when the run
    has no live view (``anodize run --foxglove``), so a role can keep its usual source.

    A role that drives a channel from a live client (TinMan's Joy from Foxglove's joystick)
    reads :meth:`ClientInput.latest` and sends what it decides through ``ep``, as always.
    """
    with _lock:
        return _inputs.get((ep.role, to, label))


def register_input(found: ClientInput) -> None:
    """Make ``found`` the client input of its label in this process (a restarted group replaces it)."""
    x = found.label
    with _lock:
        _inputs[(x.sender, x.receiver, x.label)] = found


def unregister_input(found: ClientInput) -> None:
    """Forget ``found`` (its group ended), unless a newer one replaced it."""
    x = found.label
    with _lock:
        if _inputs.get((x.sender, x.receiver, x.label)) is found:
            del _inputs[(x.sender, x.receiver, x.label)]
