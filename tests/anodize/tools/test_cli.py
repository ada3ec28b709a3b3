"""The ``anodize`` command line: check, project, fsm, graph.

Most tests run :func:`anodize._tools.cli.main` in-process from the repository root
(paths in messages are then relative, as a user would type them); one runs
the installed command in a subprocess.
"""

from __future__ import annotations

import io
import json
import os
import re
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import pytest

from anodize import GroupStatus
from anodize._supervision.report import GroupState
from anodize._tools.cli import LiveStatus, ProgressLine, main

REPO = Path(__file__).resolve().parents[3]
CORPUS = REPO / "tests" / "sessiontypes" / "corpus"
PROTOCOLS = sorted(p.relative_to(REPO).as_posix() for p in (REPO / "protocols").glob("*.proto"))

# The paper's Fig. 17 with the outer loop written out (LANGUAGE.md section 5).
FIG_17 = (REPO / "tests" / "data" / "fig17.txt").read_text(encoding="utf-8")

TINMAN_ROLES = "Joy, Control, Camera, VisOdom, Visualizer, Planner, Move, Gazebo"


@pytest.fixture(autouse=True)
def _from_repo_root(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO)


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """Run the CLI in-process; return (exit status, stdout, stderr)."""
    try:
        status = main(list(argv))
    except SystemExit as exit_:  # argparse exits on usage errors
        status = exit_.code if isinstance(exit_.code, int) else 1
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return status, out, err


# ---- check ---------------------------------------------------------------------------

def test_check_shipped_protocols(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, err = run(capsys, "check", *PROTOCOLS)
    assert (status, err) == (0, "")
    assert out.splitlines() == [f"{path}: ok ({_counts(path)})" for path in PROTOCOLS]


def _counts(path: str) -> str:
    import sessiontypes

    module = sessiontypes.load(path)
    globals_, locals_ = len(module.globals), len(module.locals)
    return f"{globals_} global{'' if globals_ == 1 else 's'}, {locals_} local{'' if locals_ == 1 else 's'}"


def test_check_summary_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert run(capsys, "check", "protocols/atm.proto", "protocols/ring.proto") == (
        0, "protocols/atm.proto: ok (1 global, 2 locals)\nprotocols/ring.proto: ok (2 globals, 0 locals)\n", "")


@pytest.mark.parametrize("proto", sorted((CORPUS / "bad").glob("*.proto")), ids=lambda p: p.stem)
def test_check_bad_corpus_prints_the_expected_message(
        capsys: pytest.CaptureFixture[str], proto: Path) -> None:
    relative = proto.relative_to(REPO).as_posix()
    expected = proto.with_suffix(".expected").read_text(encoding="utf-8")
    assert run(capsys, "check", relative) == (1, "", expected)


@pytest.mark.parametrize("proto", sorted((CORPUS / "good").glob("*.proto")), ids=lambda p: p.stem)
def test_check_good_corpus(capsys: pytest.CaptureFixture[str], proto: Path) -> None:
    relative = proto.relative_to(REPO).as_posix()
    status, out, err = run(capsys, "check", relative)
    assert (status, err) == (0, "")
    assert out.startswith(f"{relative}: ok (")


def test_check_reports_every_file_and_fails_if_one_is_bad(capsys: pytest.CaptureFixture[str]) -> None:
    bad = "tests/sessiontypes/corpus/bad/self_send.proto"
    status, out, err = run(capsys, "check", "protocols/ring.proto", bad, "protocols/atm.proto")
    assert status == 1
    assert out == ("protocols/ring.proto: ok (2 globals, 0 locals)\n"
                   "protocols/atm.proto: ok (1 global, 2 locals)\n")
    assert err == (CORPUS / "bad" / "self_send.expected").read_text(encoding="utf-8")


def test_unused_type_is_a_warning_and_exit_status_stays_zero(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    proto = tmp_path / "w.proto"
    proto.write_text('type Unused = "m:Unused"\nglobal P = A -> B : x\n', encoding="utf-8")
    assert run(capsys, "check", str(proto)) == (
        0,
        f"{proto}: ok (1 global, 0 locals)\n",
        (f"{proto}:1:6: warning: type Unused is declared but never used\n"
         '    type Unused = "m:Unused"\n'
         "         ^\n"),
    )
    status, out, err = run(capsys, "project", str(proto))
    assert (status, out) == (0, "A = !B(x)\nB = ?A(x)\n")
    assert "warning: type Unused is declared but never used" in err


def test_missing_file_is_one_line_and_exit_1(capsys: pytest.CaptureFixture[str]) -> None:
    assert run(capsys, "check", "no/such.proto") == (1, "", "error: no/such.proto: No such file or directory\n")
    assert run(capsys, "project", "no/such.proto") == (1, "", "error: no/such.proto: No such file or directory\n")
    status, out, err = run(capsys, "fsm", "no/such.proto", "--role", "A")
    assert (status, out, err.count("\n")) == (1, "", 1)
    status, out, err = run(capsys, "graph", "no/such.proto", "-o", "x.dot")
    assert (status, out, err.count("\n")) == (1, "", 1)


def test_a_directory_is_not_a_protocol_file(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, err = run(capsys, "check", "protocols")
    assert (status, out, err.count("\n")) == (1, "", 1)
    assert err.startswith("error: protocols: ")


def test_a_syntax_error_in_project_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    proto = CORPUS / "bad" / "syntax_missing_colon.proto"
    relative = proto.relative_to(REPO).as_posix()
    assert run(capsys, "project", relative) == (1, "", proto.with_suffix(".expected").read_text(encoding="utf-8"))


# ---- project -------------------------------------------------------------------------

def test_project_tinman_prints_figure_17(capsys: pytest.CaptureFixture[str]) -> None:
    assert run(capsys, "project", "protocols/tinman.proto", "--global", "TinMan") == (0, FIG_17, "")


def test_project_several_globals_print_headers(capsys: pytest.CaptureFixture[str]) -> None:
    assert run(capsys, "project", "protocols/ring.proto") == (0, """\
# Ring
A = mu t.!B(token(int)).?D(token(int)).t
B = mu t.?A(token(int)).!C(token(int)).t
C = mu t.?B(token(int)).!D(token(int)).t
D = mu t.?C(token(int)).!A(token(int)).t
# RingStop
A = mu t.+B{token(int).?D(token(int)).t, stop}
B = mu t.&A{token(int).!C(token(int)).t, stop.!C(stop)}
C = mu t.&B{token(int).!D(token(int)).t, stop.!D(stop)}
D = mu t.&C{token(int).!A(token(int)).t, stop}
""", "")


def test_project_one_global_has_no_header(capsys: pytest.CaptureFixture[str]) -> None:
    assert run(capsys, "project", "protocols/two_buyer.proto") == (0, """\
B1 = !S(title(str)).?S(quote(int)).!B2(share(int))
B2 = ?S(quote(int)).?B1(share(int)).+S{ok(str).?S(date(str)), quit}
S = ?B1(title(str)).!B1(quote(int)).!B2(quote(int)).&B2{ok(str).!B2(date(str)), quit}
""", "")


# TinMan's velocity limits, on every Twist of TinManParallel
LIMITS = ("{abs(linear.x) <= 0.5 and abs(angular.z) <= 1.5 and linear.y == 0 and linear.z == 0 and angular.x == 0 and "
          "angular.y == 0}")


def test_project_role_filter(capsys: pytest.CaptureFixture[str]) -> None:
    assert run(capsys, "project", "protocols/tinman.proto", "--global", "TinManParallel", "--role", "Move") == (
        0, (f"Move = (mu c.?Control(Twist{LIMITS}) within 100ms.!Gazebo(Twist{LIMITS}) within 500ms.c"
            " || mu s.?Gazebo(LaserScan) within 250ms else timeout.s"
            " || mu v.?VisOdom(Pose) within 500ms else timeout.v || mu p.?Planner(Path).p)\n"), "")
    assert run(capsys, "project", "protocols/ring.proto", "--role", "B") == (0, """\
# Ring
B = mu t.?A(token(int)).!C(token(int)).t
# RingStop
B = mu t.&A{token(int).!C(token(int)).t, stop.!C(stop)}
""", "")


def test_project_unknown_global_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert run(capsys, "project", "protocols/tinman.proto", "--global", "Nope") == (
        2, "", ("anodize project: error: no global Nope in protocols/tinman.proto; "
                "expected one of TinMan, TinManParallel\n"))


def test_project_unknown_role_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    # The role list fixes the role order for everything that lists roles.
    assert run(capsys, "project", "protocols/tinman.proto", "--global", "TinMan", "--role", "Nobody") == (
        2, "", f"anodize project: error: no role Nobody in global TinMan; expected one of {TINMAN_ROLES}\n")


# ---- fsm -----------------------------------------------------------------------------

def test_fsm_json(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, err = run(capsys, "fsm", "protocols/stream.proto", "--global", "Stream", "--role", "P",
                           "--format", "json")
    assert (status, err) == (0, "")
    machine = json.loads(out)
    assert (machine["role"], machine["protocol"], machine["initial"]) == ("P", "Stream", 0)
    states = {state["id"]: state for state in machine["states"]}
    assert set(states) == {0, 1}
    assert states[0]["final"] is False and states[1]["final"] is True
    assert states[0]["type"] == "+C{data(int).t, stop}"
    assert [(t["action"], t["peer"], t["label"], t["sort"], t["target"]) for t in states[0]["transitions"]] == [
        ("send", "C", "data", "int", 0),
        ("send", "C", "stop", None, 1),
    ]
    assert states[0]["transitions"][0]["location"] == "protocols/stream.proto:11:9"
    assert states[1]["transitions"] == []


def test_fsm_dot_is_the_default(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, err = run(capsys, "fsm", "protocols/stream.proto", "--global", "Stream", "--role", "C")
    assert (status, err) == (0, "")
    assert out.startswith('digraph "Stream C" {\n')
    assert out.rstrip().endswith("}")
    assert '[label="?P(data(int))"]' in out
    assert run(capsys, "fsm", "protocols/stream.proto", "--global", "Stream", "--role", "C",
               "--format", "dot")[1] == out


def test_fsm_global_optional_when_the_file_has_one(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(capsys, "fsm", "protocols/two_buyer.proto", "--role", "B2", "--format", "json")
    assert status == 0
    assert json.loads(out)["protocol"] == "TwoBuyer"


def test_fsm_of_a_parallel_role_has_a_fork(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(capsys, "fsm", "protocols/tinman.proto", "--global", "TinManParallel",
                         "--role", "Move", "--format", "json")
    assert status == 0
    machine = json.loads(out)
    forks = [state["fork"] for state in machine["states"] if "fork" in state]
    assert len(forks) == 1 and len(forks[0]) == 4  # control, the scans, the odometry's estimates, the plans


def test_fsm_of_a_local_declaration(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, err = run(capsys, "fsm", "protocols/atm.proto", "--local", "ATM", "--format", "json")
    assert (status, err) == (0, "")
    machine = json.loads(out)
    first = machine["states"][machine["initial"]]
    assert [(t["action"], t["peer"], t["label"], t["sort"]) for t in first["transitions"]] == [
        ("recv", None, "Int", "Int")]


@pytest.mark.parametrize(("argv", "message"), [
    (["fsm", "protocols/tinman.proto", "--global", "TinMan"],
     f"anodize fsm: error: choose a role with --role ({TINMAN_ROLES})"),
    (["fsm", "protocols/tinman.proto", "--role", "Joy"],
     ("anodize fsm: error: protocols/tinman.proto has 2 globals; choose one with --global "
      "(TinMan, TinManParallel)")),
    (["fsm", "protocols/tinman.proto", "--global", "TinMan", "--role", "X"],
     f"anodize fsm: error: no role X in global TinMan; expected one of {TINMAN_ROLES}"),
    (["fsm", "protocols/tinman.proto", "--global", "Nope", "--role", "Joy"],
     "anodize fsm: error: no global Nope in protocols/tinman.proto; expected one of TinMan, TinManParallel"),
    (["fsm", "protocols/atm.proto", "--local", "Nope"],
     "anodize fsm: error: no local Nope in protocols/atm.proto; expected one of ATM, ATM'"),
    (["graph", "protocols/tinman.proto", "-o", "x.png"],
     ("anodize graph: error: protocols/tinman.proto has 2 globals; choose one with --global "
      "(TinMan, TinManParallel)")),
    (["graph", "protocols/two_buyer.proto", "--global", "Nope", "-o", "x.png"],
     "anodize graph: error: no global Nope in protocols/two_buyer.proto; expected one of TwoBuyer"),
])
def test_usage_errors_name_the_choices(capsys: pytest.CaptureFixture[str], argv: list[str],
                                       message: str) -> None:
    assert run(capsys, *argv) == (2, "", message + "\n")


# ---- graph ---------------------------------------------------------------------------

def test_graph_dot(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    out_file = tmp_path / "g.dot"
    assert run(capsys, "graph", "protocols/two_buyer.proto", "-o", str(out_file)) == (0, f"wrote {out_file}\n", "")
    assert out_file.read_text(encoding="utf-8") == """\
digraph "TwoBuyer" {
  "B1" [shape="box", style="rounded"];
  "B2" [shape="box", style="rounded"];
  "S" [shape="box", style="rounded"];
  "B1" -> "S" [label="title(str)"];
  "B1" -> "B2" [label="share(int)"];
  "B2" -> "S" [label="ok(str), quit"];
  "S" -> "B1" [label="quote(int)"];
  "S" -> "B2" [label="quote(int), date(str)"];
}
"""


def test_graph_png_and_svg(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    png, svg = tmp_path / "g.png", tmp_path / "g.svg"
    assert run(capsys, "graph", "protocols/ring.proto", "--global", "Ring", "-o", str(png)) == (
        0, f"wrote {png}\n", "")
    assert png.read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
    assert run(capsys, "graph", "protocols/ring.proto", "--global", "Ring", "-o", str(svg))[0] == 0
    assert b"<svg" in svg.read_bytes()[:2000]


def test_graph_bad_suffix_is_a_usage_error(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    out_file = tmp_path / "g.txt"
    assert run(capsys, "graph", "protocols/two_buyer.proto", "-o", str(out_file)) == (
        2, "", f"anodize graph: error: cannot write {out_file}: expected a name ending in .dot, .png or .svg\n")
    assert not out_file.exists()


def test_graph_into_a_missing_directory_exits_1(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    out_file = tmp_path / "missing" / "g.dot"
    assert run(capsys, "graph", "protocols/two_buyer.proto", "-o", str(out_file)) == (
        1, "", f"error: {out_file}: No such file or directory\n")


# ---- argparse usage errors -------------------------------------------------------------

@pytest.mark.parametrize("argv", [
    [],
    ["frobnicate"],
    ["check"],
    ["project"],
    ["fsm"],
    ["graph", "protocols/ring.proto"],
    ["fsm", "protocols/stream.proto", "--global", "Stream", "--role", "P", "--format", "xml"],
    ["project", "protocols/ring.proto", "--bogus"],
])
def test_missing_or_bad_arguments_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    status, out, err = run(capsys, *argv)
    assert (status, out) == (2, "")
    assert err.startswith("usage: anodize")
    assert "error: " in err


# ---- lint and run: system files -------------------------------------------------------

LINT_FIXTURES = REPO / "tests" / "anodize" / "lint_fixtures"

RUN_ROLES = '''\
import time


def producer(ep):
    for i in range(3):
        ep.send("C", "data", i)
    ep.send("C", "stop")


def consumer(ep):
    while ep.recv("P").label == "data":
        pass


def crasher(ep):
    raise RuntimeError("sensor unplugged")


def forever(ep):
    while True:
        ep.send("C", "data", 1)
        time.sleep(0.01)
'''


@pytest.fixture
def system_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[..., Path]]:
    """Writes a system file for protocols/stream.proto's Stream; roles are functions of
    a module in tmp_path (RUN_ROLES) or of lint_fixtures/. sys.path and sys.modules
    are restored afterwards."""
    (tmp_path / "cli_run_roles.py").write_text(RUN_ROLES, encoding="utf-8")
    monkeypatch.setattr(sys, "path", list(sys.path))

    def write(producer: str, consumer: str, same_group: bool = False, extra: str = "") -> Path:
        groups = (f'[groups.a]\nroles = {{ P = "{producer}", C = "{consumer}" }}\n' if same_group else
                  f'[groups.a]\nroles = {{ P = "{producer}" }}\n[groups.b]\nroles = {{ C = "{consumer}" }}\n')
        path = tmp_path / "system.toml"
        path.write_text(f'protocol = "{REPO / "protocols" / "stream.proto"}"\nglobal = "Stream"\n'
                        f'transport = "inproc"\npythonpath = [".", "{LINT_FIXTURES}"]\n{extra}{groups}',
                        encoding="utf-8")
        return path

    yield write
    sys.modules.pop("cli_run_roles", None)


def test_lint_prints_findings_and_a_summary_and_exits_1(
        capsys: pytest.CaptureFixture[str], system_file: Callable[..., Path]) -> None:
    path = system_file("back_channel:producer", "back_channel:consumer")
    status, out, err = run(capsys, "lint", str(path))
    fixture = "tests/anodize/lint_fixtures/back_channel.py"
    assert (status, err) == (1, "")
    assert out == (
        f"{fixture}:6:1: warning: threading.Lock lock is shared by group a (P) and group b (C): used as "
        "a back channel outside the protocol (P: 13:10 enters it (with); C: 19:10 enters it (with))\n"
        f"{fixture}:7:1: warning: queue.Queue handoff is shared by group a (P) and group b (C): used as "
        "a back channel outside the protocol (P: 14:9 calls .put(); C: 21:5 calls .get())\n"
        "2 findings in 1 module\n"
        "no priority inversion among 1 wait\n")


def test_lint_of_a_clean_system_exits_0(
        capsys: pytest.CaptureFixture[str], system_file: Callable[..., Path]) -> None:
    clean = "no isolation problems found in 1 module\nno priority inversion among 1 wait\n"
    assert run(capsys, "lint", str(system_file("constants:producer", "constants:consumer"))) == (0, clean, "")
    path = system_file("back_channel:producer", "back_channel:consumer", same_group=True)
    assert run(capsys, "lint", str(path)) == (0, clean, "")


def test_lint_of_a_bad_system_file_prints_one_error_line(
        capsys: pytest.CaptureFixture[str], system_file: Callable[..., Path]) -> None:
    path = system_file("constants:producer", "constants:consumer", extra="monitors = 1\n")
    assert run(capsys, "lint", str(path)) == (
        1, "", f"error: {path}: monitors: expected true or false, got 1\n")
    path = system_file("no_such_module:producer", "constants:consumer")
    status, out, err = run(capsys, "lint", str(path))
    assert (status, out) == (1, "")
    assert err.startswith(f"error: {path}: groups.a.roles.P: cannot find the source of module no_such_module")


@pytest.mark.parametrize("command", ["lint", "run"])
def test_a_system_file_that_is_not_there_is_a_usage_error(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, command: str) -> None:
    assert run(capsys, command, "no/such.toml") == (
        2, "", f"anodize {command}: error: no such system file: no/such.toml\n")
    assert run(capsys, command, str(tmp_path)) == (
        2, "", f"anodize {command}: error: {tmp_path} is a directory; expected a system file (.toml)\n")
    assert run(capsys, command, "protocols/stream.proto") == (
        2, "", f"anodize {command}: error: protocols/stream.proto: expected a system file ending in .toml\n")


def test_run_prints_status_and_the_summary_and_writes_json(
        capsys: pytest.CaptureFixture[str], system_file: Callable[..., Path], tmp_path: Path) -> None:
    report = tmp_path / "reports" / "run.json"
    status, out, err = run(capsys, "run", str(system_file("cli_run_roles:producer", "cli_run_roles:consumer")),
                           "--json", str(report))
    assert (status, err) == (0, "")
    lines = out.splitlines()
    assert [line.split()[:2] for line in lines[:2]] == [["a", "done"], ["b", "done"]]
    assert lines[2].startswith("protocol Stream: ok in ")
    assert lines[3].startswith("  group a: done (") and lines[4].startswith("  group b: done (")
    assert lines[5].startswith("  most messages waiting: P->C ")  # 1 to 4: how far the consumer fell behind
    assert lines[6:] == [f"wrote {report}"]
    data = json.loads(report.read_text(encoding="utf-8"))
    assert (data["ok"], data["protocol"], data["messages"]) == (True, "Stream", {"P->C": 4})
    assert 1 <= data["high_water"]["P->C"] <= 4


def test_run_quiet_prints_only_the_summary(
        capsys: pytest.CaptureFixture[str], system_file: Callable[..., Path]) -> None:
    status, out, err = run(capsys, "run", str(system_file("cli_run_roles:producer", "cli_run_roles:consumer")),
                           "--quiet")
    assert (status, err) == (0, "")
    assert out.startswith("protocol Stream: ok in ") and len(out.splitlines()) == 4  # groups, most waiting


def test_run_of_a_failing_system_exits_1(
        capsys: pytest.CaptureFixture[str], system_file: Callable[..., Path]) -> None:
    path = system_file("cli_run_roles:crasher", "cli_run_roles:consumer")
    status, out, err = run(capsys, "run", str(path), "--quiet")
    assert (status, err) == (1, "")
    assert out.startswith("protocol Stream: NOT ok in ")
    # Where the role raised, in its own file (the traceback's innermost frame of role code).
    assert re.search(r"^  role P: failed at .*cli_run_roles\.py:\d+ in crasher: RuntimeError: sensor unplugged$",
                     out, re.M)
    assert re.search(r"^  role C: failed at .*cli_run_roles\.py:\d+ in consumer: role C: peer P failed "
                     r"\(RuntimeError: sensor unplugged\)$", out, re.M)


def test_run_stops_roles_at_the_timeout_of_the_command_line(
        capsys: pytest.CaptureFixture[str], system_file: Callable[..., Path]) -> None:
    path = system_file("cli_run_roles:forever", "cli_run_roles:consumer", extra="timeout = 60\n")
    status, out, _ = run(capsys, "run", str(path), "--quiet", "--timeout", "0.2")
    assert status == 1
    assert out.startswith("protocol Stream: stopped, no failures in ")
    assert "  group a: stopped (" in out
    # Every role still running is named, with what it was doing when the timeout came.
    assert "  role C: stopped, waiting at the head of its loop (state 0) for ?P(data(int)) or ?P(stop)\n" in out
    assert re.search(r"^  role P: stopped, (interrupted sending data to C, in state 0|sleeping.*)$", out, re.M)


def test_run_errors_of_the_system_file_exit_1(
        capsys: pytest.CaptureFixture[str], system_file: Callable[..., Path]) -> None:
    path = system_file("cli_run_roles:producer", "cli_run_roles:nothing")
    assert run(capsys, "run", str(path)) == (
        1, "", (f"error: {path}: groups.b: role function 'cli_run_roles:nothing': module cli_run_roles "
                "has no nothing\n"))
    assert run(capsys, "run", str(path), "--timeout", "0") == (
        2, "", "anodize run: error: --timeout 0.0: expected a number of seconds > 0\n")


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_live_status_redraws_in_place_on_a_terminal() -> None:
    screen = _Terminal()
    live = LiveStatus(screen)
    a1 = GroupStatus(name="a", state=GroupState.RUNNING, messages=1)
    b1 = GroupStatus(name="b", state=GroupState.STARTING)
    a2 = GroupStatus(name="a", state=GroupState.DONE, messages=4)
    b2 = GroupStatus(name="b", state=GroupState.DONE)
    live({"a": a1, "b": b1})
    live({"a": a2, "b": b2})
    assert screen.getvalue() == (f"\x1b[2K{a1.line()}\n\x1b[2K{b1.line()}\n\x1b[J"
                                 f"\x1b[2F\x1b[2K{a2.line()}\n\x1b[2K{b2.line()}\n\x1b[J")


def test_live_status_in_a_log_prints_a_line_when_a_state_changes() -> None:
    log = io.StringIO()
    live = LiveStatus(log)
    b = GroupStatus(name="b", state=GroupState.RUNNING)
    a1 = GroupStatus(name="a", state=GroupState.RUNNING, messages=1)
    a9 = GroupStatus(name="a", state=GroupState.RUNNING, messages=9)
    a12 = GroupStatus(name="a", state=GroupState.DONE, messages=12)
    live({"a": a1, "b": b})
    live({"a": a9, "b": b})
    live({"a": a12, "b": b})
    assert log.getvalue().splitlines() == [a1.line(), b.line(), a12.line()]


LONG_NOTE = "memory limit 64 MiB exceeded; restarted after the group process was killed by the kernel"


def test_live_status_lines_fit_the_terminal_and_a_failure_stays_in_sight(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "80")
    screen = _Terminal()
    live = LiveStatus(screen)
    failed = GroupStatus(name="perception", state=GroupState.FAILED, pid=4242, memory=70 * 2**20,
                         messages=123_456, rate_hz=62.0, restarts=3, note=LONG_NOTE)
    running = GroupStatus(name="control", state=GroupState.RUNNING, messages=9, rate_hz=50.0)
    assert len(failed.line()) > 80
    live({"perception": failed, "control": running})
    lines = re.sub(r"\x1b\[(2K|J)", "", screen.getvalue()).splitlines()
    assert lines == [failed.line()[:78] + "\u2026", running.line()]
    assert lines[0].startswith("perception    failed ")
    log = io.StringIO()  # a log is no terminal: its lines are whole
    LiveStatus(log)({"perception": failed})
    assert log.getvalue() == failed.line() + "\n"


def test_progress_line_fits_the_terminal_and_names_a_failed_group(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "80")

    def describe(statuses: dict[str, GroupStatus], elapsed: float) -> str:
        return " | ".join(f"{s.name} {s.state} {s.rate_hz or 0:.0f} msg/s" for s in statuses.values())

    names = ["control", "perception", "planning", "simulation"]
    running = {name: GroupStatus(name=name, state=GroupState.RUNNING, rate_hz=1523.0) for name in names}
    failing = {**running, "simulation": GroupStatus(name="simulation", state=GroupState.FAILED)}
    screen = _Terminal()
    line = ProgressLine(screen, describe)
    line(running)
    line(failing)
    line.close()
    drawn = [text.removeprefix("\x1b[2K").removesuffix("\n") for text in screen.getvalue().split("\r")[1:]]
    assert drawn[0] == describe(running, 0)[:78] + "\u2026"
    assert len(drawn[1]) == 79 and drawn[1].endswith("\u2026 FAILED simulation")  # cut, but the failure named
    assert drawn[1].startswith("control running 1523 msg/s | perception running")
    assert screen.getvalue().endswith("\n")
    screen = _Terminal()
    ProgressLine(screen, lambda statuses, elapsed: "a FAILED")({"a": GroupStatus(name="a", state=GroupState.FAILED)})
    assert screen.getvalue() == "\r\x1b[2Ka FAILED"  # a line that fits is left alone


def test_progress_line_cuts_with_dots_where_the_stream_cannot_write_an_ellipsis() -> None:
    stream = io.TextIOWrapper(io.BytesIO(), encoding="ascii")
    assert ProgressLine.fit("x" * 100, 20, stream, ["b"]) == "xxxxxxxx... FAILED b"
    assert ProgressLine.fit("x" * 100, 5, stream, ["b"]) == "... F"  # the narrowest terminal: still a cut


# ---- the installed command -------------------------------------------------------------

def _command() -> Sequence[str]:
    script = Path(sys.executable).parent / "anodize"
    return [str(script)] if script.exists() else [sys.executable, "-m", "anodize._tools.cli"]


@pytest.mark.slow
def test_installed_command_in_a_subprocess() -> None:
    env = {**os.environ, "PYTHONIOENCODING": "utf-8"}
    env.pop("ANODIZE_DEBUG", None)
    done = subprocess.run([*_command(), "check", *PROTOCOLS], cwd=REPO, capture_output=True,
                          text=True, env=env, timeout=60)
    assert (done.returncode, done.stderr) == (0, "")
    assert len(done.stdout.splitlines()) == len(PROTOCOLS)

    done = subprocess.run([*_command(), "project", "protocols/tinman.proto", "--global", "TinMan"],
                          cwd=REPO, capture_output=True, text=True, env=env, timeout=60)
    assert (done.returncode, done.stdout, done.stderr) == (0, FIG_17, "")

    bad = "tests/sessiontypes/corpus/bad/several_errors.proto"
    done = subprocess.run([*_command(), "check", bad, "no/such.proto"], cwd=REPO, capture_output=True,
                          text=True, env=env, timeout=60)
    assert done.returncode == 1
    assert "Traceback" not in done.stderr
    assert done.stderr.endswith("error: no/such.proto: No such file or directory\n")

    done = subprocess.run([*_command(), "project"], cwd=REPO, capture_output=True, text=True, env=env,
                          timeout=60)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr


@pytest.mark.slow
@pytest.mark.parametrize(("transport", "signum"), [("inproc", signal.SIGINT), ("process", signal.SIGINT),
                                                   ("process", signal.SIGTERM)])
def test_ctrl_c_stops_the_run_and_still_prints_and_writes_the_report(
        system_file: Callable[..., Path], tmp_path: Path, transport: str, signum: int) -> None:
    path = system_file("cli_run_roles:forever", "cli_run_roles:consumer")
    path.write_text(path.read_text(encoding="utf-8").replace('transport = "inproc"', f'transport = "{transport}"'),
                    encoding="utf-8")
    report = tmp_path / "run.json"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    process = subprocess.Popen([*_command(), "run", str(path), "--json", str(report)], cwd=tmp_path, env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        assert process.stdout is not None
        for line in process.stdout:  # the live status says when the roles run
            if line.split()[1:2] == ["running"]:
                break
        process.send_signal(signum)
        out, err = process.communicate(timeout=60)
    finally:
        process.kill()
    assert (process.returncode, err) == (130, "")
    assert "protocol Stream: interrupted in " in out
    assert "  note: stopping every group: interrupted (Ctrl-C)\n" in out
    data = json.loads(report.read_text(encoding="utf-8"))
    assert (data["outcome"], data["interrupted"], data["ok"]) == ("interrupted", True, False)
    assert data["roles"]["C"]["status"] == "stopped"
    assert data["roles"]["C"]["detail"].startswith("waiting at the head of its loop (state 0) for ?P(data(int))")


@pytest.mark.parametrize("command", ["check", "project", "fsm"])
def test_a_file_that_is_not_utf8_gets_a_located_error(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, command: str) -> None:
    path = tmp_path / "latin1.proto"
    path.write_bytes(b"global G(A, B) = A -> B : x.\n// caf\xe9\n")
    extra = ["--role", "A"] if command == "fsm" else []
    status, out, err = run(capsys, command, str(path), *extra)
    assert (status, out) == (1, "")
    assert err == (f"{path}:2:7: error: the file is not UTF-8 text: byte 0xe9 cannot be decoded\n"
                   "    // caf\ufffd\n"
                   "          ^\n")
