"""The control messages between the supervisor and a group's process, as typed values.

Each message is a frozen dataclass; on the wire it is a tuple ``(tag, field, ...)``
encoded by the codec with no payload classes (so never pickle). Decoding checks
every field's type, so a group that garbles a report is caught at the door and
failed, and the supervisor never works with half-valid data.
"""

from __future__ import annotations

import dataclasses
import math
import os
import struct
import time
import types
import typing
from dataclasses import dataclass, field
from enum import IntEnum
from multiprocessing.connection import Connection
from typing import Any, ClassVar

from .._transport.codec import Codec, DecodeError, FrameKind

__all__ = [
    "ControlTag", "Ready", "Beat", "RoleEnded", "MemoryExceeded", "Crash", "Notice", "Logs", "Go", "PeerFailed", "Stop",
    "GroupMessage", "SupervisorMessage", "encode_control", "send_control", "decode_control", "FrameReader",
    "MAX_CONTROL_FRAME",
]


class ControlTag(IntEnum):
    """The first item of every control message: which message it is."""

    READY = 1
    BEAT = 2
    ROLE_ENDED = 3
    MEMORY_EXCEEDED = 4
    CRASH = 5
    NOTICE = 6
    LOGS = 7
    GO = 20
    PEER_FAILED = 21
    STOP = 22


# ---- from a group to the supervisor ----------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class Ready:
    """The group's roles are built and held at the gate; the process's facts."""

    TAG: ClassVar[ControlTag] = ControlTag.READY
    pid: int
    scheduling: str
    baseline: int
    memory_note: str


@dataclass(frozen=True, kw_only=True)
class Beat:
    """Memory (bytes above the baseline) and per-channel counts, ``"A->B"`` -> messages."""

    TAG: ClassVar[ControlTag] = ControlTag.BEAT
    at: float  # time.monotonic() when counted (the same clock in every process of the machine)
    memory: int
    peak: int
    sent: dict[str, int] = field(default_factory=dict)
    received: dict[str, int] = field(default_factory=dict)
    waiting: dict[str, int] = field(default_factory=dict)  # per channel, the most messages waiting so far
    final: bool = False  # the last beat: every role has ended
    # Per constrained interaction ("Role !Peer(m) within 15ms"): checks so far, and the closest
    # margin to its time bound in seconds (negative: missed), where it has one.
    checked: dict[str, int] = field(default_factory=dict)
    closest: dict[str, float] = field(default_factory=dict)
    timeouts: dict[str, int] = field(default_factory=dict)  # ``else timeout`` taken


@dataclass(frozen=True, kw_only=True)
class RoleEnded:
    """One role ended; ``error`` is :func:`anodize.errors.error_to_data` of its exception."""

    TAG: ClassVar[ControlTag] = ControlTag.ROLE_ENDED
    role: str
    status: str
    error: dict[str, Any] | None = None
    where: str = ""
    traceback: tuple[str, ...] = ()
    detail: str = ""


@dataclass(frozen=True, kw_only=True)
class MemoryExceeded:
    """The group met its memory bound (``error`` describes the MemoryBoundError); it exits."""

    TAG: ClassVar[ControlTag] = ControlTag.MEMORY_EXCEEDED
    role: str
    error: dict[str, Any]


@dataclass(frozen=True, kw_only=True)
class Crash:
    """The group's own machinery failed (not a role)."""

    TAG: ClassVar[ControlTag] = ControlTag.CRASH
    error: dict[str, Any]


@dataclass(frozen=True, kw_only=True)
class Notice:
    """A fact the group reports about its channels (e.g. samples rejected from a foreign DDS writer)."""

    TAG: ClassVar[ControlTag] = ControlTag.NOTICE
    text: str


@dataclass(frozen=True, kw_only=True)
class Logs:
    """A batch of the roles' log records (:class:`anodize._session.logs.LogEntry`), one column per
    field (so each is type-checked at the door), and the records dropped since the last batch."""

    TAG: ClassVar[ControlTag] = ControlTag.LOGS
    roles: tuple[str, ...] = ()
    levels: tuple[int, ...] = ()
    loggers: tuple[str, ...] = ()
    messages: tuple[str, ...] = ()
    walls: tuple[float, ...] = ()
    monotonics: tuple[float, ...] = ()
    files: tuple[str, ...] = ()
    functions: tuple[str, ...] = ()
    lines: tuple[int, ...] = ()
    dropped: dict[str, int] = field(default_factory=dict)  # per severity


# ---- from the supervisor to a group ----------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class Go:
    """Every group of the batch is ready: start the roles."""

    TAG: ClassVar[ControlTag] = ControlTag.GO


@dataclass(frozen=True, kw_only=True)
class PeerFailed:
    """A role of another group failed: its receivers here must hear of it."""

    TAG: ClassVar[ControlTag] = ControlTag.PEER_FAILED
    role: str
    cause: str


@dataclass(frozen=True, kw_only=True)
class Stop:
    """Stop every role (the run is stopping)."""

    TAG: ClassVar[ControlTag] = ControlTag.STOP


GroupMessage = Ready | Beat | RoleEnded | MemoryExceeded | Crash | Notice | Logs
SupervisorMessage = Go | PeerFailed | Stop
_CLASSES: dict[int, type[Any]] = {cls.TAG: cls for cls in (Ready, Beat, RoleEnded, MemoryExceeded, Crash,
                                                           Notice, Logs, Go, PeerFailed, Stop)}
_CODEC = Codec()  # no payload classes: control messages are plain data only


MAX_CONTROL_FRAME = 1 << 20  # bytes: no honest control message comes near it
_LENGTH = struct.Struct("<I")


def encode_control(message: GroupMessage | SupervisorMessage) -> bytes:
    """One whole frame (4-byte length, then the body) for ``message``."""
    values = tuple(getattr(message, f.name) for f in dataclasses.fields(message))
    return _CODEC.message_frame("control", (int(message.TAG), *values))


def send_control(conn: Connection, message: GroupMessage | SupervisorMessage) -> None:
    """Send one control message over ``conn`` (blocking until written).

    Raises:
        OSError: the other side is gone.
    """
    view = memoryview(encode_control(message))
    while view:
        view = view[os.write(conn.fileno(), view):]


def decode_control(body: bytes | bytearray) -> GroupMessage | SupervisorMessage:
    """The control message in a frame's body, every field checked.

    Raises:
        DecodeError: the bytes are not a well-formed control message.
    """
    kind, value = _CODEC.decode_body(body)
    if kind != FrameKind.MESSAGE or not isinstance(value[1], tuple) or not value[1]:
        raise DecodeError("a control message must be a tuple (tag, fields...)")
    tag, *values = value[1]
    cls = _CLASSES.get(tag) if type(tag) is int else None
    if cls is None:
        raise DecodeError(f"unknown control message tag {tag!r}")
    fields = dataclasses.fields(cls)
    if len(values) != len(fields):
        raise DecodeError(f"{cls.__name__}: expected {len(fields)} fields, got {len(values)}")
    hints = typing.get_type_hints(cls)
    for f, item in zip(fields, values, strict=True):
        if not _fits(item, hints[f.name]):
            raise DecodeError(f"{cls.__name__}.{f.name}: expected {hints[f.name]}, got {item!r:.80}")
    return cls(**{f.name: item for f, item in zip(fields, values, strict=True)})  # type: ignore[no-any-return]


class FrameReader:
    """Reads length-prefixed frames from a descriptor without ever blocking on a partial one.

    Call :meth:`read` when the descriptor is readable: it reads what is there and
    returns the complete frames. ``partial_since`` says since when a frame has been
    incomplete (None when none is), so the caller can give up on a sender that stops
    halfway; a frame announced over :data:`MAX_CONTROL_FRAME` is a :class:`DecodeError`.
    """

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.eof = False
        self.partial_since: float | None = None
        self._buffer = bytearray()

    @property
    def pending(self) -> bool:
        """Some bytes of an incomplete frame are buffered."""
        return bool(self._buffer)

    def read(self) -> list[bytes]:
        """Read once (blocks only if the descriptor has nothing); return the complete frames."""
        data = os.read(self.fd, 65536)
        if not data:
            self.eof = True
        self._buffer += data
        frames = []
        while len(self._buffer) >= _LENGTH.size:
            (length,) = _LENGTH.unpack_from(self._buffer)
            if length > MAX_CONTROL_FRAME:
                raise DecodeError(f"a control frame of {length} bytes, over the {MAX_CONTROL_FRAME} byte limit")
            if len(self._buffer) < _LENGTH.size + length:
                break
            frames.append(bytes(self._buffer[_LENGTH.size:_LENGTH.size + length]))
            del self._buffer[:_LENGTH.size + length]
        self.partial_since = (self.partial_since or time.monotonic()) if self._buffer else None
        return frames


def _fits(value: object, hint: Any) -> bool:
    """Whether ``value`` has type ``hint`` (the few shapes control messages use)."""
    origin = typing.get_origin(hint)
    if origin is types.UnionType:
        return any(_fits(value, option) for option in typing.get_args(hint))
    if hint is type(None):
        return value is None
    if hint is Any:
        return True
    if origin is dict:
        key_type, item_type = typing.get_args(hint)
        return isinstance(value, dict) and all(
            _fits(k, key_type) and _fits(v, item_type) for k, v in value.items())
    if origin is tuple:
        (item_type, _) = typing.get_args(hint)
        return isinstance(value, tuple) and all(_fits(v, item_type) for v in value)
    if hint is int:  # bool is an int to Python, not to us; and counts are never negative
        return type(value) is int and value >= 0
    if hint is float:
        return type(value) in (int, float) and math.isfinite(value)  # type: ignore[arg-type]
    return type(value) is hint
