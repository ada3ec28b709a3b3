"""Surface syntax to core types: names, sorts and equation-style recursion.

Resolution and the name-related checks of LANGUAGE.md section 6 happen in
one walk, so every problem is reported once with its location:
unknown sorts, unbound names, unguarded recursion, a recursion variable used
inside a parallel composition it encloses, a role sending to itself,
duplicate labels. Problems go to a :class:`Reporter`; the walk continues so
that one run reports all of them.

Equation-style recursion (``ATM = ... ATM'``, ``ATM' = ... ATM``) is expanded
into ``mu``: a reference to a declaration that is not being expanded inlines
its body, wrapped in ``mu Name.`` when the body refers back to it.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from . import global_types as g
from . import local_types as lt
from . import syntax as s
from .errors import Diagnostic
from .location import Location
from .sorts import BUILTIN_SORTS, Message, Sort, builtin_sort

__all__ = ["Reporter", "SortTable", "resolve_global", "resolve_local"]

_TARGET = re.compile(
    r"^(?:[A-Za-z_][\w]*(?:\.[A-Za-z_]\w*)*:[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*"
    r"|ros:[A-Za-z_]\w*/(?:msg|srv|action)/[A-Za-z_]\w*)$"
)


@dataclass
class Reporter:
    """Collects diagnostics for one source file."""

    source: s.SourceFile
    diagnostics: list[Diagnostic] = field(default_factory=list)

    def error(self, location: Location, message: str) -> None:
        self.diagnostics.append(
            Diagnostic("error", location, message, self.source.line(location.line)))

    def warning(self, location: Location, message: str) -> None:
        self.diagnostics.append(
            Diagnostic("warning", location, message, self.source.line(location.line)))


class SortTable:
    """The builtin sorts and the file's ``type`` declarations; records uses."""

    def __init__(self, declarations: Mapping[str, s.TypeDecl], reporter: Reporter) -> None:
        self.declared = dict(declarations)
        self.used: set[str] = set()
        self.reporter = reporter
        for decl in declarations.values():
            if not _TARGET.match(decl.target):
                reporter.error(decl.name.location,
                               f"type {decl.name.text} is bound to {decl.target!r}; expected "
                               "\"module:QualifiedName\" or \"ros:package/msg/Name\"")

    def is_sort(self, name: str) -> bool:
        return name in BUILTIN_SORTS or name in self.declared

    def sort(self, name: s.Name) -> Sort | None:
        """The sort called ``name``; reports an unknown sort and returns None."""
        if name.text in BUILTIN_SORTS:
            return builtin_sort(name.text)
        decl = self.declared.get(name.text)
        if decl is None:
            self.reporter.error(name.location, f"unknown sort '{name.text}'; expected a builtin "
                                "sort (int, nat, bool, str, float, bytes) or a declared type")
            return None
        self.used.add(name.text)
        return Sort(name.text, name.text, decl.target)

    def message(self, syntax: s.MessageSyntax) -> Message:
        """Apply the abbreviation rule: a bare sort name labels a value of that sort."""
        if syntax.parens:
            if syntax.sort is None:
                return Message(syntax.label.text, None, self.is_sort(syntax.label.text))
            return Message(syntax.label.text, self.sort(syntax.sort))
        if self.is_sort(syntax.label.text):
            return Message(syntax.label.text, self.sort(syntax.label))
        return Message(syntax.label.text)

    def defined(self) -> dict[str, Sort]:
        return {name: Sort(name, name, d.target) for name, d in self.declared.items()}


@dataclass(frozen=True, slots=True)
class _Binder:
    """A name in scope: a ``mu`` variable or a declaration being expanded."""

    name: str
    depth: int           # interactions on the path when bound (guardedness)
    parallel_depth: int  # parallel compositions on the path when bound
    declaration: bool
    level: int           # inlining level it was bound at
    shadowed: _Binder | None  # the binder of the same name it hides


class _Scope:
    """The names in scope, bound and unbound as the walk enters and leaves binders.

    One mutable map from name to innermost binder, so entering a ``mu`` and
    looking a name up cost O(1) however deep the nesting (a tuple of binders
    made both linear, and deep protocols quadratic).
    """

    def __init__(self) -> None:
        self.top: dict[str, _Binder] = {}
        # How many declaration bodies are being inlined: a mu variable is visible
        # only at the level it was bound at (a referenced body cannot see the
        # referring body's variables); declarations are visible at every level.
        self.level = 0

    def bind(self, name: str, depth: int, parallel_depth: int, declaration: bool) -> _Binder:
        """Bring ``name`` into scope; undo with :meth:`unbind` (in a ``finally``)."""
        binder = _Binder(name, depth, parallel_depth, declaration, self.level, self.top.get(name))
        self.top[name] = binder
        return binder

    def unbind(self, binder: _Binder) -> None:
        if binder.shadowed is None:
            del self.top[binder.name]
        else:
            self.top[binder.name] = binder.shadowed


class _Capture(Exception):  # noqa: N818 (a control-flow signal, not an error: STYLE.md)
    """Internal: a declaration reference would be captured by the mu variable ``name``."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.name = name


Syntax = TypeVar("Syntax")
Term = TypeVar("Term")


@dataclass
class _Walk(Generic[Syntax, Term]):
    """State shared by the global and the local resolver."""

    reporter: Reporter
    sorts: SortTable
    declarations: Mapping[str, Syntax]   # the same kind's declarations, by name
    kind: str                            # "global" or "local"
    other_kind: set[str]                 # names declared with another kind

    def lookup(self, name: s.Name, scope: _Scope, depth: int,
               parallel_depth: int) -> _Binder | str | None:
        """The binder of ``name``, or "decl" for a declaration to inline, or None (reported).

        Raises:
            _Capture: ``name`` means an enclosing declaration, but a ``mu`` of the
                referring body with the same name sits in between.
        """
        binder = scope.top.get(name.text)
        hidden = False
        while binder is not None and not (binder.declaration or binder.level == scope.level):
            hidden, binder = True, binder.shadowed
        if binder is not None:
            if hidden:
                raise _Capture(name.text)
            if binder.parallel_depth < parallel_depth:
                self.reporter.error(name.location, f"recursion variable '{name.text}' is used inside "
                                    "a parallel composition it encloses")
                return None
            if binder.depth == depth:
                self.reporter.error(name.location, f"unguarded recursion: '{name.text}' recurs "
                                    "with no interaction in between")
                return None
            return binder
        if name.text in self.declarations:
            return "decl"
        if name.text in self.other_kind:
            self.reporter.error(name.location, f"'{name.text}' is not a {self.kind} declaration")
        else:
            self.reporter.error(name.location, f"unbound name '{name.text}'")
        return None


def _check_labels(reporter: Reporter, labels: Iterable[s.Name]) -> None:
    seen: set[str] = set()
    for label in labels:
        if label.text in seen:
            reporter.error(label.location, f"duplicate label '{label.text}' in one choice")
        seen.add(label.text)


def _inline(walk: _Walk[Syntax, Term], name: s.Name, scope: _Scope, depth: int,
            parallel_depth: int, body_of: Callable[[Syntax], object],
            resolve: Callable[..., Term], make_rec: Callable[[str, Term, Location], Term],
            uses: Callable[[Term, str], bool]) -> Term:
    """Expand a reference to a declaration in place (equation-style recursion)."""
    decl = walk.declarations[name.text]
    # Not context managers: resuming generators deep in a recursion costs time
    # proportional to the depth in CPython 3.11, which made deep protocols quadratic.
    scope.level += 1
    binder = scope.bind(name.text, depth, parallel_depth, declaration=True)
    try:
        body = resolve(body_of(decl), scope, depth, parallel_depth)
    finally:
        scope.unbind(binder)
        scope.level -= 1
    if uses(body, name.text):
        return make_rec(name.text, body, name.location)
    return body


def _with_mu(walk: _Walk[Syntax, Term], var: str, scope: _Scope, depth: int,
             parallel_depth: int, build: Callable[[str], Term]) -> Term:
    """Resolve a ``mu var.`` body; rename ``var`` if it would capture a declaration name.

    Renaming happens only when an inlined declaration refers, through ``var``'s
    name, to an enclosing declaration; otherwise the written name is kept.
    """
    name = var
    while True:
        mark = len(walk.reporter.diagnostics)
        binder = scope.bind(name, depth, parallel_depth, declaration=False)
        try:
            return build(name)
        except _Capture as capture:
            if capture.name != name:
                raise
            del walk.reporter.diagnostics[mark:]
            taken = set(scope.top) | set(walk.declarations)
            while name in taken:
                name += "'"
        finally:
            scope.unbind(binder)


# ---- global ------------------------------------------------------------------------

def resolve_global(decl: s.GlobalDecl, walk: _Walk[s.GlobalDecl, g.GlobalTerm]) -> g.GlobalTerm:
    """Resolve one global declaration (the walk reports problems)."""
    scope = _Scope()
    scope.bind(decl.name.text, 0, 0, declaration=True)
    body = _resolve_g(walk, decl.body, scope, 0, 0)
    if _uses_g(body, decl.name.text):
        body = g.Rec(decl.name.text, body, decl.name.location)
    return body


def _resolve_g(walk: _Walk[s.GlobalDecl, g.GlobalTerm], node: s.GSyntax | None,
               scope: _Scope, depth: int, parallel_depth: int) -> g.GlobalTerm:
    match node:
        case None:
            return g.End()
        case s.GEnd(location=location):
            return g.End(location)
        case s.GInteraction(sender=sender, receiver=receiver, branches=branches, location=location):
            if sender.text == receiver.text:
                walk.reporter.error(receiver.location, f"role {sender.text} sends a message to itself")
            _check_labels(walk.reporter, ([b.message.label for b in branches]))
            return g.Choice(sender.text, receiver.text, tuple([
                g.Branch(walk.sorts.message(b.message),
                         _resolve_g(walk, b.continuation, scope, depth + 1, parallel_depth),
                         b.message.label.location)
                for b in branches]), location, receiver.location)
        case s.GRec(var=var, body=body, location=location):
            return _with_mu(walk, var.text, scope, depth, parallel_depth,
                            lambda name: g.Rec(name, _resolve_g(walk, body, scope, depth,
                                                                parallel_depth), location))
        case s.GParallel(branches=branches, location=location):
            return g.Parallel(tuple([_resolve_g(walk, b, scope, depth, parallel_depth + 1)
                                    for b in branches]), location)
        case s.GRef(name=name):
            found = walk.lookup(name, scope, depth, parallel_depth)
            if isinstance(found, _Binder):
                return g.Var(name.text, name.location)
            if found == "decl":
                return _inline(walk, name, scope, depth, parallel_depth,
                               lambda d: d.body, lambda *a: _resolve_g(walk, *a), g.Rec, _uses_g)
            return g.End(name.location)  # already reported
    raise AssertionError(f"unexpected global syntax {node!r}")


def _uses_g(term: g.GlobalTerm, name: str) -> bool:
    """Whether ``name`` occurs free in ``term``."""
    stack = [term]  # iterative: sequences nest deeply
    while stack:
        match stack.pop():
            case g.Var(name=n):
                if n == name:
                    return True
            case g.Choice(branches=branches):
                stack.extend([b.continuation for b in branches])
            case g.Rec(var=var, body=body):
                if var != name:
                    stack.append(body)
            case g.Parallel(branches=branches):
                stack.extend(branches)
    return False


# ---- local -------------------------------------------------------------------------

def resolve_local(decl: s.LocalDecl, walk: _Walk[s.LocalDecl, lt.LocalTerm]) -> lt.LocalTerm:
    """Resolve one local declaration (the walk reports problems)."""
    scope = _Scope()
    scope.bind(decl.name.text, 0, 0, declaration=True)
    body = _resolve_l(walk, decl.body, scope, 0, 0)
    if _uses_l(body, decl.name.text):
        body = lt.Rec(decl.name.text, body, decl.name.location)
    return body


def _resolve_l(walk: _Walk[s.LocalDecl, lt.LocalTerm], node: s.LSyntax | None,
               scope: _Scope, depth: int, parallel_depth: int) -> lt.LocalTerm:
    match node:
        case None:
            return lt.End()
        case s.LEnd(location=location):
            return lt.End(location)
        case s.LAction(direction=direction, peer=peer, message=message, continuation=rest,
                       location=location):
            if peer is None and not walk.sorts.is_sort(message.label.text):
                walk.reporter.error(message.label.location, f"unknown sort '{message.label.text}'; "
                                    f"the binary form {direction}Sort sends or receives a value of a sort")
                resolved = Message(message.label.text)
            else:
                resolved = walk.sorts.message(message)
            cont = _resolve_l(walk, rest, scope, depth + 1, parallel_depth)
            make = lt.Send if direction == "!" else lt.Recv
            return make(peer.text if peer else None, resolved, cont, location)
        case s.LChoice(kind=kind, peer=peer, branches=branches, location=location):
            _check_labels(walk.reporter, ([b.message.label for b in branches]))
            resolved_branches = tuple([
                lt.Branch(walk.sorts.message(b.message),
                          _resolve_l(walk, b.continuation, scope, depth + 1, parallel_depth),
                          b.message.label.location)
                for b in branches])
            make_choice = lt.select if kind == "+" else lt.offer
            return make_choice(peer.text if peer else None, resolved_branches, location)
        case s.LRec(var=var, body=body, location=location):
            return _with_mu(walk, var.text, scope, depth, parallel_depth,
                            lambda name: lt.Rec(name, _resolve_l(walk, body, scope, depth,
                                                                 parallel_depth), location))
        case s.LParallel(branches=branches, location=location):
            return lt.Parallel(tuple([_resolve_l(walk, b, scope, depth, parallel_depth + 1)
                                     for b in branches]), location)
        case s.LRef(name=name):
            found = walk.lookup(name, scope, depth, parallel_depth)
            if isinstance(found, _Binder):
                return lt.Var(name.text, name.location)
            if found == "decl":
                return _inline(walk, name, scope, depth, parallel_depth,
                               lambda d: d.body, lambda *a: _resolve_l(walk, *a), lt.Rec, _uses_l)
            return lt.End(name.location)
    raise AssertionError(f"unexpected local syntax {node!r}")


def _uses_l(term: lt.LocalTerm, name: str) -> bool:
    """Whether ``name`` occurs free in ``term``."""
    stack = [term]  # iterative: sequences nest deeply
    while stack:
        match stack.pop():
            case lt.Var(name=n):
                if n == name:
                    return True
            case lt.Send(continuation=cont) | lt.Recv(continuation=cont):
                stack.append(cont)
            case lt.Select(branches=branches) | lt.Offer(branches=branches):
                stack.extend([b.continuation for b in branches])
            case lt.Rec(var=var, body=body):
                if var != name:
                    stack.append(body)
            case lt.Parallel(branches=branches):
                stack.extend(branches)
    return False
