"""The global protocols of a Scribble or nuScr file, as written.

Both languages share this shape (nuScr grew out of Scribble): a protocol is a
block of interactions run in sequence. :mod:`.read` builds it from either
grammar; :mod:`.translate` turns it into the ``.proto`` surface syntax.
Constructs outside the translated subset are refused while reading, so the
tree holds only what can be translated.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..constraints import Expr
from ..location import NOWHERE, Location
from ..syntax import Name

__all__ = [
    "Payload", "Transfer", "Choice", "Rec", "Continue", "Do", "Par", "Interaction",
    "TypeAlias", "Protocol", "ForeignModule",
]


@dataclass(frozen=True, slots=True)
class Payload:
    """One payload element: a type name, nuScr's variable name (``x: T``) and refinement
    (``x: T{x > 0}``, read into the language's expressions) if written."""

    sort: Name
    name: Name | None = None
    refinement: Expr | None = None


@dataclass(frozen=True, slots=True)
class Transfer:
    """``label(payloads) from sender to receivers;``.

    ``label`` is ``None`` for Scribble's empty operator ``(Int) from A to B;``;
    ``parens`` is false for a bare message name (a Scribble ``sig`` or a nuScr label).
    ``annotation`` is nuScr's ``@"..."`` after the ``;``, read as a predicate.
    """

    label: Name | None
    payloads: tuple[Payload, ...]
    parens: bool
    sender: Name
    receivers: tuple[Name, ...]
    location: Location = field(default=NOWHERE, compare=False)
    annotation: Expr | None = None


@dataclass(frozen=True, slots=True)
class Choice:
    """``choice at role { ... } or { ... }``."""

    role: Name
    blocks: tuple[tuple[Interaction, ...], ...]
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Rec:
    """``rec X { ... }``: falling off the end of the block goes on after it."""

    var: Name
    body: tuple[Interaction, ...]
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Continue:
    """``continue X;``."""

    var: Name
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Do:
    """``do Proto(A, B);``: the protocol's body with its roles renamed, inlined."""

    protocol: Name
    roles: tuple[Name, ...]
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Par:
    """``par { ... } and { ... }``."""

    blocks: tuple[tuple[Interaction, ...], ...]
    location: Location = field(default=NOWHERE, compare=False)


Interaction = Transfer | Choice | Rec | Continue | Do | Par


@dataclass(frozen=True, slots=True)
class TypeAlias:
    """Scribble's ``type <java> "java.lang.Integer" from "rt.jar" as Int;``."""

    name: Name
    external: str
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class Protocol:
    """``[aux] global protocol Name(role A, role B) { ... }``.

    An ``aux`` protocol only serves ``do``: it is inlined, never a global of its own.
    """

    name: Name
    roles: tuple[Name, ...]
    body: tuple[Interaction, ...]
    aux: bool
    end: Location
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class ForeignModule:
    """A Scribble or nuScr file: its type aliases and protocols, in file order.

    ``declares_types`` tells the languages apart: a Scribble payload type must be
    declared (or builtin), a nuScr payload type is any name. ``refinements`` is set when a
    nuScr file refines (the ``RefinementTypes`` pragma, or an ``@"..."`` on a message): its
    payloads' variable names are then fields, which refinements name.
    """

    language: str
    aliases: tuple[TypeAlias, ...]
    protocols: tuple[Protocol, ...]
    declares_types: bool
    imports: bool = False
    refinements: bool = False
