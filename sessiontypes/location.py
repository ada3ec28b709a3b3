"""Source locations carried by every syntax node and every core type node."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Location", "NOWHERE"]


@dataclass(frozen=True, slots=True)
class Location:
    """A point in a protocol source: 1-based line and column.

    Locations are metadata: every node stores one with ``compare=False`` so
    two types equal in structure are equal wherever they were written.
    """

    path: str
    line: int
    column: int

    def __str__(self) -> str:
        return f"{self.path}:{self.line}:{self.column}"


# Nodes built by code rather than parsed from text.
NOWHERE = Location("<generated>", 0, 0)
