"""The named types users hold: a checked ``global`` declaration and a local type.

These sit above the stages they offer as methods (projection, the state
machine, the canonical print), so the term modules below them import no
stage and the package has no import circle (docs/decisions: sessiontypes layers).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from . import global_types as g
from . import local_types as lt
from .fsm import StateMachine, build_term_machine
from .location import NOWHERE, Location
from .printer import print_global
from .project import project_declared
from .sharing import Sharing
from .sorts import Sort

__all__ = ["GlobalType", "LocalType"]


@dataclass(frozen=True, slots=True, eq=False)
class LocalType:
    """A named local type: a projection of a global type, or a ``local`` declaration.

    Attributes:
        name: the ``local`` declaration's name, or the role's name for a projection.
        role: the role this type describes (``None`` if a ``local`` declaration
            does not say ``at ROLE``).
        body: the local type term.
        protocol: the global type it was projected from ("" for declarations).
        location: where it was declared (or the global's declaration).
    """

    name: str
    role: str | None
    body: lt.LocalTerm
    protocol: str = ""
    location: Location = NOWHERE

    def fsm(self) -> StateMachine:
        """Compile to a deterministic state machine (see :mod:`sessiontypes.fsm`)."""
        # A 'local' declaration has no protocol; its own name identifies the machine.
        return build_term_machine(self.body, self.role, self.protocol or self.name)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, LocalType):
            return NotImplemented
        return (self.name, self.role, self.body, self.protocol) == (
            other.name, other.role, other.body, other.protocol)

    def __hash__(self) -> int:
        return hash((self.name, self.role, self.body, self.protocol))

    def __str__(self) -> str:
        return lt.print_local(self.body)


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
    body: g.GlobalTerm
    location: Location = NOWHERE
    sorts: Mapping[str, Sort] = field(default_factory=dict, repr=False)
    source_lines: tuple[str, ...] = field(default=(), repr=False)
    shared: Sharing = field(default_factory=Sharing, repr=False)
    # Projections are pure functions of the type; the check computes them all once.
    cached_projections: dict[str, LocalType] = field(default_factory=dict, init=False, repr=False)

    def project(self, role: str) -> LocalType:
        """Return the local type of ``role``.

        Raises:
            UnknownRoleError: (a ``KeyError``) ``role`` is not a role of this global type.
            ProjectionError: the global type has no projection onto ``role``: some
                choice's branches do not merge for it, or (a
                :class:`~sessiontypes.errors.ChoiceRaceError`) a message may overtake
                the one from which ``role`` learns a choice.
        """
        cached = self.cached_projections.get(role)
        if cached is not None:
            return cached
        body = project_declared(self.name, self.roles, self.body, role, self.source_lines, self.shared)
        local = LocalType(role, role, body, self.name, self.location)
        self.cached_projections[role] = local
        return local

    def projections(self) -> dict[str, LocalType]:
        """Return the local type of every role, in role order."""
        return {role: self.project(role) for role in self.roles}

    def __str__(self) -> str:
        """``global Name(A, B) = <type>``."""
        return f"global {self.name}({', '.join(self.roles)}) = {print_global(self.body)}"
