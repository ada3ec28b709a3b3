"""Races at a choice learnt from several peers (LANGUAGE.md section 5, branches to different receivers).

A role whose local type receives from several peers at one state (an
``&{?A(m).T, ?C(n).U}``, made by merging the branches of a choice) takes the
branch of whichever message arrives first. That is safe only if, in the
branch a message decides, no other of those peers can send the role anything
before the deciding message has been received: messages travel
asynchronously, so a message sent without waiting for it may arrive first
and be taken for the other branch (or be refused, though the protocol was
followed).

:func:`check_races` walks the global type alongside the role's state machine.
At each receive the role makes in a state that waits on several peers, it
watches the other peers: a peer is *informed* once it has received a message
sent, causally, after the deciding receive (the role itself is informed at
once, and so is everyone it or an informed role sends to afterwards). A
watched peer that sends the role a message while not informed is a race, and
the global type is not projectable onto the role (:class:`ChoiceRaceError`).
Each (place in the global type, state, watches) is walked once, so loops end.

The globals of one file share the declarations they use, so the walks of a
chain of declarations would cover the chain once per global. A walk that
reaches a shared node with nothing else left to walk (what its work list holds
was walked already), outside every loop and with the rest of the role's local
type closed, walks from
there exactly what a walk of that node alone would, and finds the same race
or none: that outcome is remembered in the module's ``Sharing`` and the
next global that reaches the node in the same state takes it from there.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

from . import global_types as g
from . import local_types as lt
from .errors import ChoiceRaceError
from .fsm import LazyStateMachine, StateMachine
from .location import Location
from .printer import print_message
from .sharing import Sharing
from .sorts import Interaction
from .work import METER

__all__ = ["check_races", "has_offer_among"]


class _Watch(NamedTuple):
    peers: frozenset[str]       # the peers that must not send the role anything uninformed
    informed: frozenset[str]    # roles whose later actions come after the deciding receive
    decided_by: tuple[str, str, Location]   # the deciding receive: its print, peer, location


_Env = dict[str, tuple[g.Rec, "_Env"]]
_Machine = StateMachine | LazyStateMachine
_Config = tuple[g.GlobalTerm, _Env, _Machine | None, int, frozenset[_Watch]]
_Key = tuple[int, int, int, int, frozenset[_Watch]]  # a configuration, by the ids of its parts
# A walk's outcome from a shared node, whichever global it was walked for: by
# (the rest of the local type's id or None, watches), (that rest, the race or None).
_Outcomes = dict[tuple[int | None, frozenset[_Watch]], tuple[lt.LocalTerm | None, ChoiceRaceError | None]]


def has_offer_among(term: lt.LocalTerm, shared: Sharing | None = None) -> bool:
    """Whether a receive from several peers at once occurs in ``term``.

    With ``shared``, the answer for every node walked is remembered there, so
    the projections of the globals of one file, which share the projections
    of the declarations they use, are walked once together (a chain of n
    declarations was walked n times, quadratic).
    """
    memo: dict[int, tuple[lt.LocalTerm, bool]] = {} if shared is None else shared.table("offer_among")
    visits = 0
    # Post-order, iterative (sequences nest deeply): a node is answered once
    # its children are.
    stack: list[tuple[lt.LocalTerm, bool]] = [(term, False)]
    try:
        while stack:
            node, children_done = stack.pop()
            if id(node) in memo and memo[id(node)][0] is node:
                continue
            children = _local_children(node)
            if children_done or not children:
                found = isinstance(node, lt.OfferAmong) or any(memo[id(c)][1] for c in children)
                memo[id(node)] = (node, found)
                continue
            visits += 1
            if isinstance(node, lt.OfferAmong):
                memo[id(node)] = (node, True)
                continue
            stack.append((node, True))
            stack.extend((child, False) for child in children)
    finally:
        METER.add("offer_among", visits)
    return memo[id(term)][1]


def _local_children(node: lt.LocalTerm) -> list[lt.LocalTerm]:
    match node:
        case lt.Send(continuation=cont) | lt.Recv(continuation=cont):
            return [cont]
        case lt.Select(branches=branches) | lt.Offer(branches=branches):
            return [b.continuation for b in branches]
        case lt.SelectAmong(branches=actions) | lt.OfferAmong(branches=actions):
            return list(actions)
        case lt.Rec(body=body):
            return [body]
        case lt.Parallel(branches=parts):
            return list(parts)
    return []


def check_races(protocol: str, role: str, body: g.GlobalTerm, local: lt.LocalTerm,
                project_part: Callable[[g.GlobalTerm], lt.LocalTerm],
                source_lines: tuple[str, ...] = (), shared: Sharing | None = None) -> None:
    """Raise :class:`ChoiceRaceError` if a message can overtake the one that decides a choice for ``role``.

    Args:
        protocol: the global type's name (for the error).
        role: the role; ``local`` is its projection of ``body``.
        project_part: projects a sub-term (a parallel branch) onto ``role``.
        source_lines: the file's lines, for the error.
        shared: the module's shared nodes; the outcome of walking on from
            them is remembered there, for the other globals of the module.
    """
    machine = LazyStateMachine(local, role, protocol)
    try:
        _Walk(protocol, role, project_part, source_lines, shared).run(body, machine)
    finally:
        METER.add("fsm", machine.size)


class _Walk:
    def __init__(self, protocol: str, role: str, project_part: Callable[[g.GlobalTerm], lt.LocalTerm],
                 source_lines: tuple[str, ...], shared: Sharing | None) -> None:
        self.protocol = protocol
        self.role = role
        self.project_part = project_part
        self.source_lines = source_lines
        self.shared = shared
        self.envs: dict[tuple[int, int], _Env] = {}   # one env per (loop, outer env): keys stay few
        self.keep: list[object] = []                    # what the ids of the keys stand for
        # Shared nodes this walk went on from with nothing else left: each gets its outcome.
        self.entries: list[tuple[g.GlobalTerm, tuple[int | None, frozenset[_Watch]], lt.LocalTerm | None]] = []

    def run(self, body: g.GlobalTerm, machine: LazyStateMachine) -> None:
        seen: set[_Key] = set()
        root: _Env = {}
        self.keep.append(root)
        try:
            self.walk((body, root, machine, machine.initial, frozenset()), seen)
        except ChoiceRaceError as race:
            self.remember(race)
            raise
        else:
            self.remember(None)
        finally:
            METER.add("races", len(seen))

    def remember(self, race: ChoiceRaceError | None) -> None:
        """Every entry's walk found ``race`` (or none): what is left of a walk is a walk from its entry."""
        if self.shared is None:
            return
        table = self.shared.table(("races", self.role))
        for node, key, rest in self.entries:
            outcomes: _Outcomes
            _, outcomes = table.setdefault(id(node), (node, {}))
            outcomes[key] = (rest, race)

    def known(self, node: g.GlobalTerm, env: _Env, machine: _Machine | None, state: int,
              watches: frozenset[_Watch]) -> bool:
        """Whether the walk on from this configuration, with nothing else left, is known.

        Known clean: True (nothing to walk). Known racy: the race, raised as
        this global's. Unknown: False, and the configuration is an entry.
        """
        if self.shared is None or env or id(node) not in self.shared.nodes:
            return False  # inside a loop, what is walked depends on the loops around
        rest = None if machine is None else machine.term_at(state)
        if rest is not None and _free_local(rest, self.shared):
            return False  # a state inside a loop of the role's: ditto
        key = (None if rest is None else id(rest), watches)
        found = self.shared.get(("races", self.role), node)
        outcome = None if found is None else found.get(key)
        if outcome is None or outcome[0] is not rest:
            self.entries.append((node, key, rest))
            return False
        race = outcome[1]
        if race is None:
            return True
        if race.protocol == self.protocol:
            raise race.with_traceback(None)
        raise ChoiceRaceError(self.protocol, race.role, race.location, race.left, race.right, race.reason,
                              race.decided_at, race.source_line)

    def walk(self, first: _Config, seen: set[_Key]) -> None:
        """Walk every configuration reachable from ``first`` once, depth first."""
        stack: list[tuple[_Key, _Config]] = []
        # Configurations on the stack not walked yet, by key; and how many in all.
        # None left means the one being walked is all that is left to walk.
        waiting: dict[_Key, int] = {}
        unwalked = 0
        following: list[_Config] = [first]
        while True:
            for config in following:
                node, env, machine_, state, watches = config
                key = (id(node), id(env), id(machine_), state, watches)
                stack.append((key, config))
                if key not in seen:
                    waiting[key] = waiting.get(key, 0) + 1
                    unwalked += 1
            if not stack:
                return
            key, (node, env, machine_, state, watches) = stack.pop()
            following = []
            if key in seen:
                continue
            seen.add(key)
            unwalked -= waiting.pop(key)  # its copies further down will be skipped
            if not unwalked and self.known(node, env, machine_, state, watches):
                continue
            match node:
                case g.Rec():
                    following.append((node.body, self.enter(node, env), machine_, state, watches))
                case g.Var(name=name):
                    if name in env:
                        loop, inner = env[name]
                        following.append((loop.body, inner, machine_, state, watches))
                case g.Choice(sender=sender, receiver=receiver, branches=branches):
                    for b in branches:
                        after = self.step(machine_, state, watches, sender, receiver, b.message,
                                          b.location if len(branches) > 1 else node.location)
                        if after is not None:
                            following.append((b.continuation, env, machine_, after[0], after[1]))
                case g.Routed(sender=sender, branches=routes):
                    for r in routes:
                        after = self.step(machine_, state, watches, sender, r.receiver, r.message, r.location)
                        if after is not None:
                            following.append((r.continuation, env, machine_, after[0], after[1]))
                case g.Parallel(branches=parts):
                    following.extend(self.parts(parts, env, machine_, state, watches))

    def enter(self, loop: g.Rec, env: _Env) -> _Env:
        key = (id(loop), id(env))
        found = self.envs.get(key)
        if found is None:
            found = dict(env)
            found[loop.var] = (loop, found)
            self.envs[key] = found
            self.keep.append(found)
        return found

    def parts(self, parts: tuple[g.GlobalTerm, ...], env: _Env, machine: _Machine | None, state: int,
              watches: frozenset[_Watch]) -> list[_Config]:
        """Each parallel branch with the role's machine for it (None where the role takes no part)."""
        kept = [not isinstance(self.project_part(p), lt.End) for p in parts] if machine else [False] * len(parts)
        forks = machine.fork_at(state) if machine is not None else None
        if forks is not None:
            branch_machines = iter(forks)
            return [(p, env, next(branch_machines), 0, watches) if k else (p, env, None, 0, watches)
                    for p, k in zip(parts, kept, strict=True)]
        # one branch (or none) left for the role: its projection is that branch's, inline
        return [(p, env, machine if k else None, state, watches) for p, k in zip(parts, kept, strict=True)]

    def step(self, machine: _Machine | None, state: int, watches: frozenset[_Watch], sender: str,
             receiver: str, message: Interaction, location: Location) -> tuple[int, frozenset[_Watch]] | None:
        """One interaction: check and update the watches, step the role's machine."""
        role = self.role
        updated: set[_Watch] = set()
        for watch in watches:
            if receiver == role and sender in watch.peers and sender not in watch.informed:
                raise self.race(watch, sender, message, location)
            informed = watch.informed | {receiver} if sender in watch.informed else watch.informed
            if not watch.peers <= informed:
                updated.add(watch._replace(informed=informed))
        if machine is not None and machine.fork_at(state) is None:
            if receiver == role:
                peers = machine.peers_at(state, "recv")
                if len(peers) > 1:
                    deciding = f"?{sender}({print_message(message)})"
                    updated.add(_Watch(frozenset(p for p in peers if p is not None and p != sender),
                                       frozenset({role}), (deciding, sender, location)))
                moved = machine.step(state, "recv", sender, message.label)
                if moved is None:  # the projection does not follow this path: nothing to check on it
                    return None
                state = moved.target
            elif sender == role:
                moved = machine.step(state, "send", receiver, message.label)
                if moved is None:
                    return None
                state = moved.target
        return state, frozenset(updated)

    def race(self, watch: _Watch, sender: str, message: Interaction, location: Location) -> ChoiceRaceError:
        deciding, decider, decided_at = watch.decided_by
        peers = sorted(watch.peers | {decider})
        line = self.source_lines[location.line - 1] if 0 < location.line <= len(self.source_lines) else ""
        return ChoiceRaceError(self.protocol, self.role, location, deciding,
                               f"?{sender}({print_message(message)})", " or ".join(peers), decided_at, line)


def _free_local(term: lt.LocalTerm, shared: Sharing) -> frozenset[str]:
    """The recursion variables free in ``term``, remembered per node in ``shared`` (one walk for a module)."""
    memo: dict[int, tuple[lt.LocalTerm, frozenset[str]]] = shared.table("free_local")
    stack: list[tuple[lt.LocalTerm, bool]] = [(term, False)]
    while stack:  # post-order, iterative: sequences nest deeply
        node, children_done = stack.pop()
        if id(node) in memo and memo[id(node)][0] is node:
            continue
        children = _local_children(node)
        if not children_done and children:
            stack.append((node, True))
            stack.extend((child, False) for child in children)
            continue
        match node:
            case lt.Var(name=name):
                free: frozenset[str] = frozenset({name})
            case lt.Rec(var=var, body=body):
                free = memo[id(body)][1] - {var}
            case _:
                free = frozenset().union(*[memo[id(c)][1] for c in children])
        memo[id(node)] = (node, free)
    return memo[id(term)][1]
