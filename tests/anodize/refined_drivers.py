"""Random drivers that keep or break refinements, for the agreement tests
(tests/anodize/session/test_constraint_agreement.py), importable by a group's process.

A generated protocol's deadlines are made generous (at least 30 s: a random run keeps no
deadline of nanoseconds); a driver's payloads usually keep their message's refinement and now
and then break it, and each attempted send is noted with the reference's verdict
(``sessiontypes.refine.compile_predicate``) before it is tried. ``agreement_role`` is the role
function of a run in other processes: it reads the protocol and seed from the environment.
"""

from __future__ import annotations

import dataclasses
import os
import random
import threading

from role_drivers import Recorder, RoleDriver, load_global, machines_of, payload_for
from timed_machines import _Primed

import anodize
from sessiontypes import GlobalType, Sort, StateMachine, Transition
from sessiontypes.refine import compile_predicate

GENEROUS = 30 * 10**9  # ns: no deadline a random run could miss
BREAK = 0.35  # how often a driver tries to break a refinement
PROTOCOL_VARIABLE, SEED_VARIABLE = "ANODIZE_AGREE_PROTOCOL", "ANODIZE_AGREE_SEED"

Channel = tuple[str, str]
Attempt = tuple[str, object, "str | None"]  # label, payload, the reference's verdict (None: holds)


def relax(machine: StateMachine) -> StateMachine:
    """``machine`` with every deadline at least GENEROUS (``else timeout`` kept), forks included."""
    for row in machine.table:
        for key, t in list(row.items()):
            if t.timing is not None and t.timing.within is not None and t.timing.within < GENEROUS:
                row[key] = dataclasses.replace(t, timing=dataclasses.replace(t.timing, within=GENEROUS))
    for branches in machine.forks.values():
        for branch in branches:
            relax(branch)
    return machine


def refined(machine: StateMachine) -> bool:
    """Whether some message of ``machine`` carries a refinement."""
    return any(t.refinement is not None for row in machine.table for t in row.values()) or any(
        refined(b) for branches in machine.forks.values() for b in branches)


def generous(text: str) -> GlobalType:
    """The global ``G`` of ``text``, its roles' machines relaxed (``System`` runs these)."""
    gt = load_global(text)
    for role, machine in machines_of(gt).items():
        local = gt.project(role)
        primed = _Primed(local.name, local.role, local.body, local.protocol, local.location)
        object.__setattr__(primed, "machine", relax(machine))
        gt.cached_projections[role] = primed
    return gt


def value(sort: Sort | None, rng: random.Random) -> object:
    """A value of ``sort``, small numbers around the bounds the generated refinements draw."""
    if sort is not None and sort.fields is not None:
        return {f.name: value(f.sort, rng) for f in sort.fields}
    key = sort.key if sort is not None else None
    if key == "int":
        return rng.randint(-12, 12)
    if key == "nat":
        return rng.randint(0, 12)
    if key == "float":
        return rng.choice([-3.5, -0.5, 0.0, 0.5, 1.0, 10.5, 11.0, 1e9])
    return payload_for(sort, rng)


class RefinedDriver(RoleDriver):
    """A random driver whose payloads usually keep their message's refinement; each attempted
    send is noted in ``attempts`` with the reference's verdict before it is tried."""

    def __init__(self, role: str, machine: StateMachine, recorder: Recorder, seed: int, monitored: bool,
                 attempts: dict[Channel, list[Attempt]]) -> None:
        super().__init__(role, machine, recorder, seed, monitored)
        self.attempts = attempts
        self.lock = threading.Lock()

    def payload(self, t: Transition, rng: random.Random) -> object:
        check = compile_predicate(t.refinement) if t.refinement is not None else None
        breaking = rng.random() < BREAK
        payload = value(t.sort, rng)
        for _ in range(40):
            if check is None or (check(payload, {}) is not None) == breaking:
                break
            payload = value(t.sort, rng)
        verdict = check(payload, {}) if check is not None else None
        with self.lock:
            self.attempts.setdefault((self.role, str(t.peer)), []).append((t.label, payload, verdict))
        return payload


ATTEMPTS: dict[Channel, list[Attempt]] = {}  # of agreement_role's runs in this process


def agreement_role(ep: anodize.Endpoint) -> None:
    """The driver of ``ep``'s role for the protocol and seed the environment names."""
    gt = generous(os.environ[PROTOCOL_VARIABLE])
    machine = gt.project(ep.role).fsm()
    RefinedDriver(ep.role, machine, Recorder(gt.roles), int(os.environ[SEED_VARIABLE]), True, ATTEMPTS)(ep)
