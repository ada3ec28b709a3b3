"""The canonical print of local and global types (LANGUAGE.md section 5).

``!Peer(msg)`` / ``?Peer(msg)``, ``+Peer{msg.T, msg.T}`` / ``&Peer{...}``,
``+{!B(msg).T, !C(msg).T}`` / ``&{?A(msg).T, ?C(msg).T}`` (branches with
different peers), ``mu t.T``, ``(T1 || T2)``, ``.`` without spaces and no trailing ``.end``.
A message prints as ``Sort`` when its label is the sort's spelling,
``label(Sort)`` when they differ, ``label(f: Sort, g: Sort)`` for named
payloads, and ``label`` when it carries nothing.
Global types print in the same style (``A->B:msg.G``, ``A->{B:msg.G, C:msg.G}``) so that printing then
parsing gives the same type back.

The print of local terms lives with them (:mod:`sessiontypes.local_types`, whose
``str()`` it is) and that of a message with it (:mod:`sessiontypes.sorts`); this
module prints global terms and gathers all three under one name.
"""

from __future__ import annotations

from . import global_types as g
from .constraints import Timing
from .local_types import describe_local, print_local  # re-exported: the print of local terms
from .printing import Printer, PrintTooLongError, run_print
from .sorts import print_message  # re-exported

__all__ = ["print_message", "print_local", "print_global", "describe_local", "PrintTooLongError"]


def print_global(term: g.GlobalTerm, limit: int | None = None) -> str:
    """The print of a global type term, in the language's own syntax.

    Raises:
        PrintTooLongError: ``limit`` is given and the print is longer.
    """
    return run_print(_global, term, limit)


def _global(term: g.GlobalTerm, printer: Printer) -> str:
    known = printer.known(term)
    if known is not None:
        return known
    start = term
    parts: list[str] = []
    while isinstance(term, g.Choice) and len(term.branches) == 1:
        only = term.branches[0]
        parts.append(f"{term.sender}->{term.receiver}:{print_message(only.message)}{_timed(term.timing)}")
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
            tail = f"{sender}->{receiver}:{{{inner}}}{_timed(term.timing)}"
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


def _timed(timing: Timing | None) -> str:
    """The time clause after a message or a choice's ``}``, with its leading space; "" for none."""
    return "" if timing is None else f" {timing}"


def _global_branch(branch: g.Branch, printer: Printer) -> str:
    head = print_message(branch.message)
    if isinstance(branch.continuation, g.End):
        return head
    return f"{head}.{_global(branch.continuation, printer)}"
