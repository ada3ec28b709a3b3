"""The base of generated typed states (``anodize project FILE -o DIR``).

A generated state class derives from :class:`State`: it holds the role's
endpoint and may be used once; each of its methods performs one action and
returns the next state. Kept here, in anodize's public API, so that every
generated module shares one copy.
"""

from __future__ import annotations

from ..errors import LinearityError
from .endpoint import Endpoint, Message

__all__ = ["State"]


class State:
    """A state of a role: it holds the endpoint and may be used once."""

    __slots__ = ("_endpoint", "_used")

    def __init__(self, endpoint: Endpoint) -> None:
        self._endpoint = endpoint
        self._used = False

    def _use(self) -> Endpoint:
        """Mark the state used and return the endpoint (``LinearityError`` the second time)."""
        if self._used:
            raise LinearityError(type(self).__name__)
        self._used = True
        return self._endpoint

    def _recv(self, peer: str, labels: tuple[str, ...], timeout: float | None) -> Message:
        """Receive from ``peer`` one of ``labels``; a timeout leaves the state unused."""
        endpoint = self._use()
        try:
            message = endpoint.recv(peer, timeout)
        except TimeoutError:
            self._used = False  # nothing arrived, so the state is still unused
            raise
        if message.label not in labels:
            raise AssertionError(
                f"{type(self).__name__} expected {' or '.join(labels)} from {peer}, but the "
                f"endpoint delivered {message.label}: it does not monitor this role's protocol")
        return message
