"""Global types: the core calculus a protocol's ``global`` declarations denote.

A global type term is one of :class:`Choice` (``p -> q : {l_i(S_i). G_i}``;
a single message is a choice with one branch), :class:`Routed` (``p -> {q_i :
l_i(S_i). G_i}``: a choice whose branches go to different receivers), :class:`Rec`, :class:`Var`,
:class:`End` and :class:`Parallel`. Terms are frozen, slotted dataclasses
whose :class:`~sessiontypes.location.Location` is left out of equality.
:class:`GlobalType` is a named, checked global declaration: the object users
hold, with :meth:`GlobalType.project`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .location import NOWHERE, Location
from .sharing import Sharing
from .sorts import Message, Sort

if TYPE_CHECKING:
    from .local_types import LocalType

__all__ = [
    "Branch", "Choice", "RoutedBranch", "Routed", "Rec", "Var", "End", "Parallel", "GlobalTerm", "GlobalType",
]


@dataclass(frozen=True, slots=True)
class Branch:
    """One labelled alternative of a :class:`Choice` and what follows it."""

    message: Message
    continuation: GlobalTerm
    location: Location = field(default=NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Choice:
    """``sender -> receiver : {branches}``: the sender picks one branch."""

    sender: str
    receiver: str
    branches: tuple[Branch, ...]
    location: Location = field(default=NOWHERE, compare=False, repr=False)
    receiver_location: Location = field(default=NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class RoutedBranch:
    """One alternative of a :class:`Routed` choice: its receiver, its message, what follows."""

    receiver: str
    message: Message
    continuation: GlobalTerm
    location: Location = field(default=NOWHERE, compare=False, repr=False)
    receiver_location: Location = field(default=NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Routed:
    """``sender -> {q_1 : l_1. G_1, ...}``: the sender picks one branch, each to its receiver.

    At least two receivers differ (else it is a :class:`Choice`); the pairs
    ``(receiver, label)`` are distinct.
    """

    sender: str
    branches: tuple[RoutedBranch, ...]
    location: Location = field(default=NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Rec:
    """``mu var. body``."""

    var: str
    body: GlobalTerm
    location: Location = field(default=NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Var:
    """A recursion variable bound by an enclosing :class:`Rec`."""

    name: str
    location: Location = field(default=NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class End:
    """``end``: the conversation is over."""

    location: Location = field(default=NOWHERE, compare=False, repr=False)


@dataclass(frozen=True, slots=True)
class Parallel:
    """``(G1 || G2 || ...)``: independent conversations on disjoint channels."""

    branches: tuple[GlobalTerm, ...]
    location: Location = field(default=NOWHERE, compare=False, repr=False)


GlobalTerm = Choice | Routed | Rec | Var | End | Parallel


@dataclass(frozen=True, slots=True, eq=False)
class GlobalType:
    """A checked ``global`` declaration.

    Attributes:
        name: the declaration's name.
        roles: the roles in print order (the declared list, or first occurrence).
        body: the global type term (equation-style references expanded into
            ``mu`` with the declaration's name as variable).
        location: where the declaration starts.
        sorts: every sort declared in the file, by name.
        source_lines: the file's lines, for error messages.
        shared: the nodes ``body`` shares with itself and with the other
            globals of its file (a declaration referred to in several places
            is one node), and projections of them, so projecting stays linear.
    """

    name: str
    roles: tuple[str, ...]
    body: GlobalTerm
    location: Location = NOWHERE
    sorts: Mapping[str, Sort] = field(default_factory=dict, repr=False)
    source_lines: tuple[str, ...] = field(default=(), repr=False)
    shared: Sharing = field(default_factory=Sharing, repr=False)
    # Projections are pure functions of the type; the check computes them all once.
    cached_projections: dict[str, LocalType] = field(default_factory=dict, init=False, repr=False)

    def project(self, role: str) -> LocalType:
        """Return the local type of ``role``.

        Raises:
            KeyError: ``role`` is not a role of this global type.
            ProjectionError: the global type has no projection onto ``role``.
        """
        from .project import project_global

        return project_global(self, role)

    def projections(self) -> dict[str, LocalType]:
        """Return the local type of every role, in role order."""
        return {role: self.project(role) for role in self.roles}

    def __str__(self) -> str:
        from .printer import print_global_decl

        return print_global_decl(self)
