"""Payload sorts and messages (a label with an optional payload sort)."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["BUILTIN_SORTS", "Sort", "Message", "builtin_sort"]

# Every spelling of a builtin sort, mapped to its canonical name.
BUILTIN_SORTS: dict[str, str] = {
    "int": "int", "Int": "int",
    "nat": "nat", "Nat": "nat",
    "bool": "bool", "Bool": "bool",
    "str": "str", "String": "str",
    "float": "float", "Float": "float",
    "bytes": "bytes", "Bytes": "bytes",
}


@dataclass(frozen=True, slots=True)
class Sort:
    """The sort of a payload.

    Attributes:
        key: identity for every check: the canonical builtin name (``int``)
            or the name of the ``type`` declaration (``Twist``).
        spelling: how it was written where it occurs; used only for printing.
        target: for declared sorts, the bound class (``module:QualifiedName``)
            or ROS 2 type (``ros:pkg/msg/Name``); ``None`` for builtins.
    """

    key: str
    spelling: str = field(compare=False)
    target: str | None = field(default=None, compare=False)

    @property
    def is_builtin(self) -> bool:
        return self.target is None

    def __str__(self) -> str:
        return self.spelling


def builtin_sort(spelling: str) -> Sort:
    """Return the builtin sort spelled ``spelling`` (``KeyError`` if none)."""
    return Sort(BUILTIN_SORTS[spelling], spelling)


@dataclass(frozen=True, slots=True)
class Message:
    """A label and the sort of the value it carries (``None``: no payload).

    ``empty_parens`` records that a payload-less label was written ``label()``
    because its name is a sort's; the printer keeps the parentheses so the
    text reads back the same. It is not part of equality.
    """

    label: str
    sort: Sort | None = None
    empty_parens: bool = field(default=False, compare=False)
