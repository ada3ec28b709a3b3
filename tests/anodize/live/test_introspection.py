"""``anodize ps|status|channels|echo|hz`` against systems running in another process.

Each end-to-end test starts ``anodize run`` as a subprocess (its runs' directory the
test's own, ``ANODIZE_RUN_DIR``, so other runs on the machine are not seen), asks it
with the commands as subprocesses, and stops it with Ctrl-C. Every wait is bounded.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import introspect_roles
import pytest

import sessiontypes
from anodize import Inproc, Processes, System
from anodize._live.introspection import Introspection
from anodize._live.plan import live_plan
from anodize._live.runs import RUN_DIR_ENV, running
from anodize._live.tap import WANT_MESSAGES, WANT_TIMES, GroupLiveView, LiveTap
from anodize._supervision.events import Counts, Ready
from anodize._tools.cli import main
from anodize.errors import AnodizeError

REPO = Path(__file__).resolve().parents[3]
COMMAND = [sys.executable, "-m", "anodize._tools.cli"]
ANSWER_WITHIN = 60.0  # seconds a command may take on a busy machine
RUNNING_WITHIN = 90.0  # seconds a run has to start its groups


def _env(runs: Path) -> dict[str, str]:
    paths = [str(REPO), str(REPO / "tinman" / "src"), str(REPO / "tests" / "anodize")]
    return {**os.environ, RUN_DIR_ENV: str(runs), "PYTHONPATH": os.pathsep.join(paths), "PYTHONUNBUFFERED": "1"}


def _anodize(runs: Path, *argv: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*COMMAND, *argv], env=_env(runs), cwd=cwd, capture_output=True, text=True,
                          timeout=ANSWER_WITHIN)


def _until(seconds: float, condition: Callable[[], bool]) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.2)
    return False


@contextlib.contextmanager
def _running(runs: Path, argv: list[str], cwd: Path) -> Iterator[subprocess.Popen[str]]:
    """``anodize run ...`` in another process, until every group runs; Ctrl-C at the end."""
    process = subprocess.Popen([*COMMAND, "run", *argv], env=_env(runs), cwd=cwd, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        def every_group_runs() -> bool:
            assert process.poll() is None, process.communicate()
            status = _anodize(runs, "status")
            return status.returncode == 0 and "  running  " in status.stdout and "starting" not in status.stdout
        assert _until(RUNNING_WITHIN, every_group_runs)
        yield process
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.communicate(timeout=60)
        finally:
            process.kill()


@pytest.fixture
def watched(tmp_path: Path) -> Path:
    """A system file of introspect_roles's Watched, on processes."""
    (tmp_path / "watched.proto").write_text(introspect_roles.PROTOCOL, encoding="utf-8")
    path = tmp_path / "watched.toml"
    path.write_text(introspect_roles.SYSTEM.format(transport="process"), encoding="utf-8")
    return path


@pytest.mark.slow
def test_ps_status_channels_echo_and_hz_answer_for_a_run_in_another_process(watched: Path, tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    with _running(runs, [str(watched), "--quiet"], tmp_path) as process:
        run = f"watched-{process.pid}"
        ps = _anodize(runs, "ps")
        assert (ps.returncode, ps.stderr) == (0, "")
        header, row = ps.stdout.splitlines()
        assert header.split() == ["RUN", "PID", "SYSTEM", "STARTED", "TRANSPORT", "STATE", "GROUPS"]
        assert row.split()[:3] == [run, str(process.pid), "watched"]
        assert row.split()[-3:] == ["process", "running", "listener,talker"]

        status = _anodize(runs, "status", run)
        lines = status.stdout.splitlines()
        assert lines[0].startswith(f"run {run} (pid {process.pid}): {watched}, protocol Watched, transport process, "
                                   "running since ")
        assert [line.split("  ")[:2] for line in lines if line.startswith("group ")] == [
            ["group listener", "running"], ["group talker", "running"]]
        assert {"  role L: running", "  role M: running", "  role T: running"} <= set(lines)
        assert any(line.startswith("  channel L->M: ") and ", high-water mark " in line for line in lines)

        rows: dict[str, list[str]] = {}

        def scans_counted() -> bool:  # the counts come with the groups' heartbeats: the first may be on its way
            channels = _anodize(runs, "channels", str(process.pid)).stdout.splitlines()
            assert channels[0].split() == ["CHANNEL", "TOPIC", "TYPE", "MESSAGES", "RATE/s"]
            rows.update({line.split()[0]: line.split()[1:] for line in channels[1:]})
            return int(rows["T->L:scan"][2]) > 0
        assert _until(RUNNING_WITHIN, scans_counted), rows
        assert sorted(rows) == ["L->M:seen", "L->M:stop", "T->L:scan", "T->L:stop", "T->L:tick"]
        assert rows["T->L:scan"][:2] == ["/scan", "Scan"]
        assert rows["T->L:stop"][:3] == ["-", "-", "0"]

        echo = _anodize(runs, "echo", "T->L:scan", "-n", "3")
        assert (echo.returncode, echo.stderr) == (0, "")
        assert echo.stdout.count("---\n") == 3 and echo.stdout.count("# T->L:scan\n") == 3
        assert echo.stdout.count("ranges: <array 360 float32 min 2.5 max 2.5>\n") == 3
        assert "  frame_id: laser\n" in echo.stdout
        inside = _anodize(runs, "echo", run, "L->M", "-n", "2")  # a channel inside a group's process
        assert inside.stdout.count("# L->M:seen\n") == 2, inside
        by_topic = _anodize(runs, "echo", str(process.pid), "/scan", "-n", "1")
        assert by_topic.stdout.startswith("# T->L:scan\nheader:\n  stamp:\n    sec: ")

        hz = _anodize(runs, "hz", "T->L:tick", "--count", "2")
        assert (hz.returncode, hz.stderr) == (0, "")
        reports = hz.stdout.splitlines()
        assert [line.split(":")[0] for line in reports] == ["average rate", "\tmin", "average rate", "\tmin"]
        assert reports[1].split()[-2:][0] == "window:" and int(reports[3].split()[-1]) > 2

        wrong = _anodize(runs, "echo", "T->M:scan")
        assert (wrong.returncode, wrong.stdout) == (1, "")
        assert wrong.stderr.startswith(f"error: no channel 'T->M:scan' in run {run}; expected Sender->Receiver:label, "
                                       "Sender->Receiver or a topic (e.g. L->M:seen, L->M:stop, T->L:scan; ")
    assert process.returncode == 130
    assert list(runs.iterdir()) == []  # its sockets are removed at its end
    after = _anodize(runs, "ps")
    assert (after.returncode, after.stdout, after.stderr) == (0, "", "")


@dataclasses.dataclass(frozen=True)
class _EventsSeen(Processes):
    """Processes whose runner also keeps, in order, every event it hands the supervisor."""

    seen: list[Any] = dataclasses.field(default_factory=list, compare=False)

    def runner(self, plan: Any) -> Any:
        runner = super().runner(plan)
        events = runner.events

        def kept(timeout: float) -> list[Any]:
            found: list[Any] = events(timeout)
            self.seen.extend(found)
            return found

        runner.events = kept
        return runner


def test_a_group_is_ready_only_with_its_channels_counts() -> None:
    """``anodize status`` shows a group's channels from the counts its beats carry, and the group as
    running once it is ready: a group's first counts (every channel out of its roles, nothing sent
    yet, and the high-water mark of the one inside it) reach the supervisor before its "ready", so
    no status shows it running without its channels (CI saw "status" list none, its first beat
    not in yet)."""
    transport = _EventsSeen()
    system = System(sessiontypes.loads(introspect_roles.PROTOCOL, "watched.proto").globals["Watched"], transport)
    system.group("talker").role("T", introspect_roles.talker)
    system.group("listener").role("L", introspect_roles.listener).role("M", introspect_roles.mirror)
    system.run(timeout=0.5)
    for group, sends in (("talker", {"T->L"}), ("listener", {"L->M"})):
        events = [event for event in transport.seen if getattr(event, "group", None) == group]
        ready = next(i for i, event in enumerate(events) if isinstance(event, Ready))
        counts = [event for event in events[:ready] if isinstance(event, Counts) and event.sent is not None]
        assert counts, f"group {group}: no counts before its ready"
        assert counts[0].sent == dict.fromkeys(sends, 0)
    assert counts[0].waiting == {"L->M": 0}  # a channel inside a group: its queue says how many wait


def test_with_no_run_ps_prints_nothing_and_status_names_the_directory(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    runs = tmp_path / "runs"
    runs.mkdir(mode=0o700)
    dead = subprocess.Popen(["true"])
    dead.wait(timeout=30)
    stale = runs / f"crashed-{dead.pid}.sock"  # a run killed before it removed its socket
    stale.touch()
    monkeypatch.setenv(RUN_DIR_ENV, str(runs))
    assert main(["ps"]) == 0
    assert capsys.readouterr() == ("", "")
    assert not stale.exists()
    assert main(["status"]) == 1
    assert capsys.readouterr().err == f"error: no system is running on this host (none has a socket in {runs})\n"
    assert main(["echo", "nope-1", "A->B:x"]) == 1
    assert capsys.readouterr().err == ("error: no running system 'nope-1'; expected a run id or pid of "
                                       "'anodize ps' (none is running)\n")


def test_the_socket_is_the_users_alone(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    runs = tmp_path / "runs"
    monkeypatch.setenv(RUN_DIR_ENV, str(runs))
    served = Introspection("mode")
    try:
        assert stat.S_IMODE(runs.stat().st_mode) == 0o700
        assert stat.S_IMODE(served.path.stat().st_mode) == 0o600
        assert served.path.name == f"mode-{os.getpid()}.sock"
    finally:
        served.close()
    assert not served.path.exists()
    runs.chmod(0o755)  # a directory others can enter is refused, not used
    with pytest.raises(AnodizeError, match=rf"^{runs}: expected a directory of uid {os.getuid()}'s that only it "
                                           rf"can open \(mode 0700\), got a directory of uid {os.getuid()}, "
                                           r"mode 0755$"):
        Introspection("mode")


@pytest.mark.skipif(os.getuid() != 0, reason="needs root to run a client as another user (nobody)")
def test_a_client_of_another_user_is_refused_by_its_credentials(monkeypatch: pytest.MonkeyPatch) -> None:
    top = Path(tempfile.mkdtemp(prefix="anodize-creds-"))  # not under pytest's folder, which nobody cannot enter
    runs = top / "runs"
    monkeypatch.setenv(RUN_DIR_ENV, str(runs))
    served = Introspection("creds")
    try:
        # Open the way on purpose (as a mistaken chmod would): the server still checks who connects.
        for folder in (top, runs):
            folder.chmod(0o711)
        served.path.chmod(0o666)
        assert json.loads(_as_nobody(str(served.path))) == {"error": "refused: this run answers only uid 0"}
    finally:
        served.close()
        shutil.rmtree(top)


def _as_nobody(path: str) -> str:
    """What a client running as uid 65534 (nobody) gets when it asks ``path`` for the run's info."""
    read, write = os.pipe()
    child = os.fork()
    if child == 0:  # the child: no exec (nobody may not run this interpreter), no return into pytest
        code = 1
        try:
            os.close(read)
            os.setuid(65534)
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
                sock.settimeout(30)
                sock.connect(path)
                with contextlib.suppress(BrokenPipeError):  # the refusal may come (and the server close) first
                    sock.sendall(b'{"op": "info"}\n')
                os.write(write, sock.recv(4096))
            code = 0
        except BaseException as error:
            os.write(write, repr(error).encode())
        finally:
            os._exit(code)
    os.close(write)
    with os.fdopen(read, "rb") as answer:
        text = answer.read().decode()
    _, status = os.waitpid(child, 0)
    assert os.waitstatus_to_exitcode(status) == 0, text
    return text


def test_two_runs_of_one_process_get_two_sockets(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(RUN_DIR_ENV, str(tmp_path / "runs"))
    first, second = Introspection("twice"), Introspection("twice")
    try:
        assert (first.run, second.run) == (f"twice-{os.getpid()}", f"twice.2-{os.getpid()}")
        assert running() == sorted([first.run, second.run])
    finally:
        first.close()
        second.close()
    assert running() == []


def test_an_unwatched_label_is_counted_not_forwarded(tmp_path: Path) -> None:
    machines = {role: global_type().project(role).fsm() for role in ("T", "L", "M")}
    path = tmp_path / "taps"
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(str(path))
    listener.listen()
    plan = live_plan(str(path), machines, {"T": "talker", "L": "listener", "M": "listener"}, {}, on_demand=True)
    tap = LiveTap(plan, "talker", ["T"])
    try:
        scan, tick = plan.index[("T", "L", "scan")], plan.index[("T", "L", "tick")]
        for n in range(100):
            tap.offer(("T", "L"), "scan", introspect_roles._scan(n))
            tap.offer(("T", "L"), "tick", n)
        assert (tap.seen[scan], tap.seen[tick], tap.dropped, tap.thinned) == (100, 100, 0, 0)
        assert (len(tap._small), len(tap._large)) == (0, 0)  # nothing encoded, nothing queued
        tap.wanted[tick] = WANT_TIMES
        tap.offer(("T", "L"), "tick", 100)
        tap.offer(("T", "L"), "scan", introspect_roles._scan(100))
        assert [(index, data) for index, _, data in tap._small] == [(tick, b"")]  # its time alone
    finally:
        tap.close()
        listener.close()


def global_type() -> sessiontypes.GlobalType:
    return sessiontypes.loads(introspect_roles.PROTOCOL).globals["Watched"]


def test_a_client_that_never_reads_neither_blocks_nor_slows_the_roles(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(RUN_DIR_ENV, str(tmp_path / "runs"))
    taps: list[LiveTap] = []
    opened = GroupLiveView.open
    monkeypatch.setattr(GroupLiveView, "open", lambda self, group: taps.append(opened(self, group)) or taps[-1])
    system = System(global_type(), transport=Inproc())
    system.group("talker").role("T", introspect_roles.burst)
    system.group("listener").role("L", introspect_roles.listener).role("M", introspect_roles.mirror)
    served = Introspection("burst")
    introspect_roles.GO.clear()

    def forwarded() -> None:  # the tap's queue is bounded too: a slow tap thread would drop first
        deadline = time.monotonic() + 60
        while any(tap._small for tap in taps) and time.monotonic() < deadline:
            time.sleep(0.002)

    introspect_roles.PACE[:] = [forwarded]
    reports = []
    running = threading.Thread(target=lambda: reports.append(system.run(timeout=120, taps=[served])))
    running.start()
    client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        client.settimeout(60)
        client.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        assert _until(60, lambda: served.plan is not None)
        client.connect(str(served.path))
        client.sendall(b'{"op": "echo", "channel": "T->L:scan"}\n')
        assert client.recv(len(b'{"watching": ["T->L:scan"]}\n')) == b'{"watching": ["T->L:scan"]}\n'
        scan = served.plan.index[("T", "L", "scan")] if served.plan is not None else -1
        assert _until(60, lambda: any(tap.wanted[scan] == WANT_MESSAGES for tap in taps))  # the talker's tap heard
        introspect_roles.GO.set()  # and never read again
        running.join(timeout=180)
        assert not running.is_alive()
    finally:
        introspect_roles.GO.set()
        introspect_roles.PACE.clear()
        served.close()
        client.close()
    report = reports[0]
    assert report.ok, report.summary()
    burst = introspect_roles.BURST
    assert report.messages == {"T->L": 2 * burst + 2, "L->M": burst + 1}  # every one, though nobody read
    [watcher] = served.watchers
    # Every scan reached the watcher (the burst waited for its tap); the client took none past its
    # socket's buffer, so the watcher's queue overflowed, whatever the load: the oldest went, counted.
    assert watcher.dropped > 0 and watcher.sent + watcher.dropped <= burst + 1
    [note] = [n for n in report.notes if n.startswith("introspection: ")]
    said = re.fullmatch(rf"introspection: answered 1 client\(s\) at {re.escape(str(served.path))}; (\d+) messages "
                        "dropped for clients that read slower than the run sent", note)
    assert said is not None, note
    assert 0 < int(said[1]) <= watcher.dropped  # the note counts those dropped by the run's end


@pytest.mark.slow
def test_anodize_status_shows_tinmans_groups(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    argv = ["tinman", "--quiet", "--duration", "60", "--out", str(tmp_path / "out"), "--world", "easy"]
    with _running(runs, argv, REPO) as process:
        status = _anodize(runs, "status")
        assert status.stdout.startswith(f"run tinman-{process.pid} (pid {process.pid}): tinman, protocol ")
        groups = [line.split("  ")[0] for line in status.stdout.splitlines() if line.startswith("group ")]
        assert groups == ["group control", "group perception", "group planning", "group simulation"]
        # Each role with its state (on a busy host TinMan's Joy may miss its period, failing the run: not ours)
        roles = [line.split(":")[0].split()[1] for line in status.stdout.splitlines() if line.startswith("  role ")]
        assert sorted(roles) == sorted(["Joy", "Control", "Move", "Camera", "VisOdom", "Planner", "Gazebo",
                                        "Visualizer"])
