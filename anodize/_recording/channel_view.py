"""One role's state machine seen from one channel: what it allows on that channel alone.

A recording holds each channel's messages in order, but not (in general) how the
channels interleave. Restricted to one channel, with every other action of the role
erased, a role's machine still says which sequences of labels it may send (or
receive) there: that is what a channel of a recording is checked against. The view
is a small nondeterministic automaton (erased actions are silent moves; a parallel
composition enters each branch silently) kept as a set of states.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from sessiontypes import StateMachine, Transition
from sessiontypes.fsm import Action

__all__ = ["ChannelView", "Node", "sort_key"]

Node = tuple[int, int]  # (machine, state): a machine is the role's, or one of a parallel branch


@dataclass(frozen=True)
class _Move:
    label: str
    transition: Transition
    target: Node


class ChannelView:
    """The actions ``action`` with ``peer`` of ``machine``; everything else is silent."""

    def __init__(self, machine: StateMachine, action: Action, peer: str) -> None:
        self.machines: list[StateMachine] = []
        self._index: dict[int, int] = {}
        self._collect(machine)
        self.action = action
        self.peer = peer
        self._silent: dict[Node, list[Node]] = {}
        self._moves: dict[Node, list[_Move]] = {}
        for number, m in enumerate(self.machines):
            for state in m.states:
                node = (number, state)
                silent = self._silent[node] = []
                moves = self._moves[node] = []
                for (kind, who, label), t in m.table[state].items():
                    if kind == action and who == peer:
                        moves.append(_Move(label, t, (number, t.target)))
                    else:
                        silent.append((number, t.target))
                silent.extend((self._index[id(branch)], branch.initial) for branch in m.forks.get(state, ()))
        self._steps: dict[tuple[frozenset[Node], str, frozenset[str | None] | None], frozenset[Node]] = {}
        self.start = self.closure([(0, machine.initial)])

    def _collect(self, machine: StateMachine) -> None:
        self._index[id(machine)] = len(self.machines)
        self.machines.append(machine)
        for branches in machine.forks.values():
            for branch in branches:
                self._collect(branch)

    def closure(self, nodes: Iterable[Node]) -> frozenset[Node]:
        seen = set(nodes)
        stack = list(seen)
        while stack:
            for target in self._silent[stack.pop()]:
                if target not in seen:
                    seen.add(target)
                    stack.append(target)
        return frozenset(seen)

    def step(self, nodes: frozenset[Node], label: str,
             sorts: frozenset[str | None] | None = None) -> frozenset[Node]:
        """The states after ``label`` (empty: the label is not allowed here).

        ``sorts``: only through transitions carrying one of these sorts (by key; None for
        no payload), for a label that carries different sorts on different paths.
        """
        key = (nodes, label, sorts)
        found = self._steps.get(key)
        if found is None:
            found = self._steps[key] = self.closure(
                move.target for node in nodes for move in self._moves[node]
                if move.label == label and (sorts is None or sort_key(move.transition) in sorts))
        return found

    def candidates(self, nodes: frozenset[Node], label: str,
                   sorts: frozenset[str | None] | None = None) -> list[tuple[Node, Transition]]:
        """The transitions ``label`` may take from ``nodes`` (through one of ``sorts``, if given),
        each with the state it leaves (for constraints that narrow them down: :meth:`advance`)."""
        return [(node, move.transition) for node in sorted(nodes) for move in self._moves[node]
                if move.label == label and (sorts is None or sort_key(move.transition) in sorts)]

    def advance(self, taken: list[tuple[Node, Transition]]) -> frozenset[Node]:
        """The states after taking ``taken`` (some of :meth:`candidates`)."""
        return self.closure((node[0], t.target) for node, t in taken)

    def allowed(self, nodes: frozenset[Node]) -> list[Transition]:
        """The channel's transitions possible next, one per label, sorted by label."""
        found: dict[str, Transition] = {}
        for node in sorted(nodes):
            for move in self._moves[node]:
                found.setdefault(move.label, move.transition)
        return [found[label] for label in sorted(found)]

    def taken(self, nodes: frozenset[Node], label: str) -> list[Transition]:
        """The transitions ``label`` may take from ``nodes`` (their sorts and locations)."""
        return [move.transition for node in sorted(nodes) for move in self._moves[node] if move.label == label]

    def describe(self, nodes: frozenset[Node]) -> str:
        """Where the role is, as the remaining local types that act on this channel next."""
        acting = sorted(node for node in nodes if self._moves[node]) or sorted(nodes)[:1]
        texts = [f"{state} ({self.machines[m].describe(state)})" for m, state in acting[:3]]
        more = f" and {len(acting) - 3} more" if len(acting) > 3 else ""
        return " or ".join(texts) + more


def sort_key(transition: Transition) -> str | None:
    return transition.sort.key if transition.sort is not None else None
