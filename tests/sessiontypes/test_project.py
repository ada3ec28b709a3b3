"""Projection with full merge (LANGUAGE.md section 5)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import sessiontypes
from sessiontypes import ProjectionError, ProtocolCheckError, UnknownRoleError
from sessiontypes import local_types as lt
from sessiontypes.project import MergeError, merge, substitute, unfold
from sessiontypes.sorts import Interaction, builtin_sort

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
    limits = ("{abs(linear.x) <= 0.5 and abs(angular.z) <= 1.5 and linear.y == 0 and linear.z == 0 and "
              "angular.x == 0 and angular.y == 0}")  # the contract: tinman.proto
    assert str(parallel.project("Move")) == (
        f"(mu c.?Control(Twist{limits}) within 100ms.!Gazebo(Twist{limits}) within 500ms.c"
        " || mu s.?Gazebo(LaserScan) within 250ms else timeout.s || mu v.?VisOdom(Pose) within 500ms else timeout.v"
        " || mu p.?Planner(Path).p)")
    assert str(parallel.project("Joy")) == "mu c.!Control(Joy) every 20ms +- 15ms.c"


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
    ("global G = A -> B : {l1. B -> C : x, l2. B -> C : y, l3. end}", ("l1", "l3"),
     "a receive cannot merge with end"),
    # Sends merge only with the same peer, labels and sorts (LANGUAGE.md 5).
    ("global G = A -> B : {l1. C -> B : x. B -> C : l1, l2. C -> B : y. B -> C : l2}", ("l1", "l2"),
     "it sends 'x' in one and 'y' in the other"),
    ("global G = A -> B : {l1. C -> B : x, l2. C -> A : x}", ("l1", "l2"),
     "one sends to B, the other to A"),
    ("global G = A -> B : {l1. C -> B : x(int). B -> C : l1, l2. C -> B : x(str). B -> C : l2}",
     ("l1", "l2"), "label 'x' carries int in one and str in the other"),
    (("global G = A -> B : {l1. C -> B : {a. B -> C : l1, b. B -> C : l1},"
      " l2. C -> B : {a. B -> C : l2, c. B -> C : l2}}"), ("l1", "l2"),
     "it sends one of 'a', 'b' in one and one of 'a', 'c' in the other"),
    ("global G = A -> B : {l1. C -> B : x. B -> C : l1, l2. C -> B : {x. B -> C : l2, y. B -> C : l2}}",
     ("l1", "l2"), "it sends 'x' in one and one of 'x', 'y' in the other"),
    ("global G = A -> B : {l1. C -> B : x. B -> C : y, l2. C -> B : x}", ("l1", "l2"),
     "a receive cannot merge with end"),
    ("global G = A -> B : {l1. C -> B : x, l2. B -> C : x}", ("l1", "l2"),
     "a send cannot merge with a receive"),
    ("global G = A -> B : {l1. C -> B : x. B -> C : l1, l2. C -> B : x. B -> C : l2, l3. end}",
     ("l1", "l3"), "a send cannot merge with end"),
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
    send = lt.Send("A", Interaction("x"), lt.End())
    other = lt.Send("A", Interaction("y"), lt.End())
    with pytest.raises(MergeError, match=r"^it sends 'x' in one and 'y' in the other$"):
        merge(send, other)


def test_merge_rejects_loops_back_to_different_places() -> None:
    with pytest.raises(MergeError, match=r"^one loops back to t, the other to s$"):
        merge(lt.Var("t"), lt.Var("s"))


# ---- full merge of sends (LANGUAGE.md 5, issue 17) ----------------------------------------

def test_sends_to_one_peer_with_one_label_merge_their_continuations() -> None:
    # The example of issue 17: C sends x either way, then learns the choice from B.
    result = projections("global G(A, B, C) = A -> B : { l1. C -> B : x. B -> C : l1,"
                         " l2. C -> B : x. B -> C : l2 }")
    assert result == {"A": "+B{l1, l2}", "B": "&A{l1.?C(x).!C(l1), l2.?C(x).!C(l2)}",
                      "C": "!B(x).&B{l1, l2}"}


def test_sends_merge_whatever_spelling_of_the_sort() -> None:
    result = projections("global G = A -> B : {l1. C -> B : x(int). B -> C : l1,"
                         " l2. C -> B : x(Int). B -> C : l2}")
    assert result["C"] == "!B(x(int)).&B{l1, l2}"


def test_selections_with_the_same_labels_merge_label_by_label_in_first_order() -> None:
    result = projections("global G = A -> B : {l1. C -> B : {a. B -> C : l1, b(int). B -> C : l1},"
                         " l2. C -> B : {b(int). B -> C : l2. C -> B : z, a. B -> C : l2}}")
    assert result["C"] == "+B{a.&B{l1, l2}, b(int).&B{l1, l2.!B(z)}}"


def test_send_merges_nest_inside_offers_and_across_three_branches() -> None:
    result = projections("global G = A -> B : {l1. B -> C : go. C -> B : x. B -> C : l1,"
                         " l2. B -> C : go. C -> B : x. B -> C : l2, l3. B -> C : stop. C -> B : bye}")
    assert result["C"] == "&B{go.!B(x).&B{l1, l2}, stop.!B(bye)}"


def test_long_common_sends_merge_without_recursion_errors() -> None:
    sends = ". ".join(f"C -> B : m{i}" for i in range(20_000))
    result = projections(f"global G = A -> B : {{l1. {sends}. B -> C : l1, l2. {sends}. B -> C : l2}}")
    assert result["C"].startswith("!B(m0).!B(m1).")
    assert result["C"].endswith("!B(m19999).&B{l1, l2}")


@pytest.mark.parametrize("loop", [False, True])
def test_merging_long_common_sends_compares_each_message_a_few_times(
        loop: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    # Comparing the whole rest of both sides at every message (merge's identity test,
    # or the equivalence of two loops) would be quadratic: n * n / 2 comparisons.
    n = 2_000
    sends = ". ".join(f"C -> B : m{i}" for i in range(n))
    if loop:
        text = (f"global G = A -> B : {{l1. mu t. {sends}. B -> C : {{a. t, done. end}},"
                f" l2. mu s. {sends}. B -> C : {{a. s, quit. end}}}}")
    else:
        text = f"global G = A -> B : {{l1. {sends}. B -> C : l1, l2. {sends}. B -> C : l2}}"
    global_type = sessiontypes.loads(text).globals["G"]
    global_type.cached_projections.clear()
    calls = 0
    original = lt.Send.__eq__

    def counting(self: lt.Send, other: object) -> bool:
        nonlocal calls
        calls += 1
        return original(self, other)

    monkeypatch.setattr(lt.Send, "__eq__", counting)
    projected = str(global_type.project("C"))
    monkeypatch.undo()
    assert projected.endswith("&B{a.t, done, quit}" if loop else "!B(m1999).&B{l1, l2}")
    assert calls < 10 * n


def test_send_merge_inside_a_loop() -> None:
    result = projections("global G = mu t. A -> B : {l1. C -> B : x. B -> C : l1. t,"
                         " l2. C -> B : x. B -> C : l2}")
    assert result["C"] == "mu t.!B(x).&B{l1.t, l2}"


def test_two_sending_loops_merge_by_unfolding() -> None:
    # C sends x and is then told whether to go on; the two branches' loops differ in
    # how C learns they are over, so neither is the other: merge unfolds both.
    result = projections("global G = A -> B : {l1. mu t. C -> B : x. B -> C : {a. t, done. end},"
                         " l2. mu s. C -> B : x. B -> C : {a. s, quit. end}}")
    assert result["C"] == "mu t.!B(x).&B{a.t, done, quit}"


def test_send_merge_after_unfolding_one_side() -> None:
    result = projections("global G = A -> B : {l1. mu t. C -> B : x. B -> C : {a. t, done. end},"
                         " l2. C -> B : x. B -> C : {a. mu t. C -> B : x. B -> C : {a. t, done. end},"
                         " quit. end}}")
    # After 'a' both branches are in the same loop, which 'quit' does not leave.
    assert result["C"] == "!B(x).&B{a.mu t.!B(x).&B{a.t, done}, done, quit}"


def test_send_merge_failure_deep_inside_names_the_outer_branches() -> None:
    text = ("global G(A, B, C) =\n"
            "  A -> B : {\n"
            "    l1. C -> B : x. B -> C : y. C -> B : ok,\n"
            "    l2. C -> B : x. B -> C : y. C -> B : ko\n"
            "  }\n")
    with pytest.raises(ProtocolCheckError) as caught:
        sessiontypes.loads(text, "deep.proto")
    (diagnostic,) = caught.value.errors
    assert (diagnostic.location.line, diagnostic.location.column) == (2, 3)
    assert diagnostic.message == (
        "global G is not projectable onto role C: branches 'l1' and 'l2' give C different "
        "behaviours that do not merge (it sends 'ok' in one and 'ko' in the other): "
        "!B(x).?B(y).!B(ok) versus !B(x).?B(y).!B(ko)")


def test_merge_of_offers_is_their_union_in_order() -> None:
    int_ = builtin_sort("int")
    left = lt.offer("P", (lt.Branch(Interaction("a", int_), lt.End()), lt.Branch(Interaction("b"), lt.End())))
    right = lt.offer("P", (lt.Branch(Interaction("c"), lt.End()),
                           lt.Branch(Interaction("a", builtin_sort("Int")), lt.End())))
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
    loop = lt.Rec("t", lt.Recv("A", Interaction("x"), lt.Var("t")))
    assert str(unfold(loop)) == "?A(x).mu t.?A(x).t"
    # substituting a term with free 's' under a binder 's' renames the binder
    inner = lt.Rec("s", lt.Send("B", Interaction("y"), lt.Var("t")))
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

    send = lambda cont: lt.Send("B", Interaction("x"), cont)  # noqa: E731
    once = lt.Rec("t", send(lt.Var("t")))
    twice = lt.Rec("u", send(send(lt.Var("u"))))
    assert equivalent(once, twice) and equivalent(twice, once)
    assert equivalent(once, send(once))
    assert not equivalent(once, send(lt.End()))
    assert not equivalent(once, lt.Rec("t", lt.Send("B", Interaction("y"), lt.Var("t"))))
