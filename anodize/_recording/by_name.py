"""Payload checks that run no code: what ``verify`` checks when the protocol came from the recording.

A sort bound to a class by import path (``type X = "module:Name"``) would be checked by
importing the class, and a recording's protocol is untrusted: then the payload is checked
by the class name the recording gives it (``module:Qualified``, :mod:`.encoding`), and a
record sort by its fields, each checked so. Builtin and ROS 2 sorts name no code: their
checks are the usual ones.
"""

from __future__ import annotations

from sessiontypes import Sort

from .._session.payloads import Validator, record_validator, validator_for
from .encoding import UnknownObject

__all__ = ["validator_by_name", "sort_text"]


def validator_by_name(sort: Sort | None) -> Validator:
    """The check of a payload of ``sort`` that imports nothing (see the module docstring)."""
    if sort is None or (sort.fields is None and (sort.target is None or sort.target.startswith("ros:"))):
        return validator_for(sort)  # no payload, a builtin or a ROS 2 type: nothing is imported
    if sort.fields is not None:
        return _record(sort)
    target, wanted = sort.target, sort_text(sort)

    def check(payload: object) -> str | None:
        if isinstance(payload, UnknownObject):  # its class is not imported here: its recorded name
            found = payload.class_name
            return None if found == target else f"a recorded {found}, the label carries {wanted}"
        # A class rebuilt from a module imported already (never imported for this): it or a base by name.
        names = {f"{kind.__module__}:{kind.__qualname__}" for kind in type(payload).__mro__}
        return None if target in names else f"a recorded {_name(type(payload))}, the label carries {wanted}"
    return check


def _record(sort: Sort) -> Validator:
    """Named payloads: a ``dict`` with exactly the record's field names, each checked by name."""
    return record_validator(sort, validator_by_name)


def sort_text(sort: Sort | None) -> str:
    """A sort as a violation shows it: ``Twist (ros:geometry_msgs/msg/Twist)``, ``int``, ``no payload``."""
    if sort is None:
        return "no payload"
    return f"{sort.spelling} ({sort.target})" if sort.target else sort.spelling


def _name(kind: type) -> str:
    return kind.__name__ if kind.__module__ == "builtins" else f"{kind.__module__}:{kind.__qualname__}"
