"""Global types: the core calculus a protocol's ``global`` declarations denote.

A global type term is one of :class:`Choice` (``p -> q : {l_i(S_i). G_i}``;
a single message is a choice with one branch), :class:`Routed` (``p -> {q_i :
l_i(S_i). G_i}``: a choice whose branches go to different receivers), :class:`Rec`, :class:`Var`,
:class:`End` and :class:`Parallel`. Terms are frozen, slotted dataclasses
whose :class:`~sessiontypes.location.Location` is left out of equality.
This module imports no stage: the named, checked declaration users hold,
with its ``project``, is :class:`sessiontypes.declarations.GlobalType`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .constraints import Timing
from .location import NOWHERE, Location
from .sorts import Interaction

__all__ = [
    "Branch", "Choice", "RoutedBranch", "Routed", "Rec", "Var", "End", "Parallel", "GlobalTerm", "children",
]


@dataclass(frozen=True, slots=True)
class Branch:
    """One labelled alternative of a :class:`Choice` and what follows it."""

    message: Interaction
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
    timing: Timing | None = None  # ``within``/``every`` written on the interaction (all its branches)


@dataclass(frozen=True, slots=True)
class RoutedBranch:
    """One alternative of a :class:`Routed` choice: its receiver, its message, what follows."""

    receiver: str
    message: Interaction
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


def children(term: GlobalTerm) -> list[GlobalTerm]:
    """The terms right below ``term``: each branch's continuation, a loop's body, each parallel part."""
    match term:
        case Choice(branches=branches):
            return [b.continuation for b in branches]
        case Routed(branches=routes):
            return [r.continuation for r in routes]
        case Rec(body=body):
            return [body]
        case Parallel(branches=parts):
            return list(parts)
    return []
