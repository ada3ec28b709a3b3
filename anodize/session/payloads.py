"""Checking payloads against the sorts of a protocol.

Builtin sorts map to Python types (``nat`` is an ``int >= 0``; ``float``
also takes an ``int``); a declared sort ``"module:QualifiedName"`` is checked
with ``isinstance`` against that class, imported once when a monitor is
built. ROS 2 sorts (``"ros:pkg/msg/Name"``) cannot be checked without ROS:
any payload is accepted for them.
"""

from __future__ import annotations

import dataclasses
import importlib
import typing
from collections.abc import Callable, Iterable

from sessiontypes import Sort

from ..errors import AnodizeError

__all__ = ["Validator", "validator_for", "exact_types_for", "resolve_class", "with_field_classes"]

# A validator returns None when the payload fits, or why it does not.
Validator = Callable[[object], "str | None"]


def _no_payload(payload: object) -> str | None:
    return None if payload is None else f"this label carries no payload, got {type(payload).__name__}"


def _of(*types: type, name: str) -> Validator:
    def check(payload: object) -> str | None:
        if isinstance(payload, types) and not (isinstance(payload, bool) and bool not in types):
            return None
        return f"expected a payload of sort {name}, got {type(payload).__name__}"
    return check


def _nat(payload: object) -> str | None:
    if isinstance(payload, int) and not isinstance(payload, bool):
        return None if payload >= 0 else f"expected a payload of sort nat (>= 0), got {payload}"
    return f"expected a payload of sort nat, got {type(payload).__name__}"


_BUILTIN: dict[str, Validator] = {
    "int": _of(int, name="int"),
    "nat": _nat,
    "bool": _of(bool, name="bool"),
    "str": _of(str, name="str"),
    "float": _of(float, int, name="float"),
    "bytes": _of(bytes, name="bytes"),
}


def _anything(payload: object) -> str | None:
    return None


def resolve_class(target: str) -> type:
    """Import the class named by ``"module:QualifiedName"``.

    Raises:
        AnodizeError: the module or the name cannot be found.
    """
    module_name, _, qualified = target.partition(":")
    try:
        value: object = importlib.import_module(module_name)
        for part in qualified.split("."):
            value = getattr(value, part)
    except (ImportError, AttributeError) as error:
        raise AnodizeError(f"cannot load payload class {target!r}: {error}") from None
    if not isinstance(value, type):
        raise AnodizeError(f"payload class {target!r} is not a class")
    return value


def with_field_classes(classes: Iterable[type]) -> list[type]:
    """``classes`` and every dataclass their dataclass fields are declared with, recursively.

    A sort such as ``PoseStamped`` names one class, but its fields hold a ``Header``
    and a ``Pose``: those are part of the message type the protocol names, so they
    may cross processes too (``tuple[PoseStamped, ...]`` fields count as well).
    """
    found: dict[type, None] = {}
    pending = list(classes)
    while pending:
        kind = pending.pop()
        if kind in found:
            continue
        found[kind] = None
        if dataclasses.is_dataclass(kind):
            try:
                hints = typing.get_type_hints(kind)
            except Exception:  # unresolvable annotations: keep the class, skip its fields
                continue
            for hint in hints.values():
                pending.extend(_dataclasses_in(hint))
    return list(found)


def _dataclasses_in(hint: object) -> list[type]:
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return [hint]
    return [k for arg in typing.get_args(hint) for k in _dataclasses_in(arg)]


def validator_for(sort: Sort | None) -> Validator:
    """The payload check for a transition carrying ``sort`` (None: no payload)."""
    if sort is None:
        return _no_payload
    if sort.target is None:
        return _BUILTIN[sort.key]
    if sort.target.startswith("ros:"):
        return _anything
    cls = resolve_class(sort.target)
    return _of(cls, name=f"{sort.spelling} ({sort.target})")


_EXACT: dict[str, frozenset[type]] = {
    "int": frozenset({int}), "bool": frozenset({bool}), "str": frozenset({str}),
    "float": frozenset({float, int}), "bytes": frozenset({bytes}),
}


def exact_types_for(sort: Sort | None) -> frozenset[type]:
    """Types whose instances fit ``sort`` without calling its validator (a fast path).

    Empty when every payload needs the full check (``nat``, which must be >= 0).
    """
    if sort is None:
        return frozenset({type(None)})
    if sort.target is None:
        return _EXACT.get(sort.key, frozenset())
    if sort.target.startswith("ros:"):
        return frozenset()
    return frozenset({resolve_class(sort.target)})
