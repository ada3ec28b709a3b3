"""Multicast ``A -> B, C : m`` (docs/language.md, 4.5): shorthand the parser expands."""

from __future__ import annotations

import pytest

import sessiontypes
from sessiontypes import Location, ProtocolSyntaxError
from sessiontypes import global_types as g
from sessiontypes.printer import print_global


def body(text: str) -> g.GlobalTerm:
    return sessiontypes.loads(text, "m.proto").globals["P"].body


@pytest.mark.parametrize(("short", "long"), [
    ("A -> B, C : m(int)", "A -> B : m(int). A -> C : m(int)"),
    ("A -> B, C, D : m. B -> A : ok", "A -> B : m. A -> C : m. A -> D : m. B -> A : ok"),
    ("A → C, B : int", "A -> C : int. A -> B : int"),
    ("mu t. A -> B, C : {go. t, stop(str)}",
     "mu t. A -> B : {go. A -> C : go. t, stop(str). A -> C : stop(str)}"),
    ("A -> B, C : {yes: B -> A : x, no: end}",
     "A -> B : {yes. A -> C : yes. B -> A : x, no. A -> C : no}"),
    ("(A -> B, C : m || D -> E : n)", "(A -> B : m. A -> C : m || D -> E : n)"),
])
def test_a_multicast_is_the_sequence_of_sends(short: str, long: str) -> None:
    assert body(f"global P = {short}") == body(f"global P = {long}")


def test_the_canonical_print_is_the_expansion_and_reads_back() -> None:
    expanded = body("global P = A -> B, C : {go(int). B -> A, C : done, stop}")
    printed = print_global(expanded)
    assert printed == "A->B:{go(int).A->C:go(int).B->A:done.B->C:done, stop.A->C:stop}"
    assert body(f"global P = {printed}") == expanded


def test_projection_of_a_multicast() -> None:
    global_type = sessiontypes.loads("global P = A -> B, C : {go(int). B -> A : ok, stop}").globals["P"]
    assert {r: str(global_type.project(r)) for r in global_type.roles} == {
        "A": "+B{go(int).!C(go(int)).?B(ok), stop.!C(stop)}",
        "B": "&A{go(int).!A(ok), stop}",
        "C": "&A{go(int), stop}",
    }


def test_every_interaction_of_the_expansion_points_at_the_multicast() -> None:
    term = body("global P =\n  A -> B, C : m.\n  B -> A : ok")
    assert isinstance(term, g.Choice)
    second = term.branches[0].continuation
    assert isinstance(second, g.Choice)
    assert (second.sender, second.receiver) == ("A", "C")
    assert term.location == second.location == Location("m.proto", 2, 3)
    assert term.receiver_location == Location("m.proto", 2, 8)
    assert second.receiver_location == Location("m.proto", 2, 11)
    assert term.branches[0].location == second.branches[0].location == Location("m.proto", 2, 15)


def test_a_receiver_listed_twice_is_an_error() -> None:
    with pytest.raises(ProtocolSyntaxError) as info:
        sessiontypes.loads("global P = A -> B, C, B : m", "m.proto")
    assert str(info.value) == (
        "m.proto:1:23: error: syntax error; expected a receiver not listed yet, got 'B' again "
        "(a multicast sends to each receiver once)\n"
        "    global P = A -> B, C, B : m\n"
        "                          ^")
    assert (info.value.location, info.value.got, info.value.expected) == (
        Location("m.proto", 1, 23), "'B' again", ("a receiver not listed yet",))


def test_roles_come_in_the_order_of_the_receivers() -> None:
    assert sessiontypes.loads("global P = A -> C, B : m").globals["P"].roles == ("A", "C", "B")
