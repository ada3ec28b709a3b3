"""Names in scope and equation-style references, each declaration expanded once.

A reference to a declaration that is not being expanded stands for its body
(LANGUAGE.md section 2), so the resolved type is the body inlined, wrapped in
``mu Name.`` when it refers back to the declaration. Inlining a fresh copy
at every use makes a file whose declarations each refer twice to the next
one exponential (``G0 = A -> B : {l. G1, r. G1}``, ``G1 = ...``), and a chain
of n declarations quadratic. Instead a declaration's body is resolved once
per *context* and the same node is returned at every use, so the resolved
types form a DAG of the size of the file; the passes that walk them memoise
on the shared nodes (:mod:`sessiontypes.sharing`).

What a body resolves to depends on its context only through the declarations
of its own strongly connected component of the reference graph that are
being expanded around it (a reference to one of them is a recursion variable,
or an unguarded-recursion error), so that is the memo key; a declaration that
is not in a cycle has one expansion. The key is exact only when no ``mu``
hides a declaration being expanded and no ``mu`` had to be renamed; in those
rare cases the body is resolved again, as before.
"""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from . import syntax as s
from .errors import Diagnostic
from .filescope import Reporter, SortTable
from .work import METER

__all__ = ["Binder", "Scope", "Capture", "Walk", "components"]


@dataclass(frozen=True, slots=True)
class Binder:
    """A name in scope: a ``mu`` variable or a declaration being expanded."""

    name: str            # the name as written: the scope's key
    var: str             # the variable it stands for in the resolved term (a renamed mu's differs)
    depth: int           # interactions on the path when bound (guardedness)
    parallel_depth: int  # parallel compositions on the path when bound
    declaration: bool
    level: int           # expansion level it was bound at
    shadowed: Binder | None  # the binder of the same name it hides
    hides_declaration: bool  # a mu named like a declaration being expanded


class _Component:
    """The declarations of one cycle of references that are being expanded, innermost last."""

    __slots__ = ("contexts", "depths", "parallel_depths")

    def __init__(self) -> None:
        self.depths: list[int] = []
        self.parallel_depths: list[int] = []
        self.contexts: list[int] = []


class Scope:
    """The names in scope, bound and unbound as the walk enters and leaves binders.

    One mutable map from name to innermost binder, so entering a ``mu`` and
    looking a name up cost O(1) however deep the nesting (a tuple of binders
    made both linear, and deep protocols quadratic).
    """

    def __init__(self, components: Mapping[str, int], contexts: dict[tuple[int, str], int]) -> None:
        self.components = components
        self.contexts = contexts  # shared by every scope of a walk, so contexts compare
        self.top: dict[str, Binder] = {}
        # How many declaration bodies are being expanded: a mu variable is visible
        # only at the level it was bound at (a referenced body cannot see the
        # referring body's variables); declarations are visible at every level.
        self.level = -1
        self.expanding: set[str] = set()
        self.hiding = 0  # mu binders in scope that hide a declaration being expanded
        self.cycles: dict[int, _Component] = {}

    def bind(self, name: str, depth: int, parallel_depth: int, declaration: bool,
             var: str | None = None) -> Binder:
        """Bring ``name`` into scope; undo with :meth:`unbind` (in a ``finally``)."""
        hides = not declaration and name in self.expanding
        binder = Binder(name, var or name, depth, parallel_depth, declaration, self.level,
                        self.top.get(name), hides)
        self.top[name] = binder
        if declaration:
            self.expanding.add(name)
            component = self.components.get(name, -1)
            if component >= 0:
                cycle = self.cycles.setdefault(component, _Component())
                parent = cycle.contexts[-1] if cycle.contexts else 0
                cycle.depths.append(depth)
                cycle.parallel_depths.append(parallel_depth)
                cycle.contexts.append(self.contexts.setdefault((parent, name), len(self.contexts) + 1))
        elif hides:
            self.hiding += 1
        return binder

    def unbind(self, binder: Binder) -> None:
        if binder.shadowed is None:
            del self.top[binder.name]
        else:
            self.top[binder.name] = binder.shadowed
        if binder.declaration:
            self.expanding.discard(binder.name)
            component = self.components.get(binder.name, -1)
            if component >= 0:
                cycle = self.cycles[component]
                cycle.depths.pop()
                cycle.parallel_depths.pop()
                cycle.contexts.pop()
        elif binder.hides_declaration:
            self.hiding -= 1

    def context(self, name: str, depth: int, parallel_depth: int) -> object | None:
        """What the expansion of declaration ``name`` here depends on; None: not memoisable.

        A declaration outside any cycle always expands the same way. One in a
        cycle depends on which declarations of its cycle are being expanded and,
        for guardedness and parallel checks, on which of them were bound at the
        current depth and parallel depth (a suffix of them: depths only grow).
        """
        component = self.components.get(name, -1)
        if component < 0:
            return name
        if self.hiding:
            return None
        cycle = self.cycles.get(component)
        if cycle is None or not cycle.contexts:
            return (name, 0, 0, 0)
        return (name, cycle.contexts[-1], bisect_left(cycle.depths, depth),
                bisect_left(cycle.parallel_depths, parallel_depth))


class Capture(Exception):  # noqa: N818 (a control-flow signal, not an error: STYLE.md)
    """Internal: a declaration reference would be captured by the mu variable ``name``."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.name = name


Decl = TypeVar("Decl", bound="s.GlobalDecl | s.LocalDecl")
Term = TypeVar("Term")


@dataclass
class _Frame:
    """A declaration body being resolved: the expanding declarations it refers to."""

    name: str
    refers_to: set[str] = field(default_factory=set)


@dataclass(frozen=True, slots=True)
class _Expansion(Generic[Term]):
    """A resolved declaration body, returned again wherever the same context recurs."""

    body: Term
    recursive: bool                    # refers to its own declaration: wrap it in mu
    refers_to: frozenset[str]          # enclosing declarations it refers to
    diagnostics: tuple[Diagnostic, ...]  # reported while resolving it, replayed on reuse


@dataclass
class Walk(Generic[Decl, Term]):
    """State shared by the resolution of every declaration of one kind in a file."""

    reporter: Reporter
    sorts: SortTable
    declarations: Mapping[str, Decl]   # the same kind's declarations, by name
    kind: str                          # "global" or "local"
    other_kind: set[str]               # names declared with another kind
    resolve_body: Callable[[Walk[Decl, Term], Decl, Scope, int, int], Term]
    _components: dict[str, int] = field(default_factory=dict)
    _contexts: dict[tuple[int, str], int] = field(default_factory=dict)
    _memo: dict[object, _Expansion[Term]] = field(default_factory=dict)
    _frames: list[_Frame] = field(default_factory=list)
    _referenced: set[str] = field(default_factory=set)  # declarations another one refers to
    _renames: int = 0
    resolutions: int = 0               # declaration bodies resolved (not reused); for tests
    visits: int = 0                    # syntax nodes resolved, for the work meter
    # Syntax nodes that occur in several places (see SourceFile.shared) with their
    # free names, and what each resolved to, by node and meaning of those names.
    shared_syntax: Mapping[int, tuple[object, frozenset[str]]] = field(default_factory=dict)
    _syntax_memo: dict[tuple[object, ...], tuple[Term, tuple[Diagnostic, ...], list[Binder]]] = field(
        default_factory=dict)
    # The bodies that may be used in more than one place (every remembered
    # expansion of a declaration that is referred to), by id: the passes over
    # the resolved types memoise on them.
    shared: dict[int, Term] = field(default_factory=dict)

    def __post_init__(self) -> None:
        memo: dict[int, tuple[str, ...]] = {}  # shared across the bodies: they share nodes
        visits = [0]
        graph = {name: _references(decl.body, self.declarations, self.shared_syntax, memo, visits)
                 for name, decl in self.declarations.items()}
        METER.add("references", visits[0])
        self._components = components(graph)
        self._referenced = {target for name, targets in graph.items() for target in targets if target != name}

    def new_scope(self) -> Scope:
        """An empty scope, to resolve one declaration in."""
        return Scope(self._components, self._contexts)

    def lookup(self, name: s.Name, scope: Scope, depth: int,
               parallel_depth: int) -> Binder | str | None:
        """The binder of ``name``, or "decl" for a declaration to expand, or None (reported).

        Raises:
            Capture: ``name`` means an enclosing declaration, but a ``mu`` of the
                referring body with the same variable name sits in between.
        """
        binder = scope.top.get(name.text)
        hidden = False
        while binder is not None and not (binder.declaration or binder.level == scope.level):
            hidden = hidden or binder.var == name.text
            binder = binder.shadowed
        if binder is not None:
            if hidden:
                raise Capture(name.text)
            if binder.parallel_depth < parallel_depth:
                self.reporter.error(name.location, f"recursion variable '{name.text}' is used inside "
                                    "a parallel composition it encloses")
                return None
            if binder.depth == depth:
                self.reporter.error(name.location, f"unguarded recursion: '{name.text}' recurs "
                                    "with no interaction in between")
                return None
            if binder.declaration:
                self._frames[-1].refers_to.add(name.text)
            return binder
        if name.text in self.declarations:
            return "decl"
        if name.text in self.other_kind:
            self.reporter.error(name.location, f"'{name.text}' is not a {self.kind} declaration")
        else:
            self.reporter.error(name.location, f"unbound name '{name.text}'")
        return None

    def expand(self, name: str, scope: Scope, depth: int, parallel_depth: int) -> tuple[Term, bool]:
        """The body of declaration ``name`` resolved here, and whether it refers to itself.

        The same context gives the same (identical) node, resolved once.
        """
        key = scope.context(name, depth, parallel_depth)
        known = self._memo.get(key) if key is not None else None
        if known is not None:
            self.reporter.diagnostics.extend(known.diagnostics)
            if self._frames:
                self._frames[-1].refers_to.update(known.refers_to)
            return known.body, known.recursive
        frame = _Frame(name)
        mark, renames = len(self.reporter.diagnostics), self._renames
        # Not context managers: resuming generators deep in a recursion costs time
        # proportional to the depth in CPython 3.11, which made deep protocols quadratic.
        scope.level += 1
        binder = scope.bind(name, depth, parallel_depth, declaration=True)
        self._frames.append(frame)
        try:
            body = self.resolve_body(self, self.declarations[name], scope, depth, parallel_depth)
        finally:
            self._frames.pop()
            scope.unbind(binder)
            scope.level -= 1
        self.resolutions += 1
        recursive = name in frame.refers_to
        frame.refers_to.discard(name)
        if self._frames:
            self._frames[-1].refers_to.update(frame.refers_to)
        if key is not None and renames == self._renames:
            diagnostics = tuple(dict.fromkeys(self.reporter.diagnostics[mark:]))
            self._memo[key] = _Expansion(body, recursive, frozenset(frame.refers_to), diagnostics)
            if name in self._referenced:  # else only its own global holds it
                self.shared[id(body)] = body
        return body, recursive

    def shared_node(self, node: object, scope: Scope, depth: int, parallel_depth: int,
                    resolve: Callable[[], Term]) -> Term:
        """Resolve a syntax node that occurs in several places once per meaning of its free names.

        What a node resolves to depends on its context only through the
        binders its free names see, whether each was bound at the current
        depth (guardedness) and outside the current parallel composition.
        Such nodes come from Scribble ``do`` (no declaration references), so
        no capture or renaming can make the result depend on more.
        """
        _, free = self.shared_syntax[id(node)]
        key: list[object] = [id(node)]
        binders: list[Binder] = []
        for name in sorted(free):
            binder = scope.top.get(name)
            while binder is not None and not (binder.declaration or binder.level == scope.level):
                binder = binder.shadowed
            if binder is None:
                key.append((name, None))
                continue
            binders.append(binder)  # held, so that its id stays its own
            key.append((name, id(binder), binder.depth == depth, binder.parallel_depth < parallel_depth))
        memo_key = tuple(key)
        known = self._syntax_memo.get(memo_key)
        if known is not None:
            self.reporter.diagnostics.extend(known[1])
            return known[0]
        mark, renames = len(self.reporter.diagnostics), self._renames
        result = resolve()
        if renames == self._renames:
            diagnostics = tuple(dict.fromkeys(self.reporter.diagnostics[mark:]))
            self._syntax_memo[memo_key] = (result, diagnostics, binders)
            self.shared[id(result)] = result
        return result

    def with_mu(self, var: str, body: s.GSyntax | s.LSyntax, scope: Scope, depth: int, parallel_depth: int,
                build: Callable[[str], Term]) -> Term:
        """Resolve a ``mu var.`` body; rename ``var`` if it would capture a declaration name.

        Renaming happens only when an expanded declaration refers, through
        ``var``'s name, to an enclosing declaration; otherwise the written name
        is kept. The body's own uses of ``var`` stand for the renamed variable;
        the new name is none in scope and none written in the body (an inner
        ``mu`` of that name would capture them).
        """
        name = var
        while True:
            mark = len(self.reporter.diagnostics)
            binder = scope.bind(var, depth, parallel_depth, declaration=False, var=name)
            try:
                return build(name)
            except Capture as capture:
                if capture.name != var or name != var:
                    raise
                del self.reporter.diagnostics[mark:]
                # What is taken depends on the scope around: not memoisable.
                self._renames += 1
                taken = (set(scope.top) | {b.var for b in scope.top.values()} | set(self.declarations)
                         | _written_names(body))
                while name in taken:
                    name += "'"
            finally:
                scope.unbind(binder)


def _written_names(body: s.GSyntax | s.LSyntax) -> set[str]:
    """Every name written in a body: references and ``mu`` variables."""
    names: set[str] = set()
    seen: set[int] = set()  # a node in several places (Scribble 'do') is looked at once
    stack: list[s.GSyntax | s.LSyntax | None] = [body]
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        match node:
            case s.GRef(name=name) | s.LRef(name=name):
                names.add(name.text)
            case s.GRec(var=var, body=inner) | s.LRec(var=var, body=inner):
                names.add(var.text)
                stack.append(inner)
            case _:
                stack.extend(_children(node))
    return names


def _children(node: s.GSyntax | s.LSyntax | None) -> list[s.GSyntax | s.LSyntax | None]:
    match node:
        case s.GInteraction(branches=gbranches):
            return [b.continuation for b in gbranches]
        case s.GRouted(branches=routes):
            return list(routes)
        case s.LChoice(branches=lbranches):
            return [b.continuation for b in lbranches]
        case s.LChoiceAmong(branches=actions):
            return list(actions)
        case s.LAction(continuation=rest):
            return [rest]
        case s.GRec(body=inner) | s.LRec(body=inner):
            return [inner]
        case s.GParallel(branches=gparts):
            return list(gparts)
        case s.LParallel(branches=lparts):
            return list(lparts)
    return []


# One per shared node being summarised (None: the body), innermost last: that node,
# the nodes left to look at, the names found (in order), the nodes looked at.
_RefFrame = tuple[object, list[s.GSyntax | s.LSyntax | None], dict[str, None], set[int]]


def _references(body: s.GSyntax | s.LSyntax, declarations: Mapping[str, object],
                shared: Mapping[int, object], memo: dict[int, tuple[str, ...]], visits: list[int]) -> list[str]:
    """The declarations a body names (a superset of those it refers to: mu names count).

    A node in several places (Scribble 'do', :attr:`sessiontypes.syntax.SourceFile.shared`)
    is looked at once for all the bodies: what it names is remembered in
    ``memo`` (the globals of a chain of Scribble protocols each hold the rest
    of the chain; walking it once per global was quadratic). ``visits[0]``
    counts the nodes looked at, for the work meter.
    """
    frames: list[_RefFrame] = [(None, [body], {}, set())]
    while True:  # iterative: sequences and chains of 'do' nest deeply
        summarised, stack, found, seen = frames[-1]
        inner: _RefFrame | None = None
        while stack:
            node = stack.pop()
            if id(node) in seen:
                continue
            seen.add(id(node))
            visits[0] += 1
            if node is not summarised and id(node) in shared:
                known = memo.get(id(node))
                if known is None:  # summarise it first, then come back to it
                    seen.discard(id(node))
                    stack.append(node)
                    inner = (node, [node], {}, set())
                    break
                found.update(dict.fromkeys(known))
                continue
            match node:
                case s.GRef(name=name) | s.LRef(name=name):
                    if name.text in declarations:
                        found[name.text] = None
                case _:
                    stack.extend(_children(node))
        if inner is not None:
            frames.append(inner)
            continue
        frames.pop()
        if summarised is None:
            return list(found)
        memo[id(summarised)] = tuple(found)


def components(graph: Mapping[str, Iterable[str]]) -> dict[str, int]:
    """Number the strongly connected components of ``graph`` that contain a cycle.

    Returns a map from each node on a cycle of two or more nodes to its
    component's number; nodes on no such cycle are left out (a declaration
    referring only to itself expands the same way everywhere).
    """
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: dict[str, int] = {}
    count = 0
    for root in graph:
        if root in index:
            continue
        # Tarjan's algorithm with an explicit stack of iterators: chains of
        # thousands of declarations would exhaust Python's recursion limit.
        work: list[tuple[str, Iterator[str]]] = [(root, iter(graph[root]))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            advanced = False
            for successor in successors:
                if successor not in index:
                    index[successor] = low[successor] = len(index)
                    stack.append(successor)
                    on_stack.add(successor)
                    work.append((successor, iter(graph[successor])))
                    advanced = True
                    break
                if successor in on_stack:
                    low[node] = min(low[node], index[successor])
            if advanced:
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                members = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    members.append(member)
                    if member == node:
                        break
                if len(members) > 1:
                    found.update(dict.fromkeys(members, count))
                    count += 1
    return found
