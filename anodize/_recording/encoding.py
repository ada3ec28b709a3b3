"""How a payload is written into a recording, and read back.

Every channel of a recording is a ROS 2 topic of a real ROS 2 message type, so that
``ros2 bag play``, rosbags and Foxglove open every channel, not only some:

- a payload of a ROS 2 sort (``"ros:pkg/msg/Name"``) is the CDR ROS 2 publishes, under
  a ``ros2msg`` schema of that type (the bytes that went on the wire);
- any other payload is a ``std_msgs/msg/String`` whose ``data`` is the payload as JSON
  (:func:`to_json`; docs/recording.md describes the format), and the channel's metadata
  names the sort (``anodize.sort``), so the JSON is read back into a value of the sort.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import math
import sys
import types
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from sessiontypes import Sort

from .._ros import RosType, ros_type

__all__ = ["JSON_TYPE", "SortCodec", "codec_for_sort", "to_json", "from_json", "UnknownObject", "imported_class",
           "class_sorts"]

JSON_TYPE = "std_msgs/msg/String"  # the ROS type that carries a JSON payload


@dataclass(frozen=True)
class UnknownObject:
    """A recorded object whose class cannot be rebuilt here (not importable, or not a dataclass)."""

    class_name: str
    text: str


@dataclass(frozen=True)
class SortCodec:
    """How the payloads of one sort (or of no payload: ``sort`` None) are recorded.

    Attributes:
        ros: the ROS 2 type of the recorded messages (the sort's own, or String for JSON).
        json: whether the payload travels as JSON inside a String.
    """

    sort: Sort | None
    ros: RosType
    json: bool

    @property
    def type_name(self) -> str:
        return self.ros.name

    def encode(self, payload: object) -> bytes:
        """The recorded bytes of ``payload`` (CDR with its encapsulation header)."""
        if not self.json:
            return self.ros.serialize(payload)
        text = json.dumps(to_json(payload), separators=(",", ":"), allow_nan=False)
        return self.ros.serialize(self.ros.cls(data=text))

    def decode(self, data: bytes | memoryview) -> object:
        """The payload recorded as ``data``.

        Raises:
            RosDecodeError: ``data`` is not a message of the recorded type.
            ValueError: the String does not hold this format's JSON.
        """
        message = self.ros.deserialize(data)
        if not self.json:
            return message
        try:
            return from_json(json.loads(message.data))  # type: ignore[attr-defined]
        except (RecursionError, TypeError, KeyError, AttributeError, OverflowError) as error:
            # Whatever a hostile recording's JSON provokes, it is not a recorded value.
            raise ValueError(f"not a recorded value: {type(error).__name__}: {error}") from None


def codec_for_sort(sort: Sort | None) -> SortCodec:
    """The recording codec of ``sort`` (None: a label without payload, recorded as JSON ``null``).

    Raises:
        AnodizeError: a ROS 2 sort whose type rosbags does not know.
    """
    if sort is not None and sort.target is not None and sort.target.startswith("ros:"):
        return SortCodec(sort, ros_type(sort.target), json=False)
    return SortCodec(sort, ros_type(JSON_TYPE), json=True)


# ---- the JSON format --------------------------------------------------------------------
# JSON has no tuples, bytes, non-finite floats or classes: those become one-key objects
# whose key starts with "$", which a plain dict never produces (dicts are "$dict" lists).

def to_json(value: object) -> Any:
    """``value`` as JSON-ready data (see docs/recording.md, "Payloads that are not ROS messages")."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else {"$float": repr(value)}
    if isinstance(value, bytearray):
        return {"$bytearray": base64.b64encode(bytes(value)).decode()}
    if isinstance(value, bytes):
        return {"$bytes": base64.b64encode(value).decode()}
    if isinstance(value, complex):
        return {"$complex": [to_json(value.real), to_json(value.imag)]}
    if isinstance(value, list):
        return [to_json(v) for v in value]
    if isinstance(value, tuple):
        return {"$tuple": [to_json(v) for v in value]}
    if isinstance(value, frozenset):
        return {"$frozenset": [to_json(v) for v in value]}
    if isinstance(value, set):
        return {"$set": [to_json(v) for v in value]}
    if isinstance(value, dict):
        return {"$dict": [[to_json(k), to_json(v)] for k, v in value.items()]}
    numpy = _numpy_json(value)
    if numpy is not None:
        return numpy
    kind = type(value)
    name = f"{kind.__module__}:{kind.__qualname__}"
    if dataclasses.is_dataclass(value):
        return {"$dataclass": name,
                "fields": {f.name: to_json(getattr(value, f.name)) for f in dataclasses.fields(value)}}
    return {"$object": name, "repr": repr(value)[:1000]}


def _numpy_json(value: object) -> Any:
    if type(value).__module__ != "numpy":
        return None
    import numpy as np

    if isinstance(value, np.ndarray):
        array = np.ascontiguousarray(value)
        return {"$ndarray": {"dtype": array.dtype.str, "shape": list(array.shape),
                             "data": base64.b64encode(array.tobytes()).decode()}}
    if isinstance(value, np.generic):
        return to_json(value.item())
    return None


def from_json(data: Any) -> object:
    """The value :func:`to_json` wrote as ``data``.

    A dataclass is rebuilt (without calling its ``__init__``, as the process transport
    does) when its class's module is imported already: a recording never makes a module
    be imported. Otherwise, and for other objects, it is an :class:`UnknownObject`.

    Raises:
        ValueError: ``data`` is not in this format.
    """
    if isinstance(data, list):
        return [from_json(v) for v in data]
    if not isinstance(data, dict):
        return data
    if len(data) == 1 or "$dataclass" in data or "$object" in data:
        key = next(iter(data))
        reader = _READERS.get(key)
        if reader is not None:
            return reader(data)
    raise ValueError(f"not a recorded value: an object with keys {sorted(data)[:5]}")


def _read_dataclass(data: dict[str, Any]) -> object:
    name, fields = data["$dataclass"], data.get("fields")
    if not isinstance(name, str) or not isinstance(fields, dict):
        raise ValueError("a recorded dataclass needs a class name and its fields")
    values = {field: from_json(v) for field, v in fields.items()}
    kind = imported_class(name)
    if kind is None:
        return UnknownObject(name, json.dumps(fields)[:1000])
    if not dataclasses.is_dataclass(kind) or {f.name for f in dataclasses.fields(kind)} != set(values):
        return UnknownObject(name, json.dumps(fields)[:1000])
    instance = object.__new__(kind)
    for field, value in values.items():
        object.__setattr__(instance, field, value)
    return instance


def imported_class(name: str) -> type | None:
    """The class ``module:Qualified`` names, if its module is imported already (else None).

    A recording never makes anything be imported (importing runs a module's code), and the
    look-up runs none either: each name is looked up in its namespace's own dict, never
    through ``getattr`` (a module's ``__getattr__`` may import, a metaclass's may do anything).
    """
    module_name, _, qualified = name.partition(":")
    value: object = sys.modules.get(module_name)
    if value is None or not qualified:
        return None
    for part in qualified.split("."):
        namespace = getattr(value, "__dict__", None)  # a module's or a class's own: no code runs
        if not isinstance(namespace, (dict, types.MappingProxyType)):
            return None
        value = namespace.get(part)
    return value if isinstance(value, type) else None


def class_sorts(sorts: Iterable[Sort | None]) -> list[Sort]:
    """The sorts among ``sorts`` (and their records' fields) bound to a class by import path
    (``type X = "module:Name"``; not ROS 2 types, which name no code), each once."""
    found: dict[str, Sort] = {}
    pending = [sort for sort in sorts if sort is not None]
    while pending:
        sort = pending.pop()
        if sort.fields is not None:
            pending.extend(f.sort for f in sort.fields)
        elif sort.target is not None and not sort.target.startswith("ros:"):
            found.setdefault(sort.target, sort)
    return [found[target] for target in sorted(found)]


def _read_ndarray(data: dict[str, Any]) -> object:
    import numpy as np

    spec = data["$ndarray"]
    try:
        raw = base64.b64decode(spec["data"], validate=True)
        return np.frombuffer(raw, dtype=np.dtype(spec["dtype"])).reshape(spec["shape"]).copy()
    except (KeyError, TypeError, ValueError) as error:
        raise ValueError(f"a recorded array that does not decode: {error}") from None


def _number(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"a recorded complex number with a part that is not a number: {value!r}")
    return float(value)


def _pairs(items: Any) -> dict[Any, Any]:
    return {_hashable(from_json(k)): from_json(v) for k, v in items}


def _hashable(value: object) -> object:
    """A set member or dict key as it was: JSON lists were tuples, sets frozensets there."""
    if isinstance(value, list):
        return tuple(_hashable(v) for v in value)
    if isinstance(value, set):
        return frozenset(value)
    return value


_READERS: dict[str, Callable[[dict[str, Any]], object]] = {
    "$float": lambda d: float(d["$float"]),
    "$bytes": lambda d: base64.b64decode(d["$bytes"], validate=True),
    "$bytearray": lambda d: bytearray(base64.b64decode(d["$bytearray"], validate=True)),
    "$complex": lambda d: complex(*(_number(from_json(v)) for v in d["$complex"])),
    "$tuple": lambda d: tuple(from_json(v) for v in d["$tuple"]),
    "$set": lambda d: {_hashable(from_json(v)) for v in d["$set"]},
    "$frozenset": lambda d: frozenset(_hashable(from_json(v)) for v in d["$frozenset"]),
    "$dict": lambda d: _pairs(d["$dict"]),
    "$ndarray": _read_ndarray,
    "$dataclass": _read_dataclass,
    "$object": lambda d: UnknownObject(str(d["$object"]), str(d.get("repr", ""))),
}
