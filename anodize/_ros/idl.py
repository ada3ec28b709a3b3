"""The Cyclone DDS class of a ROS 2 message type, as ROS 2's own middleware declares it.

ROS 2 maps a message ``pkg/msg/Name`` to the IDL struct ``pkg::msg::dds_::Name_`` (its
nested messages likewise) with the field names of the definition and these member
types (rosidl_adapter): ``bool`` boolean, ``byte`` octet, ``char`` uint8, integers and
floats as such, ``string`` and ``string<=N`` (bounded) strings, ``T[N]`` arrays,
``T[]`` and ``T[<=N]`` sequences. Built with the binding's ``make_idl_struct``, so the
XTypes type information Cyclone advertises for a topic of the class carries the ROS
type's names and layout (final extensibility, the binding's default), and the binding's
serialiser writes the same XCDR1 bytes as :meth:`~anodize._ros.RosType.serialize`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from typing import Any, Protocol

from .._extras import import_extra
from ..errors import AnodizeError
from .checks import attr_name

__all__ = ["IdlSource", "idl_class"]


class IdlSource(Protocol):
    """What a class is built from: :class:`anodize._ros.RosType` is one.

    A protocol rather than ``RosType`` itself so that this module sits below
    ``messages`` (which calls it) instead of in a circle with it.
    """

    @property
    def name(self) -> str: ...

    @property
    def distro(self) -> str: ...

    @property
    def dds_name(self) -> str: ...

    def field_descriptions(self) -> Sequence[tuple[str, Any]]:
        """rosbags' field definitions of the type: ``(field name, (node type, detail))``."""
        ...


Resolve = Callable[[str, str], IdlSource]  # (pkg/msg/Name, distro) -> the nested type

_BASE, _NAME, _ARRAY = 1, 2, 3  # rosbags.interfaces.Nodetype: a primitive, a message, a fixed array
_LOCK = threading.RLock()  # a type's class is built after those of its fields, under the same lock
_CLASSES: dict[tuple[str, str], type] = {}  # (name, distro) -> its one class


def idl_class(ros: IdlSource, resolve: Resolve) -> type:
    """The ``IdlStruct`` subclass for ``ros``, typename ``ros.dds_name``; one per (name, distro).

    ``resolve`` gives the types of nested message fields.

    Raises:
        MissingExtraError: the Cyclone DDS binding is not installed (the ros extra).
        AnodizeError: the type has a field
            kind the binding cannot declare (``wstring``).
    """
    key = (ros.name, ros.distro)
    found = _CLASSES.get(key)
    if found is None:
        with _LOCK:
            found = _CLASSES.get(key)
            if found is None:
                found = _CLASSES[key] = _build(ros, resolve)
    return found


def _build(ros: IdlSource, resolve: Resolve) -> type:
    import_extra("cyclonedds.idl", "ros", "the DDS class of a ROS 2 message type")
    from cyclonedds.idl import make_idl_struct

    fields = {attr_name(field_name): _member(ros, field_name, description, resolve)
              for field_name, description in ros.field_descriptions()}
    return make_idl_struct(ros.dds_name.rpartition("::")[2], ros.dds_name, fields)


def _member(ros: IdlSource, field_name: str, description: tuple[Any, Any], resolve: Resolve) -> Any:
    from cyclonedds.idl import types  # optional binding, present once _build got here

    # The binding's generics are classes with __class_getitem__, which mypy does not index.
    array: Any = types.array
    sequence: Any = types.sequence
    node, detail = description
    if node == _BASE:
        return _primitive(ros, field_name, *detail)
    if node == _NAME:
        return idl_class(resolve(detail, ros.distro), resolve)
    (item_node, item_detail), count = detail
    item = (idl_class(resolve(item_detail, ros.distro), resolve) if item_node == _NAME
            else _primitive(ros, field_name, *item_detail))
    if node == _ARRAY:
        return array[item, count]
    return sequence[item, count] if count else sequence[item]


def _primitive(ros: IdlSource, field_name: str, kind: str, bound: int) -> Any:
    from cyclonedds.idl import types  # optional binding, present once _build got here

    bounded_str: Any = types.bounded_str
    if kind == "string":
        return bounded_str[bound] if bound else str
    if kind == "bool":
        return bool
    member = {"byte": types.byte, "char": types.uint8}.get(kind) or getattr(types, kind, None)
    if member is None:
        raise AnodizeError(f"{ros.name} field {field_name}: the Cyclone DDS binding has no member type for {kind}")
    return member
