"""Exceptions a role (or the code that runs a system) can meet.

``AnodizeError`` is the root. Facts live in attributes; the text is built in
``__str__``. A violation names the protocol, the role, the peer, the state,
every action the protocol allowed there, the action attempted, who is to
blame, and where in the ``.proto`` file the interaction is written.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

__all__ = [
    "AnodizeError", "ConfigurationError", "ParameterError",
    "ProtocolViolationError", "DeadlineMissedError", "PeerFailedError",
    "MemoryBoundError",
    "LinearityError", "MissingExtraError", "Action", "RoleError", "RoleStopped", "error_to_data", "error_from_data",
]


class AnodizeError(Exception):
    """Root of the runtime's errors: every error a user can cause derives from it."""


class ConfigurationError(AnodizeError, ValueError):
    """A system declared wrongly: a bad group, priority, memory size, CPU set, policy,
    transport or role placement (also a ``ValueError``, as lark's configuration errors are)."""


class ParameterError(ConfigurationError):
    """A role's parameter refused: one its function does not take, a value of another type than
    it declares, or one it needs and is not given. Raised by ``System(params=...)`` for a value
    no ROS parameter has, and before a run starts for the rest.

    Attributes:
        role: the role.
        parameter: the parameter's name ("" when the fault is not one parameter's).
        problem: what is wrong, e.g. ``expected float, got str ("fast")``.
    """

    def __init__(self, role: str, parameter: str, problem: str) -> None:
        self.role = role
        self.parameter = parameter
        self.problem = problem
        super().__init__(str(self))

    def __str__(self) -> str:
        if self.parameter:
            return f"role {self.role}: parameter {self.parameter}: {self.problem}"
        return f"role {self.role}: {self.problem}"


class MissingExtraError(AnodizeError, ImportError):
    """Raised when a feature needs a library that an optional extra installs and it is missing.

    Attributes:
        feature: what was asked for, e.g. ``"the DDS transport"``.
        extra: the extra that installs it, e.g. ``"dds"``.
        module: the module that could not be imported.
    """

    def __init__(self, feature: str, extra: str, module: str) -> None:
        super().__init__(feature, extra, module)
        self.feature = feature
        self.extra = extra
        self.module = module

    def __str__(self) -> str:
        return (f"{self.feature} needs the Python package of module {self.module!r}, which is not installed; "
                f"install it with: pip install 'anodize[{self.extra}]'")


@dataclass(frozen=True, slots=True)
class Action:
    """A send or receive as the monitor sees it: ``!B(label)`` / ``?A(label)``."""

    kind: str          # "send" | "recv" | "end" | "fork"
    peer: str | None
    label: str
    payload_type: str | None = None   # the sort (expected) or the Python type (actual)

    def __str__(self) -> str:
        if self.kind == "end":
            return "end (the role's function returned)"
        if self.kind == "fork":
            return "fork (start parallel branches)"
        arrow = "!" if self.kind == "send" else "?"
        message = f"{self.label}({self.payload_type})" if self.payload_type else self.label
        return f"{arrow}{self.peer}({message})" if self.peer else f"{arrow}{message}"


class ProtocolViolationError(AnodizeError):
    """Raised when an action is not allowed by the role's local type.

    Raised in the role that attempted a forbidden send (blame: that role), in
    the role that received a forbidden message (blame: the sender), and when a
    role's function returns before its local type reached ``end`` or a payload
    does not have the sort the protocol says.

    Attributes:
        protocol: the global type's name.
        role: the role whose monitor rejected the action.
        peer: the other role of the action (None if there is none).
        state: the monitor's state number and the local type that remained.
        expected: every action allowed in that state, sorted.
        actual: the action attempted.
        blame: the role at fault.
        location: ``file:line:col`` of the global interaction, where known.
        reason: a short sentence when the label was right but the payload was not.
    """

    def __init__(self, protocol: str, role: str, peer: str | None, state: str,
                 expected: Sequence[Action], actual: Action, blame: str,
                 location: str = "", reason: str = "") -> None:
        self.protocol = protocol
        self.role = role
        self.peer = peer
        self.state = state
        self.expected = tuple(expected)
        self.actual = actual
        self.blame = blame
        self.location = location
        self.reason = reason
        super().__init__(str(self))

    def __str__(self) -> str:
        expected = ", ".join(str(a) for a in self.expected) or "nothing (the local type has ended)"
        where = f" ({self.location})" if self.location else ""
        reason = f": {self.reason}" if self.reason else ""
        return (f"protocol {self.protocol}, role {self.role}: protocol violation by {self.blame}"
                f"{reason}; in state {self.state} expected {expected}, got {self.actual}{where}")


class DeadlineMissedError(ProtocolViolationError):
    """A time constraint of the protocol did not hold (``within``, ``every``).

    Raised in a sender whose send came too late after its previous action, or too early or
    too late after its previous send of a periodic interaction (nothing is sent; blame: the
    sender), and in a receiver whose deadline passed with nothing arrived (blame: the sender,
    raised the moment the deadline passes). Times are read on the role's own clock.

    Attributes (besides those of :class:`ProtocolViolationError`):
        deadline_ns: the bound that was missed, in nanoseconds: ``within``'s duration, or the
            period's ``every`` for ``kind`` "period".
        late_ns: how far past the bound, in nanoseconds; for a period sent too early, how far
            before the earliest allowed moment, as a negative number.
        kind: ``"deadline"`` (``within``) or ``"period"`` (``every``).
    """

    def __init__(self, protocol: str, role: str, peer: str | None, state: str,
                 expected: Sequence[Action], actual: Action, blame: str,
                 location: str = "", reason: str = "", deadline_ns: int = 0, late_ns: int = 0,
                 kind: str = "deadline") -> None:
        self.deadline_ns = deadline_ns
        self.late_ns = late_ns
        self.kind = kind
        super().__init__(protocol, role, peer, state, expected, actual, blame, location, reason)


class PeerFailedError(AnodizeError):
    """Raised in a role waiting on (or sending to) a peer that crashed or was stopped.

    Attributes:
        role: the role that was waiting.
        peer: the role that failed.
        cause: a description of the peer's failure.
    """

    def __init__(self, role: str, peer: str, cause: str) -> None:
        self.role = role
        self.peer = peer
        self.cause = cause
        super().__init__(str(self))

    def __str__(self) -> str:
        return f"role {self.role}: peer {self.peer} failed ({self.cause})"


class MemoryBoundError(AnodizeError):
    """Raised (and reported) for a group that exceeded its memory bound.

    Attributes:
        group: the group's name.
        bound: the bound in bytes.
        peak: the highest use measured, in bytes (0 if unknown).
    """

    def __init__(self, group: str, bound: int, peak: int = 0) -> None:
        self.group = group
        self.bound = bound
        self.peak = peak
        super().__init__(str(self))

    def __str__(self) -> str:
        peak = f" (peak {_mib(self.peak)})" if self.peak else ""
        return (f"group {self.group} exceeded its memory bound of {_mib(self.bound)}{peak}; "
                "the group was stopped as a whole")


def _mib(size: int) -> str:
    return f"{size / 2**20:.1f} MiB"


class LinearityError(AnodizeError):
    """Raised when a typed state object of generated code is used a second time.

    Attributes:
        state: the state class's name.
    """

    def __init__(self, state: str) -> None:
        self.state = state
        super().__init__(str(self))

    def __str__(self) -> str:
        return (f"state {self.state} was already used; each state object allows one action, "
                "continue with the state that action returned")


class RoleStopped(BaseException):
    """Raised inside a role when the run, or its group, is stopped (timeout, Ctrl-C, policy).

    A ``BaseException`` so that a role's ``except Exception`` does not swallow it.

    Attributes:
        detail: what the role was doing, e.g. ``blocked in state 3 waiting for ?Cam(Frame)``.
    """

    def __init__(self, detail: str = "") -> None:
        self.detail = detail
        super().__init__(detail)


class RoleError(AnodizeError):
    """An exception raised by a role in another group's process, as the supervisor saw it.

    Attributes:
        type_name: the exception's class name in that process.
        message: its text.
        traceback: the formatted traceback, for debugging.
    """

    def __init__(self, type_name: str, message: str, traceback: str = "") -> None:
        self.type_name = type_name
        self.message = message
        self.traceback = traceback
        super().__init__(str(self))

    def __str__(self) -> str:
        return f"{self.type_name}: {self.message}"


def error_to_data(error: BaseException) -> dict[str, object]:
    """Plain data for ``error`` (sent from a group's process to the supervisor)."""
    import traceback

    data: dict[str, object] = {"type": type(error).__name__, "message": str(error),
                               "traceback": "".join(traceback.format_exception(error))[-8000:]}
    if isinstance(error, ProtocolViolationError):
        data["violation"] = [error.protocol, error.role, error.peer, error.state,
                             [[a.kind, a.peer, a.label, a.payload_type] for a in error.expected],
                             [error.actual.kind, error.actual.peer, error.actual.label,
                              error.actual.payload_type],
                             error.blame, error.location, error.reason]
        if isinstance(error, DeadlineMissedError):
            data["deadline"] = [error.deadline_ns, error.late_ns, error.kind]
    elif isinstance(error, PeerFailedError):
        data["peer_failed"] = [error.role, error.peer, error.cause]
    elif isinstance(error, MemoryBoundError):
        data["memory"] = [error.group, error.bound, error.peak]
    return data


def error_from_data(data: dict[str, object]) -> AnodizeError:
    """Rebuild what :func:`error_to_data` sent: the same class for anodize's errors."""
    try:
        if "violation" in data:
            protocol, role, peer, state, expected, actual, blame, location, reason = _items(data["violation"])
            if "deadline" in data:
                deadline, late, kind = _items(data["deadline"])
                return DeadlineMissedError(_text(protocol), _text(role), _optional_text(peer), _text(state),
                                           [_action(a) for a in _items(expected)], _action(actual),
                                           _text(blame), _text(location), _text(reason), _number(deadline),
                                           _number(late), _text(kind))
            return ProtocolViolationError(_text(protocol), _text(role), _optional_text(peer), _text(state),
                                          [_action(a) for a in _items(expected)], _action(actual),
                                          _text(blame), _text(location), _text(reason))
        if "peer_failed" in data:
            role, peer, cause = _items(data["peer_failed"])
            return PeerFailedError(_text(role), _text(peer), _text(cause))
        if "memory" in data:
            group, bound, peak = _items(data["memory"])
            return MemoryBoundError(_text(group), _number(bound), _number(peak))
    except (TypeError, ValueError):
        pass  # malformed: fall back to the text
    return RoleError(str(data.get("type", "Exception")), str(data.get("message", "")),
                     str(data.get("traceback", "")))


# Checked readers for error_from_data: a wrong type raises TypeError, so malformed data falls back to RoleError.
def _items(value: object) -> Sequence[object]:
    if not isinstance(value, list | tuple):
        raise TypeError(f"expected a list, got {type(value).__name__}")
    return value


def _text(value: object) -> str:
    if not isinstance(value, str):
        raise TypeError(f"expected a str, got {type(value).__name__}")
    return value


def _optional_text(value: object) -> str | None:
    return None if value is None else _text(value)


def _number(value: object) -> int:
    if not isinstance(value, int) or isinstance(value, bool):
        raise TypeError(f"expected an int, got {type(value).__name__}")
    return value


def _action(value: object) -> Action:
    kind, peer, label, payload_type = _items(value)
    return Action(_text(kind), _optional_text(peer), _text(label), _optional_text(payload_type))

