"""A small reference interpreter of global types, independent of projection.

Synchronous interleaving semantics: a global state is a closed global term; a
step is one interaction ``p -> q : l(S)``; ``mu`` unfolds; the branches of a
parallel composition interleave and it is over when all of them are. Nothing
here uses :mod:`sessiontypes.project` or :mod:`sessiontypes.fsm`: only the
term classes of :mod:`sessiontypes.global_types`, so the property tests can
compare the implementation's state machines against this.

Events are ``(sender, receiver, label, sort)``; their restriction to a role is
``("send", receiver, label, sort)`` for the sender, ``("recv", sender, label,
sort)`` for the receiver, and nothing (a silent move) for anyone else.
"""

from __future__ import annotations

import itertools
import random
from collections.abc import Sequence
from dataclasses import dataclass, field

from sessiontypes import global_types as g
from sessiontypes.sorts import Sort

Event = tuple[str, str, str, Sort | None]
LocalEvent = tuple[str, str, str, Sort | None]


class SearchBoundExceededError(Exception):
    """The bounded search gave up before deciding."""


def alpha_rename(term: g.GlobalTerm) -> g.GlobalTerm:
    """Give every ``mu`` a unique variable name, so substitution cannot capture."""
    counter = itertools.count()

    def walk(node: g.GlobalTerm, env: dict[str, str]) -> g.GlobalTerm:
        match node:
            case g.End():
                return g.End()
            case g.Var(name=name):
                if name not in env:
                    raise ValueError(f"free recursion variable {name!r}")
                return g.Var(env[name])
            case g.Rec(var=var, body=body):
                fresh = f"{var}#{next(counter)}"
                return g.Rec(fresh, walk(body, {**env, var: fresh}))
            case g.Choice(sender=p, receiver=q, branches=branches):
                return g.Choice(p, q, tuple(g.Branch(b.message, walk(b.continuation, env))
                                            for b in branches))
            case g.Routed(sender=p, branches=routes):
                return g.Routed(p, tuple(g.RoutedBranch(r.receiver, r.message, walk(r.continuation, env))
                                         for r in routes))
            case g.Parallel(branches=parts):
                return g.Parallel(tuple(walk(part, env) for part in parts))
        raise AssertionError(node)

    return walk(term, {})


def substitute(term: g.GlobalTerm, name: str, replacement: g.GlobalTerm) -> g.GlobalTerm:
    """``term[replacement / name]``; binder names are unique (see :func:`alpha_rename`)."""
    match term:
        case g.Var(name=n):
            return replacement if n == name else term
        case g.End():
            return term
        case g.Rec(var=var, body=body):
            return term if var == name else g.Rec(var, substitute(body, name, replacement))
        case g.Choice(sender=p, receiver=q, branches=branches):
            return g.Choice(p, q, tuple(
                g.Branch(b.message, substitute(b.continuation, name, replacement))
                for b in branches))
        case g.Routed(sender=p, branches=routes):
            return g.Routed(p, tuple(
                g.RoutedBranch(r.receiver, r.message, substitute(r.continuation, name, replacement))
                for r in routes))
        case g.Parallel(branches=parts):
            return g.Parallel(tuple(substitute(part, name, replacement) for part in parts))
    raise AssertionError(term)


def restrict(event: Event, role: str) -> LocalEvent | None:
    """What ``role`` sees of an interaction (None: it is not involved)."""
    sender, receiver, label, sort = event
    if role == sender:
        return ("send", receiver, label, sort)
    if role == receiver:
        return ("recv", sender, label, sort)
    return None


@dataclass
class GlobalSemantics:
    """The labelled transition system of one closed global type.

    ``initial`` is the (alpha-renamed, normalised) start state; :meth:`steps`
    is memoised per state.
    """

    body: g.GlobalTerm
    initial: g.GlobalTerm = field(init=False)
    _steps: dict[g.GlobalTerm, tuple[tuple[Event, g.GlobalTerm], ...]] = field(
        default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        self.initial = self.normalise(alpha_rename(self.body))

    # ---- states ----
    def normalise(self, state: g.GlobalTerm) -> g.GlobalTerm:
        """Unfold leading ``mu`` and drop finished parallel branches."""
        for _ in range(10_000):
            if not isinstance(state, g.Rec):
                break
            state = substitute(state.body, state.var, state)
        else:  # a guarded type unfolds in at most as many steps as it has binders
            raise ValueError("unguarded recursion")
        if isinstance(state, g.Parallel):
            parts = tuple(p for p in (self.normalise(b) for b in state.branches)
                          if not isinstance(p, g.End))
            if not parts:
                return g.End()
            return parts[0] if len(parts) == 1 else g.Parallel(parts)
        return state

    def steps(self, state: g.GlobalTerm) -> tuple[tuple[Event, g.GlobalTerm], ...]:
        """Every interaction possible in ``state`` and the state after it."""
        cached = self._steps.get(state)
        if cached is not None:
            return cached
        out: list[tuple[Event, g.GlobalTerm]] = []
        match state:
            case g.Choice(sender=p, receiver=q, branches=branches):
                for b in branches:
                    event = (p, q, b.message.label, b.message.sort)
                    out.append((event, self.normalise(b.continuation)))
            case g.Routed(sender=p, branches=routes):
                out.extend(((p, r.receiver, r.message.label, r.message.sort), self.normalise(r.continuation))
                           for r in routes)
            case g.Parallel(branches=parts):
                for index, part in enumerate(parts):
                    for event, after in self.steps(part):
                        rest = (*parts[:index], after, *parts[index + 1:])
                        out.append((event, self.normalise(g.Parallel(rest))))
            case g.End():
                pass
            case _:
                raise AssertionError(f"not a normal state: {state!r}")
        result = tuple(out)
        self._steps[state] = result
        return result

    def is_final(self, state: g.GlobalTerm) -> bool:
        """The conversation is over (``end``, or a parallel of finished branches)."""
        return isinstance(state, g.End)

    # ---- runs ----
    def random_run(self, rng: random.Random, max_steps: int) -> tuple[list[Event], g.GlobalTerm]:
        """A random run of at most ``max_steps`` interactions and the state it reaches."""
        state = self.initial
        events: list[Event] = []
        for _ in range(max_steps):
            options = self.steps(state)
            if not options:
                break
            event, state = options[rng.randrange(len(options))]
            events.append(event)
        return events, state

    def explore_prefix(self, role: str, word: Sequence[LocalEvent],
                       max_nodes: int = 50_000) -> tuple[bool, bool]:
        """Search the runs whose restriction to ``role`` starts with ``word``.

        Other roles' interactions are silent moves. Returns ``(matched,
        more)``: whether some run has ``word`` as a prefix of its
        restriction, and whether after ``word`` the role can still act in
        some run (some reachable state has a step of ``role``).

        Raises:
            SearchBoundExceededError: more than ``max_nodes`` (state, position) pairs.
        """
        start = (self.initial, 0)
        seen = {start}
        stack = [start]
        matched = more = False
        while stack:
            state, position = stack.pop()
            if position == len(word):
                matched = True
            for event, after in self.steps(state):
                seen_by_role = restrict(event, role)
                if seen_by_role is None:
                    node = (after, position)
                elif position == len(word):
                    more = True
                    return matched, more
                elif seen_by_role == word[position]:
                    node = (after, position + 1)
                else:
                    continue
                if node not in seen:
                    seen.add(node)
                    stack.append(node)
                    if len(seen) > max_nodes:
                        raise SearchBoundExceededError(f"{len(seen)} nodes")
        return matched, more
