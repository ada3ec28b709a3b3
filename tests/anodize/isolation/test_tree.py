"""A group's remembered tree: what is killed once the group process is dead, and what is not."""

from __future__ import annotations

import subprocess
import sys

from anodize._isolation.tree import kill_remembered, snapshot, start_time

SLEEPER = [sys.executable, "-c", "import time; time.sleep(60)"]


def test_a_remembered_process_is_killed_with_what_it_started() -> None:
    parent = subprocess.Popen([sys.executable, "-c",
                               "import subprocess, sys, time; subprocess.Popen(sys.argv[1:]); time.sleep(60)",
                               *SLEEPER])
    try:
        for _ in range(200):  # its child is there once the tree shows it (bounded: 200 looks)
            if snapshot(parent.pid):
                break
            subprocess.run(["sleep", "0.05"], check=True)
        children = snapshot(parent.pid)
        assert len(children) == 1
        started = start_time(parent.pid)
        assert started is not None
        assert kill_remembered({parent.pid: started}) == 1
        assert parent.wait(10) == -9
        for _ in range(200):  # SIGKILL takes effect when the child next runs (bounded: 200 looks)
            if all(start_time(pid) != when or _zombie(pid) for pid, when in children.items()):
                break
            subprocess.run(["sleep", "0.05"], check=True)
        else:
            raise AssertionError(f"the child {children} outlived the remembered process that started it")
    finally:
        parent.kill()
        parent.wait(10)


def test_a_pid_that_is_now_another_process_is_left_alone() -> None:
    other = subprocess.Popen(SLEEPER)
    try:
        started = start_time(other.pid)
        assert started is not None
        assert kill_remembered({other.pid: started - 1}) == 0  # remembered from an earlier process
        assert other.poll() is None
    finally:
        other.kill()
        other.wait(10)


def _zombie(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(") ", 1)[1].startswith("Z")
    except OSError:
        return True
