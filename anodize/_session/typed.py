"""The base of generated typed states (``anodize project FILE -o DIR``).

A generated state class derives from :class:`State`: it holds the role's
endpoint and may be used once; each of its methods performs one action and
returns the next state. Kept here, in anodize's public API, so that every
generated module shares one copy.
"""

from __future__ import annotations

import inspect
import logging
import typing
from collections.abc import Callable
from typing import Any

from ..errors import AnodizeError, LinearityError
from .endpoint import TIMEOUT, Endpoint, Message

__all__ = ["State", "argument_for"]


class State:
    """A state of a role: it holds the endpoint and may be used once."""

    __slots__ = ("_endpoint", "_used")

    def __init__(self, endpoint: Endpoint) -> None:
        self._endpoint = endpoint
        self._used = False

    def now(self) -> float:
        """The role's monotonic clock (:meth:`Endpoint.now`): reading it is no action of the
        protocol, so the state stays unused."""
        return self._endpoint.now()

    def wall(self) -> float:
        """The wall clock (:meth:`Endpoint.wall`), for stamps; the state stays unused."""
        return self._endpoint.wall()

    @property
    def logger(self) -> logging.Logger:
        """The role's logger (:attr:`Endpoint.logger`); logging is no action: the state stays unused."""
        return self._endpoint.logger

    def _use(self) -> Endpoint:
        """Mark the state used and return the endpoint (``LinearityError`` the second time)."""
        if self._used:
            raise LinearityError(type(self).__name__)
        self._used = True
        return self._endpoint

    def _recv(self, peer: str, labels: tuple[str, ...], timeout: float | None) -> Message:
        """Receive from ``peer`` one of ``labels``; a timeout leaves the state unused, and so
        does the protocol's own (``else timeout``: the label ``TIMEOUT``, the role's state unchanged)."""
        endpoint = self._use()
        try:
            message = endpoint.recv(peer, timeout)
        except TimeoutError:
            self._used = False  # nothing arrived, so the state is still unused
            raise
        if message.label == TIMEOUT and TIMEOUT not in labels:  # (a choice with `else timeout` has no such label)
            self._used = False  # the role is where it was: this state is still the one to use
            return message
        if message.label not in labels:
            raise AssertionError(
                f"{type(self).__name__} expected {' or '.join(labels)} from {peer}, but the "
                f"endpoint delivered {message.label}: it does not monitor this role's protocol")
        return message


    def _recv_any(self, choices: tuple[tuple[str, str], ...], timeout: float | None) -> tuple[str, Message]:
        """Receive the first of ``choices`` (peer, label) to come; a timeout leaves the state unused."""
        endpoint = self._use()
        try:
            peer, message = endpoint.recv_any(timeout)
        except TimeoutError:
            self._used = False
            raise
        if message.label == TIMEOUT and (peer, TIMEOUT) not in choices:
            self._used = False  # as in _recv: the protocol's timeout leaves the state where it was
            return peer, message
        if (peer, message.label) not in choices:
            wanted = " or ".join(f"{label} from {p}" for p, label in choices)
            raise AssertionError(
                f"{type(self).__name__} expected {wanted}, but the endpoint delivered {message.label} "
                f"from {peer}: it does not monitor this role's protocol")
        return peer, message


def argument_for(function: Callable[..., Any], endpoint: Endpoint) -> Any:
    """What a role function is called with: the endpoint, or the generated typed initial
    state when the function's first parameter is annotated with one.

    Raises:
        AnodizeError: the function takes no argument.
    """
    try:
        parameters = list(inspect.signature(function).parameters.values())
        hints = typing.get_type_hints(function)
    except (TypeError, ValueError, NameError):
        return endpoint
    if not parameters:
        raise AnodizeError(f"role function {function.__qualname__} must take one argument "
                           "(an Endpoint or the typed initial state)")
    wanted = hints.get(parameters[0].name)
    if isinstance(wanted, type) and issubclass(wanted, State):  # a generated typed state
        return wanted(endpoint)
    return endpoint
