"""Well-formedness of a parsed file (LANGUAGE.md section 6), all errors at once.

:func:`check_file` resolves every declaration (see :mod:`sessiontypes.resolve`),
checks roles, parallel channels, projectability, refinements
(:mod:`sessiontypes.refinecheck`) and periods (:mod:`sessiontypes.timecheck`), and returns the checked
:class:`ProtocolModule` together with every diagnostic found.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from . import global_types as g
from . import local_types as lt
from . import syntax as s
from .declarations import GlobalType, LocalType
from .deep import run_deep
from .errors import Diagnostic, ProjectionError
from .location import Location
from .refinecheck import check_refinements, has_refinement
from .resolve import Reporter, SortTable, global_walk, local_walk, resolve_global, resolve_local
from .sharing import Sharing
from .sorts import BUILTIN_SORTS, Sort
from .timecheck import check_timing
from .work import METER

__all__ = ["ProtocolModule", "check_file"]


@dataclass(frozen=True)
class ProtocolModule:
    """A checked protocol file.

    Attributes:
        path: where it was read from.
        globals: the global types, by name, in file order.
        locals: the ``local`` declarations, by name, in file order.
        sorts: the declared sorts, by name.
        warnings: diagnostics that did not stop the file from being accepted.
    """

    path: str
    globals: dict[str, GlobalType]
    locals: dict[str, LocalType]
    sorts: dict[str, Sort]
    warnings: tuple[Diagnostic, ...] = field(default=())


def check_file(source: s.SourceFile) -> tuple[ProtocolModule, list[Diagnostic]]:
    """Check a parsed file; return the module and its diagnostics (errors and warnings).

    The module is meaningful only when no diagnostic is an error.
    """
    return run_deep(_check, source)


def _check(source: s.SourceFile) -> tuple[ProtocolModule, list[Diagnostic]]:
    reporter = Reporter(source)
    by_kind = _declarations(source, reporter)
    types: dict[str, s.TypeDecl] = by_kind["type"]  # type: ignore[assignment]
    globals_: dict[str, s.GlobalDecl] = by_kind["global"]  # type: ignore[assignment]
    locals_: dict[str, s.LocalDecl] = by_kind["local"]  # type: ignore[assignment]
    sorts = SortTable(types, reporter)
    names = {kind: set(decls) for kind, decls in by_kind.items()}

    globals_walk = global_walk(reporter, sorts, globals_, names["local"] | names["type"], source.shared)
    # The declaration bodies resolution shares between uses (it adds to them as
    # it goes); every pass below memoises on them, across all the globals.
    shared = Sharing(globals_walk.shared)
    global_types: dict[str, GlobalType] = {}
    unprojectable: set[tuple[object, ...]] = set()
    for decl in globals_.values():
        before = len(reporter.diagnostics)
        body = resolve_global(decl, globals_walk)
        roles = _check_roles(decl, body, reporter, shared)
        _check_parallel_global(body, reporter, shared)
        global_type = GlobalType(decl.name.text, roles, body, decl.location, sorts.defined(),
                                   source.lines, shared)
        global_types[decl.name.text] = global_type
        # The refinement and time checks walk the whole body: only where it holds what they
        # check (answers remembered per node across the globals, which share their callees).
        if not _has_error(reporter.diagnostics[before:]):
            if _reaches(body, shared.table("refined"), _is_refined):
                for location, message in check_refinements(body):
                    reporter.error(location, message)
            _check_projectable(global_type, reporter, unprojectable)
        if not _has_error(reporter.diagnostics[before:]) and _reaches(body, shared.table("periodic"), _is_periodic):
            for location, message in check_timing(global_type):
                reporter.error(location, message)

    locals_walk = local_walk(reporter, sorts, locals_, names["global"] | names["type"])
    shared_l = Sharing(locals_walk.shared)
    local_types: dict[str, LocalType] = {}
    for ldecl in locals_.values():
        body_l = resolve_local(ldecl, locals_walk)
        _check_local_forms(ldecl, body_l, reporter, shared_l)
        _check_parallel_local(body_l, reporter, shared_l)
        role = ldecl.role.text if ldecl.role else None
        local_types[ldecl.name.text] = LocalType(ldecl.name.text, role, body_l, "", ldecl.location)

    METER.add("resolve", globals_walk.visits)
    for name, type_decl in types.items():
        if name not in sorts.used:
            reporter.warning(type_decl.name.location, f"type {name} is declared but never used")

    diagnostics = _sorted_unique(reporter.diagnostics)
    module = ProtocolModule(source.path, global_types, local_types, sorts.defined(),
                            tuple([d for d in diagnostics if d.severity == "warning"]))
    return module, diagnostics


def _reaches(term: g.GlobalTerm, table: dict[int, tuple[object, bool]],
             here: Callable[[g.GlobalTerm], bool]) -> bool:
    """Whether ``here`` holds for ``term`` or a term below it. ``table`` remembers the answer
    per node (with the node, so its id stays its own) across the globals of a file: each
    node is looked at once, however many globals reach it."""
    pending: list[tuple[g.GlobalTerm, bool]] = [(term, False)]
    visits = 0
    while pending:  # post-order with an explicit stack: sequences can be long
        node, ready = pending.pop()
        if id(node) in table:
            continue
        below = g.children(node)
        if not ready:
            pending.append((node, True))
            pending.extend((child, False) for child in below if id(child) not in table)
            continue
        visits += 1
        table[id(node)] = (node, here(node) or any(table[id(child)][1] for child in below))
    METER.add("reaches", visits)
    return table[id(term)][1]


def _is_refined(term: g.GlobalTerm) -> bool:
    """A message of ``term`` itself (not below it) has a refinement, or a field of its payload does."""
    return isinstance(term, g.Choice | g.Routed) and any(has_refinement(branch.message) for branch in term.branches)


def _is_periodic(term: g.GlobalTerm) -> bool:
    """``term`` is an interaction with ``every``."""
    return isinstance(term, g.Choice) and term.timing is not None and term.timing.every is not None


def _declarations(source: s.SourceFile, reporter: Reporter) -> dict[str, dict[str, s.Declaration]]:
    """Split declarations by kind, reporting duplicates and redefined builtins."""
    by_kind: dict[str, dict[str, s.Declaration]] = {"type": {}, "global": {}, "local": {}}
    first: dict[str, s.Declaration] = {}
    for decl in source.declarations:
        name = decl.name
        if name.text in first:
            where = first[name.text].name.location
            reporter.error(name.location, f"duplicate declaration '{name.text}'; "
                           f"first declared at {where.line}:{where.column}")
            continue
        if isinstance(decl, s.TypeDecl) and name.text in BUILTIN_SORTS:
            reporter.error(name.location, f"type {name.text} redefines the builtin sort "
                           f"{BUILTIN_SORTS[name.text]}")
            continue
        first[name.text] = decl
        kind = {s.TypeDecl: "type", s.GlobalDecl: "global", s.LocalDecl: "local"}[type(decl)]
        by_kind[kind][name.text] = decl
    return by_kind


def _check_roles(decl: s.GlobalDecl, body: g.GlobalTerm, reporter: Reporter,
                 shared: Sharing) -> tuple[str, ...]:
    """Roles in print order; reports undeclared, unused and repeated roles."""
    occurring = _roles_in_order(body, shared)
    if decl.roles is None:
        return tuple(occurring)
    declared: list[str] = []
    for role in decl.roles:
        if role.text in declared:
            reporter.error(role.location, f"role {role.text} is listed twice in global {decl.name.text}")
            continue
        declared.append(role.text)
        if role.text not in occurring:
            reporter.error(role.location, f"role {role.text} is declared in global "
                           f"{decl.name.text} but never occurs")
    for occurring_role, location in occurring.items():
        if occurring_role not in declared:
            reporter.error(location, f"role {occurring_role} is not declared in global {decl.name.text}"
                           f"({', '.join(declared)})")
    return tuple(declared)


def _roles_in_order(term: g.GlobalTerm, shared: Sharing) -> dict[str, Location]:
    """Every role with the location of its first occurrence, in order of first occurrence."""
    found: dict[str, Location] = {}
    _collect_roles(term, found, shared, summarising=False)
    return found


def _collect_roles(node: g.GlobalTerm, found: dict[str, Location], shared: Sharing,
                   summarising: bool) -> None:
    """Add the roles of ``node`` to ``found``; a shared node's roles are collected once."""
    while True:  # a loop along sequences: they can be very long
        if id(node) in shared.nodes and not summarising:
            summary: dict[str, Location] | None = shared.get("roles", node)
            if summary is None:
                summary = {}
                _collect_roles(node, summary, shared, summarising=True)
                shared.put("roles", node, summary)
            for role, location in summary.items():
                found.setdefault(role, location)
            return
        summarising = False
        match node:
            case g.Choice(sender=sender, receiver=receiver, branches=branches):
                found.setdefault(sender, node.location)
                found.setdefault(receiver, node.receiver_location)
                if len(branches) > 1:
                    for branch in branches:
                        _collect_roles(branch.continuation, found, shared, False)
                    return
                node = branches[0].continuation
            case g.Routed(sender=sender, branches=routes):
                found.setdefault(sender, node.location)
                for route in routes:
                    found.setdefault(route.receiver, route.receiver_location)
                for route in routes:
                    _collect_roles(route.continuation, found, shared, False)
                return
            case g.Rec(body=body):
                node = body
            case g.Parallel(branches=parts):
                for part in parts:
                    _collect_roles(part, found, shared, False)
                return
            case _:
                return


def _channels(term: g.GlobalTerm, shared: Sharing) -> frozenset[tuple[str, str]]:
    known: frozenset[tuple[str, str]] | None = shared.get("channels", term) if id(term) in shared.nodes else None
    if known is not None:
        return known
    match term:
        case g.Choice(sender=sender, receiver=receiver, branches=branches):
            found = frozenset({(sender, receiver)}).union(
                *([_channels(b.continuation, shared) for b in branches]))
        case g.Routed(sender=sender, branches=routes):
            found = frozenset({(sender, r.receiver) for r in routes}).union(
                *([_channels(r.continuation, shared) for r in routes]))
        case g.Rec(body=body):
            found = _channels(body, shared)
        case g.Parallel(branches=parts):
            found = frozenset().union(*([_channels(p, shared) for p in parts]))
        case _:
            found = frozenset()
    if id(term) in shared.nodes:
        shared.put("channels", term, found)
    return found


def _check_parallel_global(term: g.GlobalTerm, reporter: Reporter, shared: Sharing) -> None:
    """Parallel branches must not share a directed channel."""
    if id(term) in shared.nodes:
        _once(term, reporter, shared, "parallel", lambda: _check_parallel_in(term, reporter, shared))
    else:
        _check_parallel_in(term, reporter, shared)


def _check_parallel_in(term: g.GlobalTerm, reporter: Reporter, shared: Sharing) -> None:
    match term:
        case g.Choice(branches=branches):
            for b in branches:
                _check_parallel_global(b.continuation, reporter, shared)
        case g.Routed(branches=routes):
            for r in routes:
                _check_parallel_global(r.continuation, reporter, shared)
        case g.Rec(body=body):
            _check_parallel_global(body, reporter, shared)
        case g.Parallel(branches=parts, location=location):
            _report_shared([_channels(p, shared) for p in parts], location, reporter,
                           lambda c: f"{c[0]} -> {c[1]}")
            for part in parts:
                _check_parallel_global(part, reporter, shared)


def _once(node: object, reporter: Reporter, shared: Sharing, table: str, check: Callable[[], None]) -> None:
    """Run ``check`` on a shared node once; replay its diagnostics on later visits.

    Replayed, not skipped: the caller looks at the diagnostics of each global.
    """
    done: tuple[Diagnostic, ...] | None = shared.get(table, node)
    if done is not None:
        reporter.diagnostics.extend(done)
        return
    mark = len(reporter.diagnostics)
    check()
    shared.put(table, node, tuple(reporter.diagnostics[mark:]))


def _report_shared(channel_sets: list[frozenset[tuple[str, str]]], location: Location,
                   reporter: Reporter, show: Callable[[tuple[str, str]], str]) -> None:
    for i, first in enumerate(channel_sets):
        for j in range(i + 1, len(channel_sets)):
            for channel in sorted(first & channel_sets[j]):
                reporter.error(location, f"parallel branches {i + 1} and {j + 1} share the channel "
                               f"{show(channel)}; each channel must belong to one branch")


def _local_channels(term: lt.LocalTerm, shared: Sharing) -> frozenset[tuple[str, str]]:
    known: frozenset[tuple[str, str]] | None = shared.get("channels", term) if id(term) in shared.nodes else None
    if known is not None:
        return known
    match term:
        case lt.Send(peer=peer, continuation=cont):
            found = frozenset({("!", peer or "")}) | _local_channels(cont, shared)
        case lt.Recv(peer=peer, continuation=cont):
            found = frozenset({("?", peer or "")}) | _local_channels(cont, shared)
        case lt.Select(peer=peer, branches=branches) | lt.Offer(peer=peer, branches=branches):
            arrow = "!" if isinstance(term, lt.Select) else "?"
            found = frozenset({(arrow, peer or "")}).union(
                *([_local_channels(b.continuation, shared) for b in branches]))
        case lt.SelectAmong(branches=actions) | lt.OfferAmong(branches=actions):
            found = frozenset().union(*([_local_channels(a, shared) for a in actions]))
        case lt.Rec(body=body):
            found = _local_channels(body, shared)
        case lt.Parallel(branches=parts):
            found = frozenset().union(*([_local_channels(p, shared) for p in parts]))
        case _:
            found = frozenset()
    if id(term) in shared.nodes:
        shared.put("channels", term, found)
    return found


def _check_parallel_local(term: lt.LocalTerm, reporter: Reporter, shared: Sharing) -> None:
    if id(term) in shared.nodes:
        _once(term, reporter, shared, "parallel", lambda: _check_parallel_local_in(term, reporter, shared))
    else:
        _check_parallel_local_in(term, reporter, shared)


def _check_parallel_local_in(term: lt.LocalTerm, reporter: Reporter, shared: Sharing) -> None:
    match term:
        case lt.Send(continuation=cont) | lt.Recv(continuation=cont):
            _check_parallel_local(cont, reporter, shared)
        case lt.Select(branches=branches) | lt.Offer(branches=branches):
            for b in branches:
                _check_parallel_local(b.continuation, reporter, shared)
        case lt.SelectAmong(branches=actions) | lt.OfferAmong(branches=actions):
            for a in actions:
                _check_parallel_local(a.continuation, reporter, shared)
        case lt.Rec(body=body):
            _check_parallel_local(body, reporter, shared)
        case lt.Parallel(branches=parts, location=location):
            _report_shared([_local_channels(p, shared) for p in parts], location, reporter,
                           lambda c: ("sending to " if c[0] == "!" else "receiving from ") + (c[1] or "the peer"))
            for part in parts:
                _check_parallel_local(part, reporter, shared)


def _check_local_forms(decl: s.LocalDecl, body: lt.LocalTerm, reporter: Reporter, shared: Sharing) -> None:
    """A local type is binary (no peers) or multiparty (every action names a peer), not both."""
    peers = {peer for _, peer in _local_channels(body, shared)}
    if "" in peers and len(peers) > 1:
        reporter.error(decl.name.location, f"local {decl.name.text} mixes the binary form (no peer) "
                       "with the multiparty form (!Peer(msg)); use one of them")


def _check_projectable(global_type: GlobalType, reporter: Reporter,
                       reported: set[tuple[object, ...]]) -> None:
    """Report each role ``global_type`` does not project onto.

    A cause is reported once for the file (``reported``): the globals of a
    chain of declarations that all use one unmergeable choice fail for the
    same reason, at the same place, and one message says it.
    """
    for role in global_type.roles:
        try:
            global_type.project(role)
        except ProjectionError as error:
            cause = (type(error), error.location, error.role, error.labels, error.left, error.right,
                     error.reason)
            if cause not in reported:
                reported.add(cause)
                reporter.error(error.location, error.message, error.diagnostics[0].hint)


def _has_error(diagnostics: Iterable[Diagnostic]) -> bool:
    return any(d.severity == "error" for d in diagnostics)


def _sorted_unique(diagnostics: list[Diagnostic]) -> list[Diagnostic]:
    unique = dict.fromkeys(diagnostics)  # inlined declarations report their errors once per use
    return sorted(unique, key=lambda d: (d.location.line, d.location.column))
