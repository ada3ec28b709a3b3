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
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NoReturn, assert_never

from .. import syntax as s
from ..errors import Diagnostic, ProtocolCheckError
from ..location import Location
from ..sorts import BUILTIN_SORTS
from . import tree as t
from .errors import UnsupportedConstructError

__all__ = ["translate"]

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
    for protocol in module.protocols:
        if protocol.aux:
            continue
        scope = _Scope(protocol, {r.text: r.text for r in protocol.roles}, {}, frozenset(),
                       (protocol.name.text,))
        body = translator.sequence(protocol.body, s.GEnd(protocol.end), scope)
        globals_.append(s.GlobalDecl(protocol.name, protocol.roles, body, protocol.location))
    return s.SourceFile(path, lines, (*translator.sorts.values(), *globals_))


@dataclass(frozen=True)
class _Scope:
    """What names mean inside one protocol's body (an inlined one included)."""

    protocol: t.Protocol
    roles: Mapping[str, str]                 # the protocol's role -> the role it stands for
    variables: Mapping[str, str]             # rec variable -> its .proto name
    taken: frozenset[str]                    # .proto variables bound around here, callers included
    calls: tuple[str, ...] = field(default=())  # the protocols being inlined, outermost first


class _Translator:
    def __init__(self, module: t.ForeignModule, lines: tuple[str, ...]) -> None:
        self.module = module
        self.lines = lines
        self.protocols = {p.name.text: p for p in module.protocols}
        self.aliases = {a.name.text: a for a in module.aliases}
        self.sorts: dict[str, s.TypeDecl] = {}

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
        """The global type of ``block`` followed by ``then``."""
        if not block:
            return then
        first, rest = block[0], block[1:]
        match first:
            case t.Continue():
                if rest:
                    self._error(_location(rest[0]), f"this interaction is never reached: "
                                                    f"it follows 'continue {first.var.text}'")
                if first.var.text not in scope.variables:
                    self._error(first.var.location, f"'continue {first.var.text}': no enclosing "
                                                    f"'rec {first.var.text}'")
                return s.GRef(s.Name(scope.variables[first.var.text], first.var.location))
            case t.Transfer():
                return self._transfer(first, self.sequence(rest, then, scope), scope)
            case t.Rec():
                after = self.sequence(rest, then, scope)
                var = _fresh(first.var.text, scope.taken)
                inner = _Scope(scope.protocol, scope.roles,
                               {**scope.variables, first.var.text: var}, scope.taken | {var},
                               scope.calls)
                body = self.sequence(first.body, after, inner)
                self._check_reached(body, after, rest)
                return s.GRec(s.Name(var, first.var.location), body, first.location)
            case t.Choice():
                after = self.sequence(rest, then, scope)
                choice = self._choice(first, after, scope)
                self._check_reached(choice, after, rest)
                return choice
            case t.Do():
                return self._do(first, self.sequence(rest, then, scope), scope)
            case t.Par():
                after = self.sequence(rest, then, scope)
                if not isinstance(after, s.GEnd):
                    self._refuse(_location(rest[0]) if rest else first.location,
                                 "an interaction after 'par'",
                                 "a parallel composition of the language has no continuation")
                return s.GParallel(tuple(self.sequence(b, s.GEnd(first.location), scope)
                                         for b in first.blocks), first.location)
            case _:
                assert_never(first)

    def _check_reached(self, body: s.GSyntax, after: s.GSyntax,
                       rest: tuple[t.Interaction, ...]) -> None:
        """Refuse ``rest`` when every path through ``body`` loops back before reaching it."""
        if rest and not _reaches(body, after):
            self._error(_location(rest[0]), "this interaction is never reached: every path "
                                            "before it ends in 'continue'")

    def _transfer(self, transfer: t.Transfer, then: s.GSyntax, scope: _Scope) -> s.GSyntax:
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
        if len(payloads) > 1:  # several payloads: a message with named payloads (fields p1, p2, ... unnamed)
            if transfer.label is None:
                self._refuse(transfer.location, "several payloads without a label")
            fields = tuple(s.FieldSyntax(p.name or s.Name(f"p{number}", p.sort.location), sort)
                           for number, (p, sort) in enumerate(payloads, start=1))
            return s.MessageSyntax(self._label(transfer.label), None, parens=True, fields=fields)
        sort = payloads[0][1] if payloads else None
        if transfer.label is None:  # Scribble's "(Int) from A to B": the sort names the label
            if sort is None:
                self._refuse(transfer.location, "a message with neither label nor payload")
            return s.MessageSyntax(sort, None, parens=False)
        return s.MessageSyntax(self._label(transfer.label), sort, parens=True)

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
            branch = _substitute(branch.body, branch.var.text, branch)
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

    def _do(self, do: t.Do, then: s.GSyntax, scope: _Scope) -> s.GSyntax:
        name = do.protocol.text.rsplit(".", 1)[-1]
        callee = self.protocols.get(name)
        if callee is None and (self.module.imports or "." in do.protocol.text):
            self._refuse(do.protocol.location, "'do' of a protocol of another module",
                         "imports are not followed")
        if callee is None:
            self._error(do.protocol.location, f"'do {do.protocol.text}': no protocol "
                                              f"{do.protocol.text} in this file")
        if name in scope.calls:
            self._refuse(do.location, f"a recursive 'do' ({' -> '.join((*scope.calls, name))})",
                         "write the recursion with 'rec' and 'continue'")
        if len(do.roles) != len(callee.roles):
            self._error(do.location, f"'do {name}' passes {len(do.roles)} roles; protocol "
                                     f"{name} has {len(callee.roles)}")
        roles = {param.text: self._role(arg, scope).text for param, arg in zip(callee.roles, do.roles, strict=True)}
        inner = _Scope(callee, roles, {}, scope.taken, (*scope.calls, name))
        return self.sequence(callee.body, then, inner)


def _fresh(name: str, taken: frozenset[str]) -> str:
    # An inner 'rec X' inside an outer one would capture the outer's continuation's X.
    while name in taken:
        name += "'"
    return name


def _reaches(body: s.GSyntax, target: s.GSyntax) -> bool:
    """Whether ``target`` (the very object) occurs in ``body``."""
    seen: set[int] = set()
    stack = [body]
    while stack:
        node = stack.pop()
        if node is target:
            return True
        if id(node) in seen:
            continue
        seen.add(id(node))
        match node:
            case s.GInteraction():
                stack.extend(b.continuation for b in node.branches if b.continuation is not None)
            case s.GRouted():
                stack.extend(node.branches)
            case s.GRec():
                stack.append(node.body)
            case s.GParallel():
                stack.extend(node.branches)
            case s.GRef() | s.GEnd():
                pass
            case _:
                assert_never(node)
    return False


def _substitute(body: s.GSyntax, var: str, replacement: s.GSyntax) -> s.GSyntax:
    """``body`` with the free ``var`` replaced (unfolding ``mu var. body`` once)."""
    match body:
        case s.GRef():
            return replacement if body.name.text == var else body
        case s.GEnd():
            return body
        case s.GRec():
            inner = body.body if body.var.text == var else _substitute(body.body, var, replacement)
            return body if inner is body.body else s.GRec(body.var, inner, body.location)
        case s.GInteraction():
            continuations = [None if b.continuation is None
                             else _substitute(b.continuation, var, replacement)
                             for b in body.branches]
            if all(c is b.continuation for c, b in zip(continuations, body.branches, strict=True)):
                return body  # unchanged: keep the object, which _reaches looks for
            branches = tuple(s.GBranchSyntax(b.message, c)
                             for b, c in zip(body.branches, continuations, strict=True))
            return s.GInteraction(body.sender, body.receiver, branches, body.braced, body.location)
        case s.GRouted():
            routes = [_substitute(r, var, replacement) for r in body.branches]
            if all(n is r for n, r in zip(routes, body.branches, strict=True)):
                return body
            return s.GRouted(body.sender, tuple(r for r in routes if isinstance(r, s.GInteraction)),
                             body.location)
        case s.GParallel():
            parts = tuple(_substitute(b, var, replacement) for b in body.branches)
            if all(p is b for p, b in zip(parts, body.branches, strict=True)):
                return body
            return s.GParallel(parts, body.location)
        case _:
            assert_never(body)


def _location(interaction: t.Interaction) -> Location:
    return interaction.location
