"""Choices whose branches go to different receivers (issue 17 item 2).

``A -> {B : m1. G1, C : m2. G2}``: A's local type is an internal choice over
(peer, label) pairs, ``+{!B(m1).L1, !C(m2).L2}``; any other role learns the
branch from the first message it gets, from whichever peer, ``&{?A(m1).L1,
?C(x).L2}``, or the global type is not projectable onto it; and the choice must
be free of races (a message that may overtake the deciding one).
"""

from __future__ import annotations

import pytest

import sessiontypes
from sessiontypes import ProtocolCheckError
from sessiontypes import global_types as g
from sessiontypes import local_types as lt
from sessiontypes.printer import print_global
from sessiontypes.recursion import equivalent
from sessiontypes.sorts import Interaction


def load(text: str) -> sessiontypes.ProtocolModule:
    return sessiontypes.loads(text, "r.proto")


def projections(text: str, name: str = "G") -> dict[str, str]:
    global_type = load(text).globals[name]
    return {role: str(local) for role, local in global_type.projections().items()}


def error_of(text: str) -> tuple[str, str]:
    with pytest.raises(ProtocolCheckError) as caught:
        load(text)
    (diagnostic,) = caught.value.errors
    return f"{diagnostic.location.line}:{diagnostic.location.column}", diagnostic.message


# ---- syntax and canonical print --------------------------------------------------------

def test_global_syntax_core_term_and_canonical_print() -> None:
    body = load("global G = A -> { B : m1(int). B -> C : done, C : m2. C -> B : x, }").globals["G"].body
    assert isinstance(body, g.Routed)
    assert body.sender == "A"
    assert [(r.receiver, r.message.label) for r in body.branches] == [("B", "m1"), ("C", "m2")]
    printed = print_global(body)
    assert printed == "A->{B:m1(int).B->C:done, C:m2.C->B:x}"
    assert load(f"global G = {printed}").globals["G"].body == body


def test_one_receiver_is_an_ordinary_choice() -> None:
    assert (load("global G = A -> {B : x. B -> A : ok, B : y}").globals["G"].body
            == load("global G = A -> B : {x. B -> A : ok, y}").globals["G"].body)


def test_locations_point_at_each_receiver_and_label() -> None:
    body = load("global G =\n  A -> {\n    B : m1. B -> C : x,\n    C : m2. C -> B : y\n  }").globals["G"].body
    assert isinstance(body, g.Routed)
    assert (body.location.line, body.location.column) == (2, 3)
    first, second = body.branches
    assert (first.receiver_location.line, first.receiver_location.column) == (3, 5)
    assert (second.location.line, second.location.column) == (4, 9)


def test_local_syntax_and_canonical_print() -> None:
    module = load("local L = +{ !B(m1(int)). ?B(ok), !C(m2) }\n"
                  "local M = &{?A(m1), ?C(x(str)). !A(ok)}\n"
                  "local N = +{!B(x), !B(y).end}")
    select, offer, one_peer = (module.locals[n].body for n in "LMN")
    assert isinstance(select, lt.SelectAmong) and isinstance(offer, lt.OfferAmong)
    assert str(select) == "+{!B(m1(int)).?B(ok), !C(m2)}"
    assert str(offer) == "&{?A(m1), ?C(x(str)).!A(ok)}"
    assert str(one_peer) == "+B{x, y}" and isinstance(one_peer, lt.Select)  # one peer: an ordinary choice
    again = load(f"local L = {select}\nlocal M = {offer}")
    assert again.locals["L"].body == select and again.locals["M"].body == offer


@pytest.mark.parametrize(("text", "where", "message"), [
    ("global G = A -> {B : m, C : n, B : m}", "1:36", "duplicate label 'm' for B in one choice"),
    ("global G = A -> {B : m, A : n}", "1:25", "role A sends a message to itself"),
    ("local L = &{?A(m), ?C(n), ?C(n)}", "1:30", "duplicate label 'n' for C in one choice"),
])
def test_rejected_forms(text: str, where: str, message: str) -> None:
    assert error_of(text) == (where, message)


def test_the_same_label_to_two_receivers_is_two_branches() -> None:
    assert projections("global G = A -> {B : go. B -> C : ok, C : go. C -> B : ok}") == {
        "A": "+{!B(go), !C(go)}",
        "B": "&{?A(go).!C(ok), ?C(ok)}",
        "C": "&{?B(ok), ?A(go).!B(ok)}",
    }


def test_syntax_errors_in_a_routed_choice() -> None:
    with pytest.raises(sessiontypes.ProtocolSyntaxError) as caught:
        load("global G = A -> {B : m, C}")
    assert "expected ':'" in str(caught.value)
    with pytest.raises(sessiontypes.ProtocolSyntaxError):
        load("local L = +{!B(m), C}")


# ---- projection ----------------------------------------------------------------------

def test_projections_of_the_scribble_example() -> None:
    text = "global G = A -> {B : m1(int). B -> C : done, C : m2. C -> B : x(str)}"
    assert projections(text) == {
        "A": "+{!B(m1(int)), !C(m2)}",
        "B": "&{?A(m1(int)).!C(done), ?C(x(str))}",
        "C": "&{?B(done), ?A(m2).!B(x(str))}",
    }


def test_an_ordinary_choice_learnt_from_different_peers() -> None:
    # C hears from B in one branch and from A in the other; nothing can overtake either.
    assert projections("global G = A -> B : {l1. B -> C : x, l2. A -> C : y}")["C"] == "&{?B(x), ?A(y)}"


def test_a_role_told_in_every_branch_by_the_same_peer_merges_as_before() -> None:
    text = "global G = A -> {B : m1. B -> D : go. B -> C : done, C : m2. C -> B : x. B -> D : stop}"
    assert projections(text)["D"] == "&B{go, stop}"


def test_a_loop_and_nested_routed_choices() -> None:
    module = sessiontypes.load("tests/sessiontypes/corpus/good/routed_choice.proto")
    poll = {r: str(t) for r, t in module.globals["Poll"].projections().items()}
    assert poll == {"A": "mu t.+{!B(ping).?B(pong).!C(again).t, !C(stop)}",
                    "B": "mu t.&{?A(ping).!A(pong).t, ?C(stop)}",
                    "C": "mu t.&A{again.t, stop.!B(stop)}"}
    lookup = {r: str(t) for r, t in module.globals["Lookup"].projections().items()}
    assert lookup["Client"] == ("+{!Cache(lookup(str)).&{?Cache(hit(str)).!Server(done), ?Server(page(str))}, "
                                "!Server(fetch(str)).?Server(page(str))}")
    assert lookup["Server"] == ("&{?Client(done), ?Cache(miss(str)).!Client(page(str)), "
                                "?Client(fetch(str)).!Client(page(str)).!Cache(store(str))}")


def test_a_role_that_never_learns_the_branch_is_named() -> None:
    where, message = error_of("global G = A -> {B : m1. B -> C : x, C : m2}")
    assert where == "1:12"
    assert message.startswith("global G is not projectable onto role B: branches 'B:m1' and 'C:m2'")
    assert "(a receive cannot merge with end): ?A(m1).!C(x) versus end" in message


def test_a_race_is_rejected_naming_the_role_the_peers_and_the_messages() -> None:
    text = "global G = A -> {B : m1. A -> C : go. C -> B : y, C : m2. C -> B : x}"
    where, message = error_of(text)
    assert where == "1:39"  # at the interaction that may overtake
    assert message == ("global G is not projectable onto role B: B learns a choice from whichever message "
                       "arrives first from A or C, but in the branch that ?A(m1) (at 1:22) decides, C may "
                       "send y here before m1 has reached B, so B could take y first")


def test_a_race_through_a_loop_is_rejected() -> None:
    # After m1 A tells C to go round again, and C's next stop may overtake m1.
    where, message = error_of("global G = mu t. A -> {B : m1. A -> C : again. t, C : stop. C -> B : stop}")
    assert where == "1:61"
    assert "role B" in message and "C may send stop here before m1 has reached B" in message


def test_a_message_sent_after_the_deciding_one_was_received_is_no_race() -> None:
    # C's later message to B waits for B's ack (B -> C) after m1: it cannot overtake m1.
    text = "global G = A -> {B : m1. B -> C : ack. C -> B : more, C : m2. C -> B : x}"
    assert projections(text)["B"] == "&{?A(m1).!C(ack).?C(more), ?C(x)}"


# ---- merge, equivalence, state machines ------------------------------------------------

def test_merge_of_choices_among_peers_pair_by_pair() -> None:
    # A makes the same choice in both branches of X's, in another order, and learns X's afterwards.
    text = ("global G = X -> Y : {"
            " l1. A -> {B : m1. B -> C : no. Y -> A : l1, C : m2. C -> B : no. Y -> A : l1},"
            " l2. A -> {C : m2. C -> B : no. Y -> A : l2, B : m1. B -> C : no. Y -> A : l2}}")
    result = projections(text)
    assert result["A"] == "+{!B(m1).&Y{l1, l2}, !C(m2).&Y{l1, l2}}"
    assert result["B"] == "&{?A(m1).!C(no), ?C(no)}"
    with pytest.raises(ProtocolCheckError, match="one sends to B and C, the other to B"):
        load("global G = X -> Y : {"
             " l1. A -> {B : m1. B -> C : no. Y -> A : l1, C : m2. C -> B : no. Y -> A : l1},"
             " l2. A -> B : m1. B -> C : no. Y -> A : l2}")


def test_equivalence_ignores_the_order_of_branches() -> None:
    m = Interaction("m")
    n = Interaction("n")
    left = lt.OfferAmong((lt.Recv("A", m, lt.End()), lt.Recv("C", n, lt.End())))
    right = lt.OfferAmong((lt.Recv("C", n, lt.End()), lt.Recv("A", m, lt.End())))
    assert equivalent(left, right)
    assert not equivalent(left, lt.OfferAmong((lt.Recv("C", m, lt.End()), lt.Recv("A", m, lt.End()))))


def test_state_machines_key_transitions_by_peer() -> None:
    global_type = load("global G = A -> {B : m1(int). B -> C : done, C : m2. C -> B : x(str)}").globals["G"]
    a, b = global_type.project("A").fsm(), global_type.project("B").fsm()
    assert sorted(a.table[a.initial]) == [("send", "B", "m1"), ("send", "C", "m2")]
    assert sorted(b.table[b.initial]) == [("recv", "A", "m1"), ("recv", "C", "x")]
    assert b.peers_at(b.initial, "recv") == ["A", "C"]
    assert b.waits_on_several() and not a.waits_on_several()
    assert global_type.project("C").fsm().waits_on_several()  # from B (done) or A (m2)
