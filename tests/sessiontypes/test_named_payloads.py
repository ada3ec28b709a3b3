"""Messages with named payloads, ``quote(price: int, date: str)`` (docs/language.md, 4.6)."""

from __future__ import annotations

import pytest

import sessiontypes
from sessiontypes import Location, ProtocolCheckError, ProtocolError
from sessiontypes import global_types as g
from sessiontypes.printer import print_global, print_message
from sessiontypes.sorts import Field, Interaction, builtin_sort, record_sort


def message_of(text: str) -> Interaction:
    body = sessiontypes.loads(text, "q.proto").globals["P"].body
    assert isinstance(body, g.Choice)
    return body.branches[0].message


def test_a_message_carries_a_record_of_named_fields() -> None:
    message = message_of('type Twist = "m:Twist"\nglobal P = A -> B : quote(price: Int, when: Twist)')
    assert message.label == "quote"
    assert message.sort is not None and message.sort.fields is not None
    assert [(f.name, f.sort.key, f.sort.spelling, f.sort.target) for f in message.sort.fields] == [
        ("price", "int", "Int", None), ("when", "Twist", "Twist", "m:Twist")]
    assert (message.sort.key, message.sort.spelling) == ("price: int, when: Twist", "price: Int, when: Twist")
    assert message.sort.is_record and not message.sort.is_builtin
    assert message.sort.components() == (builtin_sort("int"), message.sort.fields[1].sort)


def test_records_are_equal_when_names_order_and_sorts_are() -> None:
    def sort(*fields: tuple[str, str]) -> object:
        return record_sort(tuple(Field(name, builtin_sort(spelling)) for name, spelling in fields))

    assert sort(("a", "int"), ("b", "str")) == sort(("a", "Int"), ("b", "String"))
    assert sort(("a", "int"), ("b", "str")) != sort(("b", "str"), ("a", "int"))
    assert sort(("a", "int")) != sort(("b", "int"))
    assert sort(("a", "int")) != builtin_sort("int")
    assert message_of("global P = A -> B : q(a: int)") != message_of("global P = A -> B : q(int)")


@pytest.mark.parametrize("text", [
    "A -> B : quote(price: int, date: str)",
    "A -> B : quote(x': nat).B -> A : {ok(int: int, y: bytes), no(bool)}",
    "A -> B, C : q(a: float)",
])
def test_print_then_parse_gives_the_same_type(text: str) -> None:
    global_type = sessiontypes.loads(f"global P = {text}").globals["P"]
    printed = print_global(global_type.body)
    assert sessiontypes.loads(f"global P = {printed}").globals["P"].body == global_type.body
    for role in global_type.roles:
        local = str(global_type.project(role))
        assert str(sessiontypes.loads(f"local L at {role} = {local}").locals["L"]) == local


def test_the_canonical_print() -> None:
    message = message_of("global P = A -> B : quote( price :Int ,date:str )")
    assert print_message(message) == "quote(price: Int, date: str)"
    global_type = sessiontypes.loads("global P = A -> B : quote(price: Int, date: str). B -> A : ok").globals["P"]
    assert {r: str(global_type.project(r)) for r in global_type.roles} == {
        "A": "!B(quote(price: Int, date: str)).?B(ok)",
        "B": "?A(quote(price: Int, date: str)).!A(ok)",
    }


def test_local_types_write_named_payloads() -> None:
    local = sessiontypes.loads("local L at B = ?A(quote(price: int)).&A{ok(n: nat), no}").locals["L"]
    transitions = local.fsm().all_transitions()
    assert [(t.label, t.sort.spelling if t.sort else None) for t in transitions] == [
        ("quote", "price: int"), ("ok", "n: nat"), ("no", None)]
    assert str(transitions[0]) == "?A(quote(price: int))"


@pytest.mark.parametrize(("text", "error"), [
    ("global P = A -> B : q(a: int, a: str)",
     "q.proto:1:31: error: duplicate field 'a' in message 'q'"),
    ("global P = A -> B : q(a: Twist)",
     ("q.proto:1:26: error: unknown sort 'Twist'; expected a builtin sort (int, nat, bool, str, float, bytes) "
     "or a declared type")),
    ("global P = A -> B : q(a: int,)", "q.proto:1:30: error: syntax error; expected a name, got ')'"),
    ("global P = A -> B : q(a int)", ("q.proto:1:25: error: syntax error; expected one of ')', ':', '{', got 'int' "
      "(a named payload is written 'name: Sort')")),
    ("global P = C -> A : {l1. A -> B : q(a: int), l2. A -> B : q(b: int)}",
     ("q.proto:1:12: error: global P is not projectable onto role B: branches 'l1' and 'l2' give B different "
     "behaviours that do not merge (label 'q' carries a: int in one and b: int in the other): "
     "?A(q(a: int)) versus ?A(q(b: int))")),
])
def test_what_is_rejected(text: str, error: str) -> None:
    with pytest.raises(ProtocolError) as info:
        sessiontypes.loads(text, "q.proto")
    assert str(info.value).splitlines()[0] == error


def test_a_duplicate_field_is_located_at_the_second_one() -> None:
    with pytest.raises(ProtocolCheckError) as info:
        sessiontypes.loads("global P =\n  A -> B : q(a: int,\n            a: str)", "q.proto")
    assert [d.location for d in info.value.errors] == [Location("q.proto", 3, 13)]
