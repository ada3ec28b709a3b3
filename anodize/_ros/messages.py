"""ROS 2 message types: what a ``"ros:pkg/msg/Name"`` sort means, resolved through rosbags.

rosbags carries the message definitions of the ROS 2 distributions (a dataclass per
message, its CDR serialiser and its RIHS01 type hash) in pure Python. A
:class:`RosType` wraps one message of one distribution with what anodize needs of it:
a field-by-field check (:mod:`.checks`), the CDR bytes ROS 2 publishes, a decoder that
fails only with :class:`RosDecodeError`, and its Cyclone DDS class (:mod:`.idl`).

rosbags (a dependency of anodize, pure Python) is imported when the first
type is resolved.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any

from .._extras import import_extra
from ..errors import AnodizeError
from .checks import Compiled, compile_message, failure_text
from .idl import idl_class

__all__ = ["DEFAULT_DISTRO", "RosType", "ros_type", "RosDecodeError", "RosEncodeError"]

DEFAULT_DISTRO = "jazzy"
_STORES_MODULE = "rosbags.typesys.stores"  # rosbags' modules of message classes, one per typestore


class RosDecodeError(AnodizeError):
    """Raised by :meth:`RosType.deserialize` for bytes that are not a message of the type.

    Attributes:
        type_name: the message type, ``pkg/msg/Name``.
        reason: what is wrong with the bytes.
    """

    def __init__(self, type_name: str, reason: str) -> None:
        self.type_name = type_name
        self.reason = reason
        super().__init__(str(self))

    def __str__(self) -> str:
        return f"cannot decode a {self.type_name}: {self.reason}"


class RosEncodeError(AnodizeError):
    """Raised by :meth:`RosType.serialize` for a value that is not a message of the type.

    Attributes:
        type_name: the message type, ``pkg/msg/Name``.
        reason: why the value does not fit (what :meth:`RosType.check` says).
    """

    def __init__(self, type_name: str, reason: str) -> None:
        self.type_name = type_name
        self.reason = reason
        super().__init__(str(self))

    def __str__(self) -> str:
        return f"cannot encode a {self.type_name}: {self.reason}"


@dataclass(frozen=True)
class RosType:
    """One ROS 2 message type of one distribution; get it from :func:`ros_type` (one per name and distro).

    Attributes:
        name: ``pkg/msg/Name``, e.g. ``geometry_msgs/msg/Twist``.
        distro: the ROS 2 distribution whose definition this is, e.g. ``jazzy``.
        cls: rosbags' dataclass of the message: what role code constructs and receives.
        dds_name: the DDS type name ROS 2 uses, e.g. ``geometry_msgs::msg::dds_::Twist_``.
        type_hash: the RIHS01 hash ROS 2 (Iron and later) advertises: ``RIHS01_`` and 64 hex digits.
    """

    name: str
    distro: str
    cls: type = field(compare=False)
    dds_name: str = field(compare=False)
    type_hash: str = field(compare=False)
    _store: Any = field(compare=False, repr=False)  # rosbags' Typestore of the distro
    _compiled: Compiled = field(compare=False, repr=False)

    def check(self, value: object) -> str | None:
        """Why ``value`` is not a message of this type (None: it is).

        Checked field by field against the definition: integer kinds with their ranges
        (``byte`` as rosbags holds it, -128..127; ``char`` 0..255), ``bool``, floats (an
        int fits, a bool does not; a float32 must not round to infinity), strings (UTF-8;
        ``string<=N``: at most N bytes), fixed arrays ``T[N]`` (exactly N items), bounded
        sequences ``T[<=N]`` (at most N), nested messages (an instance of their rosbags
        class, recursively). An array or sequence of a primitive kind may be a 1-D numpy
        array of rosbags' dtype for it (what rosbags decodes), a list or tuple of fitting
        values, or for one-byte kinds ``bytes``; numpy scalars fit where their kind does.

        Returns:
            None, or the reason naming the field, e.g. ``field header.stamp.sec: expected
            int32 (-2**31..2**31-1), got 4294967296`` or ``field poses[3].pose: ...``.
        """
        compiled = self._compiled
        if compiled.fits(value):
            return None
        try:
            failure = compiled.explain(value)
        except Exception as error:  # a value whose __len__ or __eq__ misbehaves
            return f"cannot check the value: {type(error).__name__}: {error}"
        return None if failure is None else failure_text(failure)

    def serialize(self, value: object) -> bytes:
        """``value`` as ROS 2 publishes it: the encapsulation header ``00 01 00 00``, then little-endian CDR.

        Raises:
            RosEncodeError: ``value`` is not a message of this type (:meth:`check`).
        """
        reason = self.check(value)
        if reason is not None:
            raise RosEncodeError(self.name, reason)
        if self._compiled.prepare is not None:
            value = self._compiled.prepare(value)
        try:
            data = self._store.serialize_cdr(value, self.name, little_endian=True)
        except Exception as error:  # check passed: a case it does not foresee, still the value's
            raise RosEncodeError(self.name, f"{type(error).__name__}: {error}") from None
        return bytes(data)

    def deserialize(self, data: bytes | bytearray | memoryview) -> object:
        """The message in ``data``: CDR with its encapsulation header (either byte order).

        Arrays of primitive kinds in the result are numpy arrays viewing ``data`` (no
        copy): read-only when ``data`` is ``bytes``; pass a copy if its buffer will be
        reused. Bounds of strings and sequences are checked as well.

        Raises:
            RosDecodeError: ``data`` is truncated, malformed, or breaks a bound of the type.
        """
        try:
            view = memoryview(data).cast("B")  # slices of a view copy nothing (slices of bytes would)
            value = self._store.deserialize_cdr(view, self.name)
        except Exception as error:  # whatever the bytes provoke, they are not a message
            raise RosDecodeError(self.name, f"{type(error).__name__}: {error}") from None
        if self._compiled.bounded:  # rosbags' decoder does not check bounds
            reason = self.check(value)
            if reason is not None:
                raise RosDecodeError(self.name, reason)
        return value

    def message_definition(self) -> str:
        """The ``.msg`` text with every nested definition after it, as rosbag2 stores a ``ros2msg`` schema."""
        text: str = self._store.generate_msgdef(self.name, ros_version=2)[0]
        return text

    def field_descriptions(self) -> list[tuple[str, Any]]:
        """rosbags' definition of the fields: ``(field name, (node type, detail))`` in order."""
        fields: list[tuple[str, Any]] = self._store.fielddefs[self.name][1]
        return fields

    def idl_class(self) -> type:
        """The Cyclone DDS ``IdlStruct`` of this type (see :func:`anodize._ros.idl.idl_class`)."""
        return idl_class(self, ros_type)


_LOCK = threading.RLock()  # resolving a type resolves the types of its fields, under the same lock
_STORES: dict[str, Any] = {}  # distro -> rosbags' Typestore
_TYPES: dict[tuple[str, str], RosType] = {}  # (name, distro) -> its one RosType


def ros_type(name: str, distro: str | None = None) -> RosType:
    """The ROS 2 message type ``name`` of ``distro`` (default :data:`DEFAULT_DISTRO`).

    Args:
        name: ``pkg/msg/Name``, with or without the ``ros:`` of a sort's binding.
        distro: a ROS 2 distribution rosbags knows: ``humble``, ``iron``, ``jazzy``, ...

    Raises:
        AnodizeError: rosbags is not installed, it does not know the distribution, or the
            distribution has no message ``name``.
    """
    key = (name.removeprefix("ros:"), (distro or DEFAULT_DISTRO).lower())
    found = _TYPES.get(key)
    if found is None:
        with _LOCK:
            found = _TYPES.get(key)
            if found is None:
                found = _TYPES[key] = _resolve(*key)
    return found


def _typestore(distro: str) -> Any:
    store = _STORES.get(distro)
    if store is None:
        import_extra("rosbags.typesys", "ros", 'ROS 2 message types ("ros:pkg/msg/Name" sorts)')
        from rosbags.typesys import Stores, get_typestore

        known = sorted(s.value.removeprefix("ros2_") for s in Stores if s.value.startswith("ros2_"))
        if distro not in known:
            raise AnodizeError(f"unknown ROS 2 distribution {distro!r}; rosbags knows {', '.join(known)}")
        store = _STORES[distro] = get_typestore(Stores(_store_name(distro)))
    return store


def _store_name(distro: str) -> str:
    """rosbags' name of the typestore of ROS 2 ``distro`` (``ros2_jazzy``)."""
    return f"ros2_{distro}"


def rosbags_class(name: str, distro: str | None = None) -> tuple[str, str]:
    """Where rosbags defines the class of message ``name``: ``(module, class name)``.

    What :attr:`RosType.cls` is, spelled for an import (``rosbags.typesys.stores.ros2_jazzy``,
    ``geometry_msgs__msg__Twist``) without importing rosbags: generated code names it.

    Args:
        name: ``pkg/msg/Name``, with or without the ``ros:`` of a sort's binding.
        distro: the distribution (default :data:`DEFAULT_DISTRO`).
    """
    package, kind, message = name.removeprefix("ros:").split("/")
    return f"{_STORES_MODULE}.{_store_name((distro or DEFAULT_DISTRO).lower())}", f"{package}__{kind}__{message}"


def _resolve(name: str, distro: str) -> RosType:
    store = _typestore(distro)
    if name not in store.fielddefs:
        hint = "" if name.count("/") == 2 and name.split("/")[1] == "msg" else " (a sort names a message: pkg/msg/Name)"
        raise AnodizeError(f"ROS 2 {distro} has no message type {name!r}{hint}")
    package, kind, message = name.split("/")
    cls = store.types[name]
    compiled = compile_message(name, cls, store.fielddefs[name][1],
                               lambda nested: ros_type(nested, distro)._compiled)
    return RosType(name=name, distro=distro, cls=cls, dds_name=f"{package}::{kind}::dds_::{message}_",
                   type_hash=store.hash_rihs01(name), _store=store, _compiled=compiled)
