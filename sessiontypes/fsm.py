"""Local type to deterministic state machine: what run-time monitors execute.

Each send, receive or choice of the local type is one state; ``mu`` and
variables become edges back; ``end`` is a state with no transitions. A
parallel composition is a *fork* state holding one machine per branch: each
branch is monitored on its own, and the fork is finished when every branch
is. Stepping is one dictionary look-up: ``table[state][(action, peer, label)]``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, Literal

from . import dot
from . import local_types as lt
from .constraints import Expr, Timing
from .deep import run_deep
from .local_types import describe_local
from .location import Location
from .refine import conjunction, print_expr
from .sorts import Interaction, Sort, print_message
from .work import METER

__all__ = ["Action", "Transition", "StateMachine", "LazyStateMachine", "build_term_machine", "predicate_of"]

Action = Literal["send", "recv"]
Key = tuple[Action, "str | None", str]


@dataclass(frozen=True, slots=True)
class Transition:
    """One allowed action and the state it leads to."""

    action: Action
    peer: str | None
    label: str
    sort: Sort | None
    target: int
    location: Location = field(compare=False)
    timing: Timing | None = None  # the interaction's time constraints (sessiontypes.constraints)
    refinement: Expr | None = None  # the payload's predicate: the message's and its fields', joined by ``and``

    def __str__(self) -> str:
        """The action in local-type notation: ``!Peer(msg)``, or ``!Sort`` in binary form."""
        arrow = "!" if self.action == "send" else "?"
        message = print_message(Interaction(self.label, self.sort))
        return f"{arrow}{self.peer}({message})" if self.peer else f"{arrow}{message}"


@dataclass(frozen=True, eq=False)
class StateMachine:
    """A deterministic machine for one role (or one parallel branch of it).

    Attributes:
        role: the role it describes (None if unknown).
        protocol: the global type it was projected from ("" if none).
        initial: the start state.
        table: for each state, the allowed actions keyed by ``(action, peer, label)``.
        forks: for each fork state, the machines of its parallel branches.
        terms: for each state, the local type that remains from it.
    """

    role: str | None
    protocol: str
    initial: int
    table: tuple[dict[Key, Transition], ...]
    forks: dict[int, tuple[StateMachine, ...]]
    terms: tuple[lt.LocalTerm, ...] = field(repr=False)

    @property
    def states(self) -> range:
        return range(len(self.table))

    def with_branches(self) -> Iterator[StateMachine]:
        """This machine, then the machines of its parallel branches, at any depth."""
        stack = [self]
        while stack:
            machine = stack.pop()
            yield machine
            stack.extend(b for branches in machine.forks.values() for b in branches)

    def all_transitions(self) -> list[Transition]:
        """Every transition of this machine and of the machines of its parallel branches."""
        return [t for machine in self.with_branches() for transitions in machine.table for t in transitions.values()]

    def is_final(self, state: int) -> bool:
        """No action is left in ``state`` (a fork is final when its branches are)."""
        return not self.table[state] and state not in self.forks

    def peers_at(self, state: int, action: Action) -> list[str | None]:
        """The peers ``state`` may send to (``action`` "send") or receive from ("recv"), in order."""
        return list(dict.fromkeys(t.peer for t in self.table[state].values() if t.action == action))

    def waits_on_several(self) -> bool:
        """Whether some state (of this machine or a parallel branch's) may receive from two peers.

        Such a role takes whichever message comes first (``Endpoint.recv_any``);
        a transport gives it a doorbell, as it does a role with parallel branches.
        """
        return any(len({p for (a, p, _) in keys if a == "recv"}) > 1
                   for machine in self.with_branches() for keys in machine.table)

    def step(self, state: int, action: Action, peer: str | None, label: str) -> Transition | None:
        """The transition for that action from ``state``, or None if not allowed."""
        return self.table[state].get((action, peer, label))

    def fork_at(self, state: int) -> tuple[StateMachine, ...] | None:
        """The machines of the parallel branches if ``state`` is a fork, else None."""
        return self.forks.get(state)

    def term_at(self, state: int) -> lt.LocalTerm:
        """The local type that remains from ``state``."""
        return self.terms[state]

    def expected(self, state: int) -> list[Transition]:
        """The actions allowed in ``state``, sorted."""
        return sorted(self.table[state].values(), key=lambda t: (t.action, t.peer or "", t.label))

    def describe(self, state: int) -> str:
        """The remaining local type at ``state``: its canonical print, or its first step if very long."""
        return describe_local(self.terms[state])

    # ---- export ----
    def to_dict(self) -> dict[str, Any]:
        return {
            "role": self.role,
            "protocol": self.protocol,
            "initial": self.initial,
            "states": [
                {
                    "id": state,
                    "final": self.is_final(state),
                    "type": self.describe(state),
                    "transitions": [
                        {"action": t.action, "peer": t.peer, "label": t.label,
                         "sort": t.sort.spelling if t.sort else None, "target": t.target,
                         "location": str(t.location),
                         # only where written, so that unconstrained machines export as before
                         **({"timing": str(t.timing)} if t.timing is not None else {}),
                         **({"refinement": print_expr(t.refinement)} if t.refinement is not None else {})}
                        for t in self.expected(state)
                    ],
                    **({"fork": [m.to_dict() for m in self.forks[state]]} if state in self.forks else {}),
                }
                for state in self.states
            ],
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, ensure_ascii=False)

    def to_networkx(self) -> Any:
        """A ``networkx.MultiDiGraph``; fork branches are nested with prefixed node names."""
        # Lazy: networkx takes longer to import than all of sessiontypes, and monitors never need it.
        import networkx as nx

        graph: nx.MultiDiGraph[str] = nx.MultiDiGraph(name=f"{self.protocol} {self.role or ''}".strip())
        self._add_to(graph, "")
        return graph

    def _add_to(self, graph: Any, prefix: str) -> None:
        for state in self.states:
            node = f"{prefix}s{state}"
            shape = "doublecircle" if self.is_final(state) else "circle"
            if state in self.forks:
                shape = "box"
            graph.add_node(node, label=f"{prefix}{state}", shape=shape,
                           initial=(state == self.initial and not prefix))
            for t in self.expected(state):
                graph.add_edge(node, f"{prefix}s{t.target}", label=str(t))
            for index, branch in enumerate(self.forks.get(state, ()), start=1):
                inner = f"{prefix}{state}.{index}."
                branch._add_to(graph, inner)
                graph.add_edge(node, f"{inner}s{branch.initial}", label=f"|| branch {index}", style="dashed")

    def to_dot(self) -> str:
        """Graphviz DOT text: one node per state, one edge per transition."""
        graph = self.to_networkx()
        for _, data in graph.nodes(data=True):
            data["_initial"] = data.pop("initial")
        graph.add_node("__start", shape="point", label="")
        graph.add_edge("__start", f"s{self.initial}")
        return dot.to_dot(graph, graph.graph["name"], {"rankdir": "LR"})


def build_term_machine(term: lt.LocalTerm, role: str | None = None, protocol: str = "") -> StateMachine:
    """Compile a local type term to its state machine."""
    return run_deep(lambda: _Builder(role, protocol).build(term))


class LazyStateMachine:
    """The state machine of a local term, each state filled when it is first looked at.

    For a walk that looks at few of the states (the race check of a global
    whose rest it has checked for another global of the file): building the
    whole machine for every global of a chain of declarations was quadratic.
    States and transitions are those :func:`build_term_machine` makes.
    """

    def __init__(self, term: lt.LocalTerm, role: str | None = None, protocol: str = "") -> None:
        self._builder = _Builder(role, protocol)
        self.initial = self._builder.state_of(term, {})

    def _filled(self, state: int) -> _Builder:
        builder = self._builder
        pending = builder.pending.pop(state, None)
        if pending is not None:
            builder.fill(*pending)  # recurses only into parallel branches
        return builder

    @property
    def size(self) -> int:
        """The states made so far (filled or not)."""
        return len(self._builder.table)

    def peers_at(self, state: int, action: Action) -> list[str | None]:
        """See :meth:`StateMachine.peers_at`."""
        table = self._filled(state).table[state]
        return list(dict.fromkeys(t.peer for t in table.values() if t.action == action))

    def step(self, state: int, action: Action, peer: str | None, label: str) -> Transition | None:
        """See :meth:`StateMachine.step`."""
        return self._filled(state).table[state].get((action, peer, label))

    def fork_at(self, state: int) -> tuple[StateMachine, ...] | None:
        """See :meth:`StateMachine.fork_at`."""
        return self._filled(state).forks.get(state)

    def term_at(self, state: int) -> lt.LocalTerm:
        """See :meth:`StateMachine.term_at`."""
        return self._builder.terms[state]


class _Builder:
    def __init__(self, role: str | None, protocol: str) -> None:
        self.role = role
        self.protocol = protocol
        self.table: list[dict[Key, Transition]] = []
        self.terms: list[lt.LocalTerm] = []
        self.forks: dict[int, tuple[StateMachine, ...]] = {}
        self.ids: dict[tuple[int, int], int] = {}
        self.end: int | None = None
        self.envs: list[dict[str, int]] = []  # kept alive: their ids key self.ids
        # States made but not filled yet, by state (a work list, not recursion:
        # sequences may be very long).
        self.pending: dict[int, tuple[lt.LocalTerm, dict[str, int], int]] = {}

    def build(self, term: lt.LocalTerm) -> StateMachine:
        initial = self.state_of(term, {})
        while self.pending:
            _, (node, env, state) = self.pending.popitem()
            self.fill(node, env, state)
        METER.add("fsm", len(self.table))
        return StateMachine(self.role, self.protocol, initial, tuple(self.table), self.forks,
                            tuple(self.terms))

    def new_state(self, term: lt.LocalTerm) -> int:
        self.table.append({})
        self.terms.append(term)
        return len(self.table) - 1

    def state_of(self, term: lt.LocalTerm, env: dict[str, int]) -> int:
        """The state where ``term`` starts (allocated, and queued to fill, on first sight)."""
        match term:
            case lt.Rec():
                # Filling is deferred, so the variables can be bound once the body's
                # state exists and before any transition back to it is made.
                env = dict(env)
                self.envs.append(env)
                names = []
                while isinstance(term, lt.Rec):
                    names.append(term.var)
                    term = term.body
                state = self.state_of(term, env)
                for name in names:
                    env[name] = state
                return state
            case lt.Var(name=name):
                return env[name]
            case lt.End():
                if self.end is None:
                    self.end = self.new_state(term)
                return self.end
        key = (id(term), id(env))
        known = self.ids.get(key)
        if known is not None:
            return known
        state = self.new_state(term)
        self.ids[key] = state
        self.pending[state] = (term, env, state)
        return state

    def fill(self, term: lt.LocalTerm, env: dict[str, int], state: int) -> None:
        match term:
            case lt.Send(continuation=cont) | lt.Recv(continuation=cont):
                action: Action = "send" if isinstance(term, lt.Send) else "recv"
                self.add(state, action, term.peer, term.message, self.state_of(cont, env), term.location,
                         term.timing)
            case lt.Select(peer=peer, branches=branches) | lt.Offer(peer=peer, branches=branches):
                action = "send" if isinstance(term, lt.Select) else "recv"
                for b in branches:
                    self.add(state, action, peer, b.message, self.state_of(b.continuation, env), b.location,
                             term.timing)
            case lt.SelectAmong(branches=actions) | lt.OfferAmong(branches=actions):
                kind: Action = "send" if isinstance(term, lt.SelectAmong) else "recv"
                for a in actions:
                    self.add(state, kind, a.peer, a.message, self.state_of(a.continuation, env), a.location,
                             a.timing)
            case lt.Parallel(branches=parts):
                self.forks[state] = tuple([_Builder(self.role, self.protocol).build(p) for p in parts])
            case _:
                raise AssertionError(f"unexpected local term {term!r}")

    def add(self, state: int, action: Action, peer: str | None, message: Interaction,
            target: int, location: Location, timing: Timing | None) -> None:
        self.table[state][(action, peer, message.label)] = Transition(
            action, peer, message.label, message.sort, target, location, timing, predicate_of(message))


def predicate_of(message: Interaction) -> Expr | None:
    """The predicate a payload of ``message`` must satisfy: its own refinement and its
    fields', joined by ``and`` in that order (None if there is none)."""
    parts: list[Expr] = [] if message.refinement is None else [message.refinement]
    if message.sort is not None and message.sort.fields is not None:
        parts.extend([f.refinement for f in message.sort.fields if f.refinement is not None])
    return conjunction(parts)
