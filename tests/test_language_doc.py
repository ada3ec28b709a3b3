"""Every example of docs/language.md runs, and says what it should.

The language reference shows examples in fenced blocks. An example is a ```proto,
```scribble, ```nuscr or ```python block, and the HTML comment just above it (only
blank lines between) says what to expect:

- ``<!-- expect: ok -->``: the file loads, without errors or warnings;
- ``<!-- expect: projections -->``: it loads without warnings, and the next ```text block
  is exactly what ``anodize project FILE`` prints (``Role = <local type>`` lines, each
  local type in its canonical print; ``# Global`` above each global's block when the file
  has several);
- ``<!-- expect: locals -->``: it loads without warnings, and the next ```text block is
  ``Name = <canonical print>`` for each ``local`` declaration, in file order;
- ``<!-- expect: error -->``: loading raises a :class:`ProtocolError` whose text (what
  ``anodize check FILE`` prints: ``FILE:line:col: error: ...``, the line and a caret) is
  exactly the next ```text block;
- ``<!-- expect: warnings -->``: it loads, and its warnings are exactly the next ```text block;
- ``<!-- expect: fsm ROLE -->``: the next ```text block is exactly what
  ``anodize fsm FILE --role ROLE`` prints (the state machine in DOT);
- ``<!-- expect: doctest -->`` (```python blocks only): the block is a doctest and passes.

The file is written as ``example.proto`` (``example.scr``, ``example.nuscr``), the name
the doc's outputs show. A ```text block must belong to the example before it; a
```grammar block is a grammar fragment, whose quoted tokens must be tokens of the
parser. Any other block, an example without an expectation, an expectation without an
example or an output block missing is a failure of this test.
"""

from __future__ import annotations

import doctest
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

import sessiontypes
from anodize._tools import cli
from sessiontypes import ProtocolError

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "language.md"
GRAMMARS = [REPO / "sessiontypes" / "grammar.lark"]

# Example blocks and the file name each is loaded as.
EXAMPLE_FILES = {"proto": "example.proto", "scribble": "example.scr", "nuscr": "example.nuscr", "python": None}
NEEDS_OUTPUT = {"projections", "locals", "error", "warnings", "fsm"}
OTHER_BLOCKS = {"text", "grammar"}

FENCE = re.compile(r"^```([^\n`]*)\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
MARKER = re.compile(r"<!--\s*expect:\s*(.*?)\s*-->")


@dataclass(frozen=True)
class Block:
    kind: str  # the fence's info string
    text: str
    line: int  # of the opening fence
    start: int  # offsets in the doc
    end: int


@dataclass(frozen=True)
class Example:
    kind: str  # proto, scribble, nuscr, python
    code: str
    line: int
    expect: str  # ok, projections, locals, error, warnings, fsm ROLE, doctest
    output: str | None  # the ```text block that follows, when the expectation needs one


def _line_of(text: str, offset: int) -> int:
    return text.count("\n", 0, offset) + 1


def _blocks(text: str) -> list[Block]:
    return [Block(m.group(1).strip(), m.group(2), _line_of(text, m.start()), m.start(), m.end())
            for m in FENCE.finditer(text)]


def read_doc(text: str) -> tuple[list[Example], list[str]]:
    """The examples of the doc, and every problem with its structure (empty when sound)."""
    blocks = _blocks(text)
    problems: list[str] = []
    examples: list[Example] = []
    claimed: set[int] = set()  # indexes of text blocks that are an example's output
    markers_used: set[int] = set()
    for index, block in enumerate(blocks):
        where = f"docs/language.md:{block.line}"
        if block.kind not in EXAMPLE_FILES and block.kind not in OTHER_BLOCKS:
            problems.append(f"{where}: a ```{block.kind} block; use proto, scribble, nuscr, python, text or grammar")
            continue
        if block.kind not in EXAMPLE_FILES:
            continue
        previous_end = blocks[index - 1].end if index else 0
        between = text[previous_end:block.start]
        marker = None
        for found in MARKER.finditer(between):
            marker = found
        if marker is None or between[marker.end():].strip():
            problems.append(f"{where}: an example without an expectation (put <!-- expect: ... --> just above it)")
            continue
        markers_used.add(previous_end + marker.start())
        expect = marker.group(1)
        verb = expect.split()[0] if expect else ""
        if verb not in {"ok", "doctest"} | NEEDS_OUTPUT or (verb == "fsm") != (len(expect.split()) == 2) or (
                verb != "fsm" and len(expect.split()) != 1):
            problems.append(f"{where}: unknown expectation {expect!r}")
            continue
        if (verb == "doctest") != (block.kind == "python"):
            problems.append(f"{where}: 'doctest' is the expectation of python blocks, and theirs only")
            continue
        output = None
        if verb in NEEDS_OUTPUT:
            following = blocks[index + 1] if index + 1 < len(blocks) else None
            if following is None or following.kind != "text":
                problems.append(f"{where}: 'expect: {expect}' needs a ```text block after the example")
                continue
            claimed.add(index + 1)
            output = following.text
        examples.append(Example(block.kind, block.text, block.line, expect, output))
    for index, block in enumerate(blocks):
        if block.kind == "text" and index not in claimed:
            problems.append(f"docs/language.md:{block.line}: a ```text block that is no example's output")
    problems.extend(f"docs/language.md:{_line_of(text, marker.start())}: an expectation with no example"
                    for marker in MARKER.finditer(text) if marker.start() not in markers_used)
    return examples, problems


DOC_TEXT = DOC.read_text(encoding="utf-8")
EXAMPLES, PROBLEMS = read_doc(DOC_TEXT)


def _id(example: Example) -> str:
    return f"line{example.line}-{example.expect.replace(' ', '-')}"


def test_the_doc_exists_and_every_block_has_an_expectation() -> None:
    assert PROBLEMS == []
    assert len(EXAMPLES) >= 30
    kinds = {e.expect.split()[0] for e in EXAMPLES}
    assert kinds == {"ok", "projections", "locals", "error", "warnings", "fsm", "doctest"}


def test_the_structure_check_catches_what_it_should() -> None:
    """The reader of the doc fails on an example with no expectation or no output."""
    assert read_doc("```proto\nglobal P = A -> B : x\n```\n")[1]
    assert read_doc("<!-- expect: projections -->\n```proto\nglobal P = A -> B : x\n```\n")[1]
    assert read_doc("<!-- expect: ok -->\n```proto\nglobal P = A -> B : x\n```\n```text\nA\n```\n")[1]
    assert read_doc("<!-- expect: ok -->\ntext\n```proto\nglobal P = A -> B : x\n```\n")[1]
    assert read_doc("<!-- expect: fine -->\n```proto\nglobal P = A -> B : x\n```\n")[1]
    assert read_doc("```sh\nls\n```\n")[1]
    assert read_doc("<!-- expect: ok -->\n")[1]
    good = "<!-- expect: projections -->\n```proto\nglobal P = A -> B : x\n```\nprints\n```text\nA = !B(x)\n```\n"
    assert read_doc(good) == ([Example("proto", "global P = A -> B : x\n", 2, "projections", "A = !B(x)\n")], [])


def _load(example: Example) -> sessiontypes.ProtocolModule:
    path = EXAMPLE_FILES[example.kind]
    assert path is not None
    return sessiontypes.loads(example.code, path)


def _projections(module: sessiontypes.ProtocolModule) -> str:
    lines: list[str] = []
    for global_type in module.globals.values():
        if len(module.globals) > 1:
            lines.append(f"# {global_type.name}")
        lines.extend(f"{role} = {global_type.project(role)}" for role in global_type.roles)
    return "".join(f"{line}\n" for line in lines)


def _run_cli(args: list[str], example: Example, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
             capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    path = EXAMPLE_FILES[example.kind]
    assert path is not None
    (tmp_path / path).write_text(example.code, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    status = cli.main([args[0], path, *args[1:]])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


SOURCE_EXAMPLES = [e for e in EXAMPLES if e.kind != "python"]


@pytest.mark.parametrize("example", SOURCE_EXAMPLES, ids=_id)
def test_example(example: Example, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                 capsys: pytest.CaptureFixture[str]) -> None:
    verb, *rest = example.expect.split()
    if verb == "error":
        assert example.output is not None
        with pytest.raises(ProtocolError) as caught:
            _load(example)
        # The stated message and its location: the whole text, 'file:line:col: error: ...', line, caret.
        assert re.search(r"^example\.\w+:\d+:\d+: error: ", example.output, re.MULTILINE), "state its location"
        assert str(caught.value) + "\n" == example.output
        status, out, err = _run_cli(["check"], example, tmp_path, monkeypatch, capsys)
        assert (status, out, err) == (1, "", example.output)
        return
    module = _load(example)
    if verb == "warnings":
        assert example.output is not None
        assert module.warnings, "the example has no warnings"
        assert "".join(f"{w}\n" for w in module.warnings) == example.output
        return
    assert module.warnings == ()
    if verb == "projections":
        assert _projections(module) == example.output
        assert _run_cli(["project"], example, tmp_path, monkeypatch, capsys) == (0, example.output, "")
    elif verb == "locals":
        assert "".join(f"{name} = {local}\n" for name, local in module.locals.items()) == example.output
    elif verb == "fsm":
        (role,) = rest
        (global_type,) = module.globals.values()
        assert global_type.project(role).fsm().to_dot() + "\n" == example.output
        assert _run_cli(["fsm", "--role", role], example, tmp_path, monkeypatch, capsys) == (0, example.output, "")
    else:
        assert verb == "ok"
        for global_type in module.globals.values():
            global_type.projections()  # projectable onto every role
        for local in module.locals.values():
            local.fsm()


@pytest.mark.parametrize("example", [e for e in EXAMPLES if e.kind == "python"], ids=_id)
def test_python_example(example: Example) -> None:
    test = doctest.DocTestParser().get_doctest(example.code, {}, _id(example), str(DOC), example.line)
    assert test.examples, "a python example must be a doctest (>>> lines)"
    report: list[str] = []
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    runner.run(test, out=report.append)
    assert runner.failures == 0, "".join(report)


def test_grammar_fragments_use_the_parsers_tokens() -> None:
    """Every quoted token of a ```grammar block is a token of grammar.lark (or of the doc's own list)."""
    tokens = set()
    for grammar in GRAMMARS:
        tokens |= set(re.findall(r'"([^"\\]+)"', grammar.read_text(encoding="utf-8")))
    fragments = [b for b in _blocks(DOC_TEXT) if b.kind == "grammar"]
    assert fragments
    for block in fragments:
        for token in re.findall(r'"([^"\\]+)"', block.text):
            assert token in tokens, f"docs/language.md:{block.line}: {token!r} is not a token of the grammar"


def test_the_additions_are_folded_in() -> None:
    """docs/language-additions.md is part of this reference now; nothing links to it."""
    assert not (REPO / "docs" / "language-additions.md").exists()
    for path in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]:
        assert "language-additions" not in path.read_text(encoding="utf-8"), path
