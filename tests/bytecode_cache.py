"""Bytecode for the suite's processes where the environment forbids Python to write it.

With ``PYTHONDONTWRITEBYTECODE`` set (``python -B``; CI shells and sandboxes often set it), no
``__pycache__`` is written, so every Python process the suite starts -- each group of a system
on the process transport (multiprocessing's ``spawn``, which passes ``-B`` on), each command run
in a subprocess -- compiles anodize, sessiontypes, TinMan and the role modules from source
again: about a quarter of a second of CPU per process, thousands of processes per run.

This plugin (loaded by tests/conftest.py) compiles those sources once, at the start of the
session, into their ``__pycache__`` folders (where Python itself would have written them;
.gitignore ignores them); the processes then only read them, as ``-B`` allows. Python checks
each cached file against its source (modification time and size), so a stale one is compiled
again, never trusted. Where Python writes bytecode itself, it does nothing. ``-p no:bytecode_cache``
turns it off.
"""

from __future__ import annotations

import compileall
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("sessiontypes", "anodize", "tinman/src", "tests", "examples", "bench")  # what its processes import


def pytest_configure(config: pytest.Config) -> None:
    if not sys.dont_write_bytecode:
        return  # each process writes what it compiles, for the next
    for source in SOURCES:  # about a second on a first run, a few milliseconds after; a read-only tree is left as is
        compileall.compile_dir(ROOT / source, quiet=2)
