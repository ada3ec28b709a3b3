"""The canonical print of local and global types (LANGUAGE.md section 5).

``!Peer(msg)`` / ``?Peer(msg)``, ``+Peer{msg.T, msg.T}`` / ``&Peer{...}``,
``+{!B(msg).T, !C(msg).T}`` / ``&{?A(msg).T, ?C(msg).T}`` (branches with
different peers), ``mu t.T``, ``(T1 || T2)``, ``.`` without spaces and no trailing ``.end``.
A message prints as ``Sort`` when its label is the sort's spelling,
``label(Sort)`` when they differ, ``label(f: Sort, g: Sort)`` for named
payloads, and ``label`` when it carries nothing.
Global types print in the same style (``A->B:msg.G``, ``A->{B:msg.G, C:msg.G}``) so that printing then
parsing gives the same type back.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from . import global_types as g
from . import local_types as lt
from .deep import run_deep
from .sorts import BUILTIN_SORTS, Message

__all__ = ["print_message", "print_local", "print_global", "print_global_decl", "describe_local",
           "PrintTooLongError"]

Term = TypeVar("Term", lt.LocalTerm, g.GlobalTerm)


class PrintTooLongError(ValueError):
    """The print of a type would be longer than the limit asked for.

    A type that uses a declaration in many places is stored once per
    declaration, but its print writes every use out: ``G_i = A -> B : {l. G_i+1,
    r. G_i+1}`` prints 2**n interactions. Printing stops at the limit instead.
    """

    def __init__(self, limit: int) -> None:
        super().__init__(f"longer than {limit} characters written out")
        self.limit = limit


class _Printer:
    """One print: each node shared between places is printed once (memo by id), within a limit."""

    def __init__(self, limit: int | None) -> None:
        self.limit = limit
        self.done: dict[int, tuple[object, str]] = {}

    def checked(self, term: object, text: str) -> str:
        if self.limit is not None and len(text) > self.limit:
            raise PrintTooLongError(self.limit)
        self.done[id(term)] = (term, text)  # the term is held so that its id stays its own
        return text

    def known(self, term: object) -> str | None:
        found = self.done.get(id(term))
        return found[1] if found is not None and found[0] is term else None


def print_message(message: Message) -> str:
    """``Sort``, ``label(Sort)``, ``label(f: Sort, ...)`` or ``label``."""
    if message.sort is None:
        # 'int' alone would read back as label int carrying an int.
        if message.empty_parens or message.label in BUILTIN_SORTS:
            return f"{message.label}()"
        return message.label
    if message.label == message.sort.spelling:  # never for a record: its spelling has ':'
        return message.label
    return f"{message.label}({message.sort.spelling})"


def print_local(term: lt.LocalTerm, limit: int | None = None) -> str:
    """The canonical print of a local type term.

    Raises:
        PrintTooLongError: ``limit`` is given and the print is longer.
    """
    return _run(_local, term, limit)


def print_global(term: g.GlobalTerm, limit: int | None = None) -> str:
    """The print of a global type term, in the language's own syntax.

    Raises:
        PrintTooLongError: ``limit`` is given and the print is longer.
    """
    return _run(_global, term, limit)


def describe_local(term: lt.LocalTerm, limit: int = 4000) -> str:
    """The print of ``term`` if it is at most ``limit`` characters, else its first step and a note.

    For messages and state descriptions, which must stay short whatever the type.
    """
    try:
        return print_local(term, limit)
    except PrintTooLongError:
        return f"{_local_head(term)} (longer than {limit} characters written out)"


def _run(render: Callable[[Term, _Printer], str], term: Term, limit: int | None) -> str:
    printer = _Printer(limit)
    try:
        return render(term, printer)
    except RecursionError:
        return run_deep(render, term, _Printer(limit))


def _local_head(term: lt.LocalTerm) -> str:
    """The first action or choice of ``term``, its continuations left out as ``...``."""
    names: list[str] = []
    while isinstance(term, lt.Rec):
        names.append(f"mu {term.var}.")
        term = term.body
    match term:
        case lt.Send() | lt.Recv():
            arrow = "!" if isinstance(term, lt.Send) else "?"
            peer = "" if term.peer is None else f"{term.peer}({print_message(term.message)})"
            head = f"{arrow}{peer or term.message.sort or term.message.label}..."
        case lt.Select(peer=peer, branches=branches) | lt.Offer(peer=peer, branches=branches):
            symbol = "+" if isinstance(term, lt.Select) else "&"
            head = f"{symbol}{peer or ''}{{{', '.join(print_message(b.message) + '...' for b in branches)}}}"
        case lt.SelectAmong(branches=actions) | lt.OfferAmong(branches=actions):
            symbol = "+" if isinstance(term, lt.SelectAmong) else "&"
            arrow = "!" if isinstance(term, lt.SelectAmong) else "?"
            head = f"{symbol}{{{', '.join(f'{arrow}{a.peer}({print_message(a.message)})...' for a in actions)}}}"
        case lt.Parallel(branches=branches):
            head = "(" + " || ".join(["..."] * len(branches)) + ")"
        case _:
            head = "..."
    return "".join(names) + head


def print_global_decl(global_type: g.GlobalType) -> str:
    """``global Name(A, B) = <type>``."""
    return f"global {global_type.name}({', '.join(global_type.roles)}) = {print_global(global_type.body)}"


def _local(term: lt.LocalTerm, printer: _Printer) -> str:
    known = printer.known(term)
    if known is not None:
        return known
    start = term
    # Sequences are printed in a loop: a long protocol is one long sequence.
    parts: list[str] = []
    while isinstance(term, (lt.Send, lt.Recv)):
        arrow = "!" if isinstance(term, lt.Send) else "?"
        if term.peer is None:
            parts.append(f"{arrow}{term.message.sort or term.message.label}")
        else:
            parts.append(f"{arrow}{term.peer}({print_message(term.message)})")
        term = term.continuation
    match term:
        case lt.End():
            if parts:
                return printer.checked(start, ".".join(parts))
            tail = "end"
        case lt.Var(name=name):
            tail = name
        case lt.Rec(var=var, body=body):
            tail = f"mu {var}.{_local(body, printer)}"
        case lt.Select(peer=peer, branches=branches) | lt.Offer(peer=peer, branches=branches):
            symbol = "+" if isinstance(term, lt.Select) else "&"
            inner = ", ".join([_local_branch(b, printer) for b in branches])
            tail = f"{symbol}{peer or ''}{{{inner}}}"
        case lt.SelectAmong(branches=actions) | lt.OfferAmong(branches=actions):
            symbol = "+" if isinstance(term, lt.SelectAmong) else "&"
            tail = f"{symbol}{{{', '.join([_local(a, printer) for a in actions])}}}"
        case lt.Parallel(branches=branches):
            tail = "(" + " || ".join([_local(b, printer) for b in branches]) + ")"
        case _:
            raise AssertionError(f"unexpected local term {term!r}")
    parts.append(tail)
    return printer.checked(start, ".".join(parts))


def _local_branch(branch: lt.Branch, printer: _Printer) -> str:
    head = print_message(branch.message)
    if isinstance(branch.continuation, lt.End):
        return head
    return f"{head}.{_local(branch.continuation, printer)}"


def _global(term: g.GlobalTerm, printer: _Printer) -> str:
    known = printer.known(term)
    if known is not None:
        return known
    start = term
    parts: list[str] = []
    while isinstance(term, g.Choice) and len(term.branches) == 1:
        only = term.branches[0]
        parts.append(f"{term.sender}->{term.receiver}:{print_message(only.message)}")
        term = only.continuation
    match term:
        case g.End():
            if parts:
                return printer.checked(start, ".".join(parts))
            tail = "end"
        case g.Var(name=name):
            tail = name
        case g.Rec(var=var, body=body):
            tail = f"mu {var}.{_global(body, printer)}"
        case g.Choice(sender=sender, receiver=receiver, branches=branches):
            inner = ", ".join([_global_branch(b, printer) for b in branches])
            tail = f"{sender}->{receiver}:{{{inner}}}"
        case g.Routed(sender=sender, branches=routes):
            inner = ", ".join([f"{r.receiver}:{_global_branch(g.Branch(r.message, r.continuation), printer)}"
                               for r in routes])
            tail = f"{sender}->{{{inner}}}"
        case g.Parallel(branches=branches):
            tail = "(" + " || ".join([_global(b, printer) for b in branches]) + ")"
        case _:
            raise AssertionError(f"unexpected global term {term!r}")
    parts.append(tail)
    return printer.checked(start, ".".join(parts))


def _global_branch(branch: g.Branch, printer: _Printer) -> str:
    head = print_message(branch.message)
    if isinstance(branch.continuation, g.End):
        return head
    return f"{head}.{_global(branch.continuation, printer)}"
