"""Payload sorts and interactions (a label with an optional payload sort).

A sort is a builtin, a declared ``type``, or a *record* of named fields
(``quote(price: int, date: str)``; docs/language.md): a value of a
record sort is a ``dict`` with exactly those keys, each holding a value of its
field's sort.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .refine import print_expr

if TYPE_CHECKING:
    from .constraints import Expr

__all__ = ["BUILTIN_SORTS", "Sort", "Field", "Interaction", "builtin_sort", "record_sort", "print_message"]

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
            or ROS 2 type (``ros:pkg/msg/Name``); ``None`` for builtins and records.
        fields: for a record, its fields in written order; ``None`` otherwise.
            ``key`` and ``spelling`` are then ``price: int, date: str`` (the key
            with the fields' keys, the spelling with their spellings), so two
            records are the same sort when their field names, order and sorts are.
    """

    key: str
    spelling: str = field(compare=False)
    target: str | None = field(default=None, compare=False)
    fields: tuple[Field, ...] | None = field(default=None, compare=False)

    @property
    def is_builtin(self) -> bool:
        return self.target is None and self.fields is None

    @property
    def is_record(self) -> bool:
        return self.fields is not None

    def components(self) -> tuple[Sort, ...]:
        """The sorts a value of this sort is made of: a record's field sorts, else the sort itself."""
        if self.fields is None:
            return (self,)
        return tuple([f.sort for f in self.fields])

    def __str__(self) -> str:
        return self.spelling


@dataclass(frozen=True, slots=True)
class Field:
    """One named field of a record sort: ``price: int``."""

    name: str
    sort: Sort
    refinement: Expr | None = None  # ``price: int{price > 0}``: the predicate written on the field


def builtin_sort(spelling: str) -> Sort:
    """Return the builtin sort spelled ``spelling`` (``KeyError`` if none)."""
    return Sort(BUILTIN_SORTS[spelling], spelling)


def record_sort(fields: tuple[Field, ...]) -> Sort:
    """The record sort of ``fields`` (distinct names, in written order; not records themselves).

    A field's refinement is part of its sort: ``price: int{price > 0}`` is another record
    than ``price: int`` (the key and the spelling say so).
    """
    key = ", ".join([f"{f.name}: {f.sort.key}{_refined(f)}" for f in fields])
    spelling = ", ".join([f"{f.name}: {f.sort.spelling}{_refined(f)}" for f in fields])
    return Sort(key, spelling, None, fields)


def _refined(field_: Field) -> str:
    return "" if field_.refinement is None else f"{{{print_expr(field_.refinement)}}}"


@dataclass(frozen=True, slots=True)
class Interaction:
    """What one interaction of a type carries: a label and the sort of its value (``None``: no payload).

    Called ``Message`` up to 0.1.0; ``anodize.Message`` is a different thing, a
    label with the value a role received.

    ``empty_parens`` records that a payload-less label was written ``label()``
    because its name is a sort's; the printer keeps the parentheses so the
    text reads back the same. It is not part of equality.
    """

    label: str
    sort: Sort | None = None
    empty_parens: bool = field(default=False, compare=False)
    refinement: Expr | None = None  # ``Twist{abs(linear.x) <= 1.5}``: the predicate written on the payload


def print_message(message: Interaction) -> str:
    """``Sort``, ``label(Sort)``, ``label(f: Sort, ...)`` or ``label``; a refinement in braces
    after the sort (``Twist{abs(linear.x) <= 1.5}``, ``label(f: int{f > 0})``)."""
    if message.sort is None:
        # 'int' alone would read back as label int carrying an int.
        if message.empty_parens or message.label in BUILTIN_SORTS:
            return f"{message.label}()"
        return message.label
    refined = "" if message.refinement is None else f"{{{print_expr(message.refinement)}}}"
    if message.label == message.sort.spelling:  # never for a record: its spelling has ':'
        return message.label + refined
    return f"{message.label}({message.sort.spelling}{refined})"
