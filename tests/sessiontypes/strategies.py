"""Hypothesis strategies for the ``.proto`` language.

:func:`global_protocols` draws well-formed, projectable global types, both as
the term the parser should build (``sessiontypes.global_types``) and as text
written with the language's many spellings (ASCII and Unicode tokens, every
message form, label-only branches, optional braces, parentheses, comments,
an optional role list). Projectability holds by construction, not by
filtering; see :class:`_Generator` for the discipline.

:func:`protocol_texts` and :func:`mutated_texts` draw junk and near-valid
files for the "only ProtocolError escapes" property.
"""

from __future__ import annotations

import random
import re
from dataclasses import dataclass, replace

from hypothesis import strategies as st

from sessiontypes import constraints as c
from sessiontypes import global_types as g
from sessiontypes.refine import print_expr
from sessiontypes.sorts import BUILTIN_SORTS, Field, Interaction, Sort, builtin_sort, record_sort

__all__ = ["GeneratedGlobal", "global_protocols", "protocol_texts", "mutated_texts",
           "ROLE_POOL", "LABELS", "SORT_SPELLINGS"]

ROLE_POOL = ("A", "B", "Srv", "c'", "_d1")
LABELS = ("l0", "l1", "l2", "l3", "l4")
# Labels that spell a sort exercise the abbreviation rule (bare ``int`` is
# label int carrying an int; ``int()`` is label int carrying nothing).
SORT_LABELS = ("int", "Int", "String")
SORT_SPELLINGS = ("int", "Int", "nat", "bool", "str", "float", "bytes", "String")
VAR_POOL = ("t", "u", "v", "t'")
# Names of the fields of named payloads (``l0(x: int, when': str)``).
FIELD_NAMES = ("x", "y", "price", "when'", "int")
# Deadlines and periods, in nanoseconds, as a time clause may write them.
DURATIONS = (7, 1_500_000, 20_000_000, 100_000_000, 2_000_000_000)


def refinement_of(name: str, key: str, pick: int) -> c.Expr:
    """A predicate on field ``name`` of builtin sort ``key`` that names only the field and
    whose types agree (so that it is well-formed wherever the field is)."""
    field = c.Path((name,))
    if key in ("str", "bytes"):
        return c.Compare((">",), (c.Call("len", (field,)), c.Number(pick % 3)))
    if key == "bool":
        return c.Binary("or", field, c.Unary("not", field)) if pick % 2 else c.Compare(("!=",), (field, c.Truth(False)))
    shapes: list[c.Expr] = [
        c.Compare((">=",), (field, c.Number(0))),
        c.Compare(("<=", "<"), (c.Number(0), field, c.Number(10.5))),
        c.Compare(("<=",), (c.Call("abs", (c.Binary("-", field, c.Number(1)),)), c.Number(100))),
        c.Binary("and", c.Compare((">",), (c.Binary("*", field, c.Number(2)), c.Unary("-", c.Number(3)))),
                 c.Unary("not", c.Compare(("==",), (c.Binary("%", field, c.Number(7)), c.Number(1))))),
    ]
    return shapes[pick % len(shapes)]

Channel = tuple[str, str]


@dataclass(frozen=True)
class GeneratedGlobal:
    """A generated ``global G`` declaration.

    Attributes:
        text: the declaration as a file.
        body: the global term ``loads(text).globals["G"].body`` must equal.
        roles: the roles ``loads(text).globals["G"].roles`` must be.
    """

    text: str
    body: g.GlobalTerm
    roles: tuple[str, ...]


@dataclass(frozen=True)
class _Scope:
    """Where a subterm is generated.

    channels: the directed channels it may use (parallel branches get disjoint sets).
    env: recursion variables in scope -> (channels when bound, guarded yet?). A
        variable is usable only where the channel set is the one it was bound
        with: then no role was left out in between, so every role that sees
        the loop also sees the way back to it.
    exit: None (free), "end" or a variable name: every leaf of the term must be
        that, because some role left out by an enclosing choice has to see the
        same behaviour in every branch.
    exit_guarded: whether an interaction happened since ``exit`` was bound.
    """

    channels: frozenset[Channel]
    env: tuple[tuple[str, frozenset[Channel], bool], ...]
    exit: str | None = None
    exit_guarded: bool = True

    @property
    def roles(self) -> frozenset[str]:
        return frozenset(r for c in self.channels for r in c)

    def usable(self) -> list[str]:
        return [name for name, channels, guarded in self.env
                if guarded and channels == self.channels]

    def bind(self, name: str, keep: bool) -> tuple[tuple[str, frozenset[Channel], bool], ...]:
        outer = tuple(e for e in self.env if e[0] != name) if keep else ()
        return (*outer, (name, self.channels, False))

    def after_interaction(self) -> _Scope:
        return replace(self, env=tuple((n, c, True) for n, c, _ in self.env), exit_guarded=True)


class _Generator:
    """Builds a projectable global term, drawing every decision.

    Discipline (why the result projects, with full merge, onto every role):

    - A choice ``p -> q`` with several branches looks at every other role r in
      scope. Either r is *informed*: each branch starts by sending r a label
      distinct per branch from the same notifier (p or q), so r's branches
      are receptions from one peer with distinct labels and merge by union
      (before that label r may exchange the same messages with the notifier
      in every branch, receiving or sending them, now and then a choice of
      the same labels, the sorts spelled differently: merge recurses into
      them, for sends too); or r is *left out*: r does not occur in any
      branch (the channel set shrinks) and every leaf of every branch is
      the same (``end`` or one loop variable), so r sees identical
      behaviour; or, for at most one r, every
      branch ends in the same closed loop among p, q and r, written
      differently per branch (see :func:`respellings`), which merge must
      recognise as one behaviour.
    - ``mu`` either keeps the scope (outer loop variables stay usable) or
      narrows to fewer roles and then is closed (only its own variable is
      usable inside): the roles left out never see the loop.
    - A parallel composition splits the channels among its branches; no
      outer variable is usable inside.
    """

    def __init__(self, draw: st.DrawFn, max_nodes: int, constrained: bool) -> None:
        self.draw = draw
        self.nodes_left = max_nodes
        self.constrained = constrained  # time clauses and refinements drawn too

    # ---- small draws ----
    def message(self, label: str) -> Interaction:
        if self.draw(st.integers(0, 7)) == 0:  # now and then named payloads, now and then refined
            names = self.draw(st.lists(st.sampled_from(FIELD_NAMES), min_size=1, max_size=3, unique=True))
            fields = []
            for name in names:
                sort = builtin_sort(self.draw(st.sampled_from(SORT_SPELLINGS)))
                refined = self.draw(st.integers(0, 5)) if self.constrained else 5
                fields.append(Field(name, sort, refinement_of(name, sort.key, refined) if refined < 2 else None))
            return Interaction(label, record_sort(tuple(fields)))
        spelling = self.draw(st.none() | st.sampled_from(SORT_SPELLINGS))
        return Interaction(label, builtin_sort(spelling) if spelling else None)

    def timing(self) -> c.Timing | None:
        """Now and then a deadline (``else timeout`` sometimes); periods need loops, and are
        tried by tests/sessiontypes/test_timed.py."""
        if not self.constrained or self.draw(st.integers(0, 3)) != 0:
            return None
        return c.Timing(within=self.draw(st.sampled_from(DURATIONS)), on_expiry=self.draw(st.booleans()))

    def labels(self, count: int) -> list[str]:
        pool = LABELS + (SORT_LABELS if self.draw(st.integers(0, 5)) == 0 else ())
        return self.draw(st.lists(st.sampled_from(pool), min_size=count, max_size=count, unique=True))

    # ---- terms ----
    def term(self, scope: _Scope, depth: int, act: bool = False) -> g.GlobalTerm:
        """A term; with ``act`` it starts with an interaction when the budget allows."""
        self.nodes_left -= 1
        kinds = ["leaf"]
        if act and depth > 0:
            kinds = []
        if depth > 0 and (self.nodes_left > 0 or act):
            kinds += ["message", "message", "choice", "choice", "routed"]
            if scope.exit is None or scope.exit == "end":
                kinds += ["mu"]
                if len(scope.channels) >= 2:
                    kinds += ["parallel"]
        kind = self.draw(st.sampled_from(kinds))
        if kind == "leaf":
            if scope.exit == "end":
                return g.End()
            if scope.exit is not None:
                if scope.exit_guarded:
                    return g.Var(scope.exit)
                kind = "message"  # the loop needs an interaction before it repeats
            else:
                return self.draw(st.sampled_from([g.End()] + [g.Var(v) for v in scope.usable()]))
        if kind == "message":
            p, q = self.draw(st.sampled_from(sorted(scope.channels)))
            message = self.message(self.labels(1)[0])
            # Sometimes the same message to more receivers: the writer may spell it a multicast.
            also = [r for r in sorted(scope.roles - {p, q}) if (p, r) in scope.channels]
            receivers = [q]
            if also and self.draw(st.integers(0, 3)) == 0:
                receivers += self.draw(st.lists(st.sampled_from(also), min_size=1, unique=True))
            rest = self.term(scope.after_interaction(), depth - 1)
            timing = self.timing()
            for receiver in reversed(receivers):
                rest = g.Choice(p, receiver, (g.Branch(message, rest),), timing=timing)
            return rest
        if kind == "choice":
            return self.choice(scope, depth)
        if kind == "routed":
            return self.routed(scope, depth)
        if kind == "mu":
            return self.mu(scope, depth)
        return self.parallel(scope, depth)

    def choice(self, scope: _Scope, depth: int) -> g.GlobalTerm:
        p, q = self.draw(st.sampled_from(sorted(scope.channels)))
        count = self.draw(st.integers(2, 3))
        labels = self.labels(count)
        others = sorted(scope.roles - {p, q})
        looping = None  # a role that follows one loop in every branch, spelled differently
        if others and scope.exit in (None, "end") and depth > 1 and self.draw(st.integers(0, 3)) == 0:
            looping = self.draw(st.sampled_from(others))
            others.remove(looping)
        informed: dict[str, str] = {}   # role -> its notifier
        left_out: set[str] = set()
        for role in others:
            notifiers = [n for n in (p, q) if (n, role) in scope.channels]
            if notifiers and self.draw(st.integers(0, 9)) < 7:  # mostly informed: more roles stay
                informed[role] = self.draw(st.sampled_from(notifiers))
            else:
                left_out.add(role)
        inner = scope.after_interaction()
        if left_out:
            channels = frozenset(c for c in scope.channels if not (set(c) & left_out))
            exit_ = scope.exit
            if exit_ is None:  # a shared loop is closed: its branches can only end
                exit_ = "end" if looping else self.draw(st.sampled_from(["end", *inner.usable()]))
            inner = _Scope(channels, inner.env, exit_, True)
        loop = None
        if looping is not None:
            loop_channels = frozenset(c for c in scope.channels if set(c) <= {p, q, looping})
            loop = self.mu(_Scope(loop_channels, ()), depth - 1)
            assert isinstance(loop, g.Rec)
        # Informed roles may first exchange the same messages with their notifier in
        # every branch, received or sent (LANGUAGE.md 5 merges both, recursing into
        # the continuations), a choice of two labels now and then, with the sort
        # spelled differently per branch; then a label that differs per branch.
        common = {role: [self.common_step(informed[role], role, scope.channels)
                         for _ in range(self.draw(st.sampled_from([0, 0, 1, 1, 2])))]
                  for role in informed}
        notices = {role: self.labels(count) for role in informed}
        # Sometimes one role informed by p hears p's own choice first: the writer may spell
        # the choice a multicast, p -> q, r : {...}.
        told = [r for r, notifier in informed.items() if notifier == p]
        echo = self.draw(st.sampled_from(told)) if told and self.draw(st.integers(0, 2)) == 0 else None
        if echo is not None:
            common[echo] = []
        branches = []
        for index, label in enumerate(labels):
            message = self.message(label)
            order = self.draw(st.permutations(sorted(informed)))
            prefix = []
            if echo is not None:
                order = [echo, *(r for r in order if r != echo)]
            for r in order:
                for sender, receiver, step_labels, key in common[r]:
                    prefix.append((sender, receiver, [
                        Interaction(step_label, builtin_sort(self.draw(st.sampled_from(_SPELLINGS_BY_KEY[key]))))
                        for step_label in step_labels]))
                prefix.append((informed[r], r, [message if r == echo else self.message(notices[r][index])]))
            if loop is not None:
                # Whether the looping role receives or sends in it: LANGUAGE.md 5 merges
                # sends label by label as it does receives, so every spelling merges.
                rest = self.draw(st.sampled_from(respellings(loop)))
            else:
                rest = self.term(inner, depth - 1)
            for sender, receiver, notes in reversed(prefix):
                rest = g.Choice(sender, receiver, tuple(g.Branch(note, rest) for note in notes))
            branches.append(g.Branch(message, rest))
        return g.Choice(p, q, tuple(branches), timing=self.timing())

    def routed(self, scope: _Scope, depth: int) -> g.GlobalTerm:
        """``p -> {q1 : l1. G1, q2 : l2. G2, ...}``: branches to different receivers.

        Every other role is *told by p* (in each branch where it is not the
        receiver, p sends it a notice; its receives all come from p), *relayed*
        (in each such branch it gets a notice from that branch's receiver, or
        from p, and then takes no further part: the branches end, so no later
        message can overtake the notice), or *left out* (not a receiver, in no
        branch). All (peer, label) pairs a role may receive are distinct.
        """
        targets = {p: sorted(q for a, q in scope.channels if a == p) for p in sorted(scope.roles)}
        senders = [p for p, qs in targets.items() if len(qs) >= 2]
        if not senders:
            return self.choice(scope, depth)
        p = self.draw(st.sampled_from(senders))
        count = self.draw(st.integers(2, 3))
        receivers = self.draw(st.lists(st.sampled_from(targets[p]), min_size=count, max_size=count))
        if len(set(receivers)) == 1:
            receivers[1] = next(q for q in targets[p] if q != receivers[0])
        labels = self.labels(count)
        relay_ok = scope.exit in (None, "end")
        told: dict[str, list[tuple[str, Interaction]]] = {}   # role -> per branch (notifier, notice)
        away: set[str] = set()                            # relayed or left out: not in the branches' rest
        for role in sorted(scope.roles - {p}):
            mine = {labels[i] for i in range(count) if receivers[i] == role}
            needed = [i for i in range(count) if receivers[i] != role]
            ways = []
            if all((p, role) in scope.channels for _ in needed):
                ways += ["p", "p"]
            if relay_ok and all((receivers[i], role) in scope.channels or (p, role) in scope.channels
                                for i in needed):
                ways += ["relay", "relay"]
            if not mine:
                ways += ["out"]
            way = self.draw(st.sampled_from(ways))
            if way == "out":
                away.add(role)
                continue
            free = [label for label in LABELS if label not in mine]
            notes = self.draw(st.lists(st.sampled_from(free), min_size=len(needed), max_size=len(needed),
                                       unique=True))
            per_branch: list[tuple[str, Interaction]] = []
            for i, note in zip(needed, notes, strict=True):
                notifier = p
                if way == "relay":
                    away.add(role)
                    choices = [n for n in (receivers[i], p) if (n, role) in scope.channels]
                    notifier = self.draw(st.sampled_from(choices))
                per_branch.append((notifier, self.message(note)))
            told[role] = per_branch
        inner = scope.after_interaction()
        if away:
            channels = frozenset(c for c in scope.channels if not (set(c) & away))
            exit_ = scope.exit
            if exit_ is None:
                relayed = any(r in told for r in away)
                exit_ = "end" if relayed else self.draw(st.sampled_from(["end", *inner.usable()]))
            inner = _Scope(channels, inner.env, exit_, True)
        branches = []
        for index, (receiver, label) in enumerate(zip(receivers, labels, strict=True)):
            order = self.draw(st.permutations(sorted(r for r in told if r != receiver)))
            if inner.channels:
                rest = self.term(inner, depth - 1)
            else:  # everyone but p has gone: the branch ends as every branch must
                rest = g.End() if inner.exit in (None, "end") else g.Var(inner.exit)
            for role in reversed(order):
                position = [i for i in range(count) if receivers[i] != role].index(index)
                notifier, note = told[role][position]
                rest = g.Choice(notifier, role, (g.Branch(note, rest),))
            branches.append(g.RoutedBranch(receiver, self.message(label), rest))
        return g.Routed(p, tuple(branches))

    def common_step(self, notifier: str, role: str,
                    channels: frozenset[Channel]) -> tuple[str, str, list[str], str]:
        """A step an informed role takes in every branch: sender, receiver, labels
        (two: a choice, whose branches all go on alike) and the key of their sort."""
        key = self.draw(st.sampled_from(sorted(_SPELLINGS_BY_KEY)))
        labels = self.labels(self.draw(st.sampled_from([1, 1, 1, 1, 2])))
        if (role, notifier) in channels and self.draw(st.booleans()):
            return role, notifier, labels, key
        return notifier, role, labels, key

    def mu(self, scope: _Scope, depth: int) -> g.GlobalTerm:
        name = self.draw(st.sampled_from(VAR_POOL))
        roles = sorted(scope.roles)
        if len(roles) > 2 and self.draw(st.booleans()):
            # a loop among fewer roles: closed, the others never see it
            kept = set(self.draw(st.lists(st.sampled_from(roles), min_size=2, max_size=len(roles) - 1,
                                          unique=True)))
            channels = frozenset(c for c in scope.channels if set(c) <= kept)
            if channels:
                narrowed = _Scope(channels, (), None)
                inner = replace(narrowed, env=narrowed.bind(name, keep=False))
                return g.Rec(name, self.term(inner, depth - 1, act=True))
        inner = replace(scope, env=scope.bind(name, keep=True), exit=None)
        return g.Rec(name, self.term(inner, depth - 1, act=True))

    def parallel(self, scope: _Scope, depth: int) -> g.GlobalTerm:
        channels = self.draw(st.permutations(sorted(scope.channels)))
        count = self.draw(st.integers(2, min(3, len(channels))))
        parts: list[set[Channel]] = [{channels[i]} for i in range(count)]
        for channel in channels[count:]:
            index = self.draw(st.integers(-1, count - 1))
            if index >= 0:
                parts[index].add(channel)
        return g.Parallel(tuple(self.term(_Scope(frozenset(part), ()), depth - 1, act=True)
                                for part in parts))


_SPELLINGS_BY_KEY: dict[str, list[str]] = {}
for _spelling in SORT_SPELLINGS:
    _SPELLINGS_BY_KEY.setdefault(BUILTIN_SORTS[_spelling], []).append(_spelling)


def substitute(term: g.GlobalTerm, name: str, replacement: g.GlobalTerm) -> g.GlobalTerm:
    """``term[replacement / name]``; callers make sure nothing is captured."""
    match term:
        case g.Var(name=found):
            return replacement if found == name else term
        case g.Rec(var=var, body=body):
            return term if var == name else g.Rec(var, substitute(body, name, replacement))
        case g.Choice(sender=p, receiver=q, branches=branches):
            return g.Choice(p, q, tuple(g.Branch(b.message, substitute(b.continuation, name, replacement))
                                        for b in branches), timing=term.timing)
        case g.Routed(sender=p, branches=routes):
            return g.Routed(p, tuple(g.RoutedBranch(r.receiver, r.message,
                                                    substitute(r.continuation, name, replacement))
                                     for r in routes))
        case g.Parallel(branches=parts):
            return g.Parallel(tuple(substitute(part, name, replacement) for part in parts))
    return term


def _names(term: g.GlobalTerm) -> set[str]:
    match term:
        case g.Var(name=name):
            return {name}
        case g.Rec(var=var, body=body):
            return {var} | _names(body)
        case g.Choice(branches=branches):
            return set().union(*(_names(b.continuation) for b in branches))
        case g.Routed(branches=routes):
            return set().union(*(_names(r.continuation) for r in routes))
        case g.Parallel(branches=parts):
            return set().union(*(_names(part) for part in parts))
    return set()


def respellings(loop: g.Rec) -> list[g.GlobalTerm]:
    """Closed ``loop`` and terms with the same runs, written differently:
    unfolded once, its variable renamed, its body unrolled twice."""
    unfolded = substitute(loop.body, loop.var, loop)
    fresh = next(n for n in (*VAR_POOL, "w", "x'", "y''") if n not in _names(loop))
    renamed = g.Rec(fresh, substitute(loop.body, loop.var, g.Var(fresh)))
    twice = g.Rec(fresh, substitute(loop.body, loop.var, renamed.body))
    return [loop, unfolded, renamed, twice]


def _roles_in_text_order(term: g.GlobalTerm) -> tuple[str, ...]:
    found: dict[str, None] = {}

    def visit(node: g.GlobalTerm) -> None:
        match node:
            case g.Choice(sender=p, receiver=q, branches=branches):
                found.setdefault(p)
                found.setdefault(q)
                for b in branches:
                    visit(b.continuation)
            case g.Routed(sender=p, branches=routes):
                found.setdefault(p)
                for r in routes:
                    found.setdefault(r.receiver)
                for r in routes:
                    visit(r.continuation)
            case g.Rec(body=body):
                visit(body)
            case g.Parallel(branches=parts):
                for part in parts:
                    visit(part)

    visit(term)
    return tuple(found)


# ---- text --------------------------------------------------------------------------

_GAPS = ["", " "] * 8 + ["\n  ", " /* c */ ", " // c\n", "\t"]
_WORD_GAPS = [" "] * 6 + ["\n", " /*x*/ ", "\t"]


class _Writer:
    """Writes a global term as text, picking one of the equivalent spellings each time.

    The spelling choices come from one seeded ``Random`` (cheap: one draw per
    example); ``fancy=False`` writes the plainest text, which is what a failing
    example shrinks to.
    """

    def __init__(self, rng: random.Random, fancy: bool) -> None:
        self.rng = rng
        self.fancy = fancy

    def pick(self, plain: str, options: list[str]) -> str:
        return self.rng.choice(options) if self.fancy else plain

    def gap(self) -> str:
        return self.pick(" ", _GAPS)

    def word_gap(self) -> str:
        return self.pick(" ", _WORD_GAPS)

    def chance(self, one_in: int) -> bool:
        return self.fancy and self.rng.randrange(one_in) == 0

    def message(self, message: Interaction) -> str:
        label = message.label
        if message.sort is None:
            if label in BUILTIN_SORTS:
                return f"{label}({self.gap()})"
            return self.pick(label, [label, f"{label}()"])
        full = f"{label}({self.gap()}{self.sort(message.sort)}{self.gap()})"
        if label == message.sort.spelling:
            return self.pick(label, [label, full])
        return full

    def sort(self, sort: Sort) -> str:
        if sort.fields is None:
            return sort.spelling
        return f"{self.gap()},{self.gap()}".join(f"{f.name}{self.gap()}:{self.gap()}{f.sort.spelling}"
                                                 f"{self.refinement(f.refinement)}"
                                                 for f in sort.fields)

    def refinement(self, expr: c.Expr | None) -> str:
        """``{predicate}``, canonical or with extra parentheses and spaces."""
        if expr is None:
            return ""
        text = print_expr(expr)
        if self.chance(3):
            text = f"({self.gap()}{text}{self.gap()})"
        return f"{self.gap()}{{{self.gap()}{text}{self.gap()}}}"

    def timing(self, timing: c.Timing | None) -> str:
        """The time clause with its leading space, its parts in any order, ``±`` or ``+-``."""
        if timing is None:
            return ""
        parts: list[str] = []
        if timing.every is not None:
            jitter = f" {self.pick('+-', ['+-', '±'])} {c.format_duration(timing.jitter)}" if timing.jitter else ""
            parts.append(f"every {c.format_duration(timing.every)}{jitter}")
        if timing.within is not None:
            parts.append(f"within {self.duration(timing.within)}")
        if timing.on_expiry:
            parts.append(f"else{self.word_gap()}timeout")
        if self.fancy:
            self.rng.shuffle(parts)
        return self.word_gap() + self.word_gap().join(parts)

    def duration(self, nanos: int) -> str:
        """A duration, now and then in another unit than the shortest (``0.1s`` for ``100ms``)."""
        if self.chance(3) and nanos % 1_000_000 == 0:
            return f"{nanos / 1_000_000_000:g}s" if nanos < 10**12 else c.format_duration(nanos)
        if self.chance(3):
            return f"{nanos}ns"
        return c.format_duration(nanos)

    def term(self, term: g.GlobalTerm) -> str:
        text = self._term(term)
        if self.chance(8):
            text = f"({self.gap()}{text}{self.gap()})"
        return text

    def _term(self, term: g.GlobalTerm) -> str:
        gap = self.gap
        match term:
            case g.End():
                return self.pick("end", ["end", "⊥"])
            case g.Var(name=name):
                return name
            case g.Rec(var=var, body=body):
                keyword = self.pick("mu", ["mu", "rec", "μ"])
                space = gap() if keyword == "μ" else self.word_gap()
                return f"{keyword}{space}{var}{gap()}.{gap()}{self.term(body)}"
            case g.Parallel(branches=parts):
                inner = f"{gap()}||{gap()}".join(self.term(p) for p in parts)
                return f"({gap()}{inner}{gap()})"
            case g.Choice(sender=p, receiver=q, branches=branches):
                arrow = self.pick("->", ["->", "→"])
                receivers = [q]
                if self.chance(2):
                    receivers, branches = _multicast(term)
                written = f"{gap()},{gap()}".join(receivers)
                head = f"{p}{gap()}{arrow}{gap()}{written}{gap()}:{gap()}"
                if len(branches) == 1 and not self.chance(4):
                    return head + self.sequel(branches[0], term.timing)
                inner = f"{gap()},{gap()}".join(self.branch(b) for b in branches)
                comma = self.pick("", ["", ","])
                return f"{head}{{{gap()}{inner}{comma}{gap()}}}{self.timing(term.timing)}"
            case g.Routed(sender=p, branches=routes):
                arrow = self.pick("->", ["->", "→"])
                inner = f"{gap()},{gap()}".join(
                    f"{r.receiver}{gap()}:{gap()}{self.sequel(g.Branch(r.message, r.continuation))}"
                    for r in routes)
                comma = self.pick("", ["", ","])
                return f"{p}{gap()}{arrow}{gap()}{{{gap()}{inner}{comma}{gap()}}}"
        raise AssertionError(term)

    def sequel(self, branch: g.Branch, timing: c.Timing | None = None) -> str:
        """``msg`` or ``msg.G``, the time clause after the message."""
        head = self.message(branch.message) + self.timing(timing)
        if isinstance(branch.continuation, g.End) and not self.chance(2):
            return head
        return f"{head}{self.gap()}.{self.gap()}{self.term(branch.continuation)}"

    def branch(self, branch: g.Branch) -> str:
        if branch.message.sort is None and self.chance(4):
            # label-only branch, Fig. 2 style
            return f"{branch.message.label}{self.gap()}:{self.gap()}{self.term(branch.continuation)}"
        return self.sequel(branch)


def _multicast(choice: g.Choice) -> tuple[list[str], tuple[g.Branch, ...]]:
    """The receivers and branches of ``choice`` written as a multicast ``p -> q, r : {...}``:
    as long as every branch goes on with the sender sending its own message to one more
    receiver, that receiver joins the list and the branches go on after it."""
    receivers = [choice.receiver]
    branches = choice.branches
    while True:
        nexts = [b.continuation for b in branches]
        if not all(isinstance(n, g.Choice) and len(n.branches) == 1 and n.sender == choice.sender
                   and n.branches[0].message == b.message and n.timing == choice.timing
                   and str(n.branches[0].message.sort) == str(b.message.sort)  # spelled alike
                   for n, b in zip(nexts, branches, strict=True)):
            return receivers, branches
        heads = {n.receiver for n in nexts if isinstance(n, g.Choice)}
        if len(heads) != 1 or heads & {choice.sender, *receivers}:
            return receivers, branches
        receivers.append(heads.pop())
        branches = tuple(g.Branch(b.message, n.branches[0].continuation)
                         for b, n in zip(branches, nexts, strict=True) if isinstance(n, g.Choice))


@st.composite
def global_protocols(draw: st.DrawFn, max_depth: int = 6, max_nodes: int = 30,
                     constrained: bool = False) -> GeneratedGlobal:
    """A well-formed, projectable ``global G`` declaration (text, term and roles).

    Args:
        max_depth: how deeply terms nest.
        max_nodes: roughly how many terms are generated at most.
        constrained: draw time clauses and refinements too (for the language's own tests: a
            run's random drivers neither keep deadlines of nanoseconds nor draw values that fit).
    """
    count = draw(st.sampled_from([2, 3, 4, 5, 3, 4, 5]))  # shrinks to 2, usually more
    roles = tuple(draw(st.permutations(ROLE_POOL))[:count])
    channels = frozenset((p, q) for p in roles for q in roles if p != q)
    generator = _Generator(draw, max_nodes, constrained)
    body = generator.term(_Scope(channels, ()), max_depth)
    if not _roles_in_text_order(body):  # no interaction at all: start with one
        p, q = roles[0], roles[1]
        body = g.Choice(p, q, (g.Branch(generator.message("l0"), body),))
    occurring = _roles_in_text_order(body)
    fancy = draw(st.booleans())
    writer = _Writer(random.Random(draw(st.integers(0, 2**32 - 1)) if fancy else 0), fancy)
    text_body = writer.term(body)
    declared = draw(st.none() | st.permutations(occurring))
    role_list = "" if declared is None else f"({', '.join(declared)})"
    ending = writer.pick("", ["", ";", "\n", " // done\n"])
    leading = writer.pick("", ["", "// protocol\n", "/* a\n b */ "])
    text = f"{leading}global G{role_list} ={writer.word_gap()}{text_body}{ending}"
    return GeneratedGlobal(text, body, occurring if declared is None else tuple(declared))


# ---- junk and near-valid text --------------------------------------------------------

_TOKENS = [
    "global", "local", "type", "at", "mu", "rec", "μ", "end", "⊥", "->", "→", "+", "⊕", "&",
    "!", "?", "||", "|", "(", ")", "{", "}", ",", ":", ".", "=", ";", "G", "H", "L", "A", "B",
    "C", "t", "l0", "int", "Int", "nat", "Twist", "A'", '"m:C"', '"ros:p/msg/T"', '"bad',
    "/*", "*/", "//", "\n", " ", "0", "-", "\\", "'", '"', "é", "\x00", "\ufeff", "\u2028",
    # time clauses and refinements
    "within", "every", "else", "timeout", "100ms", "1.5s", "0ms", "1.5ns", "+-", "±", "and", "or", "not",
    "true", "false", "<=", "==", "!=", "<", "*", "/", "%", "1e999", "abs", "len", "min",
]

_SEEDS = [
    'type Twist = "tinman.messages:Twist"\nglobal P(A, B) = mu t. A -> B : Twist. B -> A : ack. t\n',
    ("local ATM = ?Int. +{ok: ATM', err: end}\n"
     "local ATM' = &{deposit: ?Int. ATM, withdraw: ?Int. +{ok: !Int. ATM, fail: ATM}, "
     "balance: !Int. ATM, quit: end}\n"),
    "global G = (A -> B : x. end || C -> D : {y(int). D -> C : z, w: end})\n",
    ("global ATM = C -> A : Int. A -> C : {ok: ATM', err: end}\n"
     "global ATM' = C -> A : {deposit: C -> A : Int. ATM, quit: end}\n"),
    "local L at A = mu t. !B(l0(int)). &B{l1. t, l2}\n",
    "global M = A -> B, C : m(int). B -> A, C : {ok. end, no: end}\n",
    "global Q = A -> B : quote(price: nat, date: str). B -> A : {ok(at: int), no}\n",
    ("global T = mu t. A -> B : m(x: float{0 <= x <= 1.5 and abs(x - 1) < 2}) every 20ms +- 2ms. "
     "B -> A : {ok(n: int{n == len(s)}). t, no} within 100ms else timeout\n"),
]


@st.composite
def protocol_texts(draw: st.DrawFn) -> str:
    """Random text: characters, or tokens of the language in random order."""
    if draw(st.booleans()):
        return draw(st.text(max_size=80))
    tokens = draw(st.lists(st.sampled_from(_TOKENS), max_size=40))
    gaps = draw(st.lists(st.sampled_from(["", " ", "\n"]), min_size=len(tokens), max_size=len(tokens)))
    return "".join(t + s for t, s in zip(tokens, gaps, strict=True))


_TOKEN_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*'*|->|\|\||\"[^\"]*\"|\S")


@st.composite
def mutated_texts(draw: st.DrawFn) -> str:
    """A valid file (generated or a seed) with a few random edits."""
    if draw(st.booleans()):
        text = draw(global_protocols(max_depth=4, max_nodes=15, constrained=True)).text
        if draw(st.booleans()):
            text += "\n" + draw(st.sampled_from(_SEEDS))
    else:
        text = draw(st.sampled_from(_SEEDS))
    for _ in range(draw(st.integers(1, 4))):
        edit = draw(st.sampled_from(["insert", "delete", "replace", "swap", "truncate", "token"]))
        n = len(text)
        at = draw(st.integers(0, n))
        if edit == "insert":
            text = text[:at] + draw(st.sampled_from(_TOKENS) | st.characters()) + text[at:]
        elif edit == "delete":
            text = text[:at] + text[at + draw(st.integers(1, 5)):]
        elif edit == "replace" and n:
            at = min(at, n - 1)
            text = text[:at] + draw(st.characters()) + text[at + 1:]
        elif edit == "truncate":
            text = text[:at]
        elif edit == "token":
            text = text[:at] + " " + draw(st.sampled_from(_TOKENS)) + " " + text[at:]
        elif edit == "swap":
            spans = [m.span() for m in _TOKEN_RE.finditer(text)]
            if len(spans) >= 2:
                i, j = sorted(draw(st.lists(st.integers(0, len(spans) - 1), min_size=2, max_size=2,
                                            unique=True)))
                (a0, a1), (b0, b1) = spans[i], spans[j]
                text = text[:a0] + text[b0:b1] + text[a1:b0] + text[a0:a1] + text[b1:]
    return text
