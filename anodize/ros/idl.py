"""The Cyclone DDS class of a ROS 2 message type, as ROS 2's own middleware declares it.

ROS 2 maps a message ``pkg/msg/Name`` to the IDL struct ``pkg::msg::dds_::Name_`` (its
nested messages likewise) with the field names of the definition and these member
types (rosidl_adapter): ``bool`` boolean, ``byte`` octet, ``char`` uint8, integers and
floats as such, ``string`` and ``string<=N`` (bounded) strings, ``T[N]`` arrays,
``T[]`` and ``T[<=N]`` sequences. Built with the binding's ``make_idl_struct``, so the
XTypes type information Cyclone advertises for a topic of the class carries the ROS
type's names and layout (final extensibility, the binding's default), and the binding's
serialiser writes the same XCDR1 bytes as :meth:`~anodize.ros.RosType.serialize`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from .._extras import import_extra
from ..errors import AnodizeError
from .checks import attr_name

if TYPE_CHECKING:
    from .messages import RosType

__all__ = ["idl_class"]

_BASE, _NAME, _ARRAY = 1, 2, 3  # rosbags.interfaces.Nodetype: a primitive, a message, a fixed array
_LOCK = threading.RLock()  # a type's class is built after those of its fields, under the same lock
_CLASSES: dict[tuple[str, str], type] = {}  # (name, distro) -> its one class


def idl_class(ros: RosType) -> type:
    """The ``IdlStruct`` subclass for ``ros``, typename ``ros.dds_name``; one per (name, distro).

    Raises:
        AnodizeError: the Cyclone DDS binding is not installed, or the type has a field
            kind the binding cannot declare (``wstring``).
    """
    key = (ros.name, ros.distro)
    found = _CLASSES.get(key)
    if found is None:
        with _LOCK:
            found = _CLASSES.get(key)
            if found is None:
                found = _CLASSES[key] = _build(ros)
    return found


def _build(ros: RosType) -> type:
    import_extra("cyclonedds.idl", "ros", "the DDS class of a ROS 2 message type")
    from cyclonedds.idl import make_idl_struct

    from .messages import ros_type

    definition = ros._store.fielddefs[ros.name][1]  # rosbags' Typestore: anodize.ros's own
    fields = {attr_name(field_name): _member(ros, field_name, description, ros_type)
              for field_name, description in definition}
    return make_idl_struct(ros.dds_name.rpartition("::")[2], ros.dds_name, fields)


def _member(ros: RosType, field_name: str, description: tuple[Any, Any],
            resolve: Callable[[str, str], RosType]) -> Any:
    from cyclonedds.idl import types

    # The binding's generics are classes with __class_getitem__, which mypy does not index.
    array: Any = types.array
    sequence: Any = types.sequence
    node, detail = description
    if node == _BASE:
        return _primitive(ros, field_name, *detail)
    if node == _NAME:
        return idl_class(resolve(detail, ros.distro))
    (item_node, item_detail), count = detail
    item = (idl_class(resolve(item_detail, ros.distro)) if item_node == _NAME
            else _primitive(ros, field_name, *item_detail))
    if node == _ARRAY:
        return array[item, count]
    return sequence[item, count] if count else sequence[item]


def _primitive(ros: RosType, field_name: str, kind: str, bound: int) -> Any:
    from cyclonedds.idl import types

    bounded_str: Any = types.bounded_str
    if kind == "string":
        return bounded_str[bound] if bound else str
    if kind == "bool":
        return bool
    member = {"byte": types.byte, "char": types.uint8}.get(kind) or getattr(types, kind, None)
    if member is None:
        raise AnodizeError(f"{ros.name} field {field_name}: the Cyclone DDS binding has no member type for {kind}")
    return member
