"""Constrained state machines for the monitor's tests, before the front end parses the syntax.

An unconstrained protocol is loaded, and the transitions of each interaction named in
``constraints`` (by its sender and label) get the timing and refinement given, at the sender
and at the receiver alike (as projection keeps them). The global type returned gives these
machines to ``System`` (its projections are primed with them).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection, Mapping

import sessiontypes
from sessiontypes import GlobalType, StateMachine
from sessiontypes.constraints import Expr, Timing
from sessiontypes.declarations import LocalType

Constraints = Mapping[tuple[str, str], tuple["Timing | None", "Expr | None"]]


class _Primed(LocalType):
    """A projection whose machine is given (the constrained one)."""

    __slots__ = ("machine",)

    def fsm(self) -> StateMachine:
        machine: StateMachine = self.machine  # type: ignore[attr-defined]
        return machine


def constrain(machine: StateMachine, role: str, constraints: Constraints) -> StateMachine:
    """``machine`` (of ``role``) with the constraints put on its transitions, forks included (in place)."""
    for row in machine.table:
        for key, t in list(row.items()):
            sender = role if t.action == "send" else t.peer
            found = constraints.get((sender or "", t.label))
            if found is not None:
                row[key] = dataclasses.replace(t, timing=found[0], refinement=found[1])
    for branches in machine.forks.values():
        for branch in branches:
            constrain(branch, role, constraints)
    return machine


def timed_global(text: str, constraints: Constraints, name: str = "G",
                 roles: Collection[str] | None = None) -> GlobalType:
    """The global ``name`` of ``text``, whose roles' machines (those of ``roles``, default all)
    carry ``constraints``: leaving a sender out makes it send what only its receiver checks."""
    gt = sessiontypes.loads(text, "timed.proto").globals[name]
    for role in gt.roles if roles is None else roles:
        local = gt.project(role)
        primed = _Primed(local.name, local.role, local.body, local.protocol, local.location)
        object.__setattr__(primed, "machine", constrain(local.fsm(), role, constraints))
        gt.cached_projections[role] = primed
    return gt


def timed_machines(text: str, constraints: Constraints, name: str = "G") -> dict[str, StateMachine]:
    """Each role's constrained machine."""
    gt = timed_global(text, constraints, name)
    return {role: gt.project(role).fsm() for role in gt.roles}
