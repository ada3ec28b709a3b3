"""Projection of a global type onto a role (LANGUAGE.md section 5).

``p -> q : {l_i(S_i). G_i}`` projects to ``+q{...}`` on p, ``&p{...}`` on q and,
on any other role, to the merge of the branches' projections
(:mod:`sessiontypes.merge`). ``p -> {q_i : l_i(S_i). G_i}`` (branches to
different receivers) projects to ``+{!q_i(l_i(S_i)). G_i↾p}`` on p and, on any
other role r, to the merge of ``?p(l_i(S_i)). G_i↾r`` (the branches to r) and
``G_i↾r`` (the others): r learns the branch from the first message it gets,
whichever peer sends it (``&{?p(l_1). ..., ?s(m). ...}``); see also
:mod:`sessiontypes.races`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from . import global_types as g
from . import local_types as lt
from .deep import run_deep
from .errors import ProjectionError, UnknownRoleError
from .location import Location
from .merge import MergeError, merge, merge_all
from .races import check_races, has_offer_among
from .recursion import free_vars, substitute, unfold  # re-exported
from .sharing import Sharing, find_shared
from .work import METER

__all__ = ["project_declared", "project", "merge", "MergeError", "unfold", "substitute", "free_vars"]


def project_declared(protocol: str, roles: tuple[str, ...], body: g.GlobalTerm, role: str,
                     source_lines: tuple[str, ...], shared: Sharing) -> lt.LocalTerm:
    """Project the body of the declared global type ``protocol`` onto ``role``.

    ``shared`` holds the nodes the body shares (and their projections, which
    this adds to); ``source_lines`` are its file's, for error messages. Users
    call :meth:`sessiontypes.GlobalType.project`, which caches the result.

    Raises:
        UnknownRoleError: ``role`` is not one of ``roles``.
        ProjectionError: some choice's branches do not merge for ``role``, or (a
            :class:`~sessiontypes.errors.ChoiceRaceError`) a message may overtake the
            one from which ``role`` learns a choice.
    """
    if role not in roles:
        raise UnknownRoleError(protocol, role, roles)
    projector = _Projector(protocol, role, source_lines, shared)
    try:
        local = run_deep(projector.project, body)
    finally:
        METER.add("project", projector.work)
    if has_offer_among(local, shared):
        check_races(protocol, role, body, local, projector.project, source_lines, shared)
    return local


def project(term: g.GlobalTerm, role: str, protocol: str = "<global>") -> lt.LocalTerm:
    """Project a global type term onto ``role`` (see :func:`project_declared`)."""
    nodes = find_shared(term, g.children)
    shared = Sharing(nodes)
    return run_deep(_Projector(protocol, role, (), shared).project, term)


@dataclass
class _Projector:
    protocol: str
    role: str
    source_lines: tuple[str, ...]
    # Nodes in several places (a declaration used twice): projected once, for
    # every global of the module (see sessiontypes.sharing).
    shared: Sharing
    _occurs: dict[int, bool] = field(default_factory=dict)
    work: int = 0  # nodes projected, for the work meter

    def project(self, term: g.GlobalTerm) -> lt.LocalTerm:
        role = self.role
        shared = self.shared.nodes
        passed: list[g.GlobalTerm] | None = None  # shared nodes that project to the same
        try:
            while True:
                if shared and id(term) in shared:
                    known: lt.LocalTerm | None = self.shared.get(("project", role), term)
                    if known is not None:
                        break
                    failed: ProjectionError | None = self.shared.get(("unprojectable", role), term)
                    if failed is not None:
                        raise self._renamed(failed)
                    if passed is None:
                        passed = []
                    passed.append(term)
                # Fast path: most interactions of a large protocol do not involve the role.
                self.work += 1
                if not (isinstance(term, g.Choice) and len(term.branches) == 1
                        and term.sender != role and term.receiver != role):
                    known = self._project_node(term)
                    break
                term = term.branches[0].continuation
        except ProjectionError as error:
            # A shared node that does not project fails the same way wherever it is
            # used: remember it, so each global that uses it (a chain of declarations
            # ending in an unmergeable choice) fails at once instead of projecting
            # the chain again.
            for node in passed or ():
                self.shared.put(("unprojectable", role), node, error)
            raise
        for node in passed or ():
            self.shared.put(("project", role), node, known)
        return known

    def _renamed(self, error: ProjectionError) -> ProjectionError:
        """``error``, found while projecting another global, as this global's (without its traceback)."""
        if type(error) is not ProjectionError or error.protocol == self.protocol:
            return error.with_traceback(None)
        return ProjectionError(self.protocol, error.role, error.location, error.labels, error.left,
                               error.right, error.reason, error.source_line, error.chooser)

    def _project_node(self, term: g.GlobalTerm) -> lt.LocalTerm:
        role = self.role
        if isinstance(term, g.Choice) and len(term.branches) == 1:
            only = term.branches[0]
            make = lt.Send if term.sender == role else lt.Recv
            peer = term.receiver if term.sender == role else term.sender
            # sender and receiver keep the timing (each reads its own part); others never see it
            return make(peer, only.message, self.project(only.continuation), term.location, term.timing)
        match term:
            case g.End(location=location):
                return lt.End(location)
            case g.Var(name=name, location=location):
                return lt.Var(name, location)
            case g.Rec(var=var, body=body, location=location):
                if not self.occurs(body):
                    return self._absent_loop(term)
                projected = self.project(body)
                if isinstance(projected, lt.Var) and projected.name == var:
                    return lt.End(location)
                return lt.Rec(var, projected, location)
            case g.Parallel(branches=branches, location=location):
                kept = tuple([p for p in ([self.project(b) for b in branches])
                             if not isinstance(p, lt.End)])
                if not kept:
                    return lt.End(location)
                return kept[0] if len(kept) == 1 else lt.Parallel(kept, location)
            case g.Choice(sender=sender, receiver=receiver, branches=branches, location=location):
                if self.role == sender:
                    return lt.select(receiver, self._branches(branches, location), location, term.timing)
                if self.role == receiver:
                    return lt.offer(sender, self._branches(branches, location), location, term.timing)
                if len(branches) == 1:
                    return self.project(branches[0].continuation)
                return self._merge_branches(branches, location, sender)
            case g.Routed(sender=sender, branches=routes, location=location):
                if self.role == sender:
                    return lt.select_among(tuple([lt.Send(r.receiver, r.message, self.project(r.continuation),
                                                          r.location) for r in routes]), location)
                return self._merge_routes(term)
        raise AssertionError(f"unexpected global term {term!r}")

    def _branches(self, branches: tuple[g.Branch, ...], location: Location) -> tuple[lt.Branch, ...]:
        return tuple([lt.Branch(b.message, self.project(b.continuation), location) for b in branches])

    def _merge_branches(self, branches: tuple[g.Branch, ...], location: Location, chooser: str) -> lt.LocalTerm:
        projections = [self.project(b.continuation) for b in branches]
        try:
            return merge_all(projections)
        except MergeError as error:
            raise self._blame(branches, projections, error.index, location, chooser) from None

    def _merge_routes(self, term: g.Routed) -> lt.LocalTerm:
        """Onto a role other than the sender: its view of each branch, merged."""
        projections: list[lt.LocalTerm] = []
        for route in term.branches:
            rest = self.project(route.continuation)
            if route.receiver == self.role:
                rest = lt.Recv(term.sender, route.message, rest, route.location)
            projections.append(rest)
        try:
            return merge_all(projections)
        except MergeError as error:
            # the branches as the error names them: 'B:m1' and 'C:m2'
            branches = tuple([g.Branch(replace(r.message, label=f"{r.receiver}:{r.message.label}"),
                                       r.continuation) for r in term.branches])
            raise self._blame(branches, projections, error.index, term.location, term.sender) from None

    def _blame(self, branches: tuple[g.Branch, ...], projections: list[lt.LocalTerm],
               index: int, location: Location, chooser: str) -> ProjectionError:
        """Name the first earlier branch that does not merge with branch ``index``."""
        other, reason = 0, "they differ"
        for earlier in range(index):
            try:
                merge(projections[earlier], projections[index])
            except MergeError as error:
                other, reason = earlier, error.reason
                break
        else:  # every pair merges; the accumulated merge does not
            other = index - 1
            reason = "the earlier branches together do not merge with it"
        line = self.source_lines[location.line - 1] if 0 < location.line <= len(self.source_lines) else ""
        return ProjectionError(
            self.protocol, self.role, location,
            (branches[other].message.label, branches[index].message.label),
            # Bounded: the behaviours can be long, or exponential written out.
            lt.describe_local(projections[other]), lt.describe_local(projections[index]), reason, line, chooser)

    def _absent_loop(self, loop: g.Rec) -> lt.LocalTerm:
        """Project a loop the role takes no part in.

        For the role the loop is silent; what matters is where it can leave to:
        ``end``, or an outer loop's variable (then the role goes on with that
        loop; answering ``end`` would cut the outer loop short). If it can leave
        to two different places the role cannot tell which, and the type is not
        projectable.
        """
        exits: dict[str, g.Choice | g.Routed | None] = {}
        self._collect_exits(loop.body, {loop.var: 1}, None, exits, summarising=False)
        if len(exits) > 1:
            raise self._blame_exits(loop, exits)
        if not exits or "end" in exits:
            return lt.End(loop.location)
        (name,) = exits
        return lt.Var(name, loop.location)

    def _collect_exits(self, term: g.GlobalTerm, bound: dict[str, int], choice: g.Choice | g.Routed | None,
                       exits: dict[str, g.Choice | g.Routed | None], summarising: bool) -> None:
        """Record where ``term`` can leave to; ``bound`` counts the loops entered per name.

        ``bound`` is one mutable counter, entered and left as the walk goes, so deep
        nests of loops stay linear. A shared node's exits are collected once, as
        if no loop were entered (``summarising``), then filtered per use.
        """
        entered: list[str] = []
        try:
            while True:
                if id(term) in self.shared.nodes and not summarising:
                    summary: dict[str, g.Choice | g.Routed | None] | None = self.shared.get("exits", term)
                    if summary is None:
                        summary = {}
                        self._collect_exits(term, {}, None, summary, summarising=True)
                        self.shared.put("exits", term, summary)
                    for name, inner in summary.items():
                        if not bound.get(name):
                            exits.setdefault(name, inner if inner is not None else choice)
                    return
                summarising = False
                match term:
                    case g.End() | g.Parallel():  # a parallel composition ends when its branches do
                        exits.setdefault("end", choice)
                        return
                    case g.Var(name=name):
                        if not bound.get(name):
                            exits.setdefault(name, choice)
                        return
                    case g.Rec(var=var, body=body):
                        bound[var] = bound.get(var, 0) + 1
                        entered.append(var)
                        term = body
                    case g.Choice(branches=branches):
                        if len(branches) > 1:
                            for branch in branches:
                                self._collect_exits(branch.continuation, bound, term, exits, False)
                            return
                        term = branches[0].continuation
                    case g.Routed(branches=routes):
                        for route in routes:
                            self._collect_exits(route.continuation, bound, term, exits, False)
                        return
                    case _:
                        raise AssertionError(f"unexpected global term {term!r}")
        finally:
            for var in entered:
                bound[var] -= 1

    def _blame_exits(self, loop: g.Rec, exits: dict[str, g.Choice | g.Routed | None]) -> ProjectionError:
        (first, _), (second, choice) = list(exits.items())[:2]
        location = choice.location if choice else loop.location
        labels = ("?", "?")
        if choice is not None:  # name the branches of the choice that leads to each exit
            labels = tuple([next((b.message.label for b in choice.branches
                                 if self._leads_to(b.continuation, name)), "?")
                           for name in (first, second)])  # type: ignore[assignment]
        line = self.source_lines[location.line - 1] if 0 < location.line <= len(self.source_lines) else ""
        return ProjectionError(self.protocol, self.role, location, labels, first, second,
                               f"{self.role} takes no part in the loop and cannot tell how it ends", line,
                               choice.sender if choice is not None else "")

    def _leads_to(self, term: g.GlobalTerm, exit_name: str) -> bool:
        found: dict[str, g.Choice | g.Routed | None] = {}
        self._collect_exits(term, {}, None, found, summarising=False)
        return exit_name in found

    def occurs(self, term: g.GlobalTerm) -> bool:
        """Whether the role sends or receives anywhere in ``term``."""
        key = id(term)
        cached = self._occurs.get(key)
        if cached is None and id(term) in self.shared.nodes:
            cached = self.shared.get(("occurs", self.role), term)
        if cached is None:
            match term:
                case g.Choice(sender=sender, receiver=receiver, branches=branches):
                    # map, not a generator: resuming generators deep in a recursion
                    # costs time proportional to the depth in CPython 3.11.
                    cached = self.role in (sender, receiver) or any(
                        map(self.occurs, [b.continuation for b in branches]))
                case g.Routed(sender=sender, branches=routes):
                    cached = self.role == sender or any(r.receiver == self.role for r in routes) or any(
                        map(self.occurs, [r.continuation for r in routes]))
                case g.Rec(body=body):
                    cached = self.occurs(body)
                case g.Parallel(branches=parts):
                    cached = any(map(self.occurs, parts))
                case _:
                    cached = False
            self._occurs[key] = cached
            if id(term) in self.shared.nodes:
                self.shared.put(("occurs", self.role), term, cached)
        return cached
