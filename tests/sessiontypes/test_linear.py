"""Reading and checking cost work linear in the protocol's size (issue 27, items 4 and 9).

Work is counted, never timed: the reader and the checker add what they did
(nodes resolved and projected, merge steps, interactions translated, nodes
searched for a choice among peers) to :data:`sessiontypes.work.METER`. Each
family of protocols is read at two sizes, n and 4n, and the work of the
larger may be at most 4.5 times that of the smaller. Property tests pin that
the sharing behind it changes no result: a Scribble ``do`` means its callee's
body written out in place, and the projections of a file's globals (and the
causes of their failures) are those each global gets on its own.
"""

from __future__ import annotations

import contextlib
import importlib
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

from budget import examples  # noqa: E402
from test_references import reference_files, write  # noqa: E402

import sessiontypes  # noqa: E402
from sessiontypes import ProjectionError, ProtocolError  # noqa: E402
from sessiontypes.check import check_file  # noqa: E402
from sessiontypes.declarations import GlobalType  # noqa: E402
from sessiontypes.errors import ProtocolCheckError  # noqa: E402
from sessiontypes.foreign import read as foreign_read  # noqa: E402
from sessiontypes.parse import parse_file  # noqa: E402
from sessiontypes.printer import print_local  # noqa: E402
from sessiontypes.project import project_declared  # noqa: E402
from sessiontypes.sharing import Sharing  # noqa: E402
from sessiontypes.work import METER  # noqa: E402

foreign_translate = importlib.import_module("sessiontypes.foreign.translate")  # the package exports its function

# ---- the families ---------------------------------------------------------------------


def chain(n: int) -> str:
    """n declarations, each sending once and going on with the next."""
    lines = [f"global G{i}(A, B) = A -> B : x. G{i + 1}" for i in range(n)]
    return "\n".join([*lines, f"global G{n}(A, B) = A -> B : done"])


def unmergeable_chain(n: int) -> str:
    """Every declaration's choice is unmergeable for C (C sends in one branch, receives in the other)."""
    lines = [f"global G{i}(A, B, C) = A -> B : {{l. C -> A : x. G{i + 1}, r. A -> C : y. G{i + 1}}}"
             for i in range(n)]
    return "\n".join([*lines, f"global G{n}(A, B, C) = A -> C : done"])


def chain_to_an_unmergeable_choice(n: int) -> str:
    lines = [f"global G{i}(A, B, C) = A -> B : {{l. B -> C : x. G{i + 1}, r. B -> C : y. G{i + 1}}}"
             for i in range(n)]
    return "\n".join([*lines, f"global G{n}(A, B, C) = A -> B : {{l. C -> A : x, r. A -> C : y}}"])


def chain_to_a_choice_among_peers(n: int) -> str:
    """C receives in every declaration; the last is a choice C learns from whichever of A and B speaks first."""
    lines = [f"global G{i}(A, B, C) = A -> C : x. G{i + 1}" for i in range(n)]
    return "\n".join([*lines, f"global G{n}(A, B, C) = A -> B : {{l. A -> C : x, r. B -> C : y}}"])


def chain_to_a_race(n: int) -> str:
    """The same, and in the branch B's 'y' decides, A may send C 'z' before 'y' arrives."""
    lines = [f"global G{i}(A, B, C) = A -> C : x. G{i + 1}" for i in range(n)]
    return "\n".join([*lines, f"global G{n}(A, B, C) = A -> B : {{l. B -> C : y. A -> C : z, r. A -> C : w}}"])


def wide_choice(n: int) -> str:
    branches = ", ".join(f"l{i}. B -> C : m{i}" for i in range(n))
    return f"global G(A, B, C) = A -> B : {{{branches}}}"


def deep_nesting(n: int) -> str:
    return "global G(A, B, C) = " + "A -> B : {l. B -> C : a. " * n + "end" + ", r. B -> C : b}" * n


def long_sequence(n: int) -> str:
    return "global G(A, B, C) = mu t. " + "A -> B : x. B -> C : y. " * n + "t"


def scribble_do_per_branch(n: int) -> str:
    """Each level is a choice with a ``do`` of the next level in each branch: 2**n written out."""
    out = ["global protocol P0(role A, role B) { do P1(A, B); do P1(B, A); }"]
    out.extend(f"aux global protocol P{i}(role A, role B) {{ choice at A "
               f"{{ l() from A to B; do P{i + 1}(A, B); }} or {{ r() from A to B; do P{i + 1}(B, A); }} }}"
               for i in range(1, n))
    out.append(f"aux global protocol P{n}(role A, role B) {{ e() from A to B; }}")
    return "\n".join(out) + "\n"


def scribble_do_in_a_loop(n: int) -> str:
    """The same inside a loop: the continuation after each ``do`` is ``continue Loop``."""
    out = [("global protocol P0(role A, role B) { rec Loop { choice at A { go() from A to B; "
            "do P1(A, B); continue Loop; } or { stop() from A to B; } } }")]
    out.extend(f"aux global protocol P{i}(role A, role B) {{ choice at A "
               f"{{ l() from A to B; do P{i + 1}(A, B); }} or {{ r() from A to B; do P{i + 1}(A, B); }} }}"
               for i in range(1, n))
    out.append(f"aux global protocol P{n}(role A, role B) {{ e() from A to B; }}")
    return "\n".join(out) + "\n"


def scribble_chain(n: int) -> str:
    """n global protocols, each sending once and doing the next: each global reaches the rest of the chain."""
    out = [f"global protocol P{i}(role A, role B) {{ m() from A to B; do P{i + 1}(A, B); }}" for i in range(n)]
    out.append(f"global protocol P{n}(role A, role B) {{ e() from A to B; }}")
    return "\n".join(out) + "\n"


def scribble_chain_of_choices(n: int) -> str:
    """The same with a choice whose branches both do the next protocol."""
    out = [f"global protocol P{i}(role A, role B, role C) {{ choice at A {{ l() from A to B; do P{i + 1}(A, B, C); }} "
           f"or {{ r() from A to B; do P{i + 1}(A, B, C); }} }}" for i in range(n)]
    out.append(f"global protocol P{n}(role A, role B, role C) {{ choice at A {{ l() from A to C; }} "
               "or { r() from A to B; s() from B to C; } }")
    return "\n".join(out) + "\n"


def scribble_sequence(n: int) -> str:
    body = "\n".join(f"  m{i % 7}() from {'AB'[i % 2]} to {'BA'[i % 2]};" for i in range(n))
    return f"global protocol P(role A, role B) {{\n{body}\n}}\n"


def scribble_nesting(n: int) -> str:
    return ("global protocol P(role A, role B, role C) {\n"
            + "choice at A { l() from A to B; m() from B to C; " * n
            + "}" * n + "\n}\n")


def work(text: str, path: str) -> int:
    """The units of work reading and checking ``text`` takes (rejected or not)."""
    before = METER.total()
    with contextlib.suppress(ProtocolError):
        sessiontypes.loads(text, path)
    return METER.total() - before


FAMILIES: list[tuple[Callable[[int], str], str, int]] = [
    (chain, "p.proto", 400),
    (unmergeable_chain, "p.proto", 300),
    (chain_to_an_unmergeable_choice, "p.proto", 300),
    (chain_to_a_choice_among_peers, "p.proto", 300),
    (chain_to_a_race, "p.proto", 300),
    (wide_choice, "p.proto", 300),
    (deep_nesting, "p.proto", 300),
    (long_sequence, "p.proto", 500),
    (scribble_do_per_branch, "p.scr", 100),
    (scribble_do_in_a_loop, "p.scr", 100),
    (scribble_chain, "p.scr", 200),
    (scribble_chain_of_choices, "p.nuscr", 200),
    (scribble_sequence, "p.nuscr", 500),
    (scribble_nesting, "p.scr", 200),
]


@pytest.mark.parametrize(("family", "path", "n"), FAMILIES, ids=[f[0].__name__ for f in FAMILIES])
def test_work_grows_linearly(family: Callable[[int], str], path: str, n: int) -> None:
    small, large = work(family(n), path), work(family(4 * n), path)
    assert 0 < large <= 4.5 * small, (small, large)


# ---- item 9: chains and unmergeable branches ------------------------------------------


def test_an_unmergeable_choice_used_by_a_chain_is_reported_once_where_it_is() -> None:
    with pytest.raises(ProtocolCheckError) as caught:
        sessiontypes.loads(chain_to_an_unmergeable_choice(50), "chain.proto")
    (error,) = caught.value.diagnostics  # not once per global that uses it
    assert (error.location.line, error.location.column) == (51, 23)
    assert "not projectable onto role C: branches 'l' and 'r'" in error.message
    assert error.message.endswith("!A(x) versus ?A(y)")


def test_every_global_of_the_chain_still_says_it_is_not_projectable() -> None:
    source = parse_file(chain_to_an_unmergeable_choice(5), "chain.proto")
    module, _ = check_file(source)
    for name, glob in module.globals.items():
        with pytest.raises(ProjectionError) as caught:
            glob.project("C")
        assert caught.value.protocol == name  # named for the global asked about
        assert caught.value.location.line == 6


def test_the_behaviours_named_in_a_merge_error_are_bounded() -> None:
    # C's two behaviours are 2**40 actions long written out.
    lines = [f"global G{i}(B, C) = B -> C : {{l. G{i + 1}, r. G{i + 1}}}" for i in range(40)]
    text = "\n".join([*lines, "global G40(B, C) = B -> C : x",
                      "global Top(A, B, C) = A -> B : {l. C -> A : x. G0, r. A -> C : y. G0}"])
    with pytest.raises(ProtocolCheckError) as caught:
        sessiontypes.loads(text, "wide.proto")
    (error,) = caught.value.diagnostics
    assert len(error.message) < 10_000
    assert "longer than 4000 characters written out" in error.message


# ---- item 4: Scribble and nuScr ------------------------------------------------------


@pytest.mark.parametrize("path", ["seq.scr", "seq.nuscr"])
def test_a_long_flat_sequence_is_read(path: str) -> None:
    module = sessiontypes.loads(scribble_sequence(3000), path)
    assert len(module.globals["P"].project("A").fsm().table) >= 3000


def test_a_do_in_each_branch_of_each_level_is_shared() -> None:
    text = scribble_do_per_branch(60).replace("do P1(B, A)", "do P1(A, B)").replace(
        "(B, A); }", "(A, B); }")  # 2**61 interactions written out
    module = sessiontypes.loads(text, "dag.scr")
    body = module.globals["P0"].body
    left, right = body.branches  # type: ignore[union-attr]
    shared = left.continuation is right.continuation  # (a failing 'is' would print both)
    assert shared
    assert len(module.globals["P0"].project("B").fsm().table) < 500


def test_blocks_nested_too_deeply_are_a_located_error_with_the_limit(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(foreign_read, "MAX_NESTING", 30)
    assert sessiontypes.loads(scribble_nesting(30), "deep.scr")
    with pytest.raises(ProtocolCheckError) as caught:
        sessiontypes.loads(scribble_nesting(31), "deep.scr")
    (error,) = caught.value.diagnostics
    assert error.location.line == 2
    assert error.location.column == 30 * 48 + len("choice at A ") + 1  # the '{' of the 31st block
    assert "nested more than 30 deep" in error.message
    assert "at most 30 levels are read" in error.message


@pytest.mark.slow
@pytest.mark.parametrize("path", ["deep.scr", "deep.nuscr"])
def test_blocks_nested_beyond_the_real_limit_are_refused_cleanly(path: str) -> None:
    with pytest.raises(ProtocolCheckError) as caught:
        sessiontypes.loads(scribble_nesting(foreign_read.MAX_NESTING + 1), path)
    assert f"nested more than {foreign_read.MAX_NESTING} deep" in str(caught.value)


# ---- the same results as before --------------------------------------------------------


def _cause(message: str) -> str:
    """A message without the global's name and the positions it quotes (copies differ in those)."""
    message = re.sub(r"\(at \d+:\d+\)", "(at _)", message)
    return re.sub(r"^global \S+ is not projectable", "global _ is not projectable", message)


@given(reference_files())
@settings(deadline=None, max_examples=examples(200))
def test_projections_are_those_each_global_gets_on_its_own(declarations: dict[str, object]) -> None:
    """Remembering projections and failures across globals changes nothing but repetition."""
    text = "\n".join(f"global {name}(A, B, C) = {write(body)}"  # type: ignore[arg-type]
                     for name, body in declarations.items())
    try:
        module, diagnostics = check_file(parse_file(text, "refs.proto"))
    except ProtocolError:
        return
    causes: set[tuple[int, int, str]] = set()
    for name, glob in module.globals.items():
        if not set(glob.roles) >= {"A", "B", "C"} or any(d.severity == "error" and "projectable" not in d.message
                                                          for d in diagnostics):
            return  # a role that never occurs, or another error: projection is not checked
        for role in glob.roles:
            fresh = Sharing(glob.shared.nodes)  # nothing remembered from other globals
            try:
                alone = print_local(project_declared(name, glob.roles, glob.body, role, glob.source_lines, fresh))
            except ProjectionError as error:
                causes.add((error.location.line, error.location.column, _cause(error.message)))
                continue
            assert print_local(glob.project(role).body) == alone
    reported = [(d.location.line, d.location.column, _cause(d.message)) for d in diagnostics
                if d.severity == "error"]
    assert len(reported) == len(set(reported))  # each cause once
    assert set(reported) == causes


# Scribble files whose protocols 'do' later ones: the translation against the text with
# every 'do' written out in place (roles renamed).

ROLES = ("A", "B", "C")


@dataclass(frozen=True)
class Msg:
    label: str
    sender: int  # an index into the protocol's roles
    receiver: int


@dataclass(frozen=True)
class Do:
    callee: int
    roles: tuple[int, ...]  # a permutation of the caller's role indices


@dataclass(frozen=True)
class Choice:
    blocks: tuple[tuple[object, ...], ...]  # each begins with a message from role 0


@st.composite
def scribble_files(draw: st.DrawFn) -> list[tuple[object, ...]]:
    count = draw(st.integers(1, 5))
    protocols: list[tuple[object, ...]] = []

    def block(index: int, depth: int, chooser_first: bool) -> tuple[object, ...]:
        items: list[object] = []
        if chooser_first:
            items.append(Msg(draw(st.sampled_from(["l", "r", "s"])), 0, draw(st.integers(1, 2))))
        for _ in range(draw(st.integers(0 if chooser_first else 1, 3))):
            kind = draw(st.sampled_from(["msg", "msg", "do", "choice"] if depth < 3 else ["msg", "do"]))
            if kind == "do" and index + 1 < count:
                items.append(Do(draw(st.integers(index + 1, count - 1)), tuple(draw(st.permutations(range(3))))))
            elif kind == "choice":
                labels = draw(st.lists(st.sampled_from(["a", "b", "c", "d"]), min_size=2, max_size=3, unique=True))
                blocks = []
                for label in labels:
                    rest = block(index, depth + 1, False)
                    blocks.append((Msg(label, 0, 1), *rest))
                items.append(Choice(tuple(blocks)))
            else:
                sender, receiver = draw(st.permutations(range(3)))[:2]
                items.append(Msg(draw(st.sampled_from(["x", "y"])), sender, receiver))
        return tuple(items)

    for index in range(count - 1, -1, -1):  # callees first
        protocols.insert(0, block(index, 0, False))
    return protocols


def _written_out_size(protocols: list[tuple[object, ...]]) -> int:
    sizes: list[int] = [0] * len(protocols)

    def size(items: tuple[object, ...]) -> int:
        total = 0
        for item in items:
            match item:
                case Do(callee=callee):
                    total += sizes[callee]
                case Choice(blocks=blocks):
                    total += sum(size(b) for b in blocks)
                case _:
                    total += 1
        return total

    for index in range(len(protocols) - 1, -1, -1):  # callees come later
        sizes[index] = size(protocols[index])
    return sizes[0]


def _write_block(items: tuple[object, ...], roles: tuple[str, ...], protocols: list[tuple[object, ...]],
                 inline: bool) -> str:
    parts: list[str] = []
    for item in items:
        match item:
            case Msg(label=label, sender=sender, receiver=receiver):
                parts.append(f"{label}() from {roles[sender]} to {roles[receiver]};")
            case Do(callee=callee, roles=args):
                passed = tuple(roles[a] for a in args)
                if inline:
                    parts.append(_write_block(protocols[callee], passed, protocols, inline))
                else:
                    parts.append(f"do P{callee}({', '.join(passed)});")
            case Choice(blocks=blocks):
                written = " or ".join("{ " + _write_block(b, roles, protocols, inline) + " }" for b in blocks)
                parts.append(f"choice at {roles[0]} {written}")
    return " ".join(parts)


def _scribble(protocols: list[tuple[object, ...]], inline: bool, globals_: frozenset[int] = frozenset({0})) -> str:
    lines = []
    for index, body in enumerate(protocols):
        if inline and index:
            continue
        aux = "" if index in globals_ else "aux "
        lines.append(f"{aux}global protocol P{index}(role A, role B, role C) "
                     f"{{ {_write_block(body, ROLES, protocols, inline)} }}")
    return "\n".join(lines) + "\n"


def _meaning(text: str) -> object:
    try:
        module = sessiontypes.loads(text, "p.nuscr")
    except ProtocolCheckError as error:  # locations differ: the written-out text is longer
        return ("rejected", sorted(_cause(d.message) for d in error.diagnostics))
    except ProtocolError as error:
        return ("rejected", type(error).__name__)
    glob = module.globals["P0"]
    return {role: print_local(glob.project(role).body) for role in glob.roles}


@given(scribble_files())
@settings(deadline=None, max_examples=examples(200))
def test_a_shared_do_means_its_callee_written_out(protocols: list[tuple[object, ...]]) -> None:
    assume(_written_out_size(protocols) < 2_000)  # the oracle writes every 'do' out
    referring, inlined = _scribble(protocols, inline=False), _scribble(protocols, inline=True)
    assert _meaning(referring) == _meaning(inlined), (referring, inlined)


# Files whose globals each refer to later ones and end in choices learnt from several
# peers: what a global's projection is, or why it has none, is what it is on its own.

_PAIRS = [(s, r) for s in ROLES for r in ROLES if s != r]


@st.composite
def peer_choice_files(draw: st.DrawFn) -> str:
    count = draw(st.integers(2, 5))

    def body(index: int, depth: int, loop: bool) -> str:
        kinds = ["ref", "end", "msg", "choice", "peers", "peers", "routed"] if depth < 4 else ["ref", "end"]
        kind = draw(st.sampled_from([*kinds, "continue"] if loop else kinds))
        sender, receiver = draw(st.sampled_from(_PAIRS))
        match kind:
            case "ref" if index + 1 < count:
                return f"G{draw(st.integers(index + 1, count - 1))}"
            case "continue":
                return "t"
            case "msg":
                return f"{sender} -> {receiver} : {draw(st.sampled_from(['x', 'y']))}. {body(index, depth + 1, loop)}"
            case "choice":
                return (f"{sender} -> {receiver} : {{l. {body(index, depth + 1, loop)}, "
                        f"r. {body(index, depth + 1, loop)}}}")
            case "peers":  # the third role learns the choice from whichever of the two tells it first
                third = next(r for r in ROLES if r not in (sender, receiver))
                return (f"{sender} -> {receiver} : {{l. {sender} -> {third} : a. {body(index, depth + 1, loop)}, "
                        f"r. {receiver} -> {third} : b. {body(index, depth + 1, loop)}}}")
            case "routed":
                first, second = (r for r in ROLES if r != sender)
                return (f"{sender} -> {{{first} : l. {body(index, depth + 1, loop)}, "
                        f"{second} : r. {body(index, depth + 1, loop)}}}")
        return "end"

    lines = []
    for index in range(count):
        loop = draw(st.booleans())
        text = body(index, 0, loop)
        lines.append(f"global G{index} = " + (f"mu t. A -> B : go. {text}" if loop else text))
    return "\n".join(lines)


def _alone(glob: GlobalType, role: str) -> object:
    """``role``'s projection of ``glob`` with nothing remembered from the file's other globals."""
    try:
        return print_local(project_declared(glob.name, glob.roles, glob.body, role, glob.source_lines,
                                            Sharing(glob.shared.nodes)))
    except ProjectionError as error:
        return (type(error).__name__, error.message)


def _in_file(glob: GlobalType, role: str) -> object:
    try:
        return print_local(glob.project(role).body)
    except ProjectionError as error:
        return (type(error).__name__, error.message)


@given(peer_choice_files())
@settings(deadline=None, max_examples=examples(300))
def test_races_remembered_across_globals_are_those_each_global_has_on_its_own(text: str) -> None:
    try:
        module, diagnostics = check_file(parse_file(text, "peers.proto"))
    except ProtocolError:
        return
    if any(d.severity == "error" and "projectable" not in d.message for d in diagnostics):
        return  # not checked for projection
    for glob in module.globals.values():
        for role in glob.roles:
            assert _in_file(glob, role) == _alone(glob, role), (text, glob.name, role)


@given(scribble_files())
@settings(deadline=None, max_examples=examples(60))
def test_each_global_of_a_scribble_file_means_what_it_means_alone(protocols: list[tuple[object, ...]]) -> None:
    """Expansions shared between the globals of one file change none of them."""
    indices = range(len(protocols))
    together = _meanings(_scribble(protocols, inline=False, globals_=frozenset(indices)))
    alone = [_meanings(_scribble(protocols, inline=False, globals_=frozenset({i}))) for i in indices]
    if "rejected" in together:
        assert any("rejected" in one for one in alone)
    else:
        assert together == {f"P{i}": one[f"P{i}"] for i, one in enumerate(alone)}


def _meanings(text: str) -> dict[str, object]:
    try:
        module = sessiontypes.loads(text, "p.nuscr")
    except ProtocolError:
        return {"rejected": True}
    return {name: {role: _in_file(glob, role) for role in glob.roles} for name, glob in module.globals.items()}


def scribble_chain_doing_first(n: int) -> str:
    """Each protocol does the next, then sends: written out, the globals are about n**2 interactions."""
    out = [f"global protocol P{i}(role A, role B) {{ do P{i + 1}(A, B); m() from A to B; }}" for i in range(n)]
    out.append(f"global protocol P{n}(role A, role B) {{ e() from A to B; }}")
    return "\n".join(out) + "\n"


def test_protocols_that_expand_beyond_the_limit_are_a_located_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(foreign_translate, "MAX_TRANSLATED", 5_000)
    assert sessiontypes.loads(scribble_chain_doing_first(50), "chain.scr")  # about 2,500 interactions
    with pytest.raises(ProtocolCheckError) as caught:
        sessiontypes.loads(scribble_chain_doing_first(80), "chain.scr")  # about 6,500
    (error,) = caught.value.diagnostics
    assert error.location.column == error.source_line.index("do ") + 1
    assert error.message == ("the protocols expand to more than 5000 interactions (a 'do' followed by more "
                             "interactions is written out at every use); at most 5000 are translated")


@pytest.mark.slow
def test_protocols_that_expand_beyond_the_real_limit_are_refused_in_bounded_work() -> None:
    before = METER.total()
    with pytest.raises(ProtocolCheckError, match="expand to more than"):
        sessiontypes.loads(scribble_chain_doing_first(3_000), "chain.scr")  # 4.5 million written out
    assert METER.total() - before < 2 * foreign_translate.MAX_TRANSLATED
