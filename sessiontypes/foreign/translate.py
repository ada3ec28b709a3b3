"""A Scribble or nuScr module (:mod:`.tree`) to ``.proto`` surface syntax.

A block of interactions in sequence becomes one global type: each interaction
takes what follows it as its continuation (``rec X { ... }`` falls through to
what follows the block; each branch of a choice goes on with it). A choice
becomes one ``p -> q : {...}`` when every branch begins with a message from
the chooser to the same receiver, and ``p -> {q1 : ..., q2 : ...}`` when the
branches begin with messages to different receivers; a branch that begins
with ``rec`` is unfolded once to find that message. ``do`` inlines the protocol it names with
its roles renamed; a ``do`` that reaches itself again is refused. Names keep
their locations in the foreign file, so the checker's errors point into it.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import NoReturn, assert_never

from .. import syntax as s
from ..errors import Diagnostic, ProtocolCheckError
from ..location import Location
from ..refine import conjunction
from ..sorts import BUILTIN_SORTS
from ..work import METER
from . import tree as t
from .errors import UnsupportedConstructError

__all__ = ["MAX_TRANSLATED", "translate"]

# How many interactions a file's protocols may expand to. A 'do' before the end
# of a protocol is written out at each use (what follows it differs), so a
# chain of protocols that each 'do' the next and then interact means a number
# of interactions quadratic in the file's size; beyond this a located error.
MAX_TRANSLATED = 1_000_000

# Payload type names of the peers that mean a builtin sort (beside BUILTIN_SORTS' own).
_SORT_SYNONYMS = {
    "integer": "int", "Integer": "int", "long": "int", "Long": "int", "short": "int", "Short": "int",
    "string": "str", "boolean": "bool", "Boolean": "bool",
    "double": "float", "Double": "float",
}
# Scribble's Java types that are builtin sorts.
_JAVA_SORTS = {
    "java.lang.Integer": "int", "java.lang.Long": "int", "java.lang.Short": "int",
    "java.lang.String": "str", "java.lang.Boolean": "bool",
    "java.lang.Double": "float", "java.lang.Float": "float",
    "int": "int", "long": "int", "boolean": "bool", "double": "float", "float": "float",
}
# nuScr's payload-less payload.
_UNIT = {"unit", "Unit"}
# A foreign type the language does not know: an opaque Python value.
OPAQUE_TARGET = "builtins:object"
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def translate(module: t.ForeignModule, path: str, lines: tuple[str, ...]) -> s.SourceFile:
    """Return the ``.proto`` declarations of ``module``: one global per non-``aux`` protocol.

    Raises:
        UnsupportedConstructError: a construct outside the subset read.
        ProtocolCheckError: a problem the language has no rule for, such as
            ``continue`` of a variable no ``rec`` binds or ``do`` of an unknown protocol.
    """
    translator = _Translator(module, lines)
    globals_: list[s.Declaration] = []
    try:
        for protocol in module.protocols:
            if protocol.aux:
                continue
            scope = _Scope(protocol, {r.text: r.text for r in protocol.roles}, {}, frozenset())
            with translator.inlining(protocol.name.text):
                body = translator.sequence(protocol.body, s.GEnd(protocol.end), scope)
            globals_.append(s.GlobalDecl(protocol.name, protocol.roles, body, protocol.location))
    finally:
        METER.add("translate", translator.work)
    return s.SourceFile(path, lines, (*translator.sorts.values(), *globals_), translator.shared())


@dataclass(frozen=True)
class _Scope:
    """What names mean inside one protocol's body (an inlined one included)."""

    protocol: t.Protocol
    roles: Mapping[str, str]                 # the protocol's role -> the role it stands for
    variables: Mapping[str, str]             # rec variable -> its .proto name
    taken: frozenset[str]                    # .proto variables bound around here, callers included


class _Translator:
    def __init__(self, module: t.ForeignModule, lines: tuple[str, ...]) -> None:
        self.module = module
        self.lines = lines
        self.protocols = {p.name.text: p for p in module.protocols}
        self.aliases = {a.name.text: a for a in module.aliases}
        self.sorts: dict[str, s.TypeDecl] = {}
        self.work = 0  # interactions translated, for the work meter
        # (protocol, roles, continuation, names taken) -> (continuation, its translation)
        self._expansions: dict[tuple[object, ...], tuple[s.GSyntax, s.GSyntax]] = {}
        # (transfer, roles, continuation) -> (continuation, its translation): the
        # interactions after a 'do' are one node whether the protocol that holds
        # them is translated as a global or inlined in another's, so the 'do'
        # finds its expansion again (see _continuation_key).
        self._transfers: dict[tuple[object, ...], tuple[s.GSyntax, s.GSyntax]] = {}
        # Translations used in more than one place, and their free rec variables.
        self._shared: dict[int, tuple[s.GSyntax, frozenset[str]]] = {}
        self._free_memo: dict[int, tuple[s.GSyntax, frozenset[str]]] = {}
        self._through: dict[int, tuple[tuple[t.Interaction, ...], bool]] = {}
        self._calls: list[str] = []  # the protocols being inlined, outermost first
        self._calling: set[str] = set()

    @contextmanager
    def inlining(self, protocol: str) -> Iterator[None]:
        """Translate ``protocol``'s body within this block (a 'do' of it again is refused).

        A stack on the translator, not a tuple in each scope: a chain of
        thousands of 'do's made the tuples quadratic in time and memory.
        """
        self._calls.append(protocol)
        self._calling.add(protocol)
        try:
            yield
        finally:
            self._calls.pop()
            self._calling.discard(protocol)

    def shared(self) -> dict[int, tuple[s.GSyntax, frozenset[str]]]:
        """The translations of ``do`` used in several places, with their free ``rec`` variables."""
        return self._shared

    # ---- errors ----
    def _line(self, location: Location) -> str:
        return self.lines[location.line - 1] if 0 < location.line <= len(self.lines) else ""

    def _error(self, location: Location, message: str) -> NoReturn:
        raise ProtocolCheckError([Diagnostic("error", location, message, self._line(location))])

    def _refuse(self, location: Location, construct: str, reason: str = "") -> NoReturn:
        raise UnsupportedConstructError(location, construct, reason, self._line(location))

    # ---- names ----
    def _role(self, name: s.Name, scope: _Scope) -> s.Name:
        if name.text not in scope.roles:
            self._error(name.location, f"role {name.text} is not a role of protocol "
                                       f"{scope.protocol.name.text}")
        return s.Name(scope.roles[name.text], name.location)

    @staticmethod
    def _label(name: s.Name) -> s.Name:
        # Scribble labels may be numbers ("1() from A to B"); a label of the language is a name.
        return name if _NAME.match(name.text) else s.Name(f"_{name.text}", name.location)

    def _sort(self, name: s.Name) -> s.Name | None:
        """The sort a payload type name stands for (``None``: nuScr's ``unit``)."""
        text = name.text
        if self.module.declares_types and "." in text:  # module.Alias: Scribble's qualified name
            text = text.rsplit(".", 1)[-1]
            name = s.Name(text, name.location)
        if text in self.aliases:
            alias = self.aliases[text]
            builtin = _JAVA_SORTS.get(alias.external)
            if builtin is None and text not in BUILTIN_SORTS:
                return self._declare(name, alias.location)
            canonical = builtin or BUILTIN_SORTS[text]
            spelling = text if BUILTIN_SORTS.get(text) == canonical else canonical
            return s.Name(spelling, name.location)
        if text in BUILTIN_SORTS:
            return name
        if text in _SORT_SYNONYMS:
            return s.Name(_SORT_SYNONYMS[text], name.location)
        if text in _UNIT and not self.module.declares_types:
            return None
        if self.module.declares_types:
            self._error(name.location, f"unknown payload type {text}; declare it with "
                                       f"'type <java> \"...\" from \"...\" as {text};'")
        if not _NAME.match(text):
            self._refuse(name.location, f"the payload type name {text!r}",
                         "a sort of the language is a name without dots")
        return self._declare(name, name.location)

    def _declare(self, name: s.Name, where: Location) -> s.Name:
        if name.text not in self.sorts:
            self.sorts[name.text] = s.TypeDecl(s.Name(name.text, where), OPAQUE_TARGET, where)
        return name

    # ---- interactions ----
    def sequence(self, block: tuple[t.Interaction, ...], then: s.GSyntax, scope: _Scope) -> s.GSyntax:
        """The global type of ``block`` followed by ``then``.

        Built from the last interaction to the first, in a loop: a block can
        hold any number of interactions (only nesting costs stack).
        """
        self.work += len(block)
        for index, item in enumerate(block[:-1]):  # the first 'continue' that something follows
            if isinstance(item, t.Continue):
                self._error(_location(block[index + 1]), f"this interaction is never reached: "
                                                         f"it follows 'continue {item.var.text}'")
        result = then
        for index in range(len(block) - 1, -1, -1):
            item = block[index]
            rest = block[index + 1:index + 2]  # what follows, if anything: for errors
            match item:
                case t.Continue():
                    if item.var.text not in scope.variables:
                        self._error(item.var.location, f"'continue {item.var.text}': no enclosing "
                                                       f"'rec {item.var.text}'")
                    result = s.GRef(s.Name(scope.variables[item.var.text], item.var.location))
                case t.Transfer():
                    result = self._transfer(item, result, scope)
                case t.Rec():
                    var = _fresh(item.var.text, scope.taken)
                    inner = _Scope(scope.protocol, scope.roles,
                                   {**scope.variables, item.var.text: var}, scope.taken | {var})
                    body = self.sequence(item.body, result, inner)
                    self._check_reached(item.body, rest)
                    result = s.GRec(s.Name(var, item.var.location), body, item.location)
                case t.Choice():
                    if len(item.blocks) > 1 and not isinstance(result, (s.GEnd, s.GRef)):
                        # Every branch goes on with what follows: one node in several places.
                        self._shared[id(result)] = (result, self._free(result))
                    choice = self._choice(item, result, scope)
                    self._check_reached_any(item.blocks, rest)
                    result = choice
                case t.Do():
                    result = self._do(item, result, scope)
                case t.Par():
                    if not isinstance(result, s.GEnd):
                        self._refuse(_location(rest[0]) if rest else item.location,
                                     "an interaction after 'par'",
                                     "a parallel composition of the language has no continuation")
                    result = s.GParallel(tuple(self.sequence(b, s.GEnd(item.location), scope)
                                               for b in item.blocks), item.location)
                case _:
                    assert_never(item)
        return result

    def _check_reached(self, block: tuple[t.Interaction, ...], rest: tuple[t.Interaction, ...]) -> None:
        """Refuse ``rest`` when every path through ``block`` loops back before reaching it."""
        if rest and not self._falls_through(block):
            self._error(_location(rest[0]), "this interaction is never reached: every path "
                                            "before it ends in 'continue'")

    def _check_reached_any(self, blocks: tuple[tuple[t.Interaction, ...], ...],
                           rest: tuple[t.Interaction, ...]) -> None:
        if rest and not any(self._falls_through(b) for b in blocks):
            self._error(_location(rest[0]), "this interaction is never reached: every path "
                                            "before it ends in 'continue'")

    def _falls_through(self, block: tuple[t.Interaction, ...]) -> bool:
        """Whether some path through ``block`` reaches its end (does not end in ``continue``).

        Read off the foreign tree, remembered per block: looking for the
        continuation in the translated type walked the whole type below every
        choice followed by something, quadratic in the nesting.
        """
        known = self._through.get(id(block))
        if known is not None:
            return known[1]
        self._through[id(block)] = (block, True)  # a 'do' cycle (refused elsewhere) ends here
        last = block[-1] if block else None
        match last:
            case None | t.Transfer() | t.Par():
                found = True
            case t.Continue():
                found = False
            case t.Rec():
                found = self._falls_through(last.body)
            case t.Choice():
                found = any(self._falls_through(b) for b in last.blocks)
            case t.Do():
                callee = self.protocols.get(last.protocol.text.rsplit(".", 1)[-1])
                found = callee is None or self._falls_through(callee.body)
            case _:
                assert_never(last)
        self._through[id(block)] = (block, found)
        return found

    def _transfer(self, transfer: t.Transfer, then: s.GSyntax, scope: _Scope) -> s.GSyntax:
        key = (id(transfer), tuple(scope.roles.items()), _continuation_key(then))
        known = self._transfers.get(key)
        if known is not None:
            self._shared[id(known[1])] = (known[1], self._free(known[1]))
            return known[1]
        result = self._transfer_node(transfer, then, scope)
        self._transfers[key] = (then, result)
        return result

    def _transfer_node(self, transfer: t.Transfer, then: s.GSyntax, scope: _Scope) -> s.GSyntax:
        message = self._message(transfer)
        sender = self._role(transfer.sender, scope)
        # A multicast "m from A to B, C" is "A -> B : m. A -> C : m" (as the language's own).
        result = then
        for receiver in reversed(transfer.receivers):
            result = s.GInteraction(sender, self._role(receiver, scope),
                                    (s.GBranchSyntax(message, result),), False, transfer.location)
        return result

    def _message(self, transfer: t.Transfer) -> s.MessageSyntax:
        sorts = [(p, self._sort(p.sort)) for p in transfer.payloads]
        payloads = [(p, sort) for p, sort in sorts if sort is not None]
        # Predicates on no value (a 'unit' payload's refinement, the message's annotation) hold
        # of the message: they join its payload's refinements.
        loose = [p.refinement for p, sort in sorts if sort is None and p.refinement is not None]
        if transfer.annotation is not None:
            loose.append(transfer.annotation)
        named = self.module.refinements and any(p.name is not None for p, _ in payloads)
        if len(payloads) > 1 or named:  # named payloads (fields p1, p2, ... unnamed)
            if transfer.label is None:
                self._refuse(transfer.location, "several payloads without a label")
            fields = [s.FieldSyntax(p.name or s.Name(f"p{number}", p.sort.location), sort, p.refinement)
                      for number, (p, sort) in enumerate(payloads, start=1)]
            if loose:  # checked with the fields' refinements, on the whole payload: on the last field
                last = fields[-1]
                fields[-1] = s.FieldSyntax(last.name, last.sort, conjunction([r for r in (last.refinement, *loose)
                                                                              if r is not None]))
            return s.MessageSyntax(self._label(transfer.label), None, parens=True, fields=tuple(fields))
        sort = payloads[0][1] if payloads else None
        if loose and sort is None:
            self._refuse(loose[0].location, "a refinement of a message without a payload",
                         "the language refines payloads: give the message a payload for it to constrain")
        refinement = conjunction(loose)
        if transfer.label is None:  # Scribble's "(Int) from A to B": the sort names the label
            if sort is None:
                self._refuse(transfer.location, "a message with neither label nor payload")
            return s.MessageSyntax(sort, None, parens=False)
        return s.MessageSyntax(self._label(transfer.label), sort, parens=True, refinement=refinement)

    def _choice(self, choice: t.Choice, then: s.GSyntax, scope: _Scope) -> s.GSyntax:
        chooser = self._role(choice.role, scope)
        heads: list[s.GInteraction] = []  # a head that is itself a choice to several roles: one per branch
        for block in choice.blocks:
            if not block:
                self._error(choice.location, f"a branch of 'choice at {choice.role.text}' is empty")
            head = self._head(self.sequence(block, then, scope), choice, chooser)
            heads.extend(head.branches if isinstance(head, s.GRouted) else (head,))
        routes = [(head.receiver, branch) for head in heads for branch in head.branches]
        receivers = {receiver.text for receiver, _ in routes}
        if len(receivers) == 1:
            return s.GInteraction(chooser, routes[0][0], tuple(b for _, b in routes), True, choice.location)
        # Branches to different roles: "A -> {B : m1. G1, C : m2. G2}".
        return s.GRouted(chooser, tuple(s.GInteraction(chooser, receiver, (branch,), False, receiver.location)
                                        for receiver, branch in routes), choice.location)

    def _head(self, branch: s.GSyntax, choice: t.Choice, chooser: s.Name) -> s.GInteraction | s.GRouted:
        """The message that begins ``branch`` (``rec`` unfolded), checked to be the chooser's."""
        unfolded: set[int] = set()
        while isinstance(branch, s.GRec):
            if id(branch) in unfolded:  # rec X { continue X; }: no message to begin with
                self._error(branch.location, f"unguarded recursion: 'rec {branch.var.text}' "
                                             "loops with no interaction in between")
            unfolded.add(id(branch))
            branch = self._substitute(branch.body, branch.var.text, branch, {})
        match branch:
            case s.GInteraction():
                if branch.sender.text != chooser.text:
                    self._error(branch.location, f"a branch of 'choice at {chooser.text}' begins "
                                                 f"with a message from {branch.sender.text}")
                return branch
            case s.GRouted():  # a nested choice of the chooser's, to several roles
                if branch.sender.text != chooser.text:
                    self._error(branch.location, f"a branch of 'choice at {chooser.text}' begins "
                                                 f"with a message from {branch.sender.text}")
                return branch
            case s.GRef():
                self._refuse(branch.name.location, "a choice branch that begins with 'continue'",
                             "every branch begins with a message from the chooser")
            case s.GParallel():
                self._refuse(branch.location, "a choice branch that begins with 'par'")
            case s.GEnd():
                self._error(choice.location, f"a branch of 'choice at {chooser.text}' has no "
                                             "interaction")
            case _:
                assert_never(branch)
        raise AssertionError(branch)  # every case above returns or raises

    def _substitute(self, body: s.GSyntax, var: str, replacement: s.GSyntax,
                        done: dict[int, s.GSyntax]) -> s.GSyntax:
        """``body`` with the free ``var`` replaced (unfolding ``mu var. body`` once).

        A part where ``var`` is not free is kept as it is, and a part met again
        (the types are shared) is substituted once (``done``).
        """
        if var not in self._free(body):
            return body
        if id(body) in done:
            return done[id(body)]
        result = self._substitute_node(body, var, replacement, done)
        done[id(body)] = result
        return result

    def _substitute_node(self, body: s.GSyntax, var: str, replacement: s.GSyntax,
                         done: dict[int, s.GSyntax]) -> s.GSyntax:
        match body:
            case s.GRef():
                return replacement if body.name.text == var else body
            case s.GEnd():
                return body
            case s.GRec():
                inner = body.body if body.var.text == var else self._substitute(body.body, var, replacement, done)
                return body if inner is body.body else s.GRec(body.var, inner, body.location)
            case s.GInteraction():
                continuations = [None if b.continuation is None
                                 else self._substitute(b.continuation, var, replacement, done)
                                 for b in body.branches]
                if all(c is b.continuation for c, b in zip(continuations, body.branches, strict=True)):
                    return body  # unchanged: keep the object (and its sharing)
                branches = tuple(s.GBranchSyntax(b.message, c)
                                 for b, c in zip(body.branches, continuations, strict=True))
                return s.GInteraction(body.sender, body.receiver, branches, body.braced, body.location)
            case s.GRouted():
                routes = [self._substitute(r, var, replacement, done) for r in body.branches]
                if all(n is r for n, r in zip(routes, body.branches, strict=True)):
                    return body
                return s.GRouted(body.sender, tuple(r for r in routes if isinstance(r, s.GInteraction)),
                                 body.location)
            case s.GParallel():
                parts = tuple(self._substitute(b, var, replacement, done) for b in body.branches)
                if all(p is b for p, b in zip(parts, body.branches, strict=True)):
                    return body
                return s.GParallel(parts, body.location)
            case _:
                assert_never(body)

    def _do(self, do: t.Do, then: s.GSyntax, scope: _Scope) -> s.GSyntax:
        name = do.protocol.text.rsplit(".", 1)[-1]
        callee = self.protocols.get(name)
        if callee is None and (self.module.imports or "." in do.protocol.text):
            self._refuse(do.protocol.location, "'do' of a protocol of another module",
                         "imports are not followed")
        if callee is None:
            self._error(do.protocol.location, f"'do {do.protocol.text}': no protocol "
                                              f"{do.protocol.text} in this file")
        if name in self._calling:
            self._refuse(do.location, f"a recursive 'do' ({' -> '.join((*self._calls, name))})",
                         "write the recursion with 'rec' and 'continue'")
        if len(do.roles) != len(callee.roles):
            self._error(do.location, f"'do {name}' passes {len(do.roles)} roles; protocol "
                                     f"{name} has {len(callee.roles)}")
        roles = {param.text: self._role(arg, scope).text for param, arg in zip(callee.roles, do.roles, strict=True)}
        # The same protocol with the same roles before the same continuation is
        # the same type: translated once and shared (a choice with a 'do' in
        # each branch, level after level, was copied exponentially often).
        key = (name, tuple(roles.items()), _continuation_key(then), scope.taken)
        known = self._expansions.get(key)
        if known is not None:
            self._shared[id(known[1])] = (known[1], self._free(then))
            return known[1]
        if self.work > MAX_TRANSLATED:
            self._error(do.location, f"the protocols expand to more than {MAX_TRANSLATED} interactions "
                                     f"(a 'do' followed by more interactions is written out at every use); "
                                     f"at most {MAX_TRANSLATED} are translated")
        inner = _Scope(callee, roles, {}, scope.taken)
        with self.inlining(name):
            expansion = self.sequence(callee.body, then, inner)
        self._expansions[key] = (then, expansion)
        return expansion

    def _free(self, node: s.GSyntax) -> frozenset[str]:
        """The ``rec`` variables free in ``node`` (remembered per node: the types are shared)."""
        memo = self._free_memo
        stack: list[tuple[s.GSyntax, bool]] = [(node, False)]
        while stack:  # post-order, iterative: sequences nest deeply
            current, done = stack.pop()
            if id(current) in memo:
                continue
            children = _syntax_children(current)
            if not done and children:
                stack.append((current, True))
                stack.extend((child, False) for child in children)
                continue
            match current:
                case s.GRef():
                    free = frozenset({current.name.text})
                case s.GRec():
                    free = memo[id(current.body)][1] - {current.var.text}
                case _:
                    free = frozenset().union(*[memo[id(c)][1] for c in children])
            memo[id(current)] = (current, free)
        return memo[id(node)][1]


def _continuation_key(then: s.GSyntax) -> object:
    """What a translation depends on of its continuation: the node, or just that it ends.

    Every end is alike (its location is where the protocol that ends was
    written, which no check reports): the chain ``P0`` does ``P1``, ``P1``
    does ``P2``, ... translates ``P2`` once, not once per global that reaches it.
    """
    return "end" if isinstance(then, s.GEnd) else id(then)


def _fresh(name: str, taken: frozenset[str]) -> str:
    # An inner 'rec X' inside an outer one would capture the outer's continuation's X.
    while name in taken:
        name += "'"
    return name


def _syntax_children(node: s.GSyntax) -> list[s.GSyntax]:
    match node:
        case s.GInteraction():
            return [b.continuation for b in node.branches if b.continuation is not None]
        case s.GRouted():
            return list(node.branches)
        case s.GRec():
            return [node.body]
        case s.GParallel():
            return list(node.branches)
    return []


def _location(interaction: t.Interaction) -> Location:
    return interaction.location
