"""Local types: one role's view of a protocol.

Terms: :class:`Send` / :class:`Recv` (one message), :class:`Select` (this
role chooses, ``+``) / :class:`Offer` (the peer chooses, ``&``),
:class:`SelectAmong` / :class:`OfferAmong` (the same over branches with
different peers: ``+{!B(m).T, !C(n).U}``, ``&{?A(m).T, ?C(n).U}``), :class:`Rec`,
:class:`Var`, :class:`End`, :class:`Parallel`. A choice with one branch is
always built as a :class:`Send` or :class:`Recv` (see :func:`select` and
:func:`offer`), and a choice among peers whose branches all have one peer as
a :class:`Select` or :class:`Offer` (see :func:`select_among` and
:func:`offer_among`), so each behaviour has exactly one representation. ``peer`` is
``None`` in the binary form of Fig. 1 (one implicit peer).

``str()`` of any term is its canonical print (LANGUAGE.md section 5), written
here (:func:`print_local`) rather than in :mod:`sessiontypes.printer` so that
this module imports no stage: the printer needs the terms, and the terms'
``str()`` needs the print. The named :class:`~sessiontypes.LocalType` users
hold, with ``fsm()``, is in :mod:`sessiontypes.declarations`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .constraints import Timing
from .location import NOWHERE, Location
from .printing import Printer, PrintTooLongError, run_print
from .sorts import Interaction, print_message

__all__ = [
    "Branch", "Send", "Recv", "Select", "Offer", "SelectAmong", "OfferAmong", "Rec", "Var", "End",
    "Parallel", "LocalTerm", "select", "offer", "select_among", "offer_among", "one_timing", "sends_of", "receives_of",
    "print_local", "describe_local",
]


class _Printable:
    __slots__ = ()

    def __str__(self) -> str:
        return print_local(self)  # type: ignore[arg-type]


@dataclass(frozen=True, slots=True, repr=False)
class Branch(_Printable):
    """One labelled alternative of a choice and what follows it.

    ``location`` is that of the global interaction it was projected from (or
    of the local text it was parsed from).
    """

    message: Interaction
    continuation: LocalTerm
    location: Location = field(default=NOWHERE, compare=False)

    def __repr__(self) -> str:
        return f"Branch({self.message!r}, {self.continuation!r})"


@dataclass(frozen=True, slots=True, repr=False)
class Send(_Printable):
    """``!peer(message).continuation``."""

    peer: str | None
    message: Interaction
    continuation: LocalTerm
    location: Location = field(default=NOWHERE, compare=False)
    timing: Timing | None = None  # the global interaction's, if this role owns any of it

    def __repr__(self) -> str:
        return f"Send({str(self)!r})"


@dataclass(frozen=True, slots=True, repr=False)
class Recv(_Printable):
    """``?peer(message).continuation``."""

    peer: str | None
    message: Interaction
    continuation: LocalTerm
    location: Location = field(default=NOWHERE, compare=False)
    timing: Timing | None = None  # the global interaction's, if this role owns any of it

    def __repr__(self) -> str:
        return f"Recv({str(self)!r})"


@dataclass(frozen=True, slots=True, repr=False)
class Select(_Printable):
    """``+peer{branches}``: internal choice, at least two branches."""

    peer: str | None
    branches: tuple[Branch, ...]
    location: Location = field(default=NOWHERE, compare=False)
    timing: Timing | None = None  # the global interaction's, if this role owns any of it

    def __repr__(self) -> str:
        return f"Select({str(self)!r})"


@dataclass(frozen=True, slots=True, repr=False)
class Offer(_Printable):
    """``&peer{branches}``: external choice, at least two branches."""

    peer: str | None
    branches: tuple[Branch, ...]
    location: Location = field(default=NOWHERE, compare=False)
    timing: Timing | None = None  # the global interaction's, if this role owns any of it

    def __repr__(self) -> str:
        return f"Offer({str(self)!r})"


@dataclass(frozen=True, slots=True, repr=False)
class SelectAmong(_Printable):
    """``+{!B(m).T, !C(n).U}``: this role sends one of the branches, to peers that differ.

    At least two peers differ; the pairs ``(peer, label)`` are distinct.
    """

    branches: tuple[Send, ...]
    location: Location = field(default=NOWHERE, compare=False)

    def __repr__(self) -> str:
        return f"SelectAmong({str(self)!r})"


@dataclass(frozen=True, slots=True, repr=False)
class OfferAmong(_Printable):
    """``&{?A(m).T, ?C(n).U}``: the first of the branches to arrive, from peers that differ.

    At least two peers differ; the pairs ``(peer, label)`` are distinct.
    """

    branches: tuple[Recv, ...]
    location: Location = field(default=NOWHERE, compare=False)

    def __repr__(self) -> str:
        return f"OfferAmong({str(self)!r})"


@dataclass(frozen=True, slots=True, repr=False)
class Rec(_Printable):
    """``mu var. body``."""

    var: str
    body: LocalTerm
    location: Location = field(default=NOWHERE, compare=False)

    def __repr__(self) -> str:
        return f"Rec({str(self)!r})"


@dataclass(frozen=True, slots=True, repr=False)
class Var(_Printable):
    """A recursion variable."""

    name: str
    location: Location = field(default=NOWHERE, compare=False)

    def __repr__(self) -> str:
        return f"Var({self.name!r})"


@dataclass(frozen=True, slots=True, repr=False)
class End(_Printable):
    """``end``."""

    location: Location = field(default=NOWHERE, compare=False)

    def __repr__(self) -> str:
        return "End()"


@dataclass(frozen=True, slots=True, repr=False)
class Parallel(_Printable):
    """``(T1 || T2 || ...)``: independent branches on disjoint channels."""

    branches: tuple[LocalTerm, ...]
    location: Location = field(default=NOWHERE, compare=False)

    def __repr__(self) -> str:
        return f"Parallel({str(self)!r})"


LocalTerm = Send | Recv | Select | Offer | SelectAmong | OfferAmong | Rec | Var | End | Parallel


def select(peer: str | None, branches: tuple[Branch, ...], location: Location = NOWHERE,
           timing: Timing | None = None) -> LocalTerm:
    """Build an internal choice; one branch gives a :class:`Send`."""
    if len(branches) == 1:
        only = branches[0]
        return Send(peer, only.message, only.continuation, only.location, timing)
    return Select(peer, branches, location, timing)


def offer(peer: str | None, branches: tuple[Branch, ...], location: Location = NOWHERE,
          timing: Timing | None = None) -> LocalTerm:
    """Build an external choice; one branch gives a :class:`Recv`."""
    if len(branches) == 1:
        only = branches[0]
        return Recv(peer, only.message, only.continuation, only.location, timing)
    return Offer(peer, branches, location, timing)


def select_among(branches: tuple[Send, ...], location: Location = NOWHERE) -> LocalTerm:
    """Build an internal choice over (peer, label); one peer gives :func:`select`.

    The branches to one peer are one interaction and share its timing (the first's is kept;
    :func:`one_timing` says whether they agree)."""
    if len({b.peer for b in branches}) == 1:
        return select(branches[0].peer, tuple([Branch(b.message, b.continuation, b.location)
                                              for b in branches]), location, branches[0].timing)
    return SelectAmong(branches, location)


def offer_among(branches: tuple[Recv, ...], location: Location = NOWHERE) -> LocalTerm:
    """Build an external choice over (peer, label); one peer gives :func:`offer` (see :func:`select_among`)."""
    if len({b.peer for b in branches}) == 1:
        return offer(branches[0].peer, tuple([Branch(b.message, b.continuation, b.location)
                                             for b in branches]), location, branches[0].timing)
    return OfferAmong(branches, location)


def one_timing(branches: tuple[Send, ...] | tuple[Recv, ...]) -> bool:
    """Whether the branches to (or from) each peer carry the same timing: one interaction has one."""
    seen: dict[str | None, Timing | None] = {}
    return all(seen.setdefault(branch.peer, branch.timing) == branch.timing for branch in branches)


def sends_of(term: Send | Select | SelectAmong) -> tuple[Send, ...]:
    """The branches of an internal choice (or the one send) as sends that name their peer."""
    match term:
        case Send():
            return (term,)
        case SelectAmong(branches=sends):
            return sends
        case Select(peer=peer, branches=branches, timing=timing):
            return tuple([Send(peer, b.message, b.continuation, b.location, timing) for b in branches])
    raise AssertionError(term)


def receives_of(term: Recv | Offer | OfferAmong) -> tuple[Recv, ...]:
    """The branches of an external choice (or the one receive) as receives that name their peer."""
    match term:
        case Recv():
            return (term,)
        case OfferAmong(branches=recvs):
            return recvs
        case Offer(peer=peer, branches=branches, timing=timing):
            return tuple([Recv(peer, b.message, b.continuation, b.location, timing) for b in branches])
    raise AssertionError(term)


def print_local(term: LocalTerm, limit: int | None = None) -> str:
    """The canonical print of a local type term.

    Raises:
        PrintTooLongError: ``limit`` is given and the print is longer.
    """
    return run_print(_local, term, limit)


def describe_local(term: LocalTerm, limit: int = 4000) -> str:
    """The print of ``term`` if it is at most ``limit`` characters, else its first step and a note.

    For messages and state descriptions, which must stay short whatever the type.
    """
    try:
        return print_local(term, limit)
    except PrintTooLongError:
        return f"{_local_head(term)} (longer than {limit} characters written out)"


def _local_head(term: LocalTerm) -> str:
    """The first action or choice of ``term``, its continuations left out as ``...``."""
    names: list[str] = []
    while isinstance(term, Rec):
        names.append(f"mu {term.var}.")
        term = term.body
    match term:
        case Send() | Recv():
            arrow = "!" if isinstance(term, Send) else "?"
            peer = "" if term.peer is None else f"{term.peer}({print_message(term.message)})"
            head = f"{arrow}{peer or term.message.sort or term.message.label}..."
        case Select(peer=peer, branches=branches) | Offer(peer=peer, branches=branches):
            symbol = "+" if isinstance(term, Select) else "&"
            head = f"{symbol}{peer or ''}{{{', '.join(print_message(b.message) + '...' for b in branches)}}}"
        case SelectAmong(branches=actions) | OfferAmong(branches=actions):
            symbol = "+" if isinstance(term, SelectAmong) else "&"
            arrow = "!" if isinstance(term, SelectAmong) else "?"
            head = f"{symbol}{{{', '.join(f'{arrow}{a.peer}({print_message(a.message)})...' for a in actions)}}}"
        case Parallel(branches=branches):
            head = "(" + " || ".join(["..."] * len(branches)) + ")"
        case _:
            head = "..."
    return "".join(names) + head


def _local(term: LocalTerm, printer: Printer) -> str:
    known = printer.known(term)
    if known is not None:
        return known
    start = term
    # Sequences are printed in a loop: a long protocol is one long sequence.
    parts: list[str] = []
    while isinstance(term, (Send, Recv)):
        arrow = "!" if isinstance(term, Send) else "?"
        if term.peer is None:
            parts.append(f"{arrow}{term.message.sort or term.message.label}{_timed(term.timing)}")
        else:
            parts.append(f"{arrow}{term.peer}({print_message(term.message)}){_timed(term.timing)}")
        term = term.continuation
    match term:
        case End():
            if parts:
                return printer.checked(start, ".".join(parts))
            tail = "end"
        case Var(name=name):
            tail = name
        case Rec(var=var, body=body):
            tail = f"mu {var}.{_local(body, printer)}"
        case Select(peer=peer, branches=branches) | Offer(peer=peer, branches=branches):
            symbol = "+" if isinstance(term, Select) else "&"
            inner = ", ".join([_local_branch(b, printer) for b in branches])
            tail = f"{symbol}{peer or ''}{{{inner}}}{_timed(term.timing)}"
        case SelectAmong(branches=actions) | OfferAmong(branches=actions):
            symbol = "+" if isinstance(term, SelectAmong) else "&"
            tail = f"{symbol}{{{', '.join([_local(a, printer) for a in actions])}}}"
        case Parallel(branches=branches):
            tail = "(" + " || ".join([_local(b, printer) for b in branches]) + ")"
        case _:
            raise AssertionError(f"unexpected local term {term!r}")
    parts.append(tail)
    return printer.checked(start, ".".join(parts))


def _timed(timing: Timing | None) -> str:
    """The time clause after an action or a choice, with its leading space; "" for none."""
    return "" if timing is None else f" {timing}"


def _local_branch(branch: Branch, printer: Printer) -> str:
    head = print_message(branch.message)
    if isinstance(branch.continuation, End):
        return head
    return f"{head}.{_local(branch.continuation, printer)}"
