"""The text of LANGUAGE.md sections 1-4: every construct parses, and means what it should.

Equality of types ignores locations, so two spellings of one protocol are
compared with ``==`` on the global bodies (or on ``str()`` of projections).
"""

from __future__ import annotations

import pytest

import sessiontypes
from sessiontypes import Location, ProtocolSyntaxError
from sessiontypes import global_types as g
from sessiontypes import local_types as lt
from sessiontypes import syntax as s
from sessiontypes.parse import parse_file
from sessiontypes.sorts import Interaction, Sort


def body(text: str, name: str = "P") -> g.GlobalTerm:
    """The resolved body of global ``name`` in ``text``."""
    return sessiontypes.loads(text).globals[name].body


def local(text: str, name: str = "L") -> sessiontypes.LocalType:
    return sessiontypes.loads(text).locals[name]


def projections(text: str, name: str = "P") -> dict[str, str]:
    global_type = sessiontypes.loads(text).globals[name]
    return {role: str(global_type.project(role)) for role in global_type.roles}


def only_message(term: g.GlobalTerm) -> Interaction:
    assert isinstance(term, g.Choice) and len(term.branches) == 1
    return term.branches[0].message


# ---- 1. lexical rules -----------------------------------------------------------------

def test_names_may_end_in_primes() -> None:
    global_type = sessiontypes.loads("global P' = A' -> A'' : l'(int). A'' -> A' : l''").globals["P'"]
    assert global_type.roles == ("A'", "A''")
    assert str(global_type.project("A'")) == "!A''(l'(int)).?A''(l'')"


def test_names_with_underscores_and_digits() -> None:
    assert projections("global P = _a1 -> B_2 : x_3(int)") == {"_a1": "!B_2(x_3(int))",
                                                              "B_2": "?_a1(x_3(int))"}


def test_comments_and_whitespace_are_insignificant() -> None:
    plain = "global P(A, B) = A -> B : x(int). B -> A : { y. end, z }"
    commented = (
        "// a protocol\n"
        "global /* name */ P /* roles */ ( A , B ) = // body follows\n"
        "\tA\t->  B :\n x /* label */ ( int ) . /* then\n   the answer */\n"
        "  B -> A : {  // a choice\n  y . end ,\n  z  }  // done\n"
    )
    assert body(commented) == body(plain)
    assert projections(commented) == projections(plain)


def test_a_byte_order_mark_is_white_space() -> None:
    # grammar.lark's WS includes U+FEFF; editors on Windows start UTF-8 files with it.
    assert body("\ufeffglobal P = A -> B : x") == body("global P = A -> B : x")
    assert body("global P =\ufeff A -> B : x") == body("global P = A -> B : x")


def test_comment_markers_inside_a_line_comment_are_ignored() -> None:
    assert body("global P = A -> B : x // no /* block here\n") == body("global P = A -> B : x")


@pytest.mark.parametrize(("ascii_text", "unicode_text"), [
    ("global P = A -> B : x", "global P = A → B : x"),
    ("global P = mu t. A -> B : x. t", "global P = μ t. A -> B : x. t"),
    ("global P = mu t. A -> B : x. t", "global P = rec t. A -> B : x. t"),
    ("global P = A -> B : x. end", "global P = A -> B : x. ⊥"),
    ("global P = mu t. A -> B : { x. t, y. end }", "global P = μ t. A → B : { x. t, y. ⊥ }"),
    ("global P = (mu t. A -> B : x. t || C -> D : y. end)",
     "global P = (μ t. A → B : x. t || C → D : y. ⊥)"),
])
def test_unicode_spellings_are_the_same_global_type(ascii_text: str, unicode_text: str) -> None:
    assert body(unicode_text) == body(ascii_text)
    assert projections(unicode_text) == projections(ascii_text)


@pytest.mark.parametrize(("ascii_text", "unicode_text"), [
    ("local L = +B{x. end, y}", "local L = ⊕B{x. ⊥, y}"),
    ("local L = mu t. +{x. !int. t, y}", "local L = μ t. ⊕{x. !int. t, y}"),
    ("local L = mu t. &B{x. t, y}", "local L = rec t. &B{x. t, y}"),
    ("local L = !B(x). end", "local L = !B(x). ⊥"),
])
def test_unicode_spellings_are_the_same_local_type(ascii_text: str, unicode_text: str) -> None:
    assert local(unicode_text).body == local(ascii_text).body
    assert str(local(unicode_text)) == str(local(ascii_text))


KEYWORDS = ["global", "local", "type", "mu", "rec", "end", "at"]
# Places where a name is required; {} is replaced by a keyword.
NAME_PLACES = [
    "global {} = A -> B : x",
    "global P({}, B) = A -> B : x",
    "global P = A -> {} : x",
    "global P = A -> B : {}",
    "global P = A -> B : {}(int)",
    "global P = A -> B : x({})",
    "global P = A -> B : {{ {}: end, y }}",
    "global P = mu {}. A -> B : x",
    "local {} = end",
    "local L at {} = end",
    "local L = !{}(x)",
    "local L = ?B({})",
    "local L = &{}{{x, y}}",
    "type {} = \"m:C\"",
]


@pytest.mark.parametrize("keyword", KEYWORDS)
@pytest.mark.parametrize("template", NAME_PLACES)
def test_a_keyword_is_not_a_name(template: str, keyword: str) -> None:
    text = template.format(keyword)
    with pytest.raises(ProtocolSyntaxError) as caught:
        sessiontypes.loads(text, "k.proto")
    error = caught.value
    assert error.location == Location("k.proto", 1, template.replace("{{", "{").index("{}") + 1)
    assert error.got == f"'{keyword}'"
    assert "a name" in error.expected
    assert error.hint == f"'{keyword}' is a keyword and cannot be a name"


@pytest.mark.parametrize("keyword", ["mu", "rec", "end"])
def test_a_keyword_cannot_be_a_sender(keyword: str) -> None:
    with pytest.raises(ProtocolSyntaxError):
        sessiontypes.loads(f"global P = {keyword} -> B : x")


def test_names_that_only_contain_or_capitalise_keywords_are_names() -> None:
    text = "global P(types, atom, End) = mu rec'. types -> atom : endpoint. atom -> End : Global. rec'"
    assert projections(text) == {
        "types": "mu rec'.!atom(endpoint).rec'",
        "atom": "mu rec'.?types(endpoint).!End(Global).rec'",
        "End": "mu rec'.?atom(Global).rec'",
    }


# ---- 2. a file ------------------------------------------------------------------------

def test_an_empty_file_or_only_comments_is_an_empty_module() -> None:
    for text in ("", "   \n", "// nothing\n/* at all */"):
        module = sessiontypes.loads(text)
        assert (module.globals, module.locals, module.sorts, module.warnings) == ({}, {}, {}, ())


def test_declarations_in_any_order_each_optionally_ended_by_semicolon() -> None:
    text = (
        "global P(A, B) = A -> B : T. Q;\n"
        "global Q(A, B) = B -> A : done\n"
        'type T = "m:T";\n'
        "local L at A = !B(T); local M = ?int\n"
    )
    module = sessiontypes.loads(text)
    assert list(module.globals) == ["P", "Q"]
    assert list(module.locals) == ["L", "M"]
    assert module.sorts == {"T": Sort("T", "T", "m:T")}
    assert str(module.globals["P"].project("A")) == "!B(T).?B(done)"
    assert module.locals["L"].role == "A" and module.locals["M"].role is None


@pytest.mark.parametrize("target", ["tinman.messages:Twist", "m:Outer.Inner", "ros:geometry_msgs/msg/Twist"])
def test_type_declaration_targets(target: str) -> None:
    module = sessiontypes.loads(f'type Twist = "{target}"\nglobal P = A -> B : Twist')
    assert module.sorts["Twist"].target == target
    assert only_message(module.globals["P"].body) == Interaction("Twist", Sort("Twist", "Twist", target))


@pytest.mark.parametrize(("spelling", "key"), [
    ("int", "int"), ("Int", "int"), ("nat", "nat"), ("Nat", "nat"), ("bool", "bool"),
    ("Bool", "bool"), ("str", "str"), ("String", "str"), ("float", "float"),
    ("Float", "float"), ("bytes", "bytes"), ("Bytes", "bytes"),
])
def test_builtin_sorts_need_no_declaration(spelling: str, key: str) -> None:
    message = only_message(body(f"global P = A -> B : v({spelling})"))
    assert message.sort is not None
    assert (message.sort.key, message.sort.spelling, message.sort.is_builtin) == (key, spelling, True)
    assert projections(f"global P = A -> B : v({spelling})")["A"] == f"!B(v({spelling}))"


def test_role_list_fixes_the_role_order() -> None:
    assert sessiontypes.loads("global P(B, C, A) = A -> B : x. B -> C : y").globals["P"].roles == ("B", "C", "A")


def test_without_role_list_roles_are_in_order_of_first_occurrence() -> None:
    text = "global P = A -> B : { l. B -> D : x. B -> C : x, r. B -> C : y. B -> D : y }"
    assert sessiontypes.loads(text).globals["P"].roles == ("A", "B", "D", "C")


def test_equation_style_mutual_recursion() -> None:
    text = "global P = A -> B : ping. Q\nglobal Q = B -> A : pong. P"
    assert projections(text, "P") == {"A": "mu P.!B(ping).?B(pong).P", "B": "mu P.?A(ping).!A(pong).P"}
    assert projections(text, "Q") == {"B": "mu Q.!A(pong).?A(ping).Q", "A": "mu Q.?B(pong).!B(ping).Q"}


def test_a_reference_to_a_declaration_is_not_recursion_when_it_does_not_come_back() -> None:
    text = "global Tail = B -> A : done\nglobal P = A -> B : go. Tail"
    assert projections(text) == {"A": "!B(go).?B(done)", "B": "?A(go).!A(done)"}


# ---- 3. global types ------------------------------------------------------------------

@pytest.mark.parametrize(("short", "long"), [
    ("A -> B : Ping", "A -> B : Ping. end"),
    ("A -> B : { x, y }", "A -> B : { x. end, y. end }"),
    ("A -> B : { x, y, }", "A -> B : { x, y }"),
    ("A -> B : { x }", "A -> B : x"),
    ("(A -> B : x)", "A -> B : x"),
    ("A -> B : x. (B -> A : y)", "A -> B : x. B -> A : y"),
    ("((A -> B : x))", "A -> B : x"),
    ("(end)", "end"),
    ("A -> B : { ok: B -> A : y, err: end }", "A -> B : { ok(). B -> A : y, err() }"),
    ("A -> B : { ok: B -> A : y, err: end }", "A -> B : { ok. B -> A : y, err }"),
    ("mu t. (A -> B : x. t)", "mu t. A -> B : x. t"),
])
def test_equivalent_global_spellings(short: str, long: str) -> None:
    assert body(f"global P = {short}") == body(f"global P = {long}")


def test_interaction_sequence_and_choice_structure() -> None:
    term = body("global P = A -> B : x(int). B -> A : { y(str). end, z }")
    assert term == g.Choice("A", "B", (g.Branch(
        Interaction("x", Sort("int", "int")),
        g.Choice("B", "A", (
            g.Branch(Interaction("y", Sort("str", "str")), g.End()),
            g.Branch(Interaction("z"), g.End()),
        )),
    ),))


def test_recursion_and_variable() -> None:
    term = body("global P = mu t. A -> B : { more. t, stop }")
    assert term == g.Rec("t", g.Choice("A", "B", (
        g.Branch(Interaction("more"), g.Var("t")),
        g.Branch(Interaction("stop"), g.End()),
    )))


def test_nested_recursion_binds_the_nearest_variable() -> None:
    assert projections("global P = mu t. A -> B : x. mu t. B -> A : y. t") == {
        "A": "mu t.!B(x).mu t.?B(y).t",
        "B": "mu t.?A(x).mu t.!A(y).t",
    }


def test_end_alone() -> None:
    module = sessiontypes.loads("global P = end")
    assert module.globals["P"].body == g.End()
    assert module.globals["P"].roles == ()


@pytest.mark.parametrize("parts", [2, 3])
def test_parallel_composition(parts: int) -> None:
    pairs = [("A", "B"), ("C", "D"), ("E", "F")][:parts]
    text = "global P = (" + " || ".join(f"{p} -> {q} : m{i}" for i, (p, q) in enumerate(pairs)) + ")"
    term = body(text)
    assert isinstance(term, g.Parallel)
    assert term.branches == tuple(
        g.Choice(p, q, (g.Branch(Interaction(f"m{i}"), g.End()),)) for i, (p, q) in enumerate(pairs))


def test_parallel_projection_keeps_roles_that_take_part_in_several_branches() -> None:
    text = "global P = (mu c. A -> M : x. c || mu p. B -> M : y. p)"
    assert projections(text) == {
        "A": "mu c.!M(x).c",
        "M": "(mu c.?A(x).c || mu p.?B(y).p)",
        "B": "mu p.!M(y).p",
    }


def test_parallel_inside_a_sequence_and_a_choice() -> None:
    text = "global P = A -> B : { go. (B -> C : x || A -> D : y), stop. B -> C : z. A -> D : z }"
    term = body(text)
    assert isinstance(term, g.Choice)
    assert isinstance(term.branches[0].continuation, g.Parallel)


def test_parallel_needs_parentheses() -> None:
    with pytest.raises(ProtocolSyntaxError):
        sessiontypes.loads("global P = A -> B : x || C -> D : y")


def test_parallel_has_no_continuation() -> None:
    with pytest.raises(ProtocolSyntaxError) as caught:
        sessiontypes.loads("global P = (A -> B : x || C -> D : y). A -> C : z", "p.proto")
    assert caught.value.location == Location("p.proto", 1, 38)
    assert caught.value.got == "'.'"


# ---- abbreviation rule ---------------------------------------------------------------

@pytest.mark.parametrize(("msg", "message"), [
    ("int", Interaction("int", Sort("int", "int"))),
    ("Int", Interaction("Int", Sort("int", "Int"))),
    ("Twist", Interaction("Twist", Sort("Twist", "Twist", "m:Twist"))),
    ("ping", Interaction("ping")),
    ("ping()", Interaction("ping")),
    ("ping(int)", Interaction("ping", Sort("int", "int"))),
    ("ping(Twist)", Interaction("ping", Sort("Twist", "Twist", "m:Twist"))),
    ("int()", Interaction("int")),
    ("Twist()", Interaction("Twist")),
    ("int(Twist)", Interaction("int", Sort("Twist", "Twist", "m:Twist"))),
])
def test_abbreviation_rule(msg: str, message: Interaction) -> None:
    text = f'type Twist = "m:Twist"\nglobal P = A -> B : {msg}. A -> B : done(Twist)'
    assert only_message(body(text)) == message


def test_a_bare_name_is_a_sort_only_where_a_sort_is_declared() -> None:
    with_type = 'type Pose = "m:Pose"\nglobal P = A -> B : Pose'
    without = "global P = A -> B : Pose"
    assert only_message(body(with_type)).sort is not None
    assert only_message(body(without)) == Interaction("Pose")


def test_label_only_branch_carries_nothing_even_for_a_sort_name() -> None:
    term = body("global P = A -> B : { int: end, ok: end }")
    assert isinstance(term, g.Choice)
    assert [b.message for b in term.branches] == [Interaction("int"), Interaction("ok")]


def test_abbreviation_rule_in_local_types() -> None:
    assert local("local L = !B(int). ?B(ping). !B(ping()). ?B(l(Int))").body == lt.Send(
        "B", Interaction("int", Sort("int", "int")), lt.Recv(
            "B", Interaction("ping"), lt.Send(
                "B", Interaction("ping"), lt.Recv("B", Interaction("l", Sort("int", "Int")), lt.End()))))


# ---- 4. local types -------------------------------------------------------------------

@pytest.mark.parametrize(("text", "printed"), [
    ("!B(x)", "!B(x)"),
    ("?B(x(int))", "?B(x(int))"),
    ("!B(x). ?C(y). end", "!B(x).?C(y)"),
    ("!int", "!int"),
    ("?Int. !Bool", "?Int.!Bool"),
    ("!Int(x)", "!Int(x)"),  # with parentheses X is always the peer
    ("+B{x, y(int). !B(z)}", "+B{x, y(int).!B(z)}"),
    ("+{x. !int, y}", "+{x.!int, y}"),
    ("&B{x. end, y: ?B(z),}", "&B{x, y.?B(z)}"),
    ("&{x: end, y: !int}", "&{x, y.!int}"),
    ("mu t. !B(x). t", "mu t.!B(x).t"),
    ("rec t. &B{more. t, stop}", "mu t.&B{more.t, stop}"),
    ("end", "end"),
    ("(!B(x))", "!B(x)"),
    ("(!B(x) || ?C(y))", "(!B(x) || ?C(y))"),
    ("(mu t. !B(x). t || ?C(y) || !D(z))", "(mu t.!B(x).t || ?C(y) || !D(z))"),
])
def test_local_constructs_parse_and_print(text: str, printed: str) -> None:
    assert str(local(f"local L = {text}")) == printed


def test_local_term_structure() -> None:
    assert local("local L at A = mu t. +B{x(int). t, y}").body == lt.Rec("t", lt.Select("B", (
        lt.Branch(Interaction("x", Sort("int", "int")), lt.Var("t")),
        lt.Branch(Interaction("y"), lt.End()),
    )))
    assert local("local L = ?Int. !bool").body == lt.Recv(
        None, Interaction("Int", Sort("int", "Int")),
        lt.Send(None, Interaction("bool", Sort("bool", "bool")), lt.End()))


def test_a_local_choice_with_one_branch_is_a_send_or_receive() -> None:
    assert local("local L = +B{x(int)}").body == local("local L = !B(x(int))").body
    assert local("local L = &B{x}").body == local("local L = ?B(x)").body


FIG2_ATM = "local ATM = ?Int. +{ok: ATM', err: end}"
FIG2_ATM_PRIME = ("local ATM' = &{deposit: ?Int. ATM, withdraw: ?Int. +{ok: !Int. ATM, fail: ATM}, "
                  "balance: !Int. ATM, quit: end}")


def test_figure_2_parses_as_written() -> None:
    module = sessiontypes.loads(f"{FIG2_ATM}\n{FIG2_ATM_PRIME}\n")
    assert list(module.locals) == ["ATM", "ATM'"]
    assert str(module.locals["ATM"]) == (
        "mu ATM.?Int.+{ok.&{deposit.?Int.ATM, withdraw.?Int.+{ok.!Int.ATM, fail.ATM}, "
        "balance.!Int.ATM, quit}, err}"
    )
    assert str(module.locals["ATM'"]) == (
        "mu ATM'.&{deposit.?Int.?Int.+{ok.ATM', err}, "
        "withdraw.?Int.+{ok.!Int.?Int.+{ok.ATM', err}, fail.?Int.+{ok.ATM', err}}, "
        "balance.!Int.?Int.+{ok.ATM', err}, quit}"
    )


def test_figure_2_with_the_papers_symbols() -> None:
    ascii_module = sessiontypes.loads(f"{FIG2_ATM}\n{FIG2_ATM_PRIME}\n")
    paper = (f"{FIG2_ATM}\n{FIG2_ATM_PRIME}\n").replace("+", "⊕").replace("end", "⊥")
    assert "⊕{ok: ATM', err: ⊥}" in paper
    paper_module = sessiontypes.loads(paper)
    for name in ("ATM", "ATM'"):
        assert paper_module.locals[name].body == ascii_module.locals[name].body


def test_figure_2_fragment_structure() -> None:
    atm = sessiontypes.loads("local ATM = ?Int. +{ok: ATM, err: end}").locals["ATM"].body
    assert atm == lt.Rec("ATM", lt.Recv(None, Interaction("Int", Sort("int", "Int")), lt.Select(None, (
        lt.Branch(Interaction("ok"), lt.Var("ATM")),
        lt.Branch(Interaction("err"), lt.End()),
    )), ))


# ---- locations ------------------------------------------------------------------------

SOURCE = (
    "// header\n"                                   # 1
    "global P(A, B) =\n"                            # 2
    "  A -> B : x(int).\n"                          # 3
    "  mu t. B -> A : { y. t, z: end }\n"           # 4
    "/* a\n   comment */ local L at A = !B(x(int)). ⊕B{ u, v }\n"  # 5, 6
    "global U = μ t. A → B : w. t\n"                # 7
)


def test_locations_on_global_syntax() -> None:
    decl, _local_decl, _unicode_decl = parse_file(SOURCE, "f.proto").declarations
    assert isinstance(decl, s.GlobalDecl)
    assert decl.location == Location("f.proto", 2, 1)
    assert decl.name.location == Location("f.proto", 2, 8)
    assert decl.roles is not None
    assert [r.location.column for r in decl.roles] == [10, 13]
    first = decl.body
    assert isinstance(first, s.GInteraction)
    assert first.location == Location("f.proto", 3, 3)
    assert first.sender.location == Location("f.proto", 3, 3)
    assert first.receiver.location == Location("f.proto", 3, 8)
    message = first.branches[0].message
    assert message.label.location == Location("f.proto", 3, 12)
    assert message.sort is not None and message.sort.location == Location("f.proto", 3, 14)
    rec = first.branches[0].continuation
    assert isinstance(rec, s.GRec)
    assert rec.location == Location("f.proto", 4, 3)
    assert rec.var.location == Location("f.proto", 4, 6)
    choice = rec.body
    assert isinstance(choice, s.GInteraction) and choice.braced
    assert choice.location == Location("f.proto", 4, 9)
    y, z = choice.branches
    assert y.message.label.location == Location("f.proto", 4, 20)
    assert isinstance(y.continuation, s.GRef)
    assert y.continuation.name.location == Location("f.proto", 4, 23)
    assert z.message.label.location == Location("f.proto", 4, 26)
    assert isinstance(z.continuation, s.GEnd)
    assert z.continuation.location == Location("f.proto", 4, 29)


def test_locations_on_local_syntax_after_a_block_comment() -> None:
    _, decl, _ = parse_file(SOURCE, "f.proto").declarations
    assert isinstance(decl, s.LocalDecl)
    assert decl.location == Location("f.proto", 6, 15)
    assert decl.name.location == Location("f.proto", 6, 21)
    assert decl.role is not None and decl.role.location == Location("f.proto", 6, 26)
    send = decl.body
    assert isinstance(send, s.LAction)
    assert send.location == Location("f.proto", 6, 30)
    assert send.peer is not None and send.peer.location == Location("f.proto", 6, 31)
    choice = send.continuation
    assert isinstance(choice, s.LChoice)
    assert choice.location == Location("f.proto", 6, 42)
    assert choice.peer is not None and choice.peer.location == Location("f.proto", 6, 43)


def test_unicode_characters_count_as_one_column() -> None:
    *_, decl = parse_file(SOURCE, "f.proto").declarations
    assert isinstance(decl, s.GlobalDecl)
    rec = decl.body
    assert isinstance(rec, s.GRec)
    assert rec.location == Location("f.proto", 7, 12)
    interaction = rec.body
    assert isinstance(interaction, s.GInteraction)
    assert interaction.receiver.location == Location("f.proto", 7, 21)
    assert interaction.branches[0].message.label.location == Location("f.proto", 7, 25)


def test_locations_on_resolved_types() -> None:
    module = sessiontypes.loads(SOURCE, "f.proto")
    term = module.globals["P"].body
    assert isinstance(term, g.Choice)
    assert term.location == Location("f.proto", 3, 3)
    assert term.branches[0].location == Location("f.proto", 3, 12)
    rec = term.branches[0].continuation
    assert isinstance(rec, g.Rec) and rec.location == Location("f.proto", 4, 3)
    assert module.globals["P"].location == Location("f.proto", 2, 1)


def test_locations_are_left_out_of_equality() -> None:
    one = parse_file("global P = A -> B : x", "a.proto").declarations
    other = parse_file("\n\n   global   P =\n A->B:x", "b.proto").declarations
    assert one == other
    assert hash(one) == hash(other)


@pytest.mark.parametrize("space", ["\f", "\v", "\x1c", "\x85", "\u2028", "\u2029"])
def test_lines_are_counted_at_newlines_only(space: str) -> None:
    # str.splitlines() breaks at these white-space characters too: the error's line
    # number and the line it shows disagreed, and the caret pointed past the line.
    text = f"global P = A -> B : x{space}. B -> A : $\nglobal Q = A -> B : y\n"
    with pytest.raises(ProtocolSyntaxError) as caught:
        sessiontypes.loads(text, "w.proto")
    error = caught.value
    assert error.location == Location("w.proto", 1, 34)
    assert error.source_line == f"global P = A -> B : x{space}. B -> A : $"
    assert str(error) == (
        "w.proto:1:34: error: syntax error; expected one of '{', a name, got character '$'\n"
        "    global P = A -> B : x . B -> A : $\n"
        "                                     ^"
    )


def test_a_check_error_shows_its_own_line_after_a_line_separator() -> None:
    text = "global P = A -> B : x\u2028. B -> A : y\r\nglobal Q = C -> C : z\r\n"
    with pytest.raises(sessiontypes.ProtocolCheckError) as caught:
        sessiontypes.loads(text, "w.proto")
    assert str(caught.value) == (
        "w.proto:2:17: error: role C sends a message to itself\n"
        "    global Q = C -> C : z\n"
        "                    ^"
    )


def test_syntax_error_location_counts_unicode_characters() -> None:
    with pytest.raises(ProtocolSyntaxError) as caught:
        sessiontypes.loads("global P = μ t. A → B x. t", "u.proto")
    assert caught.value.location == Location("u.proto", 1, 23)
    assert caught.value.got == "'x'"


@pytest.mark.parametrize(("literal", "target"), [
    (r'"pkg.mod:Cls"', "pkg.mod:Cls"),
    (r'"a\"b"', 'a"b'),
    (r'"a\\b"', "a\\b"),
    (r'"a\sb"', r"a\sb"),  # an unknown escape stands for itself: no warning, and the target check reports it
    ('"modé:Clé"', "modé:Clé"),  # non-ASCII text is kept as written
])
def test_a_type_declarations_string_is_read_without_surprises(literal: str, target: str,
                                                              recwarn: pytest.WarningsRecorder) -> None:
    (decl,) = parse_file(f"type X = {literal}\n", "t.proto").declarations
    assert isinstance(decl, s.TypeDecl) and decl.target == target
    assert not recwarn.list
