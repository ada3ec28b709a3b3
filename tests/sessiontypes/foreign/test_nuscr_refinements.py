"""nuScr's refinements read into the language's constraints (issue 29, item 6).

The samples follow nuScr's own (github.com/nuscr/nuscr, commit ba4c7b2):
examples/refinements/Test1.nuscr, test/cram-tests/refinements/calculator.t/Calculator.nuscr,
strlen.t/PasswordManager.nuscr, state-var-higher-lower.t/HigherLower.nuscr (the 'unit'
guards), examples/annot/TwoBuyer.nuscr and Fib.nuscr (the '@"..."' annotations), and
lib/utils/pragma.ml (the pragmas). The front end's resolution of these fields is another
branch's; here the translated syntax is what is checked.
"""

from __future__ import annotations

import pytest

from sessiontypes import syntax as s
from sessiontypes.constraints import Binary, Call, Compare, Expr, Number, Path, Text, Truth, Unary
from sessiontypes.errors import ProtocolCheckError, ProtocolSyntaxError
from sessiontypes.foreign import UnsupportedConstructError, parse_foreign
from sessiontypes.location import Location
from sessiontypes.refine import print_expr

PRAGMA = "(*# RefinementTypes #*)\n"


def messages(text: str) -> list[s.MessageSyntax]:
    """The messages of the file's first global, in order (single-branch interactions)."""
    source = parse_foreign(text, "p.nuscr", "nuscr")
    body = next(d for d in source.declarations if isinstance(d, s.GlobalDecl)).body
    found = []
    while isinstance(body, s.GInteraction):
        found.append(body.branches[0].message)
        body = body.branches[0].continuation or s.GEnd()
    return found


def at(line: int, column: int) -> Location:
    return Location("p.nuscr", line, column)


def test_a_refined_payload_is_a_field_with_its_refinement() -> None:
    text = PRAGMA + ("protocol Refined(role A, role B) {\n"
                     "  Positive(x: int{x>0}) from A to B;\n"
                     "  Twice(y: int{y=x+x}) from B to A;\n"
                     "}\n")
    positive, twice = messages(text)
    assert positive.fields == (s.FieldSyntax(s.Name("x"), s.Name("int"), Compare((">",), (Path(("x",)), Number(0)))),)
    assert twice.fields is not None
    refinement = twice.fields[0].refinement
    assert refinement == Compare(("==",), (Path(("y",)), Binary("+", Path(("x",)), Path(("x",)))))
    assert refinement.location == at(4, 16)  # the expression's first token, in the nuScr file
    assert isinstance(refinement, Compare) and refinement.operands[1].location == at(4, 18)


def test_under_the_pragma_a_named_payload_is_a_field_for_later_refinements_to_name() -> None:
    text = PRAGMA + ("global protocol Calc(role S, role C) {\n"
                     "  Add(x: int) from C to S;\n  Add(y: int) from C to S;\n"
                     "  Sum(z: int{z = x + y}) from S to C;\n}\n")
    add_x, add_y, total = messages(text)
    assert add_x.fields == (s.FieldSyntax(s.Name("x"), s.Name("int")),)
    assert add_y.fields == (s.FieldSyntax(s.Name("y"), s.Name("int")),)
    assert total.fields is not None and print_expr(total.fields[0].refinement) == "z == x + y"  # type: ignore[arg-type]


def test_without_refinements_a_named_payload_stays_a_plain_sort() -> None:
    (message,) = messages("global protocol P(role A, role B) { m(x: int) from A to B; }")
    assert (message.sort, message.fields) == (s.Name("int"), None)


@pytest.mark.parametrize(("nuscr", "printed"), [
    ("a = 1 && b <> 2", "a == 1 and b != 2"),
    ("a || b && c", "(a or b) and c"),               # one level, to the left
    ("-x + 1 > 0", "-(x + 1 > 0)"),                  # '-' takes a whole expression
    ("not x = 1 && y", "not (x == 1 and y)"),
    ("a < b < c", "(a < b) < c"),                     # nested, not chained
    ("len(s) >= 6 && s <> \"password\"", 'len(s) >= 6 and s != "password"'),
    ("x - (y - 1) >= 0 || true = false", "x - (y - 1) >= 0 or true == false"),
])
def test_nuscr_expressions_keep_nuscrs_precedence(nuscr: str, printed: str) -> None:
    (message,) = messages(PRAGMA + f"global protocol P(role A, role B) {{ m(v: int{{{nuscr}}}) from A to B; }}")
    assert message.fields is not None
    refinement = message.fields[0].refinement
    assert refinement is not None and print_expr(refinement) == printed


def test_the_tree_of_each_operator() -> None:
    (message,) = messages(PRAGMA + 'global protocol P(role A, role B) { m(v: int{not len("ab") = (-v)}) from A to B; }')
    assert message.fields is not None
    expected: Expr = Unary("not", Compare(("==",), (Call("len", (Text("ab"),)), Unary("-", Path(("v",))))))
    assert message.fields[0].refinement == expected
    assert Truth(True) != expected  # locations aside, the structure is what is compared


def test_a_refinement_without_the_pragma_is_refused_as_nuscr_refuses_it() -> None:
    with pytest.raises(ProtocolCheckError) as caught:
        parse_foreign("global protocol P(role A, role B) {\n  m(x: int{x > 0}) from A to B;\n}\n", "p.nuscr", "nuscr")
    assert str(caught.value) == (
        "p.nuscr:2:5: error: a refinement type ('x: T{...}') needs the pragma (*# RefinementTypes #*) first in "
        "the file, as nuScr asks\n"
        "      m(x: int{x > 0}) from A to B;\n"
        "        ^")


def test_pragmas_are_nuscrs() -> None:
    text = ("(*# RefinementTypes, SenderValidateRefinements, ReceiverValidateRefinements #*)\n"
            "global protocol P(role A, role B) { m(x: int{x > 0}) from A to B; }\n")
    assert len(messages(text)) == 1
    with pytest.raises(ProtocolCheckError) as caught:
        parse_foreign("(*# RefinementTypes, Refinements #*)\nglobal protocol P(role A, role B) { m() from A to B; }\n",
                      "p.nuscr", "nuscr")
    assert str(caught.value).splitlines()[0] == (
        "p.nuscr:1:22: error: unknown pragma 'Refinements'; expected one of nuScr's: NestedProtocols, PrintUsage, "
        "ReceiverValidateRefinements, RefinementTypes, SenderValidateRefinements, ShowPragmas, "
        "ValidateRefinementProgress, ValidateRefinementSatisfiability")


def test_a_syntax_error_in_a_refinement_is_located_inside_it() -> None:
    with pytest.raises(ProtocolSyntaxError) as caught:
        parse_foreign(PRAGMA + "global protocol P(role A, role B) {\n  m(x: int{x * 2 > 0}) from A to B;\n}\n",
                      "p.nuscr", "nuscr")
    error = caught.value
    assert error.location == at(3, 14)
    assert error.got == "character '*'"


def test_an_annotation_is_a_predicate_on_its_message() -> None:
    text = ("global protocol TwoBuyer(role A, role B, role S) {\n"
            "  quote(y: int) from S to B;\n"
            "  ok(int) from B to S; @\"y > 2\"\n"
            "  pay(amount: int, when: string) from B to S; @\"amount <= y\"\n"
            "}\n")
    quote, ok, pay = messages(text)
    assert quote.fields == (s.FieldSyntax(s.Name("y"), s.Name("int")),)  # an annotation turns fields on
    assert (ok.sort, ok.refinement) == (s.Name("int"), Compare((">",), (Path(("y",)), Number(2))))
    assert ok.refinement is not None and ok.refinement.location == at(3, 26)
    # On a record, the message's predicate joins the last field's refinement (checked together).
    assert pay.fields is not None and pay.fields[1].refinement == Compare(("<=",), (Path(("amount",)), Path(("y",))))


def test_a_unit_payloads_refinement_joins_the_messages() -> None:
    text = PRAGMA + ("global protocol P(role B, role C) {\n  guess(x: int) from C to B;\n"
                     "  higher(n: int, ignore: unit{n > x}) from B to C;\n}\n")
    _guess, higher = messages(text)
    assert higher.fields == (s.FieldSyntax(s.Name("n"), s.Name("int"), Compare((">",), (Path(("n",)), Path(("x",))))),)


def test_a_refinement_of_no_payload_is_refused_where_it_is() -> None:
    text = PRAGMA + ("global protocol P(role B, role C) {\n  guess(x: int) from C to B;\n"
                     "  win(ignore: unit{x = 3}) from B to C;\n}\n")
    with pytest.raises(UnsupportedConstructError) as caught:
        parse_foreign(text, "p.nuscr", "nuscr")
    assert caught.value.location == at(4, 20)
    assert caught.value.message == ("a refinement of a message without a payload is not supported (the language "
                                    "refines payloads: give the message a payload for it to constrain)")


def test_an_annotation_that_is_no_predicate_is_refused_naming_it() -> None:
    text = "global protocol P(role A, role B) {\n  m(x: int) from A to B; @\"x: int\"\n}\n"
    with pytest.raises(UnsupportedConstructError) as caught:
        parse_foreign(text, "p.nuscr", "nuscr")
    assert caught.value.location == at(2, 27)  # its string
    assert caught.value.message == (
        "an annotation that is not a refinement predicate ('@\"...\"') is not supported (syntax error; expected "
        "one of '&&', ')', '+', '-', '||', a comparison, got character ':'; it is read as nuScr's refinement "
        "expressions)")


@pytest.mark.parametrize(("text", "path", "column", "construct"), [
    (PRAGMA + "global protocol P(role A, role B) { rec X [n<A>: int = 0] { m() from A to B; continue X [n]; } }",
     "p.nuscr", 43, "recursion with state variables ('rec X [...]')"),
    (PRAGMA + "global protocol P(role A, role B) @\"A>0\" { m() from A to B; }", "p.nuscr", 35,
     "an annotation ('@\"...\"')"),
])
def test_what_is_outside_the_subset_is_named_where_it_is(text: str, path: str, column: int, construct: str) -> None:
    with pytest.raises(UnsupportedConstructError) as caught:
        parse_foreign(text, path, path.rsplit(".", 1)[1] if path.endswith("nuscr") else "scribble")
    assert (caught.value.location.line, caught.value.location.column) == (2 if PRAGMA in text else 1, column)
    assert caught.value.construct == construct
