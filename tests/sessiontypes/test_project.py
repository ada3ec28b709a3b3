"""Projection with full merge (LANGUAGE.md section 5)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import sessiontypes
from sessiontypes import ProjectionError, ProtocolCheckError, UnknownRoleError
from sessiontypes import local_types as lt
from sessiontypes.project import MergeError, merge, substitute, unfold
from sessiontypes.sorts import Message, builtin_sort

ROOT = Path(__file__).resolve().parents[2]

# The paper's Fig. 17 with the outer loop written out (LANGUAGE.md section 5).
FIG_17 = (ROOT / "tests" / "data" / "fig17.txt").read_text(encoding="utf-8").rstrip("\n")


def projections(text: str, name: str = "G") -> dict[str, str]:
    global_type = sessiontypes.loads(text, "test.proto").globals[name]
    return {role: str(local) for role, local in global_type.projections().items()}


def test_fig16_projects_to_fig17() -> None:
    tinman = sessiontypes.load(ROOT / "protocols" / "tinman.proto").globals["TinMan"]
    printed = "\n".join(f"{role} = {tinman.project(role)}" for role in tinman.roles)
    assert printed == FIG_17


def test_parallel_tinman_separates_the_loops() -> None:
    parallel = sessiontypes.load(ROOT / "protocols" / "tinman.proto").globals["TinManParallel"]
    assert str(parallel.project("Move")) == (
        "(mu c.?Control(Twist).!Gazebo(Twist).c || mu v.?VisOdom(Pose).v || mu p.?Planner(Path).p)")
    assert str(parallel.project("Joy")) == "mu c.!Control(Joy).c"


def test_sender_selects_receiver_offers_in_source_order() -> None:
    result = projections("global G = A -> B : {b(int). B -> A : ack, a. end}")
    assert result == {"A": "+B{b(int).?B(ack), a}", "B": "&A{b(int).!A(ack), a}"}


def test_third_party_merges_external_choices_from_one_peer() -> None:
    result = projections("global G = A -> B : {l1. B -> C : x(int), l2. B -> C : y. C -> A : z}")
    assert result["C"] == "&B{x(int), y.!A(z)}"


def test_merge_of_identical_continuations_is_that_continuation() -> None:
    result = projections("global G = A -> B : {l1. C -> A : z, l2. C -> A : z}")
    assert result["C"] == "!A(z)"


@pytest.mark.parametrize(("text", "labels", "reason"), [
    ("global G = A -> B : {l1. C -> A : x, l2. end}", ("l1", "l2"), "a send cannot merge with end"),
    ("global G = A -> B : {l1. B -> C : x(int), l2. B -> C : x(str)}", ("l1", "l2"),
     "label 'x' carries int in one and str in the other"),
    ("global G = A -> B : {l1. B -> C : x, l2. A -> C : y}", ("l1", "l2"),
     "one receives from B, the other from A"),
    ("global G = A -> B : {l1. B -> C : x, l2. B -> C : y, l3. end}", ("l1", "l3"),
     "a receive cannot merge with end"),
])
def test_unmergeable_branches_name_role_and_branches(text: str, labels: tuple[str, str], reason: str) -> None:
    with pytest.raises(ProtocolCheckError) as caught:
        sessiontypes.loads(text, "test.proto")
    (diagnostic,) = caught.value.errors
    assert diagnostic.location.line == 1 and diagnostic.location.column == 12
    assert diagnostic.message.startswith(
        f"global G is not projectable onto role C: branches '{labels[0]}' and '{labels[1]}'")
    assert f"({reason})" in diagnostic.message


def test_projection_error_has_structured_fields() -> None:
    # Build the global type without the check (which would already reject it).
    from sessiontypes.check import check_file
    from sessiontypes.parse import parse_file

    module, _ = check_file(parse_file("global G = A -> B : {l1. C -> A : x, l2. end}", "p.proto"))
    with pytest.raises(ProjectionError) as caught:
        module.globals["G"].project("C")
    error = caught.value
    assert (error.protocol, error.role, error.labels) == ("G", "C", ("l1", "l2"))
    assert (error.left, error.right) == ("!A(x)", "end")
    assert str(error).startswith("p.proto:1:12: error: global G is not projectable onto role C")


def test_merge_unfolds_recursion_once() -> None:
    result = projections("global G = A -> B : {l1. A -> C : x. mu t. A -> C : x. t,"
                         " l2. mu t. A -> C : x. t}")
    assert result["C"] == "?A(x).mu t.?A(x).t"


def test_two_spellings_of_one_loop_merge_instead_of_looping() -> None:
    # nuScr rejects this (its issue #137); LANGUAGE.md asks us to accept it.
    result = projections("global G = A -> B : {l1. mu t. A -> C : x. A -> C : x. t,"
                         " l2. mu s. A -> C : x. s}")
    assert result["C"] == "mu t.?A(x).?A(x).t"


def test_merge_rejects_different_sends() -> None:
    send = lt.Send("A", Message("x"), lt.End())
    other = lt.Send("A", Message("y"), lt.End())
    with pytest.raises(MergeError, match=r"^only identical behaviours merge unless both receive$"):
        merge(send, other)


def test_merge_of_offers_is_their_union_in_order() -> None:
    int_ = builtin_sort("int")
    left = lt.offer("P", (lt.Branch(Message("a", int_), lt.End()), lt.Branch(Message("b"), lt.End())))
    right = lt.offer("P", (lt.Branch(Message("c"), lt.End()), lt.Branch(Message("a", builtin_sort("Int")), lt.End())))
    assert str(merge(left, right)) == "&P{a(int), b, c}"


def test_unused_recursion_is_dropped_for_uninvolved_roles() -> None:
    result = projections("global G = A -> B : x. mu t. B -> A : y. t")
    assert result == {"A": "!B(x).mu t.?B(y).t", "B": "?A(x).mu t.!A(y).t"}
    result = projections("global G = mu t. A -> B : x. C -> A : y. t")
    assert result["C"] == "mu t.!A(y).t"


def test_inner_loop_of_other_roles_keeps_outer_loop() -> None:
    # A is absent from the inner mu; its projection must still loop (t is free there).
    result = projections("global G = mu t. A -> B : x. mu s. B -> C : y. t")
    assert result["A"] == "mu t.!B(x).t"
    assert result["C"] == "mu t.mu s.?B(y).t"


def test_equation_style_recursion_uses_declaration_name() -> None:
    text = "global G = A -> B : x. H\nglobal H = B -> A : y. G"
    assert projections(text, "G") == {"A": "mu G.!B(x).?B(y).G", "B": "mu G.?A(x).!A(y).G"}
    assert projections(text, "H") == {"B": "mu H.!A(y).?A(x).H", "A": "mu H.?B(y).!B(x).H"}


def test_parallel_drops_branches_that_are_end() -> None:
    result = projections("global G = (A -> B : x || C -> D : y || A -> C : z)")
    assert result == {"A": "(!B(x) || !C(z))", "B": "?A(x)", "C": "(!D(y) || ?A(z))", "D": "?C(y)"}


def test_unknown_role_is_a_clear_error() -> None:
    global_type = sessiontypes.loads("global G = A -> B : x").globals["G"]
    with pytest.raises(UnknownRoleError, match=re.escape(
            "error: global G has no role Z; expected one of A, B")):
        global_type.project("Z")


def test_unfold_and_capture_avoiding_substitution() -> None:
    loop = lt.Rec("t", lt.Recv("A", Message("x"), lt.Var("t")))
    assert str(unfold(loop)) == "?A(x).mu t.?A(x).t"
    # substituting a term with free 's' under a binder 's' renames the binder
    inner = lt.Rec("s", lt.Send("B", Message("y"), lt.Var("t")))
    replaced = substitute(inner, "t", lt.Var("s"))
    assert str(replaced) == "mu s'.!B(y).s"


def test_long_sequences_project_without_recursion_errors() -> None:
    steps = ". ".join(f"R{i % 7} -> R{(i + 1) % 7} : m{i}" for i in range(20_000))
    global_type = sessiontypes.loads(f"global G = {steps}").globals["G"]
    printed = str(global_type.project("R0"))
    assert printed.startswith("!R1(m0).?R6(m6).!R1(m7)")
    involved = sum(1 for i in range(20_000) if i % 7 in (0, 6))
    assert printed.count("m") == involved


@pytest.mark.parametrize("second", ["mu u. A -> C : x. u", "mu u. A -> C : x. A -> C : x. u",
                                    "A -> C : x. mu u. A -> C : x. u"])
def test_sending_loops_merge_however_they_are_spelled(second: str) -> None:
    result = projections(f"global G = B -> C : {{l0. mu t. A -> C : x. t, l1. {second}}}")
    assert result["A"] == "mu t.!C(x).t"


def test_equivalence_is_up_to_unfolding_and_renaming() -> None:
    from sessiontypes.recursion import equivalent

    send = lambda cont: lt.Send("B", Message("x"), cont)  # noqa: E731
    once = lt.Rec("t", send(lt.Var("t")))
    twice = lt.Rec("u", send(send(lt.Var("u"))))
    assert equivalent(once, twice) and equivalent(twice, once)
    assert equivalent(once, send(once))
    assert not equivalent(once, send(lt.End()))
    assert not equivalent(once, lt.Rec("t", lt.Send("B", Message("y"), lt.Var("t"))))
