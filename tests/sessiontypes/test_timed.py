"""Time clauses and refinements in the language (docs/language.md, "Time and value constraints"):
syntax, contextual keywords, the terms they build, print, projection, merge, local-type text,
state machines, and each well-formedness rule with an accepted and a rejected example."""

from __future__ import annotations

import pytest

import sessiontypes
from sessiontypes import ProtocolError
from sessiontypes import global_types as g
from sessiontypes import local_types as lt
from sessiontypes.constraints import Binary, Call, Compare, Number, Path, Text, Timing, Truth, Unary
from sessiontypes.merge import MergeError, merge
from sessiontypes.parse import parse_expression
from sessiontypes.printer import print_global
from sessiontypes.refine import print_expr
from sessiontypes.sorts import Field, Interaction, builtin_sort, record_sort

TYPES = 'type Twist = "m:Twist"\ntype Pose = "m:Pose"\n'
MS = 1_000_000


def _global(body: str, name: str = "G") -> sessiontypes.GlobalType:
    return sessiontypes.loads(f"{TYPES}global {name} = {body}\n", "t.proto").globals[name]


def _error(text: str) -> str:
    with pytest.raises(ProtocolError) as caught:
        sessiontypes.loads(text, "t.proto")
    return str(caught.value)


# ---- syntax into terms -------------------------------------------------------------------

def test_time_clauses_build_timings_in_nanoseconds() -> None:
    body = _global("mu t. Control -> Move : Twist every 20ms +- 2ms. "
                   "VisOdom -> Move : Pose within 100ms else timeout. t").body
    assert isinstance(body, g.Rec) and isinstance(body.body, g.Choice)
    assert body.body.timing == Timing(every=20 * MS, jitter=2 * MS)
    odometry = body.body.branches[0].continuation
    assert isinstance(odometry, g.Choice)
    assert odometry.timing == Timing(within=100 * MS, on_expiry=True)


@pytest.mark.parametrize(("written", "nanos"), [
    ("100ms", 100 * MS), ("1.5s", 1_500 * MS), ("250us", 250_000), ("250µs", 250_000),
    ("250μs", 250_000), ("7ns", 7), ("0.001s", MS), ("2s", 2_000 * MS),
])
def test_durations_are_exact(written: str, nanos: int) -> None:
    body = _global(f"A -> B : m within {written}").body
    assert isinstance(body, g.Choice) and body.timing == Timing(within=nanos)


def test_time_clause_parts_in_any_order_and_plus_minus_sign() -> None:
    one = _global("mu t. A -> B : m else timeout within 5ms every 20ms ± 1ms. t").body
    two = _global("mu t. A -> B : m every 20ms +- 1ms within 5ms else timeout. t").body
    assert one == two
    assert print_global(one) == "mu t.A->B:m every 20ms +- 1ms within 5ms else timeout.t"


def test_choice_clause_after_the_brace_holds_for_all_branches() -> None:
    body = _global("A -> B : { ok. end, fail. end } within 50ms").body
    assert isinstance(body, g.Choice) and body.timing == Timing(within=50 * MS)
    assert print_global(body) == "A->B:{ok, fail} within 50ms"


def test_multicast_clause_goes_to_each_send() -> None:
    body = _global("A -> B, C : m within 5ms").body
    assert isinstance(body, g.Choice) and body.timing == Timing(within=5 * MS)
    second = body.branches[0].continuation
    assert isinstance(second, g.Choice) and second.receiver == "C" and second.timing == body.timing


def test_time_words_stay_names_elsewhere() -> None:
    """``within``, ``every``, ``else``, ``timeout`` (and the words of refinements) are keywords
    only where a time clause or an expression can stand: protocols using them as names parse."""
    module = sessiontypes.loads(
        "global G = within -> every : timeout. else -> timeout : else(int). "
        "every -> within : {and. end, or. end, not. end, true. end, false. end}\n"
        "local L at within = !every(timeout).?every(within(int)).end\n"
        "global H = mu timeout. within -> else : every(within: int, timeout: str). timeout\n")
    assert module.globals["G"].roles == ("within", "every", "else", "timeout")
    assert str(module.locals["L"]) == "!every(timeout).?every(within(int))"
    choice = module.globals["H"].body
    assert isinstance(choice, g.Rec) and choice.var == "timeout"
    # and a label named like a time word, followed by a time clause
    assert print_global(_global("A -> B : within within 5ms").body) == "A->B:within within 5ms"


def test_refinements_on_sorts_fields_and_payloads() -> None:
    body = _global("Control -> Move : Twist{abs(linear.x) <= 1.5 and abs(angular.z) <= 2.0}. "
                   "Buyer -> Seller : quote(price: int{price > 0}, date: str). "
                   "A -> B : reading(Pose{0 <= data <= 1})").body
    assert isinstance(body, g.Choice)
    twist = body.branches[0].message
    assert twist.refinement == Binary(
        "and", Compare(("<=",), (Call("abs", (Path(("linear", "x")),)), Number(1.5))),
        Compare(("<=",), (Call("abs", (Path(("angular", "z")),)), Number(2.0))))
    quote = body.branches[0].continuation
    assert isinstance(quote, g.Choice)
    sort = quote.branches[0].message.sort
    assert sort is not None and sort.fields is not None
    assert sort.fields[0].refinement == Compare((">",), (Path(("price",)), Number(0)))
    assert sort.fields[1].refinement is None
    assert print_global(body) == ("Control->Move:Twist{abs(linear.x) <= 1.5 and abs(angular.z) <= 2.0}."
                                  "Buyer->Seller:quote(price: int{price > 0}, date: str)."
                                  "A->B:reading(Pose{0 <= data <= 1})")


def test_a_refined_field_is_another_record() -> None:
    refined = _global("A -> B : m(x: int{x > 0})").body
    plain = _global("A -> B : m(x: int)").body
    assert refined != plain


@pytest.mark.parametrize(("text", "tree"), [
    ("a or b and not c", Binary("or", Path(("a",)), Binary("and", Path(("b",)), Unary("not", Path(("c",)))))),
    ("0 <= p <= 1", Compare(("<=", "<="), (Number(0), Path(("p",)), Number(1)))),
    ("a - b - c", Binary("-", Binary("-", Path(("a",)), Path(("b",))), Path(("c",)))),
    ("a - (b - c)", Binary("-", Path(("a",)), Binary("-", Path(("b",)), Path(("c",))))),
    ("-x * 2 % 3 + 1", Binary("+", Binary("%", Binary("*", Unary("-", Path(("x",))), Number(2)), Number(3)),
                               Number(1))),
    ('len(name) > 0 and kind == "rgb8"',
     Binary("and", Compare((">",), (Call("len", (Path(("name",)),)), Number(0))),
            Compare(("==",), (Path(("kind",)), Text("rgb8"))))),
    ("min(a, b, 3) < max(1e-3, 2.5)",
     Compare(("<",), (Call("min", (Path(("a",)), Path(("b",)), Number(3))), Call("max", (Number(1e-3), Number(2.5)))))),
    ("ok == true != false", Compare(("==", "!="), (Path(("ok",)), Truth(True), Truth(False)))),
    ("a +-b", Binary("+", Path(("a",)), Unary("-", Path(("b",))))),
    ("not (a or b)", Unary("not", Binary("or", Path(("a",)), Path(("b",))))),
])
def test_parse_expression_precedence_as_python(text: str, tree: object) -> None:
    parsed = parse_expression(text)
    assert parsed == tree
    assert parse_expression(print_expr(parsed)) == parsed


def test_parse_expression_errors_are_located() -> None:
    with pytest.raises(ProtocolError) as caught:
        parse_expression("x > ", "e.txt")
    assert str(caught.value).startswith("e.txt:1:5: error: syntax error; expected one of")


# ---- projection, merge, local text, state machines -----------------------------------

PIPELINE = ("mu t. Control -> Move : Twist{abs(linear.x) <= 1.5} every 20ms +- 2ms. "
            "VisOdom -> Move : Pose within 100ms else timeout. "
            "Move -> Control : { ok. Move -> VisOdom : go. t, fail(x: int{x > 0}). Move -> VisOdom : stop. end }"
            " within 50ms")


def test_projection_keeps_timing_for_the_two_parties_only() -> None:
    global_type = _global(PIPELINE)
    assert str(global_type.project("Control")) == (
        "mu t.!Move(Twist{abs(linear.x) <= 1.5}) every 20ms +- 2ms.&Move{ok.t, fail(x: int{x > 0})} within 50ms")
    assert str(global_type.project("Move")) == (
        "mu t.?Control(Twist{abs(linear.x) <= 1.5}) every 20ms +- 2ms.?VisOdom(Pose) within 100ms else timeout."
        "+Control{ok.!VisOdom(go).t, fail(x: int{x > 0}).!VisOdom(stop)} within 50ms")
    assert str(global_type.project("VisOdom")) == "mu t.!Move(Pose) within 100ms else timeout.&Move{go.t, stop}"


def test_local_text_round_trips() -> None:
    global_type = _global(PIPELINE)
    for role in global_type.roles:
        projected = global_type.project(role)
        parsed = sessiontypes.loads(f"{TYPES}local L at {role} = {projected}").locals["L"]
        assert parsed.body == projected.body
        assert str(parsed) == str(projected)


def test_local_text_binary_and_among_forms_take_time_clauses() -> None:
    module = sessiontypes.loads("local L = !int within 5ms.?str every 1s\n"
                                "local M at A = &{?B(x) within 5ms.end, ?C(y) within 7ms}\n")
    assert str(module.locals["L"]) == "!int within 5ms.?str every 1s"
    among = module.locals["M"].body
    assert isinstance(among, lt.OfferAmong)
    assert [b.timing for b in among.branches] == [Timing(within=5 * MS), Timing(within=7 * MS)]
    assert str(module.locals["M"]) == "&{?B(x) within 5ms, ?C(y) within 7ms}"


def test_local_choice_with_one_peer_has_one_clause() -> None:
    message = _error("local M at A = &{?B(x) within 5ms, ?B(y) within 7ms}\n")
    assert message == ("t.proto:1:16: error: the branches with one peer have different time clauses; "
                       "they are one interaction, which has one\n"
                       "    local M at A = &{?B(x) within 5ms, ?B(y) within 7ms}\n"
                       "                   ^")


def test_merge_compares_timings() -> None:
    timed = lt.Send("B", Interaction("x"), lt.End(), timing=Timing(within=5 * MS))
    untimed = lt.Send("B", Interaction("x"), lt.End())
    assert merge(timed, timed) == timed
    with pytest.raises(MergeError) as caught:
        merge(timed, untimed)
    assert caught.value.reason == "label 'x' has 'within 5ms' in one and no time clause in the other"


def test_merge_compares_refinements() -> None:
    refined = lt.Recv("B", Interaction("x", _global("A -> B : m(Pose)").body.branches[0].message.sort,  # type: ignore[union-attr]
                                       refinement=Compare((">",), (Path(("a",)), Number(1)))), lt.End())
    plain = lt.Recv("B", Interaction("x", refined.message.sort), lt.End())
    choice = lt.Offer("B", (lt.Branch(Interaction("y"), lt.End()), lt.Branch(Interaction("z"), lt.End())))
    with pytest.raises(MergeError):
        merge(lt.Recv("C", Interaction("n"), refined), lt.Recv("C", Interaction("n"), plain))
    assert merge(choice, refined) == lt.Offer("B", (*choice.branches, lt.Branch(refined.message, lt.End())))
    # a field's refinement is part of its record's sort
    positive = record_sort((Field("x", builtin_sort("int"), Compare((">",), (Path(("x",)), Number(0)))),))
    anything = record_sort((Field("x", builtin_sort("int")),))
    assert positive != anything and str(positive) == "x: int{x > 0}"
    with pytest.raises(MergeError) as caught:
        merge(lt.Recv("C", Interaction("n", positive), lt.End()), lt.Recv("C", Interaction("n", anything), lt.End()))
    assert caught.value.reason == "label 'n' carries x: int{x > 0} in one and x: int in the other"


def test_third_party_branches_with_different_timings_do_not_merge() -> None:
    message = _error("global G = A -> B : { l. C -> D : x within 5ms, r. C -> D : x }")
    assert ("different behaviours that do not merge (label 'x' has 'within 5ms' in one and no time clause "
            "in the other)") in message


def test_receives_from_one_peer_with_different_timings_do_not_merge() -> None:
    message = _error("global G = A -> B : { l. B -> C : x within 5ms, r. B -> C : y }")
    assert "(the receives from B have different time clauses)" in message


def test_substitution_and_unfolding_keep_timing() -> None:
    local = _global("mu t. A -> B : m within 5ms. t").project("A").body
    assert isinstance(local, lt.Rec)
    unfolded = sessiontypes.project.unfold(local)
    assert isinstance(unfolded, lt.Send) and unfolded.timing == Timing(within=5 * MS)
    again = unfolded.continuation
    assert isinstance(again, lt.Rec) and isinstance(again.body, lt.Send) and again.body.timing == unfolded.timing


def test_transitions_carry_timing_and_joined_refinement() -> None:
    machine = _global('A -> B : m(x: int{x > 0}, y: str{len(y) < 4}). '
                      'B -> A : {ok(Pose{z == 1}), no} within 3ms').project("A").fsm()
    found = {t.label: t for t in machine.all_transitions()}
    assert found["m"].timing is None
    assert found["m"].refinement is not None and print_expr(found["m"].refinement) == "x > 0 and len(y) < 4"
    assert found["ok"].timing == Timing(within=3 * MS) and found["no"].timing == Timing(within=3 * MS)
    assert found["ok"].refinement is not None and print_expr(found["ok"].refinement) == "z == 1"
    assert found["no"].refinement is None
    exported = machine.to_dict()["states"]
    ok = next(t for s in exported for t in s["transitions"] if t["label"] == "ok")
    assert (ok["timing"], ok["refinement"]) == ("within 3ms", "z == 1")
    plain = next(t for s in exported for t in s["transitions"] if t["label"] == "no")
    assert "refinement" not in plain


# ---- well-formedness: each rule accepted and rejected, exact messages -----------------

def test_duration_more_than_zero() -> None:
    _global("A -> B : m within 1ns")
    assert _error("global G = A -> B : m within 0ms") == (
        "t.proto:1:23: error: 'within 0': a duration must be more than 0\n"
        "    global G = A -> B : m within 0ms\n"
        "                          ^")
    assert _error("global G = mu t. A -> B : m every 0s. t").startswith(
        "t.proto:1:29: error: 'every 0': a duration must be more than 0")


def test_jitter_less_than_period() -> None:
    _global("mu t. A -> B : m every 20ms +- 19ms. t")
    assert _error("global G = mu t. A -> B : m every 20ms +- 20ms. t") == (
        "t.proto:1:40: error: the jitter 20ms must be less than the period 20ms\n"
        "    global G = mu t. A -> B : m every 20ms +- 20ms. t\n"
        "                                           ^")


def test_else_timeout_needs_within() -> None:
    _global("A -> B : m within 5ms else timeout")
    assert _error("global G = A -> B : m else timeout") == (
        "t.proto:1:23: error: 'else timeout' needs a deadline: write 'within D else timeout'\n"
        "    global G = A -> B : m else timeout\n"
        "                          ^")


def test_no_timeout_label_beside_else_timeout() -> None:
    _global("A -> B : {ok. end, timeout. end} within 5ms")
    assert _error("global G = A -> B : {ok. end, timeout. end} within 5ms else timeout") == (
        "t.proto:1:31: error: label 'timeout' in a choice with 'else timeout': the receiver takes a "
        "timeout under that name; rename the label\n"
        "    global G = A -> B : {ok. end, timeout. end} within 5ms else timeout\n"
        "                                  ^")


def test_each_part_at_most_once() -> None:
    assert _error("global G = A -> B : m within 5ms within 6ms") == (
        "t.proto:1:34: error: syntax error; expected each of 'every', 'within' and 'else timeout' at most "
        "once, got 'within' again (a time clause says each part once)\n"
        "    global G = A -> B : m within 5ms within 6ms\n"
        "                                     ^")


def test_durations_are_whole_nanoseconds() -> None:
    _global("A -> B : m within 1.5us")
    assert _error("global G = A -> B : m within 1.5ns") == (
        "t.proto:1:30: error: syntax error; expected a whole number of nanoseconds, got '1.5ns' "
        "(durations are whole nanoseconds)\n"
        "    global G = A -> B : m within 1.5ns\n"
        "                                 ^")


def test_a_period_needs_a_loop() -> None:
    _global("mu t. A -> B : m every 20ms. t")
    _global("A -> B : go. mu t. A -> B : {m. t, stop. end} every 20ms")
    assert _error("global G = A -> B : m every 20ms. mu t. A -> B : n. t") == (
        "t.proto:1:23: error: a period needs a loop: A -> B : m is not in a 'mu' loop that comes back "
        "to it, so 'every' has no second send to time\n"
        "    global G = A -> B : m every 20ms. mu t. A -> B : n. t\n"
        "                          ^")


def test_a_period_needs_a_loop_back_not_just_a_loop() -> None:
    """Inside a loop's body but after the last way back (a branch that ends): no second send."""
    assert _error("global G = mu t. A -> B : {go. t, stop. B -> A : m every 20ms}").startswith(
        "t.proto:1:52: error: a period needs a loop: B -> A : m")


def test_a_period_satisfiable_against_the_deadlines_around_its_loop() -> None:
    _global("mu t. A -> B : m every 20ms +- 2ms within 10ms. B -> A : n within 10ms. t")
    _global("mu t. A -> B : m every 20ms +- 2ms within 10ms. B -> A : n. t")  # n unbounded: no bound
    _global("mu t. A -> B : m every 20ms within 5ms. B -> A : n within 5ms else timeout. A -> C : k. t")
    assert _error("global G = mu t. A -> B : m every 20ms +- 2ms within 10ms. B -> A : n within 5ms. t") == (
        "t.proto:1:29: error: unsatisfiable: the deadlines of A's actions around the loop put its sends of "
        "'m' at most 15ms apart but the period needs at least 18ms (every 20ms +- 2ms within 10ms)\n"
        "    global G = mu t. A -> B : m every 20ms +- 2ms within 10ms. B -> A : n within 5ms. t\n"
        "                                ^")


def test_unsatisfiable_on_the_shortest_cycle() -> None:
    """A second way round the loop that is long enough does not save the short one."""
    assert "at most 6ms apart but the period needs at least 10ms" in _error(
        "global G = mu t. A -> B : m every 10ms within 3ms. "
        "B -> A : {short. t, long. A -> B : k within 20ms. t} within 3ms")


def test_refinement_needs_a_payload() -> None:
    _global("A -> B : Twist{linear.x > 0}")
    assert _error("global G = A -> B : m{x > 1}") == (
        "t.proto:1:23: error: a refinement constrains a payload, and label 'm' carries none (it names no sort)\n"
        "    global G = A -> B : m{x > 1}\n"
        "                          ^")


def test_refinement_functions_and_arity() -> None:
    assert _error("global G = A -> B : m(x: int{foo(x) > 1})") == (
        "t.proto:1:30: error: syntax error; expected one of the functions abs, min, max, len, got 'foo(' "
        "(a refinement calls only these functions)\n"
        "    global G = A -> B : m(x: int{foo(x) > 1})\n"
        "                                 ^")
    assert _error("global G = A -> B : m(x: int{max(x) > 1})").startswith(
        "t.proto:1:30: error: syntax error; expected max of two or more arguments, got max of 1 argument")


def test_no_time_clause_on_a_routed_choice() -> None:
    assert _error("global G = A -> {B: x, C: y} within 5ms").startswith(
        "t.proto:1:30: error: syntax error; expected")


def test_untimed_protocols_are_unchanged() -> None:
    body = _global("mu t. A -> B : {m(int). t, stop}").body
    assert isinstance(body, g.Rec) and isinstance(body.body, g.Choice) and body.body.timing is None
    assert all(t.timing is None and t.refinement is None
               for role in ("A", "B") for t in _global("mu t. A -> B : {m(int). t, stop}").project(role)
               .fsm().all_transitions())


def test_a_duration_needs_its_unit_attached() -> None:
    assert _error("global G = A -> B : m within 5 ms") == (
        "t.proto:1:30: error: syntax error; expected a duration such as 100ms, got '5' (a duration is a number "
        "with its unit right after it: ns, us, ms or s, as in 100ms)\n"
        "    global G = A -> B : m within 5 ms\n"
        "                                 ^")


def test_a_number_too_large_for_a_float_is_refused() -> None:
    """``1e999`` would be infinity, which prints as ``inf``: a name when read back."""
    assert _error("global G = A -> B : m(x: float{x < 1e999})").startswith(
        "t.proto:1:36: error: syntax error; expected a number a float can hold, got '1e999'")
