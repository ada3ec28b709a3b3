"""Who waits for whom: the waits-for graph of a protocol, read off its roles' state machines.

A role *waits on* a peer in a state of its state machine (or of one of its parallel
branches' machines) when, in that state,

- it can receive from the peer (``recv``): it blocks until the peer sends; a state that
  may receive from several peers waits on each of them;
- it can send to the peer on a bounded channel (``send``): it blocks while the channel
  is full, until the peer receives.

A wait is *stretched* by the peer's own waits: while the peer blocks in a state from
which it can still release the waiter (send to it, or receive from it), the waiter
waits as long as the peer does. :func:`waits_for_graph` joins the waits into a graph
whose paths are the chains A waits on B which waits on C, through the protocol's
states. The graph only says what the protocol allows; priorities are
:mod:`.inversion`'s business.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Literal

import networkx as nx

from sessiontypes import StateMachine

__all__ = ["Wait", "WaitKind", "role_waits", "waits_for_graph"]

WaitKind = Literal["recv", "send"]


@dataclass(frozen=True, order=True)
class Wait:
    """One way a role can block on a peer.

    Attributes:
        role: the role that waits.
        state: its state, as the machine's state number; a state of a parallel branch is
            written ``fork.branch.state`` (``"3.2.0"``: state 0 of branch 2 of fork state 3).
        peer: the role it waits on.
        kind: ``"recv"``: it waits for the peer's message; ``"send"``: it waits for room in
            the bounded channel to the peer, which the peer makes by receiving.
        action: the local-type action(s) it waits in, e.g. ``?VisOdom(Pose)`` (a choice
            offered by the peer: ``?Filter(pass(int)) or ?Filter(drop)``).
    """

    role: str
    state: str
    peer: str
    kind: WaitKind
    action: str


def role_waits(role: str, machine: StateMachine,
               capacities: Mapping[tuple[str, str], int]) -> list[Wait]:
    """Every wait of ``role`` in ``machine`` and its parallel branches, sorted.

    Args:
        role: the role the machine belongs to.
        machine: its state machine.
        capacities: the bounded channels, ``(sender, receiver) -> capacity``.
    """
    return sorted(wait for wait, _ in _waits_in(role, machine, "", capacities))


def waits_for_graph(machines: Mapping[str, StateMachine],
                    capacities: Mapping[tuple[str, str], int]) -> nx.DiGraph[Wait]:
    """The waits of every role, joined where one stretches another.

    Nodes are :class:`Wait` values. An edge ``w1 -> w2`` means: while ``w1.role`` waits on
    ``w1.peer`` (``w2.role``), that peer can be blocked in ``w2`` before it releases the
    waiter, i.e. from ``w2``'s state (in the same machine or parallel branch) the peer
    can still reach the action that ends ``w1`` (a send to ``w1.role`` for a ``recv``
    wait, a receive from it for a ``send`` wait). A role with no machine here (an
    external role) has no waits of its own: chains end at it.

    Args:
        machines: role -> its state machine.
        capacities: the bounded channels, ``(sender, receiver) -> capacity``.
    """
    graph: nx.DiGraph[Wait] = nx.DiGraph()
    releases: dict[str, list[tuple[Wait, set[tuple[str, str]]]]] = {}
    for role, machine in machines.items():
        found = list(_waits_in(role, machine, "", capacities))
        graph.add_nodes_from(wait for wait, _ in found)
        releases[role] = found
    for wait in list(graph.nodes):
        release = ("send", wait.role) if wait.kind == "recv" else ("recv", wait.role)
        for peer_wait, reachable in releases.get(wait.peer, []):
            if release in reachable:
                graph.add_edge(wait, peer_wait)
    return graph


def _waits_in(role: str, machine: StateMachine, prefix: str,
              capacities: Mapping[tuple[str, str], int]) -> Iterator[tuple[Wait, set[tuple[str, str]]]]:
    """(wait, the (action, peer) pairs reachable from its state) for the machine and its branches."""
    reach = _reachable_actions(machine)
    for state in machine.states:
        actions: dict[tuple[str, WaitKind], list[str]] = {}
        for transition in machine.expected(state):
            peer = transition.peer
            if peer is not None and (transition.action == "recv" or (role, peer) in capacities):
                actions.setdefault((peer, transition.action), []).append(str(transition))
        for (peer, kind), shown in actions.items():
            yield Wait(role, f"{prefix}{state}", peer, kind, " or ".join(shown)), reach[state]
        for index, branch in enumerate(machine.forks.get(state, ()), start=1):
            yield from _waits_in(role, branch, f"{prefix}{state}.{index}.", capacities)


def _reachable_actions(machine: StateMachine) -> dict[int, set[tuple[str, str]]]:
    """For each state: the (action, peer) pairs it can still reach, in this machine or in the
    branches of a fork it reaches (every branch of a fork runs once the fork is reached)."""
    graph: nx.DiGraph[int] = nx.DiGraph()
    own: dict[int, set[tuple[str, str]]] = {}
    for state in machine.states:
        graph.add_node(state)
        own[state] = {(t.action, t.peer) for t in machine.table[state].values() if t.peer is not None}
        for branch in machine.forks.get(state, ()):
            own[state] |= {(t.action, t.peer) for t in branch.all_transitions() if t.peer is not None}
        graph.add_edges_from((state, t.target) for t in machine.table[state].values())
    return {state: set().union(own[state], *(own[s] for s in nx.descendants(graph, state)))
            for state in machine.states}
