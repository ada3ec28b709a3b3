"""Canonical print (LANGUAGE.md section 5)."""

from __future__ import annotations

import pytest

import sessiontypes
from sessiontypes import local_types as lt
from sessiontypes.printer import print_global, print_message
from sessiontypes.sorts import Interaction, Sort, builtin_sort


@pytest.mark.parametrize(("message", "printed"), [
    (Interaction("Int", builtin_sort("Int")), "Int"),
    (Interaction("int", builtin_sort("int")), "int"),
    (Interaction("ok", builtin_sort("Int")), "ok(Int)"),
    (Interaction("Int", builtin_sort("int")), "Int(int)"),
    (Interaction("quit"), "quit"),
    (Interaction("Pose", Sort("Pose", "Pose", "m:Pose")), "Pose"),
    # a payload-less label spelled like a builtin sort keeps its parentheses,
    # or it would read back as a label carrying that sort
    (Interaction("int"), "int()"),
])
def test_message_forms(message: Interaction, printed: str) -> None:
    assert print_message(message) == printed


def test_sorts_print_as_spelled_but_compare_equal() -> None:
    module = sessiontypes.loads("global G = A -> B : x(Int). B -> A : y(int)")
    assert str(module.globals["G"].project("A")) == "!B(x(Int)).?B(y(int))"
    assert builtin_sort("Int") == builtin_sort("int")
    assert builtin_sort("String") == builtin_sort("str")


def test_sequence_choice_recursion_and_parallel() -> None:
    term = lt.Rec("t", lt.Select("B", (
        lt.Branch(Interaction("more", builtin_sort("nat")), lt.Recv("B", Interaction("ack"), lt.Var("t"))),
        lt.Branch(Interaction("stop"), lt.End()),
    )))
    assert str(term) == "mu t.+B{more(nat).?B(ack).t, stop}"
    assert str(lt.Parallel((lt.Send("A", Interaction("x"), lt.End()), lt.Var("s")))) == "(!A(x) || s)"
    assert str(lt.End()) == "end"


def test_binary_form_prints_without_peer() -> None:
    atm = sessiontypes.loads("local L = ?Int. +{ok: !Int. L, err: end}").locals["L"]
    assert str(atm) == "mu L.?Int.+{ok.!Int.L, err}"


def test_global_print_reads_back_to_the_same_type() -> None:
    text = ("global G = mu t. A -> B : {go(int). B -> C : x. (C -> A : y || B -> D : z(str)), "
            "stop. B -> C : stop. B -> D : stop. C -> A : bye}")
    body = sessiontypes.loads(text).globals["G"].body
    printed = print_global(body)
    assert printed == ("mu t.A->B:{go(int).B->C:x.(C->A:y || B->D:z(str)), "
                       "stop.B->C:stop.B->D:stop.C->A:bye}")
    assert sessiontypes.loads(f"global G = {printed}").globals["G"].body == body


def test_global_declaration_str_lists_roles() -> None:
    global_type = sessiontypes.loads("global P(B, A) = A -> B : ping").globals["P"]
    assert str(global_type) == "global P(B, A) = A->B:ping"
