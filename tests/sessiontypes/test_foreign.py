"""Reading Scribble (.scr) and nuScr (.nuscr) global protocols (sessiontypes.foreign)."""

from __future__ import annotations

from pathlib import Path

import pytest

import sessiontypes
from anodize._tools.cli import main
from sessiontypes import Location, ProtocolCheckError, ProtocolError, ProtocolSyntaxError
from sessiontypes.foreign import UnsupportedConstructError

REPO = Path(__file__).resolve().parents[2]
CORPUS = Path(__file__).parent / "foreign_corpus"

TWO_BUYER_SCR = """\
module demo.TwoBuyer;

type <java> "java.lang.Integer" from "rt.jar" as Int;
type <java> "java.lang.String" from "rt.jar" as String;

global protocol TwoBuyer(role B1, role B2, role S) {
  title(String) from B1 to S;
  quote(Int) from S to B1;
  quote(Int) from S to B2;
  share(Int) from B1 to B2;
  choice at B2 {
    ok(String) from B2 to S;
    date(String) from S to B2;
  } or {
    quit() from B2 to S;
  }
}
"""

TWO_BUYER_NUSCR = """\
(*# ShowPragmas #*)
(* The two-buyer protocol, nuScr style: named payloads, a multicast. *)
global protocol TwoBuyer(role B1, role B2, role S) {
  title(name: string) from B1 to S;
  quote(price: int) from S to B1, B2;   (*) one message to each receiver
  share(amount: int) from B1 to B2;
  choice at B2 {
    ok(address: string) from B2 to S;
    date(d: string) from S to B2;
  } or {
    quit() from B2 to S;
  }
}
"""


def _load(text: str, path: str) -> sessiontypes.ProtocolModule:
    return sessiontypes.loads(text, path)


@pytest.mark.parametrize(("text", "path"), [(TWO_BUYER_SCR, "TwoBuyer.scr"),
                                            (TWO_BUYER_NUSCR, "TwoBuyer.nuscr")])
def test_two_buyer_projects_as_the_proto_file_does(text: str, path: str) -> None:
    proto = sessiontypes.load(REPO / "protocols" / "two_buyer.proto").globals["TwoBuyer"]
    foreign = _load(text, path).globals["TwoBuyer"]
    assert foreign.roles == proto.roles
    for role in proto.roles:
        assert foreign.project(role) == proto.project(role)


def test_sorts_keep_their_spelling_and_unknown_nuscr_types_become_opaque_sorts() -> None:
    module = _load(TWO_BUYER_SCR, "T.scr")
    assert str(module.globals["TwoBuyer"].project("B1")) == (
        "!S(title(String)).?S(quote(Int)).!B2(share(Int))")
    nuscr = _load("global protocol P(role A, role B) { m(x: Date) from A to B; }", "P.nuscr")
    assert nuscr.sorts["Date"].target == "builtins:object"
    assert str(nuscr.globals["P"].project("B")) == "?A(m(Date))"


def test_scribble_labels_that_are_numbers_get_a_leading_underscore() -> None:
    module = _load("module M; global protocol P(role A, role B) { 1() from A to B; (Int) from B to A; }",
                   "P.scr")
    assert str(module.globals["P"].project("A")) == "!B(_1).?B(Int)"


def test_rec_falls_through_and_choices_are_followed_by_what_comes_after() -> None:
    text = """module M;
    global protocol P(role A, role B) {
      rec X {
        choice at A { more() from A to B; continue X; } or { stop() from A to B; }
      }
      bye() from B to A;
    }"""
    assert str(_load(text, "P.scr").globals["P"].project("A")) == "mu X.+B{more.X, stop.?B(bye)}"


def test_do_inlines_with_roles_renamed_and_par_becomes_parallel() -> None:
    text = """module M;
    aux global protocol Ask(role X, role Y) { q() from X to Y; a() from Y to X; }
    global protocol P(role A, role B, role C) {
      par { do Ask(A, B); } and { do Ask(C, A); }
    }"""
    module = _load(text, "P.scr")
    assert list(module.globals) == ["P"]  # an aux protocol is only inlined
    assert str(module.globals["P"].project("A")) == "(!B(q).?B(a) || ?C(q).!C(a))"


def test_a_branch_that_begins_with_rec_is_unfolded_and_merges_as_nuscr_issue_137_asks() -> None:
    # The shape of nuScr's examples/TODO/errors/MergeRec.nuscr (its issue #137): S's
    # branches are ?C(m1) and a loop of ?C(m2); full merge with unfolding accepts it.
    text = """global protocol MultipartyChoice(role C, role S, role D) {
      m2() from C to S;
      choice at C {
        m() from C to D;
        m1() from C to S;
      } or {
        rec SEND { m1() from C to D; m2() from C to S; continue SEND; }
      }
    }"""
    global_type = _load(text, "MergeRec.nuscr").globals["MultipartyChoice"]
    assert str(global_type.project("S")) == "?C(m2).&C{m1, m2.mu SEND.?C(m2).SEND}"


def test_a_choice_whose_branches_go_to_different_roles_is_a_routed_choice() -> None:
    # Scribble's "choice at A { A sends m1 to B } or { A sends m2 to C }"; each of B and C
    # learns the branch from the first message it gets (LANGUAGE.md 3, branches to different receivers).
    text = """module M;
    global protocol P(role A, role B, role C) {
      choice at A { m1(Int) from A to B; done() from B to C; }
      or { m2() from A to C; x(String) from C to B; }
      or { choice at A { m3() from A to B; m5() from A to C; } or { m4() from A to C; y() from C to B; } }
      bye() from B to A;
    }"""
    global_type = _load(text, "P.scr").globals["P"]
    assert str(global_type).startswith("global P(A, B, C) = A->{B:m1(Int).B->C:done.B->A:bye, C:m2.C->B:x(String)")
    assert str(global_type.project("A")) == (
        "+{!B(m1(Int)).?B(bye), !C(m2).?B(bye), !B(m3).!C(m5).?B(bye), !C(m4).?B(bye)}")
    assert str(global_type.project("B")) == (
        "&{?A(m1(Int)).!C(done).!A(bye), ?C(x(String)).!A(bye), ?A(m3).!A(bye), ?C(y).!A(bye)}")
    assert str(global_type.project("C")) == "&{?B(done), ?A(m2).!B(x(String)), ?A(m5), ?A(m4).!B(y)}"
    # a role that learns nothing in some branch is named, located in the Scribble file
    with pytest.raises(ProtocolCheckError, match="not projectable onto role B: branches 'B:x' and 'C:y'"):
        _load("global protocol P(role A, role B, role C) {\n choice at A { x() from A to B; } "
              "or { y() from A to C; }\n}", "p.nuscr")


def _unsupported(text: str, path: str) -> UnsupportedConstructError:
    with pytest.raises(UnsupportedConstructError) as caught:
        _load(text, path)
    assert isinstance(caught.value, ProtocolError)
    return caught.value


def test_an_unsupported_construct_is_a_located_error_naming_it() -> None:
    text = "module M;\nglobal protocol P(role A, role B) {\n  connect A to B;\n}\n"
    error = _unsupported(text, "p.scr")
    assert error.location == Location("p.scr", 3, 3)
    assert error.construct == "an explicit connection ('connect')"
    assert str(error) == (
        "p.scr:3:3: error: an explicit connection ('connect') is not supported (connections "
        "are implicit: every pair of roles that talks has a channel)\n"
        "      connect A to B;\n"
        "      ^")


def _position(text: str, at: str) -> tuple[int, int]:
    """The line and column where ``at`` first occurs in ``text``."""
    before = text[:text.index(at)]
    return before.count("\n") + 1, len(before) - (before.rfind("\n") + 1) + 1


@pytest.mark.parametrize(("text", "path", "at", "construct"), [
    ("module M; explicit global protocol P(role A, role B) { m() from A to B; }", "p.scr",
     "explicit", "an explicit protocol ('explicit')"),
    ("module M; global protocol P<type T>(role A, role B) { m() from A to B; }", "p.scr",
     "<type", "a protocol with type or signature parameters ('<...>')"),
    ("module M; global protocol P(role A, role B) { (Int, Bool) from A to B; }", "p.scr",
     "(Int", "several payloads without a label"),
    ("module M; global protocol P(role A, role B) { m(P@B) from A to B; }", "p.scr",
     "P@B", "delegation ('Protocol@Role' payload)"),
    ("module M; global protocol P(role A, role B) { do P(A, B); }", "p.scr",
     "do P", "a recursive 'do' (P -> P)"),
    ("global protocol P(role A, role B) { rec X [n<A>: int = 0] { continue X [n]; } }", "p.nuscr",
     "[n<A>", "recursion with state variables ('rec X [...]')"),
    ("global protocol P(role A, role B) @\"A>0\" { m() from A to B; }", "p.nuscr",
     "@", "an annotation ('@\"...\"')"),
    ("global protocol P(role A, role B) { A calls Q(A, B); }", "p.nuscr",
     "A calls", "a nested protocol call ('calls')"),
    (("module M; global protocol P(role A, role B) { rec X { choice at A { continue X; } "
      "or { m() from A to B; } } }"), "p.scr",
     "X;", "a choice branch that begins with 'continue'"),
    ("module M; import N; global protocol P(role A, role B) { do N.Q(A, B); }", "p.scr",
     "N.Q", "'do' of a protocol of another module"),
])
def test_each_unsupported_construct_is_named_where_it_is(text: str, path: str, at: str,
                                                          construct: str) -> None:
    error = _unsupported(text, path)
    assert (error.location.line, error.location.column) == _position(text, at)
    assert error.construct == construct


def test_par_has_no_continuation() -> None:
    text = ("module M; global protocol P(role A, role B) { "
            "par { n() from A to B; } and { o() from B to A; } m() from A to B; }")
    error = _unsupported(text, "p.scr")
    assert error.construct == "an interaction after 'par'"
    assert error.location.column == text.index("m() from A to B; }") + 1


@pytest.mark.parametrize(("text", "path", "message"), [
    ("module M; global protocol P(role A, role B) { m(Foo) from A to B; }", "p.scr",
     "unknown payload type Foo; declare it with 'type <java> \"...\" from \"...\" as Foo;'"),
    ("global protocol P(role A, role B) { m() from A to B; continue X; }", "p.nuscr",
     "'continue X': no enclosing 'rec X'"),
    ("global protocol P(role A, role B) { rec X { m() from A to B; continue X; m() from A to B; } }",
     "p.nuscr", "this interaction is never reached: it follows 'continue X'"),
    ("global protocol P(role A, role B) { m() from A to C; }", "p.nuscr",
     "role C is not a role of protocol P"),
    ("global protocol P(role A, role B) { choice at A { m() from B to A; } or { n() from A to B; } }",
     "p.nuscr", "a branch of 'choice at A' begins with a message from B"),
    ("global protocol P(role A, role B) { choice at A { rec X { continue X; } } or { n() from A to B; } }",
     "p.nuscr", "unguarded recursion: 'rec X' loops with no interaction in between"),
])
def test_translation_problems_are_located_check_errors(text: str, path: str, message: str) -> None:
    with pytest.raises(ProtocolCheckError) as caught:
        _load(text, path)
    assert [d.message for d in caught.value.errors] == [message]


def test_a_syntax_error_is_located_with_what_was_expected() -> None:
    with pytest.raises(ProtocolSyntaxError) as caught:
        _load("module M;\nglobal protocol P(role A, role B) {\n  m() from A B;\n}\n", "p.scr")
    assert caught.value.location == Location("p.scr", 3, 14)
    assert caught.value.message == "syntax error; expected 'to', got 'B'"


def test_checker_errors_point_into_the_foreign_file() -> None:
    text = "module M;\nglobal protocol P(role A, role B) {\n  m() from A to B;\n  n() from A to A;\n}\n"
    with pytest.raises(ProtocolCheckError) as caught:
        _load(text, "p.scr")
    assert caught.value.errors[0].location.path == "p.scr"
    assert [(d.location.line, d.location.column) for d in caught.value.errors] == [(4, 17)]


def test_the_cli_reads_scribble_and_nuscr_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "TwoBuyer.nuscr"
    path.write_text(TWO_BUYER_NUSCR, encoding="utf-8")
    assert main(["project", str(path)]) == 0
    assert capsys.readouterr().out.splitlines()[0] == (
        "B1 = !S(title(str)).?S(quote(int)).!B2(share(int))")
    bad = tmp_path / "bad.scr"
    bad.write_text("module M; global protocol P(role A, role B) { connect A to B; }", encoding="utf-8")
    assert main(["check", str(bad)]) == 1
    assert "an explicit connection ('connect') is not supported" in capsys.readouterr().err


# ---- the peers' own examples ------------------------------------------------------------
# Each file: the peer's verdict (from its folder: good/bad in scribble-test, errors/ in
# nuScr's examples), anodize's, and, where they differ, why (docs/foreign.md).
AGREE = "agree"
THEORY = "theory"            # anodize follows the MPST theory of LANGUAGE.md where the peer does not
OUTSIDE = "outside"          # a construct outside the subset read (UnsupportedConstructError)
CORPUS_VERDICTS: dict[str, tuple[str, str, str]] = {
    # path: (peer's verdict, anodize's verdict, reason)
    "scribble/good/efsm/gchoice/Test02.scr": ("good", "good", AGREE),
    "scribble/good/efsm/grecursion/Test03.scr": ("good", "good", AGREE),
    "scribble/good/reach/globals/grecursion/Recursion16.scr": ("good", "good", AGREE),
    "scribble/good/wfchoice/merge/Test02.scr": ("good", "good", AGREE),
    "scribble/good/wfchoice/enabling/twoparty/Test01.scr": ("good", "good", AGREE),
    "scribble/good/liveness/Test01.scr": ("good", "good", AGREE),
    "scribble/good/misc/globals/gdo/Do02.scr": ("good", "good", AGREE),
    "scribble/bad/reach/globals/grecursion/Recursion01b.scr": ("bad", "bad", AGREE),
    "scribble/bad/reach/globals/grecursion/Recursion03a.scr": ("bad", "bad", AGREE),
    "scribble/bad/reach/globals/grecursion/Recursion11.scr": ("bad", "bad", AGREE),
    "scribble/bad/reach/globals/gchoice/Test01.scr": ("bad", "bad", AGREE),
    "scribble/bad/wfchoice/gchoice/Choice01.scr": ("bad", "bad", AGREE),
    "scribble/bad/wfchoice/gchoice/Choice02.scr": ("bad", "bad", AGREE),
    "scribble/bad/liveness/roleprog/Test01.scr": ("bad", "bad", AGREE),
    "scribble/bad/syntax/disamb/globals/gprotocoldecl/GProtocolDecl01.scr": ("bad", "bad", AGREE),
    # C learns the branch from A's second message: full merge of receives accepts it
    "scribble/bad/wfchoice/merge/Test01.scr": ("bad", "good", THEORY),
    # C and D loop on their own beside A and B's loop: projectable, each role's loop is live
    "scribble/bad/wfchoice/enabling/twoparty/Test01b.scr": ("bad", "good", THEORY),
    # two branches with the same label: a choice's labels are distinct (LANGUAGE.md section 3)
    "scribble/good/efsm/gchoice/Test09.scr": ("good", "bad", THEORY),
    # C takes no part in the loop X but Scribble prunes its paths: standard merge rejects
    "scribble/good/syntax/projection/grecursion/fair/Test03.scr": ("good", "bad", THEORY),
    "scribble/good/efsm/gcontinue/choiceunguarded/Test01a.scr": ("good", "bad", OUTSIDE),
    "scribble/LoanApplication.scr": ("good", "bad", OUTSIDE),  # scribble-demos: 'explicit'
    "nuscr/test/test1/Test1.nuscr": ("good", "good", AGREE),
    "nuscr/test/test2/Test2.nuscr": ("good", "good", AGREE),
    "nuscr/test/test6/Test6.nuscr": ("good", "good", AGREE),
    "nuscr/test/test7/Test7.nuscr": ("good", "good", AGREE),
    "nuscr/exercise/voting/EProtocol.nuscr": ("good", "good", AGREE),
    # B and C are never told when a round is not theirs: a receive does not merge with a loop back
    "nuscr/demo/fase17/intro/FirstL.nuscr": ("good", "bad", THEORY),
    "nuscr/demo/supplierinfo/SupplierInfoBasic.nuscr": ("good", "good", AGREE),  # several payloads: fields
    "nuscr/test/test3/Test3.nuscr": ("good", "bad", OUTSIDE),
}


def test_the_corpus_lists_every_file() -> None:
    files = {p.relative_to(CORPUS).as_posix() for p in CORPUS.rglob("*")
             if p.suffix in {".scr", ".nuscr"}}
    assert files == set(CORPUS_VERDICTS)


@pytest.mark.parametrize("name", sorted(CORPUS_VERDICTS))
def test_a_peer_example_gets_its_verdict_or_a_documented_difference(name: str) -> None:
    peer, ours, reason = CORPUS_VERDICTS[name]
    assert (peer == ours) == (reason == AGREE)
    try:
        sessiontypes.load(CORPUS / name)
        got = "good"
    except UnsupportedConstructError:
        got = "bad"
        assert reason == OUTSIDE, name
    except ProtocolError:
        got = "bad"
        assert reason != OUTSIDE, name
    assert got == ours, name


@pytest.mark.parametrize(("text", "path", "projection"), [
    ("global protocol P(role A, role B) { quote(price: int, date: string) from A to B; }", "p.nuscr",
     "!B(quote(price: int, date: str))"),
    (("module M; type <java> \"java.lang.Integer\" from \"rt.jar\" as Int;\n"
     "global protocol P(role A, role B) { m(Int, Int) from A to B; }"), "p.scr", "!B(m(p1: Int, p2: Int))"),
    ("global protocol P(role A, role B) { m(x: int) from A to B; }", "p.nuscr", "!B(m(int))"),
])
def test_several_payloads_are_named_payloads(text: str, path: str, projection: str) -> None:
    module = sessiontypes.loads(text, path)
    assert str(next(iter(module.globals.values())).project("A")) == projection
