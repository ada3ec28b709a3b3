"""Liveness on real processes: a starved group is reported and finishes; a stopped supervisor
blames nobody; SIGSTOP and a call holding the GIL (on the CPU or asleep) are still failed."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import liveness_roles as roles
import pytest

import anodize
import sessiontypes
from anodize._supervision.report import GroupState, RunReport
from anodize.errors import RoleError

PING_SOURCE = "global Ping(A, B) = mu t. A -> B : {ping(nat). B -> A : pong(nat). t, stop}"
PING = sessiontypes.loads(PING_SOURCE, "test_liveness_runs.proto").globals["Ping"]
CPU_CGROUPS = Path("/sys/fs/cgroup/cpu")  # cgroup v1's cpu controller
LIMIT = 1.0

pytestmark = pytest.mark.slow


def run(client: Callable[..., Any], timeout: float = 60) -> RunReport:
    system = anodize.System(PING, transport=anodize.Processes(liveness=LIMIT))
    system.group("a").role("A", client)
    system.group("b").role("B", roles.server)
    return system.run(timeout=timeout, grace=1.0)


def wait_for(path: Path, seconds: float) -> str:
    deadline = time.monotonic() + seconds
    while not path.exists() or not path.read_text():
        if time.monotonic() > deadline:
            raise AssertionError(f"{path.name} did not appear within {seconds:g} s")
        time.sleep(0.02)
    return path.read_text()


def _cpu_cgroup_writable() -> str:
    if not (CPU_CGROUPS / "cpu.cfs_quota_us").exists():
        return "no cgroup v1 cpu controller mounted at /sys/fs/cgroup/cpu"
    if not os.access(CPU_CGROUPS, os.W_OK):
        return "the cgroup v1 cpu controller is not writable (needs root)"
    return ""


def _starve(tmp_path: Path, seconds: float) -> None:
    """Put the group's process in a cpu cgroup allowed 1 ms of CPU per second for ``seconds``,
    then take it out again and release the role."""
    cgroup = CPU_CGROUPS / f"anodize-test-{os.getpid()}-starve"
    pid = wait_for(tmp_path / "pid", 60)
    cgroup.mkdir(exist_ok=True)
    try:
        (cgroup / "cpu.cfs_period_us").write_text("1000000")
        (cgroup / "cpu.cfs_quota_us").write_text("1000")
        (cgroup / "cgroup.procs").write_text(pid)
        time.sleep(seconds)
        with contextlib.suppress(ProcessLookupError, OSError):
            (CPU_CGROUPS / "cgroup.procs").write_text(pid)
    finally:
        (tmp_path / "released").write_text("yes")
        for _ in range(50):
            try:
                cgroup.rmdir()
                break
            except OSError:
                time.sleep(0.1)


@pytest.mark.skipif(bool(_cpu_cgroup_writable()), reason=_cpu_cgroup_writable() or "n/a")
def test_a_starved_group_is_reported_not_killed_and_finishes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ANODIZE_TEST_DIR", str(tmp_path))
    starver = threading.Thread(target=_starve, args=(tmp_path, 4 * LIMIT), daemon=True)
    starver.start()
    report = run(roles.busy_until_released)
    starver.join(10)
    group = report.groups["a"]
    assert group.status is GroupState.DONE, report.summary()
    assert report.groups["b"].status is GroupState.DONE, report.summary()
    starved = [note for note in group.notes if note.startswith("starved, not failed")]
    assert starved, report.summary()
    assert "waiting for a CPU" in starved[0] and "by its cgroup's CPU quota (1 ms per 1000 ms)" in starved[0]


def test_a_stopped_supervisor_blames_no_group(tmp_path: Path) -> None:
    script = tmp_path / "supervisor.py"
    script.write_text(textwrap.dedent(f"""
        import sys
        sys.path[:0] = {[str(Path(__file__).parents[1])]!r}
        import anodize, sessiontypes, liveness_roles as roles
        PING = sessiontypes.loads({PING_SOURCE!r}, "stopped.proto").globals["Ping"]
        if __name__ == "__main__":
            system = anodize.System(PING, transport=anodize.Processes(liveness={LIMIT}))
            system.group("a").role("A", roles.pings_for_a_while)
            system.group("b").role("B", roles.server)
            report = system.run(timeout=60, grace=1.0)
            print(report.outcome)
            print(report.summary())
    """))
    env = {**os.environ, "ANODIZE_TEST_DIR": str(tmp_path), "PYTHONPATH": os.pathsep.join(sys.path)}
    supervisor = subprocess.Popen([sys.executable, str(script)], env=env, stdout=subprocess.PIPE, text=True)
    try:
        wait_for(tmp_path / "started", 60)
        os.kill(supervisor.pid, signal.SIGSTOP)  # the supervisor, not its groups: they run on
        time.sleep(3 * LIMIT)
        os.kill(supervisor.pid, signal.SIGCONT)
        out, _ = supervisor.communicate(timeout=60)
    finally:
        supervisor.kill()
    assert out.splitlines()[0] == "ok", out
    assert "held up" in out, out  # the stall was measured and reported


@pytest.mark.parametrize(("client", "words"), [(roles.holds_the_gil_on_the_cpu, "a call that holds the GIL"),
                                               (roles.holds_the_gil_asleep, "frozen: asleep")])
def test_a_call_holding_the_gil_is_still_failed(client: Callable[..., Any], words: str) -> None:
    report = run(client)
    group = report.groups["a"]
    assert group.status is GroupState.FAILED, report.summary()
    assert isinstance(group.error, RoleError) and group.error.type_name == "Unresponsive"
    assert words in str(group.error), report.summary()


def test_sigstop_is_still_failed_as_stopped(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ANODIZE_TEST_DIR", str(tmp_path))

    def stop_it() -> None:
        os.kill(int(wait_for(tmp_path / "started", 60)), signal.SIGSTOP)

    stopper = threading.Thread(target=stop_it, daemon=True)
    stopper.start()
    report = run(roles.pings_for_a_while)
    stopper.join(5)
    group = report.groups["a"]
    assert group.status is GroupState.FAILED, report.summary()
    assert isinstance(group.error, RoleError) and "frozen: stopped (SIGSTOP" in str(group.error)
