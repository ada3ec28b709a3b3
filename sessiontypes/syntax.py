"""Surface syntax: the declarations of a ``.proto`` file as written.

Names are resolved later (:mod:`sessiontypes.resolve`): here a bare name is
just a :class:`Name` whose meaning (recursion variable, declaration
reference, sort) depends on context. Every node carries the location of its
first token, left out of equality.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

from .constraints import Expr, Timing
from .location import NOWHERE, Location

__all__ = [
    "Name", "TimingSyntax", "FieldSyntax", "MessageSyntax", "GBranchSyntax", "GInteraction", "GRouted", "GRec", "GRef",
    "GEnd", "GParallel", "GSyntax", "LBranchSyntax", "LAction", "LChoice", "LChoiceAmong", "LRec", "LRef",
    "LEnd", "LParallel", "LSyntax", "TypeDecl", "GlobalDecl", "LocalDecl",
    "Declaration", "SourceFile",
]


@dataclass(frozen=True, slots=True)
class Name:
    """An identifier and where it was written."""

    text: str
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class TimingSyntax:
    """A time clause as written (``every 20ms +- 2ms within 100ms else timeout``).

    ``timing`` holds its values in nanoseconds, located at the clause's first word;
    ``parts`` where each part was written (``within``, ``every``, ``jitter``, ``else``),
    for the errors of the well-formedness rules.
    """

    timing: Timing
    parts: tuple[tuple[str, Location], ...] = field(default=(), compare=False)

    def where(self, part: str) -> Location:
        """Where ``part`` was written (the clause's start if it was not)."""
        return next((location for name, location in self.parts if name == part), self.timing.location)


@dataclass(frozen=True, slots=True)
class FieldSyntax:
    """``name: Sort``, one field of a message with named payloads; ``{...}`` its refinement."""

    name: Name
    sort: Name
    refinement: Expr | None = None


@dataclass(frozen=True, slots=True)
class MessageSyntax:
    """``label(Sort)``, ``label()``, ``label(f: S, ...)`` or a bare ``NAME`` (abbreviation rule).

    ``parens`` tells the written form apart: with parentheses ``sort`` is the
    payload (``None`` for ``label()``); without, the meaning of the bare name
    depends on whether it names a sort. ``fields`` holds named payloads
    (``sort`` is then None). ``refinement`` is the predicate written on the payload's sort
    (``Twist{abs(linear.x) <= 1.5}``).
    """

    label: Name
    sort: Name | None
    parens: bool
    fields: tuple[FieldSyntax, ...] | None = None
    refinement: Expr | None = None


# ---- global ---------------------------------------------------------------

@dataclass(frozen=True, slots=True)
class GBranchSyntax:
    """``msg [. G]`` or the label-only form ``label: G``."""

    message: MessageSyntax
    continuation: GSyntax | None


@dataclass(frozen=True, slots=True)
class GInteraction:
    """``p -> q : msg [. G]`` (``braced`` false) or ``p -> q : {...}``.

    A multicast ``p -> q, r : ...`` is no node of its own: the parser writes it as
    these nodes, one per receiver (docs/language.md).
    """

    sender: Name
    receiver: Name
    branches: tuple[GBranchSyntax, ...]
    braced: bool
    location: Location = field(default=NOWHERE, compare=False)
    timing: TimingSyntax | None = None


@dataclass(frozen=True, slots=True)
class GRouted:
    """``p -> {q1 : msg [. G], q2 : msg [. G], ...}``: a choice whose branches go to different receivers.

    Each branch is written as the interaction ``p -> qi : msg [. G]`` it stands for.
    """

    sender: Name
    branches: tuple[GInteraction, ...]
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class GRec:
    var: Name
    body: GSyntax
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class GRef:
    """A bare name: a recursion variable or a reference to a global declaration."""

    name: Name


@dataclass(frozen=True, slots=True)
class GEnd:
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class GParallel:
    branches: tuple[GSyntax, ...]
    location: Location = field(default=NOWHERE, compare=False)


GSyntax = GInteraction | GRouted | GRec | GRef | GEnd | GParallel


# ---- local ----------------------------------------------------------------

@dataclass(frozen=True, slots=True)
class LBranchSyntax:
    message: MessageSyntax
    continuation: LSyntax | None


@dataclass(frozen=True, slots=True)
class LAction:
    """``!peer(msg)``, ``?peer(msg)``, or the binary ``!Sort`` / ``?Sort`` (peer None)."""

    direction: Literal["!", "?"]
    peer: Name | None
    message: MessageSyntax
    continuation: LSyntax | None
    location: Location = field(default=NOWHERE, compare=False)
    timing: TimingSyntax | None = None


@dataclass(frozen=True, slots=True)
class LChoice:
    """``+peer{...}`` or ``&peer{...}`` (peer None in binary form)."""

    kind: Literal["+", "&"]
    peer: Name | None
    branches: tuple[LBranchSyntax, ...]
    location: Location = field(default=NOWHERE, compare=False)
    timing: TimingSyntax | None = None


@dataclass(frozen=True, slots=True)
class LChoiceAmong:
    """``+{!B(msg)[.T], !C(msg)[.T], ...}`` or ``&{?A(msg)[.T], ?C(msg)[.T], ...}``: branches name their peers."""

    kind: Literal["+", "&"]
    branches: tuple[LAction, ...]
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class LRec:
    var: Name
    body: LSyntax
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class LRef:
    name: Name


@dataclass(frozen=True, slots=True)
class LEnd:
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class LParallel:
    branches: tuple[LSyntax, ...]
    location: Location = field(default=NOWHERE, compare=False)


LSyntax = LAction | LChoice | LChoiceAmong | LRec | LRef | LEnd | LParallel


# ---- declarations -----------------------------------------------------------

@dataclass(frozen=True, slots=True)
class TypeDecl:
    """``type Name = "module:Class"``."""

    name: Name
    target: str
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class GlobalDecl:
    """``global Name[(roles)] = G``."""

    name: Name
    roles: tuple[Name, ...] | None
    body: GSyntax
    location: Location = field(default=NOWHERE, compare=False)


@dataclass(frozen=True, slots=True)
class LocalDecl:
    """``local Name [at Role] = T``."""

    name: Name
    role: Name | None
    body: LSyntax
    location: Location = field(default=NOWHERE, compare=False)


Declaration = TypeDecl | GlobalDecl | LocalDecl


@dataclass(frozen=True, slots=True)
class SourceFile:
    """A parsed file: its path, its text split in lines, its declarations.

    ``shared`` lists global syntax nodes that occur in several places (a
    Scribble ``do`` of one protocol before one continuation is translated
    once), by id, each with the names free in it: resolution resolves each
    once per meaning of those names instead of once per place.
    """

    path: str
    lines: tuple[str, ...]
    declarations: tuple[Declaration, ...]
    shared: Mapping[int, tuple[GSyntax, frozenset[str]]] = field(default_factory=dict, compare=False,
                                                                 repr=False)

    def line(self, number: int) -> str:
        """Return line ``number`` (1-based), or "" if out of range."""
        return self.lines[number - 1] if 0 < number <= len(self.lines) else ""
