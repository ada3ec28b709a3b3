"""Every command that reads a file, on every family of hostile file: a clean error or success.

Each case runs the real command in a subprocess under ``prlimit`` (address space, CPU time)
and a wall-clock bound, and must exit 0, 1 or 2, never by a signal, with no traceback and no
"internal error" (hostile_inputs.py). The default run takes a few representative cases per
family; ``-m slow`` adds the larger sweep.

Sizes of the deep/wide/long families are those today's reader and checker handle within the
bound (the linear checker and Scribble reader raise them: see the report of issue 27).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hostile_inputs import (
    ANODIZE,
    GOOD_PROTOCOL,
    TINMAN,
    Case,
    assert_clean,
    fifo,
    good_mcap,
    lying_chunk_mcap,
    lying_footer_mcap,
    lying_record_mcap,
    many_roles_proto,
    nested_choice_proto,
    noise,
    rosbag_folder,
    run_bounded,
    scribble_chain,
    scribble_do_per_level,
    scribble_sequence,
    sequence_proto,
    sparse,
    system_file,
    wide_choice_proto,
    write,
)

NOT_REGULAR = "not a regular file"
TOO_LARGE = "limit for a"
PROTOCOL_COMMANDS = [["check"], ["project"], ["fsm", "--role", "A"], ["graph", "-o", "out.dot"]]


def protocol_cases() -> list[Case]:
    cases: list[Case] = []
    for command in PROTOCOL_COMMANDS:
        verb = command[0]

        def argv(name: str, command: list[str] = command) -> list[str]:
            return [*ANODIZE, command[0], name, *command[1:]]

        cases += [
            Case(f"infinite-{verb}-dev-zero", lambda d, a=argv: a("/dev/zero"), NOT_REGULAR),
            Case(f"infinite-{verb}-fifo", lambda d, a=argv: a(fifo(d, "p.proto")), NOT_REGULAR),
            Case(f"huge-{verb}-9MiB", lambda d, a=argv: (sparse(d / "p.proto", 9 * 2**20), a("p.proto"))[1],
                 TOO_LARGE),
            Case(f"malformed-{verb}-noise", lambda d, a=argv: a(write(d, "p.proto", noise(1, 4096)))),
            Case(f"deep-{verb}-nested-choice-200", lambda d, a=argv: a(write(d, "p.proto", nested_choice_proto(200)))),
            Case(f"lying-{verb}-scribble-in-proto", lambda d, a=argv: a(write(d, "p.proto", scribble_sequence(3)))),
        ]
    cases += [
        Case("infinite-check-dev-urandom", lambda d: [*ANODIZE, "check", "/dev/urandom"], NOT_REGULAR),
        Case("infinite-check-directory", lambda d: [*ANODIZE, "check", "."], NOT_REGULAR),
        Case("huge-check-scr-9MiB", lambda d: (sparse(d / "p.scr", 9 * 2**20), [*ANODIZE, "check", "p.scr"])[1],
             TOO_LARGE),
        Case("huge-check-limit-raised", lambda d: (sparse(d / "p.proto", 9 * 2**20, b"global"),
                                                   [*ANODIZE, "check", "p.proto"])[1],
             env={"ANODIZE_MAX_PROTOCOL_BYTES": "10MiB"}),
        Case("huge-check-limit-lowered", lambda d: [*ANODIZE, "check", write(d, "p.proto", GOOD_PROTOCOL)],
             TOO_LARGE, env={"ANODIZE_MAX_PROTOCOL_BYTES": "16"}),
        Case("wide-check-sequence-400", lambda d: [*ANODIZE, "check", write(d, "p.proto", sequence_proto(400))], "ok"),
        Case("wide-check-choice-2000", lambda d: [*ANODIZE, "check", write(d, "p.proto", wide_choice_proto(2000))],
             "ok"),
        Case("wide-project-roles-100", lambda d: [*ANODIZE, "project", write(d, "p.proto", many_roles_proto(100))]),
        Case("wide-check-scr-sequence-2000", lambda d: [*ANODIZE, "check", write(d, "p.scr", scribble_sequence(2000))],
             "ok"),
        Case("deep-check-scr-do-per-level-18",
             lambda d: [*ANODIZE, "check", write(d, "p.scr", scribble_do_per_level(18))]),
        Case("wide-check-scr-chain-300", lambda d: [*ANODIZE, "check", write(d, "p.scr", scribble_chain(300))]),
        Case("infinite-check-nuscr-dev-zero", lambda d: [*ANODIZE, "check", _link(d, "/dev/zero", "p.nuscr")],
             NOT_REGULAR),
        Case("malformed-check-not-utf8", lambda d: [*ANODIZE, "check", write(d, "p.proto", b"global \xff\xfe")]),
        Case("malformed-check-nul", lambda d: [*ANODIZE, "check", write(d, "p.proto", b"global G\x00(A, B)")]),
        Case("malformed-check-scr-noise", lambda d: [*ANODIZE, "check", write(d, "p.scr", noise(2, 4096))]),
        Case("malformed-check-nuscr-noise", lambda d: [*ANODIZE, "check", write(d, "p.nuscr", noise(3, 4096))]),
        Case("infinite-project-check-generated-fifo", lambda d: _generated_fifo(d), NOT_REGULAR, slow=True),
        Case("lying-check-proto-in-scr", lambda d: [*ANODIZE, "check", write(d, "p.scr", GOOD_PROTOCOL)]),
        Case("malformed-check-unterminated", lambda d: [*ANODIZE, "check", write(d, "p.proto", 'type X = "abc')]),
    ]
    # The slow sweep: more seeds of noise, and sizes the checker takes seconds on (issue 27's: a
    # 10,000-message Scribble sequence, 40 levels of a 'do' per branch). A Scribble chain of
    # 'do's across declarations is still quadratic (600 take 9 s, 2,000 take 110 s): not here.
    cases += [Case(f"malformed-check-noise-{seed}", lambda d, s=seed: [*ANODIZE, "check",
                                                                       write(d, "p.proto", noise(s, 65536))],
                   slow=True) for seed in range(10, 13)]
    cases += [
        Case("deep-check-nested-choice-1000",
             lambda d: [*ANODIZE, "check", write(d, "p.proto", nested_choice_proto(1000))], slow=True),
        Case("wide-check-sequence-8000", lambda d: [*ANODIZE, "check", write(d, "p.proto", sequence_proto(8000))],
             slow=True),
        Case("wide-check-choice-20000",
             lambda d: [*ANODIZE, "check", write(d, "p.proto", wide_choice_proto(20000))], slow=True),
        Case("deep-check-scr-do-per-level-40",
             lambda d: [*ANODIZE, "check", write(d, "p.scr", scribble_do_per_level(40))], slow=True),
        Case("wide-check-scr-sequence-10000",
             lambda d: [*ANODIZE, "check", write(d, "p.scr", scribble_sequence(10000))], "ok", slow=True),
    ]
    return cases


def _generated_fifo(folder: Path) -> list[str]:
    """``project -o gen --check`` where a generated module is a FIFO: it would block for ever."""
    write(folder, "p.proto", GOOD_PROTOCOL)
    (folder / "gen").mkdir()
    fifo(folder / "gen", "g_a.py")
    return [*ANODIZE, "project", "p.proto", "-o", "gen", "--check"]


def _link(folder: Path, target: str, name: str) -> str:
    (folder / name).symlink_to(target)
    return name


def system_cases() -> list[Case]:
    cases: list[Case] = []
    for verb in ("lint", "run"):
        tail = ["--timeout", "5", "--quiet"] if verb == "run" else []

        def argv(name: str, verb: str = verb, tail: list[str] = tail) -> list[str]:
            return [*ANODIZE, verb, name, *tail]

        cases += [
            Case(f"infinite-{verb}-protocol-dev-zero", lambda d, a=argv: a(system_file(d, protocol="/dev/zero")),
                 NOT_REGULAR),
            Case(f"infinite-{verb}-protocol-fifo",
                 lambda d, a=argv: (fifo(d, "f.proto"), a(system_file(d, protocol="f.proto")))[1], NOT_REGULAR),
            Case(f"infinite-{verb}-system-file-fifo", lambda d, a=argv: a(fifo(d, "s.toml")), NOT_REGULAR),
            Case(f"huge-{verb}-system-file-2MiB",
                 lambda d, a=argv: (sparse(d / "s.toml", 2 * 2**20, b"# x\n"), a("s.toml"))[1], TOO_LARGE),
            Case(f"lying-{verb}-on-failure-array",
                 lambda d, a=argv: a(system_file(d, groups='[groups.g]\non_failure = ["a"]\nroles = { A = "r:a" }\n')),
                 'groups.g.on_failure: expected one of "stop", "restart", "stop-system", got ["a"]'),
            Case(f"deep-{verb}-nested-arrays",
                 lambda d, a=argv: a(system_file(d, extra="pythonpath = " + "[" * 3000 + "]" * 3000)), "nested"),
        ]
    cases += [
        Case("lying-lint-protocol-is-a-directory", lambda d: [*ANODIZE, "lint", system_file(d, protocol=".")]),
        Case("malformed-lint-not-toml", lambda d: [*ANODIZE, "lint", write(d, "s.toml", noise(4, 2048))]),
        Case("malformed-lint-not-utf8", lambda d: [*ANODIZE, "lint", write(d, "s.toml", b"protocol = \"\xff\"")]),
        Case("lying-lint-timeout-inf", lambda d: [*ANODIZE, "lint", system_file(d, extra="timeout = inf")],
             "timeout: expected a number of seconds > 0, got inf"),
        Case("lying-lint-role-source-fifo",
             lambda d: (fifo(d, "fiforoles.py"),
                        [*ANODIZE, "lint", system_file(d, groups='[groups.g]\nroles = { A = "fiforoles:a" }\n')])[1]),
        Case("wide-lint-5000-groups", lambda d: [*ANODIZE, "lint", system_file(
            d, groups="".join(f'[groups.g{i}]\nroles = {{ R{i} = "roles:a" }}\n' for i in range(5000)))], slow=True),
    ]
    return cases


def recording_cases() -> list[Case]:
    cases: list[Case] = []
    for verb in ("verify", "replay"):
        tail = ["--role", "A", "--function", "roles:a"] if verb == "replay" else []

        def argv(name: str, verb: str = verb, tail: list[str] = tail, protocol: bool = True) -> list[str]:
            given = ["--protocol", write_protocol(name)] if protocol else []
            return [*ANODIZE, verb, name, *given, *tail]

        cases += [
            Case(f"infinite-{verb}-dev-zero", lambda d, a=argv: a("/dev/zero"), NOT_REGULAR),
            Case(f"infinite-{verb}-fifo", lambda d, a=argv: a(fifo(d, "r.mcap")), NOT_REGULAR),
            Case(f"huge-{verb}-over-the-limit", lambda d, a=argv: (sparse(d / "r.mcap", 2**21), a("r.mcap"))[1],
                 TOO_LARGE, env={"ANODIZE_MAX_RECORDING_BYTES": "1MiB"}),
            Case(f"malformed-{verb}-noise", lambda d, a=argv: a(write(d, "r.mcap", noise(5, 8192)))),
            Case(f"lying-{verb}-record-length", lambda d, a=argv: a(write(d, "r.mcap", lying_record_mcap(d)))),
            Case(f"lying-{verb}-footer-offset", lambda d, a=argv: a(write(d, "r.mcap", lying_footer_mcap(d)))),
            Case(f"lying-{verb}-chunk-size", lambda d, a=argv: a(write(d, "r.mcap", lying_chunk_mcap(d)))),
            Case(f"lying-{verb}-truncated",
                 lambda d, a=argv: a(write(d, "r.mcap", good_mcap(d / "base.mcap")[:-40]))),
            Case(f"lying-{verb}-wrong-magic",
                 lambda d, a=argv: a(write(d, "r.mcap", b"\x89MCAP9\r\n" + good_mcap(d / "base.mcap")[8:]))),
            Case(f"infinite-{verb}-rosbag-metadata-fifo", lambda d, a=argv: a(rosbag_folder(d, "fifo")), NOT_REGULAR),
            Case(f"malformed-{verb}-rosbag-metadata", lambda d, a=argv: a(rosbag_folder(d, "{{{{ [ : not yaml"))),
            Case(f"lying-{verb}-not-an-anodize-recording",
                 lambda d, a=argv: a(write(d, "r.mcap", good_mcap(d / "base.mcap")), protocol=False)),
        ]
    cases += [
        Case("infinite-verify-protocol-dev-zero", lambda d: [
            *ANODIZE, "verify", write(d, "r.mcap", good_mcap(d / "base.mcap")), "--protocol", "/dev/zero"],
             NOT_REGULAR),
        Case("infinite-verify-topics-dev-zero", lambda d: [
            *ANODIZE, "verify", write(d, "r.mcap", good_mcap(d / "base.mcap")), "--protocol",
            write(d, "p.proto", GOOD_PROTOCOL), "--topics", "/dev/zero"], NOT_REGULAR),
        Case("lying-verify-topics-not-a-table", lambda d: [
            *ANODIZE, "verify", write(d, "r.mcap", good_mcap(d / "base.mcap")), "--protocol",
            write(d, "p.proto", GOOD_PROTOCOL), "--topics", write(d, "t.toml", "ros = { topics = [1] }")]),
        Case("deep-verify-topics-nested", lambda d: [
            *ANODIZE, "verify", write(d, "r.mcap", good_mcap(d / "base.mcap")), "--protocol",
            write(d, "p.proto", GOOD_PROTOCOL), "--topics", write(d, "t.toml", "a = " + "[" * 3000 + "]" * 3000)]),
    ]
    cases += [Case(f"malformed-verify-noise-{seed}", lambda d, s=seed: [
        *ANODIZE, "verify", write(d, "r.mcap", b"\x89MCAP0\r\n" + noise(s, 65536)), "--protocol",
        write(d, "p.proto", GOOD_PROTOCOL)], slow=True) for seed in range(20, 23)]
    return cases


def write_protocol(recording: str) -> str:
    """The protocol a recording case passes (its folder is the working directory)."""
    Path("p.proto").write_text(GOOD_PROTOCOL, encoding="utf-8")
    return "p.proto"


def tinman_cases() -> list[Case]:
    return [
        Case("infinite-tinman-ate-dev-zero", lambda d: [*TINMAN, "ate", "/dev/zero", "/dev/zero"], NOT_REGULAR),
        Case("infinite-tinman-ate-fifo", lambda d: [*TINMAN, "ate", fifo(d, "t.txt"), "/dev/null"], NOT_REGULAR),
        Case("malformed-tinman-ate-noise", lambda d: [*TINMAN, "ate", write(d, "t.txt", noise(6, 4096)),
                                                      write(d, "e.txt", noise(7, 4096))]),
    ]


CASES = protocol_cases() + system_cases() + recording_cases() + tinman_cases()

# The default run: every family, every kind of reader, each about a second (a subprocess each).
FAST = {
    "infinite-check-dev-zero", "infinite-check-fifo", "huge-check-9MiB", "malformed-check-noise",
    "deep-check-nested-choice-200", "wide-check-scr-sequence-2000", "lying-check-scribble-in-proto",
    "infinite-lint-protocol-dev-zero", "lying-lint-on-failure-array", "deep-lint-nested-arrays",
    "infinite-verify-dev-zero", "huge-verify-over-the-limit", "malformed-verify-noise",
    "lying-verify-record-length", "lying-replay-truncated", "infinite-tinman-ate-dev-zero",
}


def _fast(case: Case) -> bool:
    return case.name in FAST and not case.slow


@pytest.mark.parametrize("case", [pytest.param(c, id=c.name, marks=[] if _fast(c) else [pytest.mark.slow])
                                  for c in CASES])
def test_hostile_file(case: Case, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # the cases write relative names
    argv = case.make(tmp_path)
    assert_clean(run_bounded(argv, tmp_path, case.env), case.expect)


def test_every_family_has_a_fast_case() -> None:
    assert {case.name for case in CASES} >= FAST
    families = {case.name.split("-")[0] for case in CASES if _fast(case)}
    assert families == {"huge", "deep", "wide", "infinite", "malformed", "lying"}


def test_every_command_that_reads_a_file_has_a_case() -> None:
    commands = {case.name.split("-")[1] for case in CASES}
    assert commands >= {"check", "project", "fsm", "graph", "lint", "run", "verify", "replay", "tinman"}
