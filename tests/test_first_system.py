"""The tutorial docs/guide/first-system.md, run as written, from an empty folder.

Its ``<!-- expect: file NAME -->`` blocks are written into an empty folder as the reader
would, in the page's order; each ``<!-- expect: session -->`` block's ``$`` commands run there
(bash, with ``anodize``, ``mypy`` and ``python`` this checkout's), each must exit 0 and print
what the page shows after it: a line ``...`` stands for any lines, ``...`` in a line for any
text. Nothing of the tutorial is copied here: the page is the test's only source.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from test_docs_blocks import Checked, read_page

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "guide" / "first-system.md"


def _steps() -> list[Checked]:
    found, problems = read_page(PAGE.read_text(encoding="utf-8"), "docs/guide/first-system.md")
    assert problems == []
    return [c for c in found if c.verb in {"file", "session"}]


def session_commands(code: str) -> list[tuple[str, str]]:
    """A session block's ``$`` commands, each with the output the page shows after it."""
    commands: list[tuple[str, list[str]]] = []
    for line in code.splitlines():
        if line.startswith("$ "):
            commands.append((line[2:], []))
        else:
            assert commands, f"output before the first command: {line!r}"
            commands[-1][1].append(line)
    return [(command, "".join(f"{line}\n" for line in output)) for command, output in commands]


def shown_matches(shown: str, printed: str) -> bool:
    """Whether ``printed`` is what the page ``shown``: ``...`` alone on a line is any lines, in a line any text."""
    pattern = ""
    for line in shown.splitlines():
        if line == "...":
            pattern += r"(?:[^\n]*\n)*?"
        else:
            pattern += re.escape(line).replace(re.escape("..."), r"[^\n]*") + r"\n"
    text = "".join(f"{line.rstrip()}\n" for line in printed.splitlines())
    return re.fullmatch(pattern, text) is not None


def test_the_matcher_catches_what_it_should() -> None:
    assert shown_matches("a\n...\nz\n", "a\nb\nc\nz\n")
    assert shown_matches("a\n...\nz\n", "a\nz\n")
    assert shown_matches("ok in ... s\n", "ok in 1.25 s\n")
    assert not shown_matches("a\nz\n", "a\nb\nz\n")
    assert not shown_matches("ok in ... s\n", "ok in 1.25 s\nmore\n")
    assert not shown_matches("x ... y\n", "x 1\ny\n")  # '...' in a line does not cross lines
    assert session_commands("$ a\none\n$ b\n") == [("a", "one\n"), ("b", "")]


def _tools(folder: Path) -> dict[str, str]:
    """An environment whose ``anodize``, ``mypy`` and ``python`` are this checkout's, first on PATH."""
    tools = folder / "tools"
    tools.mkdir()
    for name, module in {"anodize": ["-m", "anodize._tools.cli"], "mypy": ["-m", "mypy"], "python": []}.items():
        tool = tools / name
        tool.write_text(f'#!/bin/sh\nexec {sys.executable} {" ".join(module)} "$@"\n', encoding="utf-8")
        tool.chmod(0o755)
    pythonpath = os.pathsep.join([str(REPO), str(REPO / "tinman" / "src")])
    return {**os.environ, "PATH": f"{tools}{os.pathsep}{os.environ.get('PATH', '')}", "PYTHONPATH": pythonpath,
            "MYPY_CACHE_DIR": str(folder / "mypy-cache")}


def test_the_page_has_files_and_sessions() -> None:
    steps = _steps()
    assert {c.argument for c in steps if c.verb == "file"} >= {"drive.proto", "roles.py", "drive.toml"}
    commands = [command for c in steps if c.verb == "session" for command, _ in session_commands(c.code)]
    for needed in ["anodize check", "anodize project", "mypy", "anodize run", "--record", "anodize verify"]:
        assert any(needed in command for command in commands), f"the tutorial runs no {needed!r}"


@pytest.mark.slow
def test_the_tutorial_runs_from_an_empty_folder(tmp_path: Path) -> None:
    folder = tmp_path / "drive"
    folder.mkdir()
    env = _tools(tmp_path)
    for step in _steps():
        if step.verb == "file":
            (folder / step.argument).write_text(step.code, encoding="utf-8")
            continue
        for command, shown in session_commands(step.code):
            done = subprocess.run(["bash", "-c", command], cwd=folder, env=env, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, text=True, timeout=180, check=False)
            where = f"{step.page}:{step.line}: $ {command}"
            assert done.returncode == 0, f"{where}\nexited {done.returncode}:\n{done.stdout}"
            assert shown_matches(shown, done.stdout), f"{where}\nthe page shows:\n{shown}\nit printed:\n{done.stdout}"
