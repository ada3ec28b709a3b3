"""Declarations referring to each other: checked once each, meaning what their inlining means.

Resolution shares one node for every use of a declaration (issue 11: files
whose declarations refer twice to the next one were exponential). These tests
pin the meaning against a textual oracle (every reference written out in
place, ``mu Name.`` around a declaration that refers back to itself) and the
cost by counting work, never by timing.
"""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from budget import examples
from hypothesis import given, settings
from hypothesis import strategies as st

import sessiontypes
from sessiontypes import ProtocolError
from sessiontypes.parse import parse_file
from sessiontypes.printer import PrintTooLongError, print_global, print_local
from sessiontypes.resolve import Reporter, SortTable, global_walk, resolve_global
from sessiontypes.syntax import GlobalDecl

ROLES = ("A", "B", "C")

# ---- a file of declarations, and its oracle ----------------------------------------


@dataclass(frozen=True)
class Interaction:
    sender: str
    receiver: str
    branches: tuple[tuple[str, Body], ...]


@dataclass(frozen=True)
class Loop:
    var: str
    body: Body


@dataclass(frozen=True)
class Name:
    text: str  # a loop variable or a declaration


Body = Interaction | Loop | Name | None  # None: end


def bodies(declarations: int) -> st.SearchStrategy[Body]:
    """Bodies whose references sit after an interaction (so every cycle is guarded)."""

    @st.composite
    def body(draw: st.DrawFn, depth: int, guarded: bool, loops: tuple[str, ...]) -> Body:
        options = ["end", "interaction"]
        if depth < 4:
            options += ["interaction", "loop"]
        if guarded:
            options += ["ref", "ref"] + (["var"] if loops else [])
        match draw(st.sampled_from(options)):
            case "interaction":
                sender, receiver = draw(st.permutations(ROLES))[:2]
                count = draw(st.integers(1, 2))
                labels = ("l", "r")[:count]
                return Interaction(sender, receiver, tuple(
                    (label, draw(body(depth + 1, True, loops))) for label in labels))
            case "loop":
                var = f"t{len(loops)}"
                return Loop(var, draw(body(depth + 1, False, (*loops, var))))
            case "ref":
                return Name(f"G{draw(st.integers(0, declarations - 1))}")
            case "var":
                return Name(draw(st.sampled_from(loops)))
        return None

    return body(0, False, ())


def write(body: Body) -> str:
    match body:
        case Interaction(sender=sender, receiver=receiver, branches=branches):
            inner = ", ".join(f"{label}. {write(rest)}" for label, rest in branches)
            return f"{sender} -> {receiver} : {{{inner}}}"
        case Loop(var=var, body=inner):
            return f"mu {var}. ({write(inner)})"
        case Name(text=text):
            return text
    return "end"


def inline(declarations: dict[str, Body], body: Body, expanding: frozenset[str]) -> tuple[str, frozenset[str]]:
    """The text of ``body`` with every reference written out, and the declarations it refers back to."""
    match body:
        case Interaction(sender=sender, receiver=receiver, branches=branches):
            parts = [(label, inline(declarations, rest, expanding)) for label, rest in branches]
            text = ", ".join(f"{label}. {rest}" for label, (rest, _) in parts)
            return f"{sender} -> {receiver} : {{{text}}}", frozenset().union(*(free for _, (_, free) in parts))
        case Loop(var=var, body=inner):
            text, free = inline(declarations, inner, expanding)
            return f"mu {var}. ({text})", free
        case Name(text=name) if name in declarations:
            if name in expanding:
                return name, frozenset({name})
            text, free = inline(declarations, declarations[name], expanding | {name})
            return (f"mu {name}. ({text})" if name in free else text), free - {name}
        case Name(text=name):
            return name, frozenset()
    return "end", frozenset()


@st.composite
def reference_files(draw: st.DrawFn) -> dict[str, Body]:
    count = draw(st.integers(1, 4))
    return {f"G{i}": draw(bodies(count)) for i in range(count)}


def outcome(text: str) -> dict[str, object] | str:
    """What a file means: per global its print and its projections; or that it is rejected."""
    try:
        module = sessiontypes.loads(text, "refs.proto")
    except ProtocolError:
        return "rejected"
    return {name: (print_global(glob.body),
                   {role: print_local(glob.project(role).body) for role in glob.roles})
            for name, glob in module.globals.items()}


@given(reference_files())
@settings(deadline=None, max_examples=examples(150))
def test_references_mean_their_inlining(declarations: dict[str, Body]) -> None:
    referring = "\n".join(f"global {name} = {write(body)}" for name, body in declarations.items())
    inlined = "\n".join(f"global {name} = {inline(declarations, body, frozenset({name}))[0]}"
                        for name, body in declarations.items())
    assert outcome(referring) == outcome(inlined), (referring, inlined)


# ---- the cost: counted, not timed --------------------------------------------------


def dag(n: int) -> str:
    """Each declaration refers twice to the next: written out, G0 has 2**n interactions."""
    lines = [f"global G{i}(A, B) = A -> B : {{l. G{i + 1}, r. G{i + 1}}}" for i in range(n)]
    return "\n".join([*lines, f"global G{n}(A, B) = A -> B : done"])


def chain(n: int) -> str:
    lines = [f"global G{i}(A, B) = A -> B : x. G{i + 1}" for i in range(n)]
    return "\n".join([*lines, f"global G{n}(A, B) = A -> B : done"])


def resolutions(text: str) -> int:
    """How many declaration bodies resolution walks for the file's globals."""
    source = parse_file(text, "refs.proto")
    reporter = Reporter(source)
    globals_ = {d.name.text: d for d in source.declarations if isinstance(d, GlobalDecl)}
    walk = global_walk(reporter, SortTable({}, reporter), globals_, set())
    for decl in globals_.values():
        resolve_global(decl, walk)
    assert not reporter.diagnostics
    return walk.resolutions


@pytest.mark.parametrize("shape", [dag, chain])
def test_each_declaration_is_resolved_once(shape) -> None:
    # Inlined afresh at every use these are 2**40 and 40*41/2 bodies.
    assert resolutions(shape(40)) == 41


def test_a_reference_dag_is_shared_not_written_out() -> None:
    module = sessiontypes.loads(dag(60), "dag.proto")  # 2**60 interactions written out
    g0 = module.globals["G0"]
    left, right = g0.body.branches  # type: ignore[union-attr]
    assert left.continuation is right.continuation
    projected = g0.project("B").body
    assert projected.branches[0].continuation is projected.branches[1].continuation  # type: ignore[union-attr]
    # The state machine has one state per shared node, not per written-out place.
    assert len(g0.project("A").fsm().table) == 62


def test_mutual_recursion_in_a_cycle_is_resolved_per_context() -> None:
    text = ("global G0(A, B) = A -> B : {a. G1, b. G2}\n"
            "global G1(A, B) = A -> B : {c. G2, d. G0}\n"
            "global G2(A, B) = A -> B : {e. G0, f. G1, g. end}\n")
    module = sessiontypes.loads(text, "cycle.proto")
    assert print_local(module.globals["G0"].project("B").body) == (
        "mu G0.&A{a.mu G1.&A{c.&A{e.G0, f.G1, g}, d.G0}, b.mu G2.&A{e.G0, f.&A{c.G2, d.G0}, g}}")


def test_prints_of_shared_types_are_bounded(tmp_path, capsys) -> None:
    from anodize._tools.cli import main

    g0 = sessiontypes.loads(dag(60), "dag.proto").globals["G0"]
    with pytest.raises(PrintTooLongError):
        print_local(g0.project("A").body, limit=10_000)
    machine = g0.project("A").fsm()
    assert machine.describe(0) == "+B{l..., r...} (longer than 4000 characters written out)"
    assert machine.describe(60) == "!B(done)"
    # written out but short enough: the same print as the inlined text gives
    assert print_local(sessiontypes.loads(dag(3), "d.proto").globals["G0"].project("B").body) == (
        "&A{l.&A{l.&A{l.?A(done), r.?A(done)}, r.&A{l.?A(done), r.?A(done)}}, "
        "r.&A{l.&A{l.?A(done), r.?A(done)}, r.&A{l.?A(done), r.?A(done)}}}")
    path = tmp_path / "dag.proto"
    path.write_text(dag(60))
    assert main(["project", str(path), "--global", "G0"]) == 1
    assert "G0 projected onto A is longer than 67108864 characters written out" in capsys.readouterr().err


@pytest.mark.parametrize(("text", "role", "projection"), [
    # The loop named like its declaration is renamed; the new name must not be one
    # an inner mu binds, else that mu captures the loop's uses (found by differential fuzzing).
    ("global M(A, B) = mu M. B -> A : {r. mu M'. M, ok. K}\nglobal K(A, B) = M\n",
     "A", "mu M.mu M''.&B{r.M'', ok.M}"),
    ("global G(A, B) = mu G. A -> B : {l. mu G'. G, r. K}\nglobal K(A, B) = B -> A : n. G\n",
     "B", "mu G.mu G''.&A{l.G'', r.!A(n).G}"),
])
def test_a_renamed_loop_is_not_captured_by_an_inner_one(text: str, role: str, projection: str) -> None:
    glob = sessiontypes.loads(text, "capture.proto").globals[text.split()[1].split("(")[0]]
    assert print_local(glob.project(role).body) == projection
