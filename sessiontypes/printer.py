"""The canonical print of local and global types (LANGUAGE.md section 5).

``!Peer(msg)`` / ``?Peer(msg)``, ``+Peer{msg.T, msg.T}`` / ``&Peer{...}``,
``mu t.T``, ``(T1 || T2)``, ``.`` without spaces and no trailing ``.end``.
A message prints as ``Sort`` when its label is the sort's spelling,
``label(Sort)`` when they differ, and ``label`` when it carries nothing.
Global types print in the same style (``A->B:msg.G``) so that printing then
parsing gives the same type back.
"""

from __future__ import annotations

from . import global_types as g
from . import local_types as lt
from .deep import run_deep
from .sorts import BUILTIN_SORTS, Message

__all__ = ["print_message", "print_local", "print_global", "print_global_decl"]


def print_message(message: Message) -> str:
    """``Sort``, ``label(Sort)`` or ``label``."""
    if message.sort is None:
        # 'int' alone would read back as label int carrying an int.
        if message.empty_parens or message.label in BUILTIN_SORTS:
            return f"{message.label}()"
        return message.label
    if message.label == message.sort.spelling:
        return message.label
    return f"{message.label}({message.sort.spelling})"


def print_local(term: lt.LocalTerm) -> str:
    """The canonical print of a local type term."""
    try:
        return _local(term)
    except RecursionError:
        return run_deep(_local, term)


def print_global(term: g.GlobalTerm) -> str:
    """The print of a global type term, in the language's own syntax."""
    try:
        return _global(term)
    except RecursionError:
        return run_deep(_global, term)


def print_global_decl(global_type: g.GlobalType) -> str:
    """``global Name(A, B) = <type>``."""
    return f"global {global_type.name}({', '.join(global_type.roles)}) = {print_global(global_type.body)}"


def _local(term: lt.LocalTerm) -> str:
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
                return ".".join(parts)
            tail = "end"
        case lt.Var(name=name):
            tail = name
        case lt.Rec(var=var, body=body):
            tail = f"mu {var}.{_local(body)}"
        case lt.Select(peer=peer, branches=branches) | lt.Offer(peer=peer, branches=branches):
            symbol = "+" if isinstance(term, lt.Select) else "&"
            inner = ", ".join([_local_branch(b) for b in branches])
            tail = f"{symbol}{peer or ''}{{{inner}}}"
        case lt.Parallel(branches=branches):
            tail = "(" + " || ".join([_local(b) for b in branches]) + ")"
        case _:
            raise AssertionError(f"unexpected local term {term!r}")
    parts.append(tail)
    return ".".join(parts)


def _local_branch(branch: lt.Branch) -> str:
    head = print_message(branch.message)
    if isinstance(branch.continuation, lt.End):
        return head
    return f"{head}.{_local(branch.continuation)}"


def _global(term: g.GlobalTerm) -> str:
    parts: list[str] = []
    while isinstance(term, g.Choice) and len(term.branches) == 1:
        only = term.branches[0]
        parts.append(f"{term.sender}->{term.receiver}:{print_message(only.message)}")
        term = only.continuation
    match term:
        case g.End():
            if parts:
                return ".".join(parts)
            tail = "end"
        case g.Var(name=name):
            tail = name
        case g.Rec(var=var, body=body):
            tail = f"mu {var}.{_global(body)}"
        case g.Choice(sender=sender, receiver=receiver, branches=branches):
            inner = ", ".join([_global_branch(b) for b in branches])
            tail = f"{sender}->{receiver}:{{{inner}}}"
        case g.Parallel(branches=branches):
            tail = "(" + " || ".join([_global(b) for b in branches]) + ")"
        case _:
            raise AssertionError(f"unexpected global term {term!r}")
    parts.append(tail)
    return ".".join(parts)


def _global_branch(branch: g.Branch) -> str:
    head = print_message(branch.message)
    if isinstance(branch.continuation, g.End):
        return head
    return f"{head}.{_global(branch.continuation)}"
