"""check_refinements: names in scope, types, satisfiability; each rule accepted and rejected, exact messages.

Terms are built with the constructors (the front end's parser is another branch's): a
refinement's nodes carry the locations a parser would give them.
"""

from __future__ import annotations

from sessiontypes.constraints import Binary, Call, Compare, Expr, Number, Path, Text, Truth, Unary
from sessiontypes.global_types import Branch, Choice, End, GlobalTerm, Parallel, Rec, Routed, RoutedBranch, Var
from sessiontypes.location import Location
from sessiontypes.refinecheck import check_refinements
from sessiontypes.sorts import Field, Interaction, Sort, builtin_sort, record_sort

HERE = Location("p.proto", 3, 7)


def at(column: int) -> Location:
    return Location("p.proto", 3, column)


def path(text: str, column: int = 7) -> Path:
    return Path(tuple(text.split(".")), at(column))


def num(value: int | float) -> Number:
    return Number(value, HERE)


def cmp(left: Expr, op: str, right: Expr) -> Compare:
    return Compare((op,), (left, right), HERE)


def both(left: Expr, right: Expr) -> Binary:
    return Binary("and", left, right, HERE)


def record(label: str, *fields: tuple[str, str] | tuple[str, str, Expr], refinement: Expr | None = None) -> Interaction:
    made = tuple(Field(f[0], builtin_sort(f[1]), f[2] if len(f) == 3 else None) for f in fields)  # type: ignore[misc]
    return Interaction(label, record_sort(made), refinement=refinement)


def msg(sender: str, receiver: str, message: Interaction, then: GlobalTerm | None = None) -> Choice:
    return Choice(sender, receiver, (Branch(message, then if then is not None else End()),))


TWIST = Sort("Twist", "Twist", target="ros:geometry_msgs/msg/Twist")


# ---- names: (1) fields of the payload ----------------------------------------------------

def test_a_field_of_the_payload_is_in_scope() -> None:
    term = msg("A", "B", record("quote", ("price", "int", cmp(path("price"), ">", num(0))), ("date", "str")))
    assert check_refinements(term) == []


def test_another_field_of_the_same_payload_is_in_scope() -> None:
    term = msg("A", "B", record("range", ("low", "int"), ("high", "int", cmp(path("low"), "<=", path("high")))))
    assert check_refinements(term) == []


def test_an_unknown_name_is_rejected() -> None:
    term = msg("A", "B", record("quote", ("price", "int", cmp(path("prize", 9), ">", num(0)))))
    assert check_refinements(term) == [
        (at(9), ("refinement names prize: no field of this message is called prize, and neither A nor B saw "
                "one before this interaction"))]


def test_a_builtin_payload_has_no_names() -> None:
    term = msg("A", "B", Interaction("count", builtin_sort("int"), refinement=cmp(path("x", 12), ">", num(0))))
    assert check_refinements(term) == [
        (at(12), ("refinement names x: no field of this message is called x, and neither A nor B saw one before "
                 "this interaction (a payload of the builtin sort int has no names: write a named field, as in "
                 "m(x: int{x > 0}))"))]


# ---- names: (2) earlier record payloads both parties saw ----------------------------------

def ack(then: GlobalTerm | None = None) -> Choice:
    return msg("B", "A", record("ack", ("n", "int", cmp(path("n"), "==", path("seq", 20)))), then)


def test_an_earlier_field_both_parties_saw_is_in_scope() -> None:
    assert check_refinements(msg("A", "B", record("req", ("seq", "int")), ack())) == []


def test_an_earlier_field_one_party_never_saw_is_rejected() -> None:
    term = msg("A", "C", record("req", ("seq", "int")), msg("C", "B", record("go"), ack()))
    assert check_refinements(term) == [
        (at(20), "refinement names seq, which B never saw before this interaction")]


def test_an_earlier_field_seen_on_one_path_only_is_rejected() -> None:
    tail = ack()  # one continuation after both branches, as the front end shares it
    choice = Choice("A", "B", (Branch(record("req", ("seq", "int")), tail),
                               Branch(record("other", ("k", "int")), tail)))
    assert check_refinements(choice) == [
        (at(20), "refinement names seq, which B and A did not both see on every path to this interaction")]


def test_an_earlier_field_seen_on_every_path_is_in_scope() -> None:
    tail = ack()
    choice = Choice("A", "B", (Branch(record("req", ("seq", "int")), tail),
                               Branch(record("retry", ("seq", "int"), ("why", "str")), tail)))
    assert check_refinements(choice) == []


def test_an_earlier_field_of_different_sorts_on_two_paths_is_rejected() -> None:
    tail = ack()
    choice = Choice("A", "B", (Branch(record("req", ("seq", "int")), tail),
                               Branch(record("named", ("seq", "str")), tail)))
    assert check_refinements(choice) == [
        (at(20), "refinement names seq, which is an int on one path to here and a str on another")]


def test_the_latest_value_must_be_the_same_message_for_both() -> None:
    # A sees a newer seq (from C) than the one B saw: each would check a different value.
    term = msg("A", "B", record("req", ("seq", "int")),
               msg("C", "A", record("renumber", ("seq", "int")),
                   msg("A", "B", record("data", ("v", "int", cmp(path("v"), ">", path("seq", 20)))))))
    assert check_refinements(term) == [
        (at(20), "refinement names seq, whose latest value A and B saw in different messages")]


def test_a_loop_keeps_what_was_seen_on_entry_and_each_turn() -> None:
    # mu t. A -> B : req(seq). B -> A : ack(n{n == seq}). t
    loop = Rec("t", msg("A", "B", record("req", ("seq", "int")), ack(Var("t"))))
    assert check_refinements(loop) == []


def test_a_name_first_bound_inside_a_loop_is_not_seen_before_its_first_turn() -> None:
    # mu t. A -> B : { first. B -> A : ack(n{n == seq}). end, next(seq). t }
    loop = Rec("t", Choice("A", "B", (Branch(record("first"), ack()),
                                      Branch(record("next", ("seq", "int")), Var("t")))))
    assert check_refinements(loop) == [
        (at(20), "refinement names seq, which B and A did not both see on every path to this interaction")]


def test_routed_and_parallel_branches_flow_their_own_way() -> None:
    routed = Routed("A", (RoutedBranch("B", record("req", ("seq", "int")), ack()),
                          RoutedBranch("C", record("other"), End())))
    par = Parallel((msg("A", "B", record("req", ("seq", "int")), ack()),
                    msg("C", "D", record("x", ("k", "int")),
                        msg("D", "C", record("y", ("j", "int", cmp(path("j"), "==", path("seq", 20))))))))
    assert check_refinements(routed) == []
    assert check_refinements(par) == [
        (at(20), ("refinement names seq: no field of this message is called seq, and neither D nor C saw one "
                 "before this interaction"))]


# ---- names: (3) attributes of a declared sort --------------------------------------------

def test_an_attribute_of_a_declared_sort_is_accepted() -> None:
    limit = both(cmp(Call("abs", (path("linear.x"),), HERE), "<=", num(1.5)),
                 cmp(Call("abs", (path("angular.z"),), HERE), "<=", num(2.0)))
    assert check_refinements(msg("Control", "Move", Interaction("Twist", TWIST, refinement=limit))) == []


def test_a_field_of_a_builtin_field_is_rejected() -> None:
    term = msg("A", "B", record("quote", ("price", "int", cmp(path("price.cents", 9), ">", num(0)))))
    assert check_refinements(term) == [
        (at(9), "refinement names price.cents, but price is an int, which has no field cents")]


# ---- types ---------------------------------------------------------------------------------

def typed(expr: Expr) -> list[tuple[Location, str]]:
    """The errors of ``expr`` on ``m(x: int, f: float, n: nat, b: bool, s: str, y: bytes)``."""
    fields = (("x", "int"), ("f", "float"), ("n", "nat"), ("b", "bool"), ("s", "str"), ("y", "bytes"))
    return check_refinements(msg("A", "B", record("m", *fields, refinement=expr)))


def test_numbers_mix() -> None:
    assert typed(cmp(Binary("+", path("x"), Binary("*", path("f"), path("n"), HERE), HERE), "<", num(3))) == []
    assert typed(cmp(Binary("/", path("x"), num(2), HERE), "!=", Binary("%", path("n"), num(2), HERE))) == []
    assert typed(cmp(Call("min", (path("x"), path("f"), num(1)), HERE), ">=", Unary("-", path("n"), HERE))) == []


def test_and_takes_bools() -> None:
    assert typed(both(path("b"), cmp(path("x"), ">", num(0)))) == []
    assert typed(both(path("x", 5), path("b"))) == [(at(5), "`and` takes bools, got int (x)")]


def test_or_and_not_take_bools() -> None:
    assert typed(Binary("or", path("b"), Unary("not", path("b"), HERE), HERE)) == []
    assert typed(Binary("or", path("b"), path("s", 4), HERE)) == [(at(4), "`or` takes bools, got str (s)")]
    assert typed(Unary("not", path("f", 4), HERE)) == [(at(4), "`not` takes a bool, got float (f)")]


def test_arithmetic_takes_numbers_and_a_bool_is_none() -> None:
    assert typed(cmp(Binary("+", Truth(True, at(2)), num(1), HERE), ">", num(0))) == [
        (at(2), "`+` takes numbers, got bool (true)")]
    assert typed(cmp(Unary("-", path("s", 3), HERE), "<", num(0))) == [(at(3), "`-` takes a number, got str (s)")]


def test_equality_compares_one_kind() -> None:
    assert typed(both(cmp(path("s"), "==", Text("go", HERE)), cmp(path("b"), "!=", Truth(False, HERE)))) == []
    assert typed(cmp(path("x"), "==", path("s"))) == [
        (HERE, "`==` compares two values of one kind, got int and str (x == s)")]


def test_ordering_takes_numbers_strs_or_bytes() -> None:
    assert typed(both(cmp(path("s"), "<", Text("m", HERE)), cmp(path("y"), ">=", path("y")))) == []
    assert typed(cmp(path("b"), "<", Truth(True, HERE))) == [
        (HERE, "`<` compares two numbers, two strs or two bytes, got bool and bool (b < true)")]
    chained = Compare(("<=", "<"), (num(0), path("x"), path("s")), HERE)
    assert typed(chained) == [(HERE, "`<` compares two numbers, two strs or two bytes, got int and str (x < s)")]


def test_functions_take_their_arguments() -> None:
    assert typed(both(cmp(Call("len", (path("s"),), HERE), ">", num(0)),
                      cmp(Call("abs", (path("f"),), HERE), "<", num(1)))) == []
    assert typed(cmp(Call("len", (path("x", 5),), HERE), ">", num(0))) == [
        (at(5), "`len` takes a str or bytes, got int (x)")]
    assert typed(cmp(Call("abs", (path("x"), path("f")), at(2)), ">", num(0))) == [
        (at(2), "`abs` takes one number, got 2 arguments")]
    assert typed(cmp(Call("max", (path("x"),), at(2)), ">", num(0))) == [
        (at(2), "`max` takes two or more numbers, got 1 argument")]
    assert typed(cmp(Call("max", (path("x"), path("s", 9)), at(2)), ">", num(0))) == [
        (at(9), "`max` takes numbers, got str (s)")]


def test_a_refinement_is_a_bool() -> None:
    assert typed(path("b")) == []
    assert typed(Binary("+", path("x"), num(1), at(2))) == [(at(2), "a refinement is a bool, got int (x + 1)")]


def test_attributes_of_a_declared_sort_are_of_unknown_type() -> None:
    odd = both(path("flag"), cmp(Binary("+", path("name"), num(1), HERE), "==", Text("a", HERE)))
    assert check_refinements(msg("A", "B", Interaction("Twist", TWIST, refinement=odd))) == []


# ---- satisfiability ------------------------------------------------------------------------

def test_disjoint_bounds_are_unsatisfiable() -> None:
    assert typed(both(cmp(path("x"), ">", num(3)), cmp(path("x"), "<", num(5)))) == []
    assert typed(Binary("and", cmp(path("x"), ">", num(5)), Compare(("<",), (path("x"), num(3)), at(20)), HERE)) == [
        (at(20), "unsatisfiable refinement: no value of x has x > 5 and x < 3")]


def test_an_int_takes_whole_values_and_a_float_does_not() -> None:
    assert typed(both(cmp(path("f"), ">", num(5)), cmp(path("f"), "<", num(6)))) == []
    assert typed(both(cmp(path("x"), ">", num(5)), cmp(path("x"), "<", num(6)))) == [
        (HERE, "unsatisfiable refinement: no value of x has x > 5 and x < 6")]


def test_abs_is_never_negative() -> None:
    assert typed(cmp(Call("abs", (path("f"),), HERE), "<=", num(0))) == []
    assert typed(cmp(Call("abs", (path("f"),), HERE), "<=", Unary("-", num(1), HERE))) == [
        (HERE, "unsatisfiable refinement: no value of abs(f) has abs(f) >= 0 and abs(f) <= -1")]


def test_abs_bounds_its_path() -> None:
    assert typed(both(cmp(Call("abs", (path("f"),), HERE), "<=", num(1)), cmp(path("f"), ">", num(2)))) == [
        (HERE, "unsatisfiable refinement: no value of f has f > 2 and abs(f) <= 1")]


def test_a_chain_bounds_both_ways() -> None:
    in_unit = Compare(("<=", "<="), (num(0), path("f"), num(1)), HERE)
    assert typed(in_unit) == []
    assert typed(both(in_unit, cmp(path("f"), ">", num(2)))) == [
        (HERE, "unsatisfiable refinement: no value of f has f > 2 and f <= 1")]


def test_a_nat_is_never_negative() -> None:
    assert typed(cmp(path("x"), "<", num(0))) == []
    assert typed(cmp(path("n"), "<", num(0))) == [
        (HERE, "unsatisfiable refinement: no value of n has n >= 0 (n is a nat) and n < 0")]


def test_an_excluded_point() -> None:
    assert typed(both(cmp(path("x"), ">=", num(3)), cmp(path("x"), "!=", num(3)))) == []
    assert typed(both(cmp(path("x"), "==", num(3)), cmp(path("x"), "!=", num(3)))) == [
        (HERE, "unsatisfiable refinement: no value of x has x == 3 and x != 3")]


def test_a_constant_conjunct_that_is_false() -> None:
    assert typed(both(Truth(True, HERE), cmp(num(1), "<", num(2)))) == []
    assert typed(both(path("b"), cmp(num(2), "<", num(1)))) == [(HERE, "unsatisfiable refinement: 2 < 1 never holds")]


def test_the_fields_refinements_are_one_conjunction() -> None:
    term = msg("A", "B", record("m", ("x", "int", cmp(path("x"), ">", num(5))), ("y", "int"),
                                refinement=cmp(path("x"), "<", num(3))))
    assert check_refinements(term) == [(HERE, "unsatisfiable refinement: no value of x has x > 5 and x < 3")]


def test_a_disjunction_is_taken_as_satisfiable() -> None:
    assert typed(Binary("or", cmp(path("x"), ">", num(5)), cmp(path("x"), "<", num(3)), HERE)) == []


def test_a_term_without_refinements_has_nothing_to_check() -> None:
    assert check_refinements(Rec("t", msg("A", "B", record("m", ("x", "int")), Var("t")))) == []


def test_an_earlier_field_one_party_saw_on_some_paths_only_is_rejected() -> None:
    tail = ack()
    term = msg("A", "C", record("req", ("seq", "int")),
               Choice("A", "B", (Branch(record("x", ("seq", "int")), tail), Branch(record("y"), tail))))
    assert check_refinements(term) == [
        (at(20), "refinement names seq, which B did not see on every path to this interaction")]


def test_a_protocol_beyond_the_scope_checks_bound_gets_a_located_error_not_an_exhausted_memory() -> None:
    # Each message's refinement names the field of the message before it: the dataflow's
    # state grows with the protocol, so its size is bounded (one error, at the first refinement).
    count = 1001
    term: GlobalTerm = End()
    for index in range(count):
        refinement = cmp(path(f"f{index + 1}"), ">", num(0)) if index < count - 1 else None
        term = msg("A", "B", record("m", ("f" + str(index), "int", refinement)) if refinement else
                   record("m", (f"f{index}", "int")), term)
    (error,) = check_refinements(term)
    assert error[1] == ("the refinements name 1000 fields of earlier messages in a protocol of 1001 interactions: "
                        "more than the 500,000 (names times interactions) whose scope is checked")
