"""Hostile inputs for every reader of a file, by family, and the bounded way to run a command on them.

Families (issue 27): huge, deep, wide, infinite (devices, FIFOs), malformed, lying (declared
lengths, counts or types that disagree with the content, wrong magic, truncated). Each
:class:`Case` writes its files into a folder and names the command line that reads them.
:func:`run_bounded` runs it in a subprocess under ``prlimit`` (address space and CPU time)
with a wall-clock bound; :func:`assert_clean` is what every case must satisfy.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

ADDRESS_SPACE = 1536 * 2**20  # bytes: the whole process, libraries included
CPU_SECONDS = 60
WALL_SECONDS = 120.0          # a bound, not an expectation: the default cases take about a second each
EXIT_STATUSES = {0, 1, 2}     # success, the input has errors, usage errors

ANODIZE = [sys.executable, "-m", "anodize._tools.cli"]
TINMAN = [sys.executable, "-c", "import sys; from tinman.cli import main; sys.exit(main())"]

GOOD_PROTOCOL = "global G(A, B) = A -> B : { ping(int). B -> A : pong. end, stop. end }\n"


@dataclass(frozen=True)
class Case:
    """One hostile input: ``make(folder)`` writes its files and returns the command line.

    Attributes:
        name: the test id, ``family-reader-what``.
        make: writes the input into a folder; returns argv (relative to the folder).
        expect: a fragment stderr or stdout must contain ("" for any clean outcome).
        slow: in the slow sweep only.
        env: extra environment variables.
    """

    name: str
    make: Callable[[Path], list[str]]
    expect: str = ""
    slow: bool = False
    env: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Outcome:
    status: int
    stdout: str
    stderr: str


def run_bounded(argv: list[str], cwd: Path, env: dict[str, str] | None = None) -> Outcome:
    """Run ``argv`` under ``prlimit --as --cpu`` in ``cwd``; kill it after ``WALL_SECONDS``."""
    environment = {key: value for key, value in os.environ.items() if key != "ANODIZE_DEBUG"}  # no tracebacks
    environment.update(PYTHONPATH=f"{ROOT}{os.pathsep}{ROOT / 'tinman' / 'src'}", **(env or {}))
    command = ["prlimit", f"--as={ADDRESS_SPACE}", f"--cpu={CPU_SECONDS}", "--", *argv]
    done = subprocess.run(command, cwd=cwd, env=environment, capture_output=True, timeout=WALL_SECONDS,
                          stdin=subprocess.DEVNULL, check=False)
    return Outcome(done.returncode, done.stdout.decode("utf-8", "replace"), done.stderr.decode("utf-8", "replace"))


def assert_clean(outcome: Outcome, expect: str = "") -> None:
    """Exit 0, 1 or 2 (never a signal); no traceback and no internal error on stderr."""
    tail = outcome.stderr[-2000:]
    assert outcome.status >= 0, f"killed by signal {-outcome.status}: {tail}"
    assert outcome.status in EXIT_STATUSES, f"exit {outcome.status}: {tail}"
    assert "Traceback" not in outcome.stderr, tail
    assert "internal error" not in outcome.stderr, tail
    if expect:
        assert expect in outcome.stderr + outcome.stdout, tail


def wait_for(predicate: Callable[[], bool], timeout: float = 60.0) -> bool:
    """Poll ``predicate`` until it holds or ``timeout`` seconds pass; return whether it held."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


# --- protocol text: .proto, .scr, .nuscr -------------------------------------------------------

def sequence_proto(messages: int) -> str:
    body = "".join(f"A -> B : m{i}(int). " for i in range(messages))
    return f"global G(A, B) = {body}end\n"


def nested_choice_proto(depth: int) -> str:
    text = "end"
    for level in range(depth):
        text = f"A -> B : {{ l{level}. {text}, r{level}. end }}"
    return f"global G(A, B) = {text}\n"


def wide_choice_proto(labels: int) -> str:
    branches = ", ".join(f"l{i}(int). end" for i in range(labels))
    return f"global G(A, B) = A -> B : {{ {branches} }}\n"


def many_roles_proto(roles: int) -> str:
    names = [f"R{i}" for i in range(roles)]
    body = "".join(f"{names[i]} -> {names[i + 1]} : m. " for i in range(roles - 1))
    return f"global G({', '.join(names)}) = {body}end\n"


def scribble_sequence(messages: int) -> str:
    body = "".join(f"  m{i}() from A to B;\n" for i in range(messages))
    return f"module M;\nglobal protocol P(role A, role B) {{\n{body}}}\n"


def scribble_do_per_level(levels: int) -> str:
    """A choice with two ``do`` per level: exponential when each ``do`` is copied."""
    protocols = [f"global protocol P{levels}(role A, role B) {{ end() from A to B; }}\n"]
    protocols.extend(
        f"global protocol P{level}(role A, role B) {{ choice at A {{ a{level}() from A to B; "
        f"do P{level + 1}(A, B); }} or {{ b{level}() from A to B; do P{level + 1}(A, B); }} }}\n"
        for level in reversed(range(levels)))
    return "module M;\n" + "".join(reversed(protocols))


def scribble_chain(declarations: int) -> str:
    """``P0`` does ``P1`` does ... ``Pn``: a declaration chain."""
    parts = [f"global protocol P{i}(role A, role B) {{ m{i}() from A to B; do P{i + 1}(A, B); }}\n"
             for i in range(declarations)]
    parts.append(f"global protocol P{declarations}(role A, role B) {{ end() from A to B; }}\n")
    return "module M;\n" + "".join(parts)


def sparse(path: Path, size: int, head: bytes = b"") -> None:
    """A file of ``size`` bytes that takes no disk: ``head`` and then a hole."""
    with path.open("wb") as file:
        file.write(head)
        file.truncate(size)


def noise(seed: int, size: int) -> bytes:
    return random.Random(seed).randbytes(size)


def write(folder: Path, name: str, content: str | bytes) -> str:
    path = folder / name
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8")
    else:
        path.write_bytes(content)
    return name


def fifo(folder: Path, name: str) -> str:
    os.mkfifo(folder / name)
    return name


# --- system files ----------------------------------------------------------------------------

def system_file(folder: Path, protocol: str = "p.proto", extra: str = "", groups: str | None = None,
                name: str = "s.toml") -> str:
    if protocol == "p.proto" and not (folder / "p.proto").exists():
        write(folder, "p.proto", GOOD_PROTOCOL)
    write(folder, "roles.py", "def a(ep):\n    pass\n\n\ndef b(ep):\n    pass\n")
    groups = groups if groups is not None else ('[groups.one]\nroles = { A = "roles:a" }\n'
                                                '[groups.two]\nroles = { B = "roles:b" }\n')
    return write(folder, name, f'protocol = "{protocol}"\nglobal = "G"\n{extra}\n{groups}')


# --- recordings --------------------------------------------------------------------------------

MCAP_MAGIC = b"\x89MCAP0\r\n"


def good_mcap(path: Path, messages: int = 3) -> bytes:
    """A small valid MCAP file (not recorded by anodize: no protocol inside); returns its bytes."""
    from mcap.writer import Writer

    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="", library="hostile")
        schema = writer.register_schema("S", "jsonschema", b"{}")
        channel = writer.register_channel("/t", "json", schema)
        for number in range(messages):
            writer.add_message(channel, number, b"{}", number)
        writer.finish()
    return path.read_bytes()


def record(opcode: int, content: bytes, declared: int | None = None) -> bytes:
    length = len(content) if declared is None else declared
    return bytes([opcode]) + length.to_bytes(8, "little") + content


def lying_record_mcap(folder: Path) -> bytes:
    """The magic, a header, then a record that declares 2**60 bytes and holds 16."""
    header = record(0x01, (0).to_bytes(4, "little") + (0).to_bytes(4, "little"))
    return MCAP_MAGIC + header + record(0x05, b"x" * 16, declared=2**60) + MCAP_MAGIC


def lying_footer_mcap(folder: Path) -> bytes:
    """A valid file whose footer's summary offset points past the end."""
    data = bytearray(good_mcap(folder / "base.mcap"))
    footer_at = len(data) - len(MCAP_MAGIC) - (1 + 8 + 20)
    data[footer_at + 9:footer_at + 17] = (2**62).to_bytes(8, "little")
    return bytes(data)


def lying_chunk_mcap(folder: Path) -> bytes:
    """A valid file whose chunks claim an uncompressed size of 2**40 bytes."""
    data = bytearray(good_mcap(folder / "base.mcap"))
    at = 0
    while (at := data.find(b"\x06", at)) != -1:  # opcode of a chunk record: patch the first that parses
        if at + 9 + 16 <= len(data) and int.from_bytes(data[at + 1:at + 9], "little") < len(data):
            data[at + 9 + 16:at + 9 + 24] = (2**40).to_bytes(8, "little")  # start, end, then the size
            break
        at += 1
    return bytes(data)


def rosbag_folder(folder: Path, metadata: str | None) -> str:
    bag = folder / "bag"
    bag.mkdir()
    if metadata == "fifo":
        os.mkfifo(bag / "metadata.yaml")
    elif metadata is not None:
        (bag / "metadata.yaml").write_text(metadata, encoding="utf-8")
    return "bag"
