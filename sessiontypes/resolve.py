"""Surface syntax to core types: names, sorts and equation-style recursion.

Resolution and the name-related checks of LANGUAGE.md section 6 happen in
one walk, so every problem is reported once with its location:
unknown sorts, unbound names, unguarded recursion, a recursion variable used
inside a parallel composition it encloses, a role sending to itself,
duplicate labels. Problems go to a :class:`Reporter`; the walk continues so
that one run reports all of them.

Equation-style recursion (``ATM = ... ATM'``, ``ATM' = ... ATM``) is expanded
into ``mu``: a reference to a declaration that is not being expanded stands
for its body, wrapped in ``mu Name.`` when the body refers back to it. Each
body is resolved once per context and shared (:mod:`sessiontypes.expand`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from . import global_types as g
from . import local_types as lt
from . import syntax as s
from .constraints import Timing, format_duration
from .expand import Binder, Scope, Walk
from .filescope import Reporter, SortTable  # re-exported
from .location import Location
from .sorts import Interaction

__all__ = ["Reporter", "SortTable", "global_walk", "local_walk", "resolve_global", "resolve_local"]

def _check_labels(reporter: Reporter, labels: Iterable[s.Name]) -> None:
    seen: set[str] = set()
    for label in labels:
        if label.text in seen:
            reporter.error(label.location, f"duplicate label '{label.text}' in one choice")
        seen.add(label.text)


def _check_pairs(reporter: Reporter, pairs: Iterable[tuple[s.Name, s.Name]]) -> None:
    """A choice among peers: each (peer, label) pair once."""
    seen: set[tuple[str, str]] = set()
    for peer, label in pairs:
        if (peer.text, label.text) in seen:
            reporter.error(label.location, f"duplicate label '{label.text}' for {peer.text} in one choice")
        seen.add((peer.text, label.text))


def _timing(reporter: Reporter, clause: s.TimingSyntax | None, labels: Iterable[s.Name]) -> Timing | None:
    """The time clause's :class:`Timing`, reporting what the language rules out.

    Durations are more than 0, the jitter is less than the period, ``else timeout`` needs
    a deadline, and a choice that times out has no label ``timeout`` (the receiver gets a
    timeout under that name).
    """
    if clause is None:
        return None
    timing = clause.timing
    for part, value in (("within", timing.within), ("every", timing.every)):
        if value == 0:
            reporter.error(clause.where(part), f"'{part} 0': a duration must be more than 0")
    if timing.every and timing.jitter >= timing.every:
        reporter.error(clause.where("jitter"), f"the jitter {format_duration(timing.jitter)} must be less "
                       f"than the period {format_duration(timing.every)}")
    if timing.on_expiry:
        if timing.within is None:
            reporter.error(clause.where("else"), "'else timeout' needs a deadline: "
                           "write 'within D else timeout'")
        for label in labels:
            if label.text == "timeout":
                reporter.error(label.location, "label 'timeout' in a choice with 'else timeout': "
                               "the receiver takes a timeout under that name; rename the label")
    return timing


# ---- global ------------------------------------------------------------------------

GlobalWalk = Walk[s.GlobalDecl, g.GlobalTerm]


def global_walk(reporter: Reporter, sorts: SortTable, declarations: Mapping[str, s.GlobalDecl],
                other_kind: set[str],
                shared_syntax: Mapping[int, tuple[s.GSyntax, frozenset[str]]] | None = None) -> GlobalWalk:
    """The state for resolving the global declarations of one file.

    ``shared_syntax``: the file's syntax nodes that occur in several places
    (:attr:`sessiontypes.syntax.SourceFile.shared`), each resolved once.
    """
    return Walk(reporter, sorts, declarations, "global", other_kind, _resolve_global_body,
                shared_syntax=shared_syntax or {})


def resolve_global(decl: s.GlobalDecl, walk: GlobalWalk) -> g.GlobalTerm:
    """Resolve one global declaration (the walk reports problems)."""
    body, recursive = walk.expand(decl.name.text, walk.new_scope(), 0, 0)
    if recursive:
        return g.Rec(decl.name.text, body, decl.name.location)
    return body


def _resolve_global_body(walk: GlobalWalk, decl: s.GlobalDecl, scope: Scope, depth: int,
                         parallel_depth: int) -> g.GlobalTerm:
    return _resolve_g(walk, decl.body, scope, depth, parallel_depth)


def _resolve_g(walk: GlobalWalk, node: s.GSyntax | None,
               scope: Scope, depth: int, parallel_depth: int, share: bool = True) -> g.GlobalTerm:
    walk.visits += 1
    if share and walk.shared_syntax and id(node) in walk.shared_syntax:
        return walk.shared_node(node, scope, depth, parallel_depth,
                                lambda: _resolve_g(walk, node, scope, depth, parallel_depth, share=False))
    match node:
        case None:
            return g.End()
        case s.GEnd(location=location):
            return g.End(location)
        case s.GInteraction(sender=sender, receiver=receiver, branches=branches, location=location):
            if sender.text == receiver.text:
                walk.reporter.error(receiver.location, f"role {sender.text} sends a message to itself")
            _check_labels(walk.reporter, ([b.message.label for b in branches]))
            timing = _timing(walk.reporter, node.timing, [b.message.label for b in branches])
            return g.Choice(sender.text, receiver.text, tuple([
                g.Branch(walk.sorts.message(b.message),
                         _resolve_g(walk, b.continuation, scope, depth + 1, parallel_depth),
                         b.message.label.location)
                for b in branches]), location, receiver.location, timing)
        case s.GRouted(sender=sender, branches=routes, location=location):
            _check_pairs(walk.reporter, [(r.receiver, r.branches[0].message.label) for r in routes])
            resolved: list[g.RoutedBranch] = []
            for route in routes:
                one = _resolve_g(walk, route, scope, depth, parallel_depth)
                assert isinstance(one, g.Choice)
                resolved.append(g.RoutedBranch(one.receiver, one.branches[0].message,
                                               one.branches[0].continuation, one.branches[0].location,
                                               one.receiver_location))
            if len({r.receiver for r in resolved}) == 1:  # one receiver: an ordinary choice
                return g.Choice(sender.text, resolved[0].receiver, tuple([
                    g.Branch(r.message, r.continuation, r.location) for r in resolved]),
                    location, resolved[0].receiver_location)
            return g.Routed(sender.text, tuple(resolved), location)
        case s.GRec(var=var, body=body, location=location):
            return walk.with_mu(var.text, body, scope, depth, parallel_depth,
                                lambda name: g.Rec(name, _resolve_g(walk, body, scope, depth,
                                                                    parallel_depth), location))
        case s.GParallel(branches=branches, location=location):
            return g.Parallel(tuple([_resolve_g(walk, b, scope, depth, parallel_depth + 1)
                                    for b in branches]), location)
        case s.GRef(name=name):
            found = walk.lookup(name, scope, depth, parallel_depth)
            if isinstance(found, Binder):
                return g.Var(found.var, name.location)
            if found == "decl":
                expanded, recursive = walk.expand(name.text, scope, depth, parallel_depth)
                return g.Rec(name.text, expanded, name.location) if recursive else expanded
            return g.End(name.location)  # already reported
    raise AssertionError(f"unexpected global syntax {node!r}")


# ---- local -------------------------------------------------------------------------

def _check_one_timing(reporter: Reporter, branches: tuple[lt.Send, ...] | tuple[lt.Recv, ...],
                      location: Location) -> None:
    """The branches of a choice to or from one peer are one interaction: one time clause."""
    if not lt.one_timing(branches):
        reporter.error(location, "the branches with one peer have different time clauses; "
                       "they are one interaction, which has one")


LocalWalk = Walk[s.LocalDecl, lt.LocalTerm]


def local_walk(reporter: Reporter, sorts: SortTable, declarations: Mapping[str, s.LocalDecl],
               other_kind: set[str]) -> LocalWalk:
    """The state for resolving the local declarations of one file."""
    return Walk(reporter, sorts, declarations, "local", other_kind, _resolve_local_body)


def resolve_local(decl: s.LocalDecl, walk: LocalWalk) -> lt.LocalTerm:
    """Resolve one local declaration (the walk reports problems)."""
    body, recursive = walk.expand(decl.name.text, walk.new_scope(), 0, 0)
    if recursive:
        return lt.Rec(decl.name.text, body, decl.name.location)
    return body


def _resolve_local_body(walk: LocalWalk, decl: s.LocalDecl, scope: Scope, depth: int,
                        parallel_depth: int) -> lt.LocalTerm:
    return _resolve_l(walk, decl.body, scope, depth, parallel_depth)


def _resolve_l(walk: LocalWalk, node: s.LSyntax | None,
               scope: Scope, depth: int, parallel_depth: int) -> lt.LocalTerm:
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
                resolved = Interaction(message.label.text)
            else:
                resolved = walk.sorts.message(message)
            timing = _timing(walk.reporter, node.timing, [message.label])
            cont = _resolve_l(walk, rest, scope, depth + 1, parallel_depth)
            make = lt.Send if direction == "!" else lt.Recv
            return make(peer.text if peer else None, resolved, cont, location, timing)
        case s.LChoice(kind=kind, peer=peer, branches=branches, location=location):
            _check_labels(walk.reporter, ([b.message.label for b in branches]))
            timing = _timing(walk.reporter, node.timing, [b.message.label for b in branches])
            resolved_branches = tuple([
                lt.Branch(walk.sorts.message(b.message),
                          _resolve_l(walk, b.continuation, scope, depth + 1, parallel_depth),
                          b.message.label.location)
                for b in branches])
            make_choice = lt.select if kind == "+" else lt.offer
            return make_choice(peer.text if peer else None, resolved_branches, location, timing)
        case s.LChoiceAmong(kind=kind, branches=actions, location=location):
            _check_pairs(walk.reporter, [(a.peer, a.message.label) for a in actions if a.peer is not None])
            resolved_actions = [_resolve_l(walk, a, scope, depth, parallel_depth) for a in actions]
            if kind == "+":
                sends = tuple([a for a in resolved_actions if isinstance(a, lt.Send)])
                _check_one_timing(walk.reporter, sends, location)
                return lt.select_among(sends, location)
            recvs = tuple([a for a in resolved_actions if isinstance(a, lt.Recv)])
            _check_one_timing(walk.reporter, recvs, location)
            return lt.offer_among(recvs, location)
        case s.LRec(var=var, body=body, location=location):
            return walk.with_mu(var.text, body, scope, depth, parallel_depth,
                                lambda name: lt.Rec(name, _resolve_l(walk, body, scope, depth,
                                                                     parallel_depth), location))
        case s.LParallel(branches=branches, location=location):
            return lt.Parallel(tuple([_resolve_l(walk, b, scope, depth, parallel_depth + 1)
                                     for b in branches]), location)
        case s.LRef(name=name):
            found = walk.lookup(name, scope, depth, parallel_depth)
            if isinstance(found, Binder):
                return lt.Var(found.var, name.location)
            if found == "decl":
                expanded, recursive = walk.expand(name.text, scope, depth, parallel_depth)
                return lt.Rec(name.text, expanded, name.location) if recursive else expanded
            return lt.End(name.location)
    raise AssertionError(f"unexpected local syntax {node!r}")
