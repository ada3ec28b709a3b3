"""Well-formedness of the refinements of a global type: names in scope, types, satisfiability.

A path's first name in the refinement of an interaction ``A -> B : m`` is, in this order:

1. a field of ``m``'s record payload;
2. a field of an earlier *record* payload that both ``A`` and ``B`` saw (sent or received) on
   every path to here, the latest such message being the same one for both: each checks the
   predicate with its own copy of the value, so both must hold the same value;
3. for a payload of a declared sort (``type Twist = "ros:..."``), an attribute of the value,
   of a type only the bound class knows (checked at run time).

What each role saw on every path is a forward dataflow over the term as a graph (a shared
continuation is one point; ``mu``'s body is entered again from each of its variables) that
runs to a fixpoint: on joining paths a role keeps the names it saw on all of them. The types
are :mod:`.refinetypes`' and the satisfiability :mod:`.refinesat`'s. A term without
refinements costs one walk that finds none.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass

from .constraints import Binary, Call, Compare, Expr, Path, Unary
from .global_types import Choice, End, GlobalTerm, Parallel, Rec, Routed, Var
from .location import NOWHERE, Location
from .refinesat import conjuncts, unsatisfiable
from .refinetypes import article, type_errors
from .sorts import Interaction, Sort
from .work import METER

__all__ = ["check_refinements", "has_refinement", "MAX_SCOPE_WORK"]

# How many (name, interaction) pairs the scope's dataflow may hold: each point of the term
# keeps what each role saw of each name refinements take from earlier messages. Far beyond
# a written protocol; a generated one beyond it gets a located error, not an exhausted memory.
MAX_SCOPE_WORK = 500_000


@dataclass(frozen=True, slots=True)
class _Seen:
    """What one role saw of one name on every path to a point: its kinds and the messages (ids)."""

    kinds: frozenset[str]
    sites: frozenset[int]


@dataclass(frozen=True, slots=True)
class _State:
    """Per role: the names seen on every path (``must``) and on some path (``may``)."""

    must: Mapping[str, Mapping[str, _Seen]]
    may: Mapping[str, frozenset[str]]

    def join(self, other: _State) -> _State:
        roles = self.must.keys() & other.must.keys()
        must = {role: {name: _Seen(seen.kinds | other.must[role][name].kinds,
                                   seen.sites | other.must[role][name].sites)
                       for name, seen in self.must[role].items() if name in other.must[role]}
                for role in roles}
        may = {role: self.may.get(role, frozenset()) | other.may.get(role, frozenset())
               for role in self.may.keys() | other.may.keys()}
        return _State(must, may)

    def after(self, roles: tuple[str, str], message: Interaction, site: int, named: frozenset[str]) -> _State:
        """The state once both ``roles`` saw ``message`` (``site`` tells that message apart).

        Only the fields some refinement names are followed: the state stays as small as
        the refinements, however many fields the protocol's messages have.
        """
        fields = message.sort.fields if message.sort is not None else None
        fields = tuple(item for item in fields if item.name in named) if fields else None
        if not fields:
            return self
        must = dict(self.must)
        may = dict(self.may)
        for role in roles:
            seen = dict(must.get(role, {}))
            for item in fields:
                seen[item.name] = _Seen(frozenset({_kind(item.sort)}), frozenset({site}))
            must[role] = seen
            may[role] = may.get(role, frozenset()) | {item.name for item in fields}
        return _State(must, may)


_START = _State({}, {})
_Key = tuple[int, tuple[object, ...]]  # a point: the term's id and its _Env
_Env = tuple[tuple[str, _Key], ...]  # each mu variable in scope, innermost first, and its point


def check_refinements(term: GlobalTerm) -> list[tuple[Location, str]]:
    """The errors of ``term``'s refinements, each with its location, in source order.

    Each says what was expected: an unknown name ("refinement names seq, which B never saw
    before this interaction"), a type that an operator does not take ("`and` takes bools, got
    int (x)"), a refinement that can never hold ("unsatisfiable refinement: no value of x has
    x > 5 and x < 3").
    """
    messages = list(_messages(term))
    refined = [(message, _refinements(message)) for message in messages if _refinements(message)]
    if not refined:
        return []
    # Only the names a refinement takes from an earlier message are followed through the term.
    earlier = frozenset(name for message, predicates in refined for p in predicates for name in _heads(p)
                        if name not in _field_names(message))
    if len(earlier) * len(messages) > MAX_SCOPE_WORK:
        first = refined[0][1][0]
        problem = (f"the refinements name {len(earlier)} fields of earlier messages in a protocol of "
                   f"{len(messages)} interactions: more than the {MAX_SCOPE_WORK:,} (names times interactions) "
                   f"whose scope is checked")
        return [(first.location, problem)]
    flow = _Flow(earlier)
    flow.run(term)
    found: dict[tuple[Location, str], None] = {}
    for key, (node, _env) in flow.nodes.items():
        state = flow.states[key]
        for sender, receiver, message, location in _branches(node):
            for error in _check_message(state, (sender, receiver), message, location):
                found[error] = None
    return sorted(found, key=lambda e: (e[0].path, e[0].line, e[0].column, e[1]))


def _kind(sort: Sort) -> str:
    """A builtin sort's name; a declared sort's, marked unknown with '?'."""
    return sort.key if sort.is_builtin else f"?{sort.spelling}"


def _messages(term: GlobalTerm) -> Iterator[Interaction]:
    stack, done = [term], set()
    while stack:
        node = stack.pop()
        if id(node) in done:
            continue
        done.add(id(node))
        match node:
            case Choice():
                for branch in node.branches:
                    yield branch.message
                    stack.append(branch.continuation)
            case Routed():
                for routed in node.branches:
                    yield routed.message
                    stack.append(routed.continuation)
            case Rec():
                stack.append(node.body)
            case Parallel():
                stack.extend(node.branches)
    METER.add("refinements", len(done))


def has_refinement(message: Interaction) -> bool:
    """Whether ``message`` or a field of its payload has a refinement (what :func:`check_refinements` checks)."""
    return bool(_refinements(message))


def _refinements(message: Interaction) -> list[Expr]:
    fields = message.sort.fields if message.sort is not None and message.sort.fields else ()
    found = [message.refinement] if message.refinement is not None else []
    return found + [item.refinement for item in fields if item.refinement is not None]


def _field_names(message: Interaction) -> frozenset[str]:
    fields = message.sort.fields if message.sort is not None and message.sort.fields else ()
    return frozenset(item.name for item in fields)


def _heads(expr: Expr) -> Iterator[str]:
    """The first names of the paths in ``expr``."""
    stack = [expr]
    while stack:
        node = stack.pop()
        match node:
            case Path():
                yield node.parts[0]
            case Unary():
                stack.append(node.operand)
            case Binary():
                stack.extend((node.left, node.right))
            case Compare():
                stack.extend(node.operands)
            case Call():
                stack.extend(node.args)


def _branches(node: GlobalTerm) -> Iterator[tuple[str, str, Interaction, Location]]:
    if isinstance(node, Choice):
        for branch in node.branches:
            location = branch.location if branch.location != NOWHERE else node.location
            yield node.sender, node.receiver, branch.message, location
    elif isinstance(node, Routed):
        for routed in node.branches:
            location = routed.location if routed.location != NOWHERE else node.location
            yield node.sender, routed.receiver, routed.message, location


class _Flow:
    """The dataflow: the state at each point (a term under its mu variables), to a fixpoint."""

    def __init__(self, named: frozenset[str]) -> None:
        self.named = named  # the names refinements use: the only fields followed
        self.nodes: dict[_Key, tuple[GlobalTerm, _Env]] = {}
        self.states: dict[_Key, _State] = {}
        self.work: list[_Key] = []

    def run(self, term: GlobalTerm) -> None:
        self._reach(term, (), _START)
        while self.work:
            key = self.work.pop()
            node, env = self.nodes[key]
            self._step(key, node, env, self.states[key])

    def _reach(self, node: GlobalTerm, env: _Env, state: _State) -> None:
        key = (id(node), env)
        old = self.states.get(key)
        if old is None:
            self.nodes[key] = (node, env)
            self.states[key] = state
        else:
            state = old.join(state)
            if state == old:
                return
            self.states[key] = state
        self.work.append(key)

    def _step(self, key: _Key, node: GlobalTerm, env: _Env, state: _State) -> None:
        match node:
            case Choice():
                for branch in node.branches:
                    self._reach(branch.continuation, env,
                                state.after((node.sender, node.receiver), branch.message, id(branch), self.named))
            case Routed():
                for routed in node.branches:
                    self._reach(routed.continuation, env,
                                state.after((node.sender, routed.receiver), routed.message, id(routed), self.named))
            case Rec():
                self._reach(node.body, ((node.var, key), *env), state)
            case Var():
                for var, target in env:
                    if var == node.name:
                        rec, rec_env = self.nodes[target]
                        self._reach(rec, rec_env, state)
                        break
            case Parallel():
                for part in node.branches:
                    self._reach(part, env, state)
            case End():
                pass


def _check_message(state: _State, roles: tuple[str, str], message: Interaction,
                   where: Location) -> list[tuple[Location, str]]:
    predicates = _refinements(message)
    if not predicates:
        return []
    resolve = _Resolver(state, roles, message).resolve
    errors: list[tuple[Location, str]] = []
    for predicate in predicates:
        errors.extend(type_errors(predicate, resolve, _where(predicate, where)))
    if errors:
        return errors
    parts = [part for predicate in predicates for part in conjuncts(predicate)]
    problem = unsatisfiable(parts, resolve, where)
    return [problem] if problem is not None else []


def _where(expr: Expr, fallback: Location) -> Location:
    return expr.location if expr.location != NOWHERE else fallback


@dataclass(frozen=True, slots=True)
class _Resolver:
    """What the names of one interaction's refinements mean (the module docstring's rule)."""

    state: _State
    roles: tuple[str, str]
    message: Interaction

    def resolve(self, path: Path) -> tuple[str | None, str | None]:
        head, dotted = path.parts[0], ".".join(path.parts)
        sort = self.message.sort
        fields = {item.name: item.sort for item in sort.fields} if sort is not None and sort.fields else {}
        if head in fields:
            kind: str | None = _kind(fields[head])
        else:
            kind, problem = self._earlier(head)
            if problem is not None:
                if sort is not None and sort.target is not None:
                    return None, None  # an attribute of a declared sort's value
                unseen = problem.startswith(f"refinement names {head}: ")  # neither party saw it anywhere
                return None, problem + (self._hint(sort) if unseen else "")
        if len(path.parts) == 1 or kind is None or kind.startswith("?"):
            return (None if kind is None or kind.startswith("?") else kind), None
        return None, f"refinement names {dotted}, but {head} is {article(kind)}, which has no field {path.parts[1]}"

    def _earlier(self, head: str) -> tuple[str | None, str | None]:
        sender, receiver = self.roles
        seen = [self.state.must.get(role, {}).get(head) for role in self.roles]
        missing = [role for role, one in zip(self.roles, seen, strict=True) if one is None]
        if not missing:
            first, second = seen
            assert first is not None and second is not None
            kinds = sorted(first.kinds | second.kinds)
            if len(kinds) > 1:
                one, other = (article(k.lstrip("?")) for k in kinds[:2])
                return None, f"refinement names {head}, which is {one} on one path to here and {other} on another"
            if first.sites != second.sites:
                return None, (f"refinement names {head}, whose latest value {sender} and {receiver} saw in "
                              f"different messages")
            return kinds[0], None
        maybe = [role for role in missing if head in self.state.may.get(role, frozenset())]
        if len(missing) == 1:
            role = missing[0]
            if maybe:
                return None, f"refinement names {head}, which {role} did not see on every path to this interaction"
            return None, f"refinement names {head}, which {role} never saw before this interaction"
        if maybe:
            return None, (f"refinement names {head}, which {sender} and {receiver} did not both see on every "
                          f"path to this interaction")
        return None, (f"refinement names {head}: no field of this message is called {head}, and neither "
                      f"{sender} nor {receiver} saw one before this interaction")

    def _hint(self, sort: Sort | None) -> str:
        if self.message.refinement is not None and (sort is None or sort.is_builtin):
            what = "no payload" if sort is None else f"a payload of the builtin sort {sort.key}"
            return f" ({what} has no names: write a named field, as in m(x: int{{x > 0}}))"
        return ""

