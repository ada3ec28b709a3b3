"""Every code block of the site and the README is run or checked, and says how.

docs/language.md has its own, stricter test (tests/test_language_doc.py). Every other page
(README.md and docs/**/*.md) marks each fenced block with the HTML comment just above it
(only blank lines or prose between the previous block and the comment), ``<!-- expect: VERB -->``:

- ```proto, ```scribble, ```nuscr: ``ok`` (loads without errors or warnings, every global
  projects), ``projections`` (and the next ```text block is exactly what ``anodize project``
  prints for it) or ``error`` (loading fails, and the next ```text block is exactly the
  error; the file is called ``example.proto``), as in the language reference;
- ```python: ``run`` (run as a script from the repository's root, exit status 0),
  ``compile`` (a fragment: compiled, not run) or ``doctest``;
- ```toml: ``toml`` (parses);
- ```sh: ``commands``, optionally ``commands (external: ros2 ip)``: each command is a
  script of the repository, a tool of ``.venv/bin`` the project installs, a program on
  PATH, or one of the named external tools; an ``anodize``/``tinman`` command's
  subcommand and options exist (its ``--help`` lists them), and the repository files it
  names exist;
- ```text: the output of the example above it, or ``report`` (a run report: it starts
  ``protocol NAME: OUTCOME in N s (TRANSPORT)`` as ``RunReport.summary()`` does, and NAME is
  a global of the repository's protocols or of a block of the same page), ``transcript``
  (an illustrative session: ``$ `` lines are checked as ``commands`` are, except that the
  files they name need not exist; the rest is output), ``usage`` (each
  ``--option`` in it exists in the command-line front ends) or ``diagram`` (a picture drawn
  in text: it shows no ``$ `` command, and each NAME in capitals it shows is a constant that
  anodize's sources define);
- a tutorial's blocks (docs/guide/first-system.md, run by tests/test_first_system.py):
  ``file NAME`` above a ```proto, ```python or ```toml block (a file the reader writes: checked
  here as ``ok``, ``compile`` and ``toml`` are) and ``session`` above a ```text block, optionally
  ``session (external: mypy)`` (``$ `` commands checked here as a transcript's are, and run by
  the tutorial's test, in order, in an empty folder with the page's files, each exiting 0 and
  printing what follows it; a line ``...`` stands for any lines, ``...`` in a line for any text).

A block of any other kind, or without an expectation, fails this test.
"""

from __future__ import annotations

import contextlib
import doctest
import importlib
import io
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from test_language_doc import MARKER, _blocks, _projections

import sessiontypes

REPO = Path(__file__).resolve().parents[1]
LANGUAGE = REPO / "docs" / "language.md"
PAGES = [REPO / "README.md", *sorted(p for p in (REPO / "docs").rglob("*.md") if p != LANGUAGE)]

SOURCE_KINDS = {"proto": "example.proto", "scribble": "example.scr", "nuscr": "example.nuscr"}
VERBS = {
    "proto": {"ok", "projections", "error", "file"}, "scribble": {"ok", "projections", "error"},
    "nuscr": {"ok", "projections", "error"}, "python": {"run", "compile", "doctest", "file"},
    "toml": {"toml", "file"}, "sh": {"commands"}, "text": {"report", "transcript", "usage", "diagram", "session"},
}
NEEDS_OUTPUT = {"projections", "error"}
# The tools `.venv/bin` holds after scripts/bootstrap: the project's scripts and its extras' tools.
VENV_TOOLS = {"python", "pip", "pytest", "mypy", "ruff", "lint-imports", "mkdocs"}


@dataclass(frozen=True)
class Checked:
    page: str  # relative to the repository
    kind: str
    verb: str
    argument: str  # what follows the verb, e.g. "(external: ros2)"
    code: str
    line: int
    output: str | None


def _rel(path: Path) -> str:
    return path.relative_to(REPO).as_posix()


def read_page(text: str, page: str) -> tuple[list[Checked], list[str]]:
    """The blocks of a page with their expectations, and every problem with its marking."""
    blocks = _blocks(text)
    found: list[Checked] = []
    problems: list[str] = []
    claimed: set[int] = set()
    used: set[int] = set()
    for index, block in enumerate(blocks):
        if index in claimed:
            continue
        where = f"{page}:{block.line}"
        if block.kind not in VERBS:
            problems.append(f"{where}: a ```{block.kind or '(no kind)'} block; use one of {', '.join(sorted(VERBS))}")
            continue
        previous_end = blocks[index - 1].end if index else 0
        markers = list(MARKER.finditer(text, previous_end, block.start))
        if not markers:
            problems.append(f"{where}: a block without an expectation (put <!-- expect: ... --> above it)")
            continue
        marker = markers[-1]
        used.add(marker.start())
        verb, _, argument = marker.group(1).partition(" ")
        if verb not in VERBS[block.kind]:
            problems.append(f"{where}: 'expect: {verb}' is not one of {sorted(VERBS[block.kind])} for ```{block.kind}")
            continue
        output = None
        if verb in NEEDS_OUTPUT:
            following = blocks[index + 1] if index + 1 < len(blocks) else None
            if following is None or following.kind != "text":
                problems.append(f"{where}: 'expect: {verb}' needs a ```text block after it")
                continue
            claimed.add(index + 1)
            output = following.text
        found.append(Checked(page, block.kind, verb, argument.strip(), block.text, block.line, output))
    problems.extend(f"{page}:{text.count(chr(10), 0, m.start()) + 1}: an expectation with no block"
                    for m in MARKER.finditer(text) if m.start() not in used)
    return found, problems


READ = {_rel(page): read_page(page.read_text(encoding="utf-8"), _rel(page)) for page in PAGES}
ALL = [checked for blocks, _ in READ.values() for checked in blocks]


def _id(checked: Checked) -> str:
    return f"{checked.page}:{checked.line}-{checked.verb}"


def test_every_block_has_an_expectation() -> None:
    problems = [problem for _, found in READ.values() for problem in found]
    assert problems == []
    assert {c.verb for c in ALL} >= {"projections", "error", "run", "compile", "toml", "commands", "report"}


def test_the_reader_catches_what_it_should() -> None:
    assert read_page("```sh\nls\n```\n", "p")[1]  # no expectation
    assert read_page("```\nls\n```\n", "p")[1]  # no kind
    assert read_page("<!-- expect: run -->\n```sh\nls\n```\n", "p")[1]  # the wrong verb for its kind
    assert read_page("<!-- expect: projections -->\n```proto\nglobal P = A -> B : x\n```\n", "p")[1]
    assert read_page("<!-- expect: commands -->\n", "p")[1]  # an expectation with no block
    good = "<!-- expect: commands (external: ros2) -->\n```sh\nros2 topic list\n```\n"
    assert read_page(good, "p") == ([Checked("p", "sh", "commands", "(external: ros2)", "ros2 topic list\n", 2,
                                              None)], [])


# ---- source blocks ----------------------------------------------------------------------------


@pytest.mark.parametrize("checked", [c for c in ALL if c.kind in SOURCE_KINDS], ids=_id)
def test_source_block(checked: Checked) -> None:
    name = SOURCE_KINDS[checked.kind]
    if checked.verb == "error":
        with pytest.raises(sessiontypes.ProtocolError) as caught:
            sessiontypes.loads(checked.code, name)
        assert str(caught.value) + "\n" == checked.output
        return
    module = sessiontypes.loads(checked.code, name)
    assert module.warnings == ()
    if checked.verb == "projections":
        assert _projections(module) == checked.output
    for global_type in module.globals.values():
        global_type.projections()


# ---- python blocks ----------------------------------------------------------------------------


@pytest.mark.parametrize("checked", [c for c in ALL if c.kind == "python"], ids=_id)
def test_python_block(checked: Checked, tmp_path: Path) -> None:
    if checked.verb in {"compile", "file"}:  # a tutorial's file runs in its test (tests/test_first_system.py)
        compile(checked.code, f"{checked.page}:{checked.line}", "exec")
    elif checked.verb == "doctest":
        test = doctest.DocTestParser().get_doctest(checked.code, {}, _id(checked), checked.page, checked.line)
        assert test.examples, "a doctest block needs >>> lines"
        report: list[str] = []
        runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
        runner.run(test, out=report.append)
        assert runner.failures == 0, "".join(report)
    else:
        script = tmp_path / "example.py"
        script.write_text(checked.code, encoding="utf-8")
        done = subprocess.run([sys.executable, str(script)], cwd=REPO, capture_output=True, text=True, timeout=120,
                              check=False)
        assert done.returncode == 0, f"{checked.page}:{checked.line} exited {done.returncode}:\n{done.stderr}"


@pytest.mark.parametrize("checked", [c for c in ALL if c.kind == "toml"], ids=_id)
def test_toml_block(checked: Checked) -> None:
    tomllib.loads(checked.code)


# ---- commands ---------------------------------------------------------------------------------


def _front_end(name: str) -> Callable[[list[str]], int]:
    """The ``main(argv)`` of the console script ``name`` as pyproject.toml declares it."""
    scripts = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]["scripts"]
    module, _, _ = scripts[name].partition(":")
    main: Callable[[list[str]], int] = importlib.import_module(module).main
    return main


def _help(program: str, args: list[str]) -> str:
    """What ``program ARGS --help`` prints; its exit status must be 0 (argparse's, or main's return)."""
    out = io.StringIO()
    status: object = None
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        try:
            status = _front_end(program)([*args, "--help"])
        except SystemExit as exited:
            status = exited.code
    assert status in (0, None), f"'{program} {' '.join(args)}' is not a command (exit status {status})"
    return out.getvalue()


OUTPUT_OPTIONS = {"-o", "--out", "--json", "--record"}
FILE_SUFFIXES = (".toml", ".proto", ".py", ".scr", ".nuscr", ".mcap")


def check_command(line: str, external: set[str], files: bool = True) -> None:
    """One shell command line: its programs exist, and anodize's options and (with ``files``) files too."""
    for part in re.split(r"&&|\|\||[;|&]", line.split(" #")[0]):
        words = shlex.split(part)
        while words and re.fullmatch(r"\w+=\S*", words[0]):
            words = words[1:]  # VARIABLE=value before the command
        if words[:3] == ["ip", "netns", "exec"]:
            words = words[4:]  # the command run inside a namespace
        if not words or words[0] in {"for", "do", "done", "then", "fi"}:
            continue
        program = words[0]
        if program.startswith(".venv/bin/"):
            program = program.removeprefix(".venv/bin/")
            assert program in VENV_TOOLS | {"anodize", "tinman"}, f"{words[0]}: not a tool the project installs"
        elif program.startswith("./"):
            assert (REPO / program).is_file(), f"{program}: no such script in the repository"
            continue
        elif program not in {"anodize", "tinman"}:
            assert program in external or shutil.which(program), f"{program}: not on PATH and not named external"
            continue
        if program in {"anodize", "tinman"}:
            args = words[1:]
            head = args[:1]
            if program == "anodize" and args[:1] == ["run"] and len(args) > 1 and not args[1].endswith(".toml"):
                head = args[:2]  # a named system has its own options
            text = _help(program, head)
            for word in args:
                if word.startswith("--"):
                    assert word.split("=")[0] in text, f"'{program} {' '.join(head)}' has no option {word}"
            for before, word in zip(["", *args], args, strict=False):
                if files and word.endswith(FILE_SUFFIXES) and before not in OUTPUT_OPTIONS \
                        and not word.startswith("out/"):
                    assert (REPO / word).exists(), f"{word}: no such file in the repository"


def _external(argument: str) -> set[str]:
    found = re.fullmatch(r"\(external:\s*([^)]*)\)", argument)
    return set(found.group(1).split()) if found else set()


@pytest.mark.parametrize("checked", [c for c in ALL if c.verb in {"commands", "transcript", "session"}], ids=_id)
def test_command_block(checked: Checked) -> None:
    lines = checked.code.replace("\\\n", " ").splitlines()  # a line continued with a backslash is one
    if checked.verb in {"transcript", "session"}:
        lines = [line[2:] for line in lines if line.startswith("$ ")]
        assert lines, "a transcript shows at least one '$ ' command"
    for line in lines:
        if line.strip() and not line.lstrip().startswith("#"):
            check_command(line, _external(checked.argument), files=checked.verb == "commands")


def test_the_command_check_catches_what_it_should() -> None:
    for bad in ["anodize frobnicate x.proto", "anodize run examples/mixed_criticality/system.toml --frob",
                "anodize check protocols/no_such.proto", "no-such-program-here --x", "./scripts/no_such"]:
        with pytest.raises(AssertionError):
            check_command(bad, set())
    check_command("ros2 topic list", {"ros2"})


# ---- text blocks ------------------------------------------------------------------------------


def _globals_of_the_repository() -> set[str]:
    names: set[str] = set()
    for path in [*REPO.glob("protocols/*.proto"), *REPO.glob("examples/**/*.proto"),
                 *REPO.glob("tinman/src/tinman/*.proto")]:
        names |= set(re.findall(r"^\s*global\s+(\w+)", path.read_text(encoding="utf-8"), re.MULTILINE))
    return names


@pytest.mark.parametrize("checked", [c for c in ALL if c.verb == "report"], ids=_id)
def test_report_block(checked: Checked) -> None:
    first = checked.code.splitlines()[0]
    found = re.match(r"protocol (\w+): (ok|NOT ok|stopped, no failures|interrupted) in [0-9.]+ s "
                     r"\((inproc|process|dds)\)$", first)
    assert found, f"a run report starts 'protocol NAME: outcome in N s (transport)' (RunReport.summary), got {first!r}"
    on_the_page = {name for c in ALL if c.page == checked.page for name in re.findall(r"global\s+(\w+)", c.code)}
    assert found.group(1) in _globals_of_the_repository() | on_the_page, \
        f"no global {found.group(1)} in the repository's protocols or on the page"


@pytest.mark.parametrize("checked", [c for c in ALL if c.verb == "usage"], ids=_id)
def test_usage_block(checked: Checked) -> None:
    sources = "".join(p.read_text(encoding="utf-8")
                      for p in [*REPO.glob("anodize/**/*.py"), *REPO.glob("tinman/src/tinman/*.py")])
    for option in sorted(set(re.findall(r"--[a-z][a-z-]*", checked.code))):
        assert f'"{option}"' in sources, f"{option}: no front end defines it"


def check_diagram(code: str) -> None:
    """A picture in text: no command in it, and each constant it names defined in anodize."""
    assert not any(line.startswith("$ ") for line in code.splitlines()), \
        "a diagram shows no command; make a session a transcript"
    sources = "".join(p.read_text(encoding="utf-8") for p in REPO.glob("anodize/**/*.py"))
    for name in sorted(set(re.findall(r"\b[A-Z][A-Z0-9]*_[A-Z0-9_]+\b|\b[A-Z]{4,}\b", code))):
        assert re.search(rf"^{name}\b.*=", sources, re.MULTILINE), f"{name}: no constant of anodize defines it"


@pytest.mark.parametrize("checked", [c for c in ALL if c.verb == "diagram"], ids=_id)
def test_diagram_block(checked: Checked) -> None:
    check_diagram(checked.code)


def test_the_diagram_check_catches_what_it_should() -> None:
    check_diagram("role --> queue (CLIENT_BACKLOG messages)\n")
    for bad in ["$ anodize run x.toml\n", "role --> queue (NO_SUCH_CONSTANT messages)\n"]:
        with pytest.raises(AssertionError):
            check_diagram(bad)
