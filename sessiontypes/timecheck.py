"""Well-formedness of time clauses that needs the whole protocol (docs/language.md, "Time and value
constraints"): a period needs a loop that repeats its interaction, and a period must be
satisfiable given the deadlines of the sender's own actions around that loop.

The rules each clause can be judged by alone (durations more than 0, the jitter less than the
period, ``else timeout`` with a deadline) are :mod:`sessiontypes.resolve`'s.
"""

from __future__ import annotations

import heapq

from . import global_types as g
from .constraints import Timing, format_duration
from .declarations import GlobalType
from .fsm import StateMachine, Transition
from .location import Location
from .work import METER

__all__ = ["check_timing"]


def check_timing(global_type: GlobalType) -> list[tuple[Location, str]]:
    """The problems of the periods in ``global_type`` (which projects onto every role), located."""
    periodic = _periodic_choices(global_type.body)
    if not periodic:
        return []  # nothing to check: untimed protocols pay one walk
    problems: list[tuple[Location, str]] = []
    repeated = _repeated(global_type.body)
    senders: dict[str, None] = {}
    for choice in periodic:
        assert choice.timing is not None
        if id(choice) not in repeated:
            problems.append((choice.timing.location,
                             (f"a period needs a loop: {_describe(choice)} is not in a 'mu' loop that "
                              "comes back to it, so 'every' has no second send to time")))
        else:
            senders[choice.sender] = None
    for role in senders:
        problems.extend(_unsatisfiable(role, global_type.project(role).fsm()))
    return problems


def _describe(choice: g.Choice) -> str:
    labels = ", ".join(b.message.label for b in choice.branches)
    return f"{choice.sender} -> {choice.receiver} : {labels}"


def _periodic_choices(body: g.GlobalTerm) -> list[g.Choice]:
    """Every interaction with ``every``, each shared node visited once."""
    found: list[g.Choice] = []
    seen: set[int] = set()
    stack = [body]
    while stack:
        term = stack.pop()
        if id(term) in seen:
            continue
        seen.add(id(term))
        if isinstance(term, g.Choice) and term.timing is not None and term.timing.every is not None:
            found.append(term)
        stack.extend(g.children(term))
    METER.add("timing", len(seen))
    return found


def _repeated(body: g.GlobalTerm) -> set[int]:
    """The ids of the interactions some enclosing loop can come back to (a variable of a ``mu``
    around them is free in them)."""
    free: dict[int, frozenset[str]] = {}

    def free_in(term: g.GlobalTerm) -> frozenset[str]:
        # post-order with an explicit stack: sequences can be long
        pending = [(term, False)]
        while pending:
            node, ready = pending.pop()
            if id(node) in free:
                continue
            if not ready:
                pending.append((node, True))
                pending.extend((child, False) for child in g.children(node) if id(child) not in free)
                continue
            if isinstance(node, g.Var):
                free[id(node)] = frozenset((node.name,))
            else:
                names = frozenset().union(*[free[id(c)] for c in g.children(node)])
                free[id(node)] = names - {node.var} if isinstance(node, g.Rec) else names
        return free[id(term)]

    repeated: set[int] = set()
    seen: set[tuple[int, frozenset[str]]] = set()
    stack: list[tuple[g.GlobalTerm, frozenset[str]]] = [(body, frozenset())]
    while stack:
        term, loops = stack.pop()
        if (id(term), loops) in seen:
            continue
        seen.add((id(term), loops))
        if isinstance(term, g.Choice) and loops & free_in(term):
            repeated.add(id(term))
        inner = loops | {term.var} if isinstance(term, g.Rec) else loops
        stack.extend((child, inner) for child in g.children(term))
    return repeated


def _bound(transition: Transition) -> int | None:
    """How long after the role's previous action this action happens at the latest, if bounded.

    A send with ``within`` is bounded (unless ``else timeout``: then the deadline is the
    receiver's alone); a receive with ``within`` happens, or times out, by its deadline.
    """
    timing = transition.timing
    if timing is None or timing.within is None:
        return None
    if transition.action == "send" and timing.on_expiry:
        return None
    return timing.within


def _unsatisfiable(role: str, machine: StateMachine) -> list[tuple[Location, str]]:
    """Each period of ``role``'s sends that the deadlines around its shortest loop rule out."""
    problems: list[tuple[Location, str]] = []
    reported: set[Location] = set()
    machines = [machine]
    while machines:
        current = machines.pop()
        machines.extend(m for branches in current.forks.values() for m in branches)
        for state in current.states:
            for transition in current.table[state].values():
                timing = transition.timing
                if transition.action != "send" or timing is None or timing.every is None:
                    continue
                own = _bound(transition)
                if own is None:
                    continue
                back = _shortest_bounded(current, transition.target, state)
                if back is None:
                    continue
                apart, needed = back + own, timing.every - timing.jitter
                if apart < needed and timing.location not in reported:
                    reported.add(timing.location)
                    problems.append((timing.location, _message(role, transition, timing, apart)))
    return problems


def _message(role: str, transition: Transition, timing: Timing, apart: int) -> str:
    assert timing.every is not None
    return (f"unsatisfiable: the deadlines of {role}'s actions around the loop put its sends of "
            f"'{transition.label}' at most {format_duration(apart)} apart but the period needs at least "
            f"{format_duration(timing.every - timing.jitter)} ({timing})")


def _shortest_bounded(machine: StateMachine, start: int, goal: int) -> int | None:
    """The least sum of deadlines on a path from ``start`` to ``goal`` whose every action is
    bounded (Dijkstra); None if there is no such path."""
    best = {start: 0}
    queue = [(0, start)]
    while queue:
        distance, state = heapq.heappop(queue)
        if state == goal:
            return distance
        if distance > best.get(state, distance):
            continue
        for transition in machine.table[state].values():
            bound = _bound(transition)
            if bound is None:
                continue
            total = distance + bound
            if total < best.get(transition.target, total + 1):
                best[transition.target] = total
                heapq.heappush(queue, (total, transition.target))
    return None
