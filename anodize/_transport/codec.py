"""Payloads across processes, without pickle's arbitrary code execution.

A message crosses a process boundary as one *frame*: a 4-byte length, a kind
byte (``M`` message, ``F`` the sender failed), then for a message the label and
the payload in a small tagged format:

- builtin values (None, bool, int, float, str, bytes, bytearray, complex) and
  containers of them (tuple, list, dict, set, frozenset) are encoded directly;
- numpy arrays of plain dtypes are encoded inline when small, and through a
  shared-memory slot when large (see :mod:`anodize._transport.shm`); numpy scalars inline;
- instances of dataclasses the protocol names as sorts are encoded field by
  field and rebuilt without calling their ``__init__``;
- ROS 2 messages of the ``"ros:pkg/msg/Name"`` sorts the protocol names travel as
  the CDR bytes ROS 2 publishes (:meth:`anodize._ros.RosType.serialize`), held in a
  uint8 array (so a large one, an image, goes through shared memory like any
  array), and are rebuilt by the type's CDR decoder (:meth:`~anodize._ros.RosType.deserialize`);
- instances of other classes the protocol names (not dataclasses) are pickled. A
  pickled payload is accepted only on a codec given that very class; before it is
  unpickled it is scanned (:mod:`anodize._transport.pickle_guard`): only the opcodes of builtin data
  and of one instance of that class, memo indices in sequence, lengths within the
  data; the unpickler then loads that class and no other. The class's own
  ``__new__``, ``__init__`` (through ``__reduce__``), ``__setstate__`` and container
  methods still run in the receiver: that is the risk a protocol takes by naming a
  class that is not a dataclass (docs/decisions/0006-pickle-on-the-wire.md).

Anything else is refused when it is sent, with a message saying why. Decoding
never executes code from the wire: a malformed frame raises :class:`DecodeError`.
"""

from __future__ import annotations

import dataclasses
import io
import pickle
import struct
import sys
from collections import deque
from collections.abc import Callable, Iterable
from enum import IntEnum
from typing import TYPE_CHECKING, Any

from ..errors import AnodizeError
from .frames import decode_run as _decode_run
from .pickle_guard import PICKLE_PROTOCOL, PickleRefusedError, scan_pickle, travels_pickled, unpickle

if TYPE_CHECKING:
    from .._ros import RosType

__all__ = ["Codec", "make_codec", "DecodeError", "EncodeError", "INLINE_ARRAY_LIMIT", "MAX_FRAME", "HEADER",
           "FrameKind", "Tag"]

HEADER = struct.Struct("<I")  # frame length, not counting these 4 bytes
INLINE_ARRAY_LIMIT = 64 * 1024  # bytes: larger arrays travel through shared memory
MAX_FRAME = 64 * 2**20  # bytes: a receiver buffers no more for one message

_I64 = struct.Struct("<q")
_F64 = struct.Struct("<d")
_U32 = struct.Struct("<I")
_U8 = struct.Struct("<B")
_C128 = struct.Struct("<dd")
_I64_MIN, _I64_MAX = -(2**63), 2**63 - 1



class FrameKind(IntEnum):
    """The byte after a frame's length: what the frame carries."""

    MESSAGE = 0x4D  # b"M": a label and its payload
    FAILURE = 0x46  # b"F": the sender failed; the rest is the cause, UTF-8


class Tag(IntEnum):
    """The byte before each encoded value: its type. Encoder and decoder share these."""

    NONE = 0
    TRUE = 1
    FALSE = 2
    INT = 3           # 8 bytes, little-endian, signed
    BIGINT = 4        # decimal text
    FLOAT = 5
    COMPLEX = 6
    STR = 7
    BYTES = 8
    BYTEARRAY = 9
    TUPLE = 10
    LIST = 11
    DICT = 12
    SET = 13
    FROZENSET = 14
    ARRAY = 15        # numpy array, inline
    SHARED_ARRAY = 16 # numpy array in a shared-memory slot
    NUMPY_SCALAR = 17
    DATACLASS = 18
    PICKLED = 19
    ROS = 20          # a ROS 2 message: its type's name, then its CDR as an array (ARRAY or SHARED_ARRAY)


_TAG_BYTE = {tag: bytes((tag,)) for tag in Tag}  # one-byte prefixes, built once


class EncodeError(AnodizeError):
    """A payload this channel cannot carry (the reason says which part and why)."""


class DecodeError(AnodizeError):
    """A frame that does not decode: corrupt, truncated, or naming a class not allowed."""


# A shared-memory writer: (array) -> (segment name, slot index, byte offset), or None: send it inline.
ArrayWriter = Callable[[Any], tuple[str, int, int] | None]
# A shared-memory reader: (segment name, slot, offset, dtype, shape) -> array.
ArrayReader = Callable[[str, int, int, str, tuple[int, ...]], Any]


class Codec:
    """Encodes and decodes the frames of one channel.

    Args:
        classes: the payload classes the protocol names (``module:Class`` sorts).
        ring: the sender's shared-memory ring (an :class:`anodize._transport.shm.ArrayRing`),
            where large arrays go (None: always inline).
        read_array: how a receiver maps a shared-memory slot (None: refuse them).
        ros_types: the ROS 2 message types the protocol names (``ros:pkg/msg/Name`` sorts).
    """

    def __init__(self, classes: Iterable[type] = (), ring: Any = None,
                 read_array: ArrayReader | None = None, ros_types: Iterable[RosType] = ()) -> None:
        self.classes = {_name_of(c): c for c in classes}
        self.ros_types = {f"{r.distro}:{r.name}": r for r in ros_types}
        self._ros_ids = {r.cls: (name.encode(), r) for name, r in self.ros_types.items()}
        self._class_ids = {c: name for name, c in self.classes.items()}
        # The classes that travel pickled: the only ones a pickled payload may name.
        self._pickled = {name: c for name, c in self.classes.items() if travels_pickled(c)}
        self.ring = ring
        self.write_array: ArrayWriter | None = ring.write if ring is not None else None
        self.read_array = read_array
        self._labels: dict[str, bytes] = {}
        self._empty_frames: dict[str, bytes] = {}  # label -> its whole frame without payload
        self._int_prefixes: dict[str, bytes] = {}  # label -> its frame up to an int payload's 8 bytes
        self._label_names: dict[bytes, str] = {}
        self._numpy: Any = sys.modules.get("numpy")  # imported lazily: only arrays need it

    # ---- frames ------------------------------------------------------------------------
    def message_frame(self, label: str, payload: object) -> bytes:
        """The whole frame for ``label(payload)``.

        Raises:
            EncodeError: the payload holds something this codec refuses.
        """
        # Fast paths for the commonest payloads, whose frames differ only in the payload's
        # bytes: no payload (the whole frame, built once), a small int (a prefix built once).
        if payload is None:
            frame = self._empty_frames.get(label)
            if frame is None:
                frame = self._empty_frames[label] = self._framed(self._head(label) + _TAG_BYTE[Tag.NONE])
            return frame
        if type(payload) is int and _I64_MIN <= payload <= _I64_MAX:
            prefix = self._int_prefixes.get(label)
            if prefix is None:
                head = self._head(label)
                prefix = self._int_prefixes[label] = HEADER.pack(len(head) + 9) + head + _TAG_BYTE[Tag.INT]
            return prefix + _I64.pack(payload)
        out = io.BytesIO()
        out.write(self._head(label))
        self._encode(payload, out, 0)
        body = out.getvalue()
        if len(body) > MAX_FRAME:
            raise EncodeError(f"the payload encodes to {len(body) / 2**20:.1f} MiB, over the "
                              f"{MAX_FRAME // 2**20} MiB a message may take (numpy arrays of any "
                              "size travel through shared memory instead)")
        return self._framed(body)

    def small_frames(self) -> tuple[dict[str, bytes], dict[str, bytes]]:
        """The frames :meth:`message_frame` has cached: per label, the whole frame without a
        payload, and the frame up to a small int's 8 bytes (live: filled as labels are sent)."""
        return self._empty_frames, self._int_prefixes

    def _head(self, label: str) -> bytes:
        """The frame kind and the label, as every message frame of ``label`` begins."""
        head = self._labels.get(label)
        if head is None:
            encoded = label.encode()
            head = self._labels[label] = bytes((FrameKind.MESSAGE,)) + _U32.pack(len(encoded)) + encoded
        return head

    @staticmethod
    def _framed(body: bytes) -> bytes:
        return HEADER.pack(len(body)) + body

    @staticmethod
    def failure_frame(cause: str) -> bytes:
        """The frame telling the receiver that the sender failed, and how."""
        body = bytes((FrameKind.FAILURE,)) + cause.encode(errors="replace")
        return HEADER.pack(len(body)) + body

    def decode_body(self, body: bytes | bytearray | memoryview) -> tuple[int, Any]:
        """``(FrameKind.MESSAGE, (label, payload))`` or ``(FrameKind.FAILURE, cause)``.

        Raises:
            DecodeError: the body is malformed.
        """
        try:
            kind = body[0]
            if kind == FrameKind.FAILURE:
                return kind, bytes(body[1:]).decode(errors="replace")
            if kind != FrameKind.MESSAGE:
                raise DecodeError(f"unknown frame kind {kind:#x}")
            (length,) = _U32.unpack_from(body, 1)
            start = 5 + length
            raw = bytes(body[5:start])
            label = self._label_names.get(raw)
            if label is None:
                label = raw.decode()
                if len(self._label_names) < 4096:  # labels are few; garbage must not grow this
                    self._label_names[raw] = label
            size = len(body)
            if size == start + 1 and body[start] == Tag.NONE:  # the commonest payloads, inline
                return kind, (label, None)
            if size == start + 9 and body[start] == Tag.INT:
                return kind, (label, _I64.unpack_from(body, start + 1)[0])
            payload, end = self._decode(body, start, 0)
            if end != len(body):
                raise DecodeError(f"{len(body) - end} bytes left over after the payload")
            return kind, (label, payload)
        except DecodeError:
            raise
        except Exception as error:  # whatever the bytes provoke, it is the sender's fault
            raise DecodeError(f"malformed frame: {type(error).__name__}: {error}") from None

    def decode_run(self, buffer: bytearray, at: int, into: deque[tuple[object, int]]) -> int:
        """Decode the complete message frames from ``at`` on that carry no payload or a small
        int (the frames :meth:`message_frame` builds from a cached prefix) into ``into``, as
        ``((label, payload), frame size)``; stop at the first other or incomplete frame.

        One loop for a run of small messages costs far less per message than a call per
        frame, and the compiled loop (:mod:`anodize._transport.frames`) far less again. Anything else
        (another payload, a failure frame, a malformed or unknown label) is left for
        :meth:`decode_body`, so every error is still reported there.

        Returns:
            The offset after the last frame decoded.
        """
        return _decode_run(buffer, at, self._label_names, into)

    # ---- encoding ----------------------------------------------------------------------
    def _encode(self, value: Any, out: io.BytesIO, depth: int) -> None:
        # ``value`` is Any: the branches test ``type(value)`` exactly (a subclass is not its base
        # here), which mypy does not narrow on, and isinstance would cost time and change meaning.
        if depth > 100:
            raise EncodeError("payload nested more than 100 levels deep")
        kind = type(value)
        if value is None:
            out.write(_TAG_BYTE[Tag.NONE])
        elif kind is bool:
            out.write(_TAG_BYTE[Tag.TRUE] if value else _TAG_BYTE[Tag.FALSE])
        elif kind is int:
            if _I64_MIN <= value <= _I64_MAX:
                out.write(_TAG_BYTE[Tag.INT] + _I64.pack(value))
            else:
                self._write_blob(Tag.BIGINT, str(value).encode(), out)
        elif kind is float:
            out.write(_TAG_BYTE[Tag.FLOAT] + _F64.pack(value))
        elif kind is complex:
            out.write(_TAG_BYTE[Tag.COMPLEX] + _C128.pack(value.real, value.imag))
        elif kind is str:
            self._write_blob(Tag.STR, value.encode(errors="surrogatepass"), out)
        elif kind is bytes:
            self._write_blob(Tag.BYTES, value, out)
        elif kind is bytearray:
            self._write_blob(Tag.BYTEARRAY, bytes(value), out)
        elif kind in _SEQUENCE_TAGS:
            items = list(value)
            out.write(_U8.pack(_SEQUENCE_TAGS[kind]) + _U32.pack(len(items)))
            for item in items:
                self._encode(item, out, depth + 1)
        elif kind is dict:
            out.write(_U8.pack(Tag.DICT) + _U32.pack(len(value)))
            for key, item in value.items():
                self._encode(key, out, depth + 1)
                self._encode(item, out, depth + 1)
        elif self._is_numpy(value):  # before named classes: a "numpy:ndarray" sort is still an array
            self._encode_numpy(value, out)
        elif kind in self._ros_ids:  # before named classes: a rosbags message is a dataclass too
            self._encode_ros(value, kind, out)
        elif kind in self._class_ids:
            self._encode_named(value, kind, out, depth)
        else:
            raise EncodeError(
                f"cannot carry a {kind.__module__}.{kind.__qualname__} across processes: only "
                "builtin values, containers of them, numpy arrays and classes the protocol "
                "names as sorts travel between groups")

    def _encode_named(self, value: object, kind: type, out: io.BytesIO, depth: int) -> None:
        name = self._class_ids[kind].encode()
        if dataclasses.is_dataclass(kind):
            fields = dataclasses.fields(kind)
            self._write_blob(Tag.DATACLASS, name, out)
            out.write(_U32.pack(len(fields)))
            for f in fields:
                self._write_blob(Tag.STR, f.name.encode(), out)
                self._encode(getattr(value, f.name), out, depth + 1)
        else:
            self._write_blob(Tag.PICKLED, name, out)
            try:
                data = pickle.dumps(value, protocol=PICKLE_PROTOCOL)
            except Exception as error:  # any pickling failure of user code
                raise EncodeError(f"cannot pickle {kind.__qualname__}: {error}") from None
            reason = scan_pickle(data, kind)  # what the receiver would refuse, refused here
            if reason is not None:
                raise EncodeError(f"cannot send a pickled {kind.__qualname__}: {reason}")
            out.write(_U32.pack(len(data)) + data)

    def _encode_ros(self, value: object, kind: type, out: io.BytesIO) -> None:
        name, ros = self._ros_ids[kind]
        try:
            data = ros.serialize(value)
        except AnodizeError as error:
            raise EncodeError(str(error)) from None
        self._write_blob(Tag.ROS, name, out)
        self._numpy = np = sys.modules["numpy"]  # rosbags imported it
        self._encode_numpy(np.frombuffer(data, np.uint8), out)

    def _is_numpy(self, value: object) -> bool:
        if self._numpy is None:
            self._numpy = sys.modules.get("numpy")
        np = self._numpy
        return np is not None and isinstance(value, (np.ndarray, np.generic))

    def _encode_numpy(self, value: Any, out: io.BytesIO) -> None:
        np = self._numpy
        if value.dtype.hasobject or value.dtype.fields is not None:
            raise EncodeError(f"cannot carry a numpy {value.dtype} array: only plain numeric "
                              "dtypes travel between groups")
        dtype = value.dtype.str.encode()
        if isinstance(value, np.generic):
            self._write_blob(Tag.NUMPY_SCALAR, dtype, out)
            self._write_blob(Tag.BYTES, value.tobytes(), out)
            return
        shape = b"".join(_I64.pack(n) for n in value.shape)
        address = None
        if self.write_array is not None and (
                value.nbytes > INLINE_ARRAY_LIMIT or self.ring.owns(value)):  # a filled slot goes as it is
            address = self.write_array(value)  # None: the receiver holds every slot; copy it inline
        if address is not None:
            segment, slot, offset = address
            self._write_blob(Tag.SHARED_ARRAY, dtype, out)
            out.write(_U8.pack(value.ndim) + shape)
            self._write_blob(Tag.STR, segment.encode(), out)
            out.write(_U32.pack(slot) + _I64.pack(offset))
        else:
            self._write_blob(Tag.ARRAY, dtype, out)
            out.write(_U8.pack(value.ndim) + shape)
            self._write_blob(Tag.BYTES, np.ascontiguousarray(value).tobytes(), out)

    @staticmethod
    def _write_blob(tag: int, data: bytes, out: io.BytesIO) -> None:
        out.write(_U8.pack(tag) + _U32.pack(len(data)))
        out.write(data)

    # ---- decoding ----------------------------------------------------------------------
    def _decode(self, buf: Any, at: int, depth: int) -> tuple[Any, int]:
        if depth > 100:
            raise DecodeError("payload nested more than 100 levels deep")
        tag = buf[at]
        at += 1
        if tag == Tag.NONE:
            return None, at
        if tag == Tag.TRUE:
            return True, at
        if tag == Tag.FALSE:
            return False, at
        if tag == Tag.INT:
            return _I64.unpack_from(buf, at)[0], at + 8
        if tag == Tag.FLOAT:
            return _F64.unpack_from(buf, at)[0], at + 8
        if tag == Tag.COMPLEX:
            real, imag = _C128.unpack_from(buf, at)
            return complex(real, imag), at + 16
        if tag in _BLOB_DECODERS:
            data, at = _read_blob(buf, at)
            return _BLOB_DECODERS[tag](data), at
        if tag in _SEQUENCE_BUILDERS:
            (count,) = _U32.unpack_from(buf, at)
            at += 4
            items = []
            for _ in range(count):
                item, at = self._decode(buf, at, depth + 1)
                items.append(item)
            return _SEQUENCE_BUILDERS[tag](items), at
        if tag == Tag.DICT:
            (count,) = _U32.unpack_from(buf, at)
            at += 4
            result = {}
            for _ in range(count):
                key, at = self._decode(buf, at, depth + 1)
                result[key], at = self._decode(buf, at, depth + 1)
            return result, at
        if tag in (Tag.ARRAY, Tag.SHARED_ARRAY, Tag.NUMPY_SCALAR):
            return self._decode_numpy(tag, buf, at)
        if tag == Tag.DATACLASS:
            return self._decode_dataclass(buf, at, depth)
        if tag == Tag.PICKLED:
            return self._decode_pickled(buf, at)
        if tag == Tag.ROS:
            return self._decode_ros(buf, at)
        raise DecodeError(f"unknown payload tag {tag}")

    def _decode_ros(self, buf: Any, at: int) -> tuple[Any, int]:
        raw, at = _read_blob(buf, at)
        name = raw.decode(errors="replace")
        ros = self.ros_types.get(name)
        if ros is None:
            raise DecodeError(f"ROS message type {name!r} is not named by the protocol")
        if buf[at] not in (Tag.ARRAY, Tag.SHARED_ARRAY):
            raise DecodeError(f"the {ros.name} message's data is not an array")
        data, at = self._decode_numpy(buf[at], buf, at + 1)
        if data.dtype.str != "|u1" or data.ndim != 1:
            raise DecodeError(f"the {ros.name} message's data is a {data.dtype} array of {data.ndim} dimensions")
        try:  # arrays in the message view ``data``: a private copy, or a shared-memory slot held while they live
            return ros.deserialize(memoryview(data)), at
        except AnodizeError as error:
            raise DecodeError(str(error)) from None

    def _decode_pickled(self, buf: Any, at: int) -> tuple[Any, int]:
        raw, at = _read_blob(buf, at)
        name = raw.decode(errors="replace")
        cls = self._pickled.get(name)
        if cls is None:  # decided on the name alone: not one byte of the pickle is looked at
            named = self.classes.get(name)
            if named is None:
                nothing = "" if self._pickled else "; nothing travels pickled on this channel"
                raise DecodeError(f"pickled payload class {name!r} is not named by the protocol{nothing}")
            why = "a dataclass travels field by field" if dataclasses.is_dataclass(named) else "it has its own tag"
            raise DecodeError(f"pickled payload class {name!r} never travels pickled ({why})")
        (length,) = _U32.unpack_from(buf, at)
        data = bytes(buf[at + 4:at + 4 + length])
        if len(data) != length:
            raise DecodeError("truncated pickled payload")
        reason = scan_pickle(data, cls)
        if reason is not None:
            raise DecodeError(f"pickled payload of class {name!r} refused: {reason}")
        try:
            return unpickle(data, cls), at + 4 + length
        except PickleRefusedError as refused:
            raise DecodeError(str(refused)) from None

    def _named_class(self, name: bytes) -> type:
        cls = self.classes.get(name.decode())
        if cls is None:
            raise DecodeError(f"payload class {name.decode()!r} is not named by the protocol")
        return cls

    def _decode_dataclass(self, buf: Any, at: int, depth: int) -> tuple[Any, int]:
        name, at = _read_blob(buf, at)
        cls = self._named_class(name)
        if not dataclasses.is_dataclass(cls):
            raise DecodeError(f"payload class {name.decode()!r} is not a dataclass")
        missing = {f.name for f in dataclasses.fields(cls)}
        (count,) = _U32.unpack_from(buf, at)
        at += 4
        value = object.__new__(cls)  # no __init__: nothing of the sender's runs here
        for _ in range(count):
            if buf[at] != Tag.STR:
                raise DecodeError("dataclass field name expected")
            raw, at = _read_blob(buf, at + 1)
            field_name = raw.decode()
            if field_name not in missing:
                raise DecodeError(f"{cls.__qualname__} has no field {field_name!r}, or it came twice")
            missing.discard(field_name)
            item, at = self._decode(buf, at, depth + 1)
            object.__setattr__(value, field_name, item)  # frozen dataclasses too
        if missing:
            raise DecodeError(f"{cls.__qualname__} arrived without {', '.join(sorted(missing))}")
        return value, at

    def _decode_numpy(self, tag: int, buf: Any, at: int) -> tuple[Any, int]:
        import numpy as np  # only receivers of arrays pay for the import

        dtype_text, at = _read_blob(buf, at)
        dtype = np.dtype(dtype_text.decode())
        if dtype.hasobject or dtype.fields is not None:
            raise DecodeError(f"numpy dtype {dtype} is not allowed")
        if tag == Tag.NUMPY_SCALAR:
            data, at = _read_blob(buf, at + 1)
            return np.frombuffer(data, dtype)[0], at
        ndim = buf[at]
        shape = tuple(_I64.unpack_from(buf, at + 1 + 8 * i)[0] for i in range(ndim))
        at += 1 + 8 * ndim
        if any(n < 0 for n in shape):
            raise DecodeError(f"negative array shape {shape}")
        if tag == Tag.ARRAY:
            data, at = _read_blob(buf, at + 1)
            return np.frombuffer(data, dtype).reshape(shape).copy(), at
        segment, at = _read_blob(buf, at + 1)
        slot = _U32.unpack_from(buf, at)[0]
        offset = _I64.unpack_from(buf, at + 4)[0]
        if self.read_array is None:
            raise DecodeError("a shared-memory array arrived on a channel without shared memory")
        return self.read_array(segment.decode(), slot, offset, dtype.str, shape), at + 12


def _read_blob(buf: Any, at: int) -> tuple[bytes, int]:
    (length,) = _U32.unpack_from(buf, at)
    start = at + 4
    data = bytes(buf[start:start + length])
    if len(data) != length:
        raise DecodeError("truncated frame")
    return data, start + length


_SEQUENCE_TAGS: dict[type, Tag] = {tuple: Tag.TUPLE, list: Tag.LIST, set: Tag.SET, frozenset: Tag.FROZENSET}
_SEQUENCE_BUILDERS: dict[int, Callable[[list[Any]], Any]] = {
    Tag.TUPLE: tuple, Tag.LIST: lambda items: items, Tag.SET: set, Tag.FROZENSET: frozenset}
_BLOB_DECODERS: dict[int, Callable[[bytes], Any]] = {
    Tag.STR: lambda data: data.decode(errors="surrogatepass"),
    Tag.BYTES: lambda data: data,
    Tag.BYTEARRAY: bytearray,
    Tag.BIGINT: lambda data: int(data.decode()),
}


def _name_of(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


def make_codec(classes: Iterable[type], ring: Any,
               read_array: Callable[..., object] | None, ros_types: Iterable[RosType] = ()) -> Codec:
    """A channel's codec: arrays go to ``ring`` (an :class:`~anodize._transport.shm.ArrayRing`, or None) when
    sending, come from ``read_array`` when receiving."""
    return Codec(classes, ring, read_array, ros_types)
