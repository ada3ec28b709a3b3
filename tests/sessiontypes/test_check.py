"""Well-formedness checks (LANGUAGE.md section 6), driven by a corpus of protocols.

``corpus/bad/<name>.proto`` must be rejected with exactly the text of
``corpus/bad/<name>.expected`` (what ``anodize check`` prints on stderr, with
paths relative to the repository root); ``corpus/good/*.proto`` must be
accepted without warnings. The other tests look at the structured fields of
the exceptions and at warnings.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import sessiontypes
from sessiontypes import (
    Diagnostic,
    Location,
    ProtocolCheckError,
    ProtocolError,
    ProtocolSyntaxError,
)

REPO = Path(__file__).resolve().parents[2]
CORPUS = Path(__file__).resolve().parent / "corpus"
BAD = sorted((CORPUS / "bad").glob("*.proto"))
GOOD = sorted((CORPUS / "good").glob("*.proto"))


def _relative(path: Path) -> str:
    """The path as the CLI prints it when run from the repository root."""
    return path.relative_to(REPO).as_posix()


def test_corpus_is_complete() -> None:
    assert len(BAD) >= 25 and len(GOOD) >= 5
    for proto in BAD:
        assert proto.with_suffix(".expected").is_file(), f"{proto.name} has no .expected file"


@pytest.mark.parametrize("proto", BAD, ids=lambda p: p.stem)
def test_bad_protocol_is_rejected_with_the_expected_message(proto: Path) -> None:
    expected = proto.with_suffix(".expected").read_text(encoding="utf-8")
    with pytest.raises(ProtocolError) as caught:
        sessiontypes.loads(proto.read_text(encoding="utf-8"), _relative(proto))
    assert isinstance(caught.value, (ProtocolSyntaxError, ProtocolCheckError))
    assert str(caught.value) + "\n" == expected


@pytest.mark.parametrize("proto", BAD, ids=lambda p: p.stem)
def test_bad_protocol_kind_matches_its_name(proto: Path) -> None:
    """``syntax_*`` files fail to parse; every other file parses and fails the checks."""
    with pytest.raises(ProtocolError) as caught:
        sessiontypes.loads(proto.read_text(encoding="utf-8"), _relative(proto))
    wanted = ProtocolSyntaxError if proto.stem.startswith("syntax_") else ProtocolCheckError
    assert type(caught.value) is wanted


@pytest.mark.parametrize("proto", GOOD, ids=lambda p: p.stem)
def test_good_protocol_is_accepted_without_warnings(proto: Path) -> None:
    module = sessiontypes.loads(proto.read_text(encoding="utf-8"), _relative(proto))
    assert module.warnings == ()
    assert module.globals or module.locals
    for global_type in module.globals.values():
        assert set(global_type.projections()) == set(global_type.roles)


@pytest.mark.parametrize("proto", sorted((REPO / "protocols").glob("*.proto")), ids=lambda p: p.stem)
def test_shipped_protocols_are_accepted(proto: Path) -> None:
    module = sessiontypes.load(proto)
    assert module.warnings == ()


# ---- accepted corner cases: what they mean ------------------------------------------

def _projections(name: str, global_name: str) -> dict[str, str]:
    module = sessiontypes.load(CORPUS / "good" / f"{name}.proto")
    return {role: str(local) for role, local in module.globals[global_name].projections().items()}


def test_merge_unfolds_a_mu_once() -> None:
    assert _projections("merge_unfold", "Unfold") == {
        "A": "+B{now.!C(x).mu t.!C(x).t, later.mu t.!C(x).t}",
        "B": "&A{now, later}",
        "C": "?A(x).mu t.?A(x).t",
    }


def test_merge_accepts_two_spellings_of_one_loop() -> None:
    projections = _projections("merge_unfold", "Spellings")
    assert projections["A"] == "+B{twice.mu t.!C(x).!C(x).t, once.mu s.!C(x).s}"
    assert projections["B"] == "&A{twice, once}"
    # Both branches make C receive x forever; any spelling of that loop will do.
    assert projections["C"] in {"mu t.?A(x).?A(x).t", "mu t.?A(x).t", "mu s.?A(x).s"}


def test_merge_of_sends_goes_label_by_label() -> None:
    assert _projections("merge_sends", "SendThenLearn")["C"] == "!B(x).&B{l1, l2}"
    # the first branch's order; slow's sort spelled Int in the other branch is the same sort
    assert _projections("merge_sends", "ChooseThenLearn")["C"] == "+B{fast.&B{l1, l2}, slow(int).&B{l1, l2}}"


def test_equation_style_recursion_prints_the_declaration_name() -> None:
    assert _projections("equation_recursion", "Ping") == {
        "A": "mu Ping.!B(ping(int)).&B{pong(int).Ping, done}",
        "B": "mu Ping.?A(ping(int)).+A{pong(int).Ping, done}",
    }
    assert _projections("equation_recursion", "Pong") == {
        "A": "mu Pong.&B{pong(int).!B(ping(int)).Pong, done}",
        "B": "mu Pong.+A{pong(int).?A(ping(int)).Pong, done}",
    }


def test_label_only_branches_and_trailing_comma() -> None:
    assert _projections("label_only_branches", "Login") == {
        "C": "!S(login(str)).&S{ok.!S(Int), err}",
        "S": "?C(login(str)).+C{ok.?C(Int), err}",
    }


def test_primes_and_comments() -> None:
    assert _projections("primes_and_comments", "Relay'") == {
        "A'": "!A''(ping'(int)).?B(pong)",
        "A''": "?A'(ping'(int)).!B(ping'(int))",
        "B": "?A''(ping'(int)).!A'(pong)",
    }


def test_unicode_spellings() -> None:
    module = sessiontypes.load(CORPUS / "good" / "unicode_spellings.proto")
    stream = module.globals["Stream"]
    assert {r: str(stream.project(r)) for r in stream.roles} == {
        "P": "mu t.+C{data(int).t, stop}",
        "C": "mu t.&P{data(int).t, stop}",
    }
    assert module.locals["Producer"].body == stream.project("P").body
    assert module.locals["Consumer"].body == stream.project("C").body


def test_separators() -> None:
    module = sessiontypes.load(CORPUS / "good" / "separators.proto")
    poll = module.globals["Poll"]
    assert str(poll.project("Hub")) == "mu t.+Sensor{poll.?Sensor(Reading).t, stop}"
    assert module.locals["Sensor"].body == poll.project("Sensor").body
    assert module.sorts["Reading"].target == "sensors.messages:Reading"


# ---- structured fields ----------------------------------------------------------------

def test_syntax_error_fields() -> None:
    text = "global P(A, B) =\n  A -> B ping(int)\n"
    with pytest.raises(ProtocolSyntaxError) as caught:
        sessiontypes.loads(text, "p.proto")
    error = caught.value
    assert error.location == Location("p.proto", 2, 10)
    assert error.got == "'ping'"
    assert error.expected == ("','", "':'")
    assert error.source_line == "  A -> B ping(int)"
    assert error.hint == "write 'Sender -> Receiver : label'"
    assert error.message == "syntax error; expected one of ',', ':', got 'ping' (write 'Sender -> Receiver : label')"
    assert error.diagnostics == (Diagnostic("error", error.location, error.message, error.source_line),)
    assert str(error) == (
        "p.proto:2:10: error: syntax error; expected one of ',', ':', got 'ping' (write 'Sender -> Receiver : label')\n"
        "      A -> B ping(int)\n"
        "             ^"
    )


def test_syntax_error_at_end_of_file() -> None:
    with pytest.raises(ProtocolSyntaxError) as caught:
        sessiontypes.loads("global P = A -> B : ping.", "p.proto")
    error = caught.value
    assert error.location == Location("p.proto", 1, 26)
    assert error.got == "end of file"
    assert error.expected == ("'('", "'end'", "'mu'", "a name")


def test_syntax_error_for_a_stray_character_expects_what_the_parser_can_take() -> None:
    with pytest.raises(ProtocolSyntaxError) as caught:
        sessiontypes.loads("global P = A -> B : ping. $", "p.proto")
    error = caught.value
    assert error.location == Location("p.proto", 1, 27)
    assert error.got == "character '$'"
    # Only what may start a global type: not '=', '!', a string, ...
    assert error.expected == ("'('", "'end'", "'mu'", "a name")


def test_keyword_hint_in_fields() -> None:
    with pytest.raises(ProtocolSyntaxError) as caught:
        sessiontypes.loads("global P = mu rec. A -> B : x. rec", "p.proto")
    error = caught.value
    assert error.location == Location("p.proto", 1, 15)
    assert error.got == "'rec'"
    assert error.expected == ("a name",)
    assert error.hint == "'rec' is a keyword and cannot be a name"


def test_check_error_collects_every_diagnostic_in_source_order() -> None:
    text = (
        "global P(A, B) =\n"
        "  A -> A : x(Item).\n"
        "  B -> A : { y, y }\n"
        "global P = A -> B : z\n"
    )
    with pytest.raises(ProtocolCheckError) as caught:
        sessiontypes.loads(text, "p.proto")
    assert caught.value.diagnostics == (
        Diagnostic("error", Location("p.proto", 2, 8), "role A sends a message to itself",
                   "  A -> A : x(Item)."),
        Diagnostic("error", Location("p.proto", 2, 14),
                   "unknown sort 'Item'; expected a builtin sort (int, nat, bool, str, float, bytes) "
                   "or a declared type", "  A -> A : x(Item)."),
        Diagnostic("error", Location("p.proto", 3, 17), "duplicate label 'y' in one choice",
                   "  B -> A : { y, y }"),
        Diagnostic("error", Location("p.proto", 4, 8), "duplicate declaration 'P'; first declared at 1:8",
                   "global P = A -> B : z"),
    )
    assert caught.value.errors == caught.value.diagnostics


def test_projection_failure_is_a_diagnostic_naming_role_and_branches() -> None:
    text = "global Deal(A, B, C) = A -> B : { buy. B -> C : ship, cancel }"
    with pytest.raises(ProtocolCheckError) as caught:
        sessiontypes.loads(text, "deal.proto")
    (diagnostic,) = caught.value.diagnostics
    assert diagnostic.severity == "error"
    assert diagnostic.location == Location("deal.proto", 1, 24)
    assert diagnostic.message == (
        "global Deal is not projectable onto role C: branches 'buy' and 'cancel' give C "
        "different behaviours that do not merge (a receive cannot merge with end): ?B(ship) versus end"
    )


def test_errors_are_protocol_errors() -> None:
    for error in (ProtocolSyntaxError, ProtocolCheckError, sessiontypes.ProjectionError,
                  sessiontypes.UnknownRoleError):
        assert issubclass(error, ProtocolError)


def test_unknown_role_error_fields() -> None:
    module = sessiontypes.loads("global P(A, B) = A -> B : x")
    with pytest.raises(sessiontypes.UnknownRoleError) as caught:
        module.globals["P"].project("C")
    assert (caught.value.protocol, caught.value.role, caught.value.roles) == ("P", "C", ("A", "B"))
    assert str(caught.value) == "error: global P has no role C; expected one of A, B"


# ---- warnings ----------------------------------------------------------------------

def test_unused_type_is_a_warning_not_an_error() -> None:
    text = 'type Unused = "m:Unused"\ntype Used = "m:Used"\nglobal P = A -> B : Used\n'
    module = sessiontypes.loads(text, "w.proto")
    assert module.warnings == (
        Diagnostic("warning", Location("w.proto", 1, 6), "type Unused is declared but never used",
                   'type Unused = "m:Unused"'),
    )
    assert str(module.warnings[0]) == (
        "w.proto:1:6: warning: type Unused is declared but never used\n"
        '    type Unused = "m:Unused"\n'
        "         ^"
    )
    assert str(module.globals["P"].project("A")) == "!B(Used)"


def test_a_type_used_only_in_a_local_is_used() -> None:
    module = sessiontypes.loads('type T = "m:T"\nlocal L = !T')
    assert module.warnings == ()


def test_spellings_of_a_builtin_sort_are_one_sort() -> None:
    # Merging needs equal sorts: Int in one branch and int in the other are the same.
    module = sessiontypes.loads(
        "global P(A, B, C) = A -> B : { l. B -> C : n(Int), r. B -> C : n(int) }")
    assert str(module.globals["P"].project("C")) == "?B(n(Int))"


def test_a_mu_variable_may_share_a_name_with_a_declaration_referred_to_from_elsewhere() -> None:
    # In Q, 'P' is not bound by an enclosing mu, so it is the declaration P (section 2);
    # inside P, 'mu P' binds a different loop. Both readings are well defined.
    text = "global P(A, B) = A -> B : start. mu P. A -> B : x. Q\nglobal Q(A, B) = B -> A : y. P"
    module = sessiontypes.loads(text)
    machine = module.globals["P"].project("A").fsm()
    state = machine.initial
    for action, label in [("send", "start"), ("send", "x"), ("recv", "y")] * 2 + [("send", "start")]:
        transition = machine.step(state, action, "B", label)  # type: ignore[arg-type]
        assert transition is not None, f"{action} {label} not allowed in {machine.describe(state)}"
        state = transition.target
