"""Well-formedness of refinements: names in scope, types that agree, satisfiability.

Filled by branch refine; this stub keeps the call site in :mod:`sessiontypes.check`.
"""

from __future__ import annotations

from .global_types import GlobalTerm
from .location import Location

__all__ = ["check_refinements"]


def check_refinements(term: GlobalTerm) -> list[tuple[Location, str]]:
    """The problems of the refinements in ``term``, each with where it was written (filled by branch refine)."""
    return []
