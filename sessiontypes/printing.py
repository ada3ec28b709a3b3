"""What the prints of terms share: each shared node printed once, and a length limit.

A type that uses a declaration in many places is stored once per declaration
(:mod:`sessiontypes.sharing`), so a print memoises on nodes; its text can
still be exponentially long, so a print may be given a limit.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from .deep import run_deep

__all__ = ["PrintTooLongError", "Printer", "run_print"]

Term = TypeVar("Term")


class PrintTooLongError(ValueError):
    """The print of a type would be longer than the limit asked for.

    A type that uses a declaration in many places is stored once per
    declaration, but its print writes every use out: ``G_i = A -> B : {l. G_i+1,
    r. G_i+1}`` prints 2**n interactions. Printing stops at the limit instead.
    """

    def __init__(self, limit: int) -> None:
        super().__init__(f"longer than {limit} characters written out")
        self.limit = limit


class Printer:
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


def run_print(render: Callable[[Term, Printer], str], term: Term, limit: int | None) -> str:
    """``render(term)`` with a fresh :class:`Printer`, past Python's recursion limit if need be."""
    printer = Printer(limit)
    try:
        return render(term, printer)
    except RecursionError:
        return run_deep(render, term, Printer(limit))
