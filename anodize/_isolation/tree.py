"""A group's process tree: every process a group started goes when the group goes.

A group process is a *child subreaper* (``PR_SET_CHILD_SUBREAPER``): a process
its roles start and then abandon (``os.system("x &")``, a double fork) is
re-parented to the group process instead of to init, so the group's tree, read
from ``/proc/<pid>/task/*/children``, holds every process the group started.
(A process group would not do: a group reading the terminal, as TinMan's
keyboard teleop does, must stay in the terminal's foreground process group.)

A subreaper adopts nothing once it is dead: when a group process is SIGKILLed,
its children go to init. So the supervisor keeps a :func:`snapshot` of each
group's tree (pids with their start times, so a reused pid is never killed) and,
when the group dies, :func:`kill_remembered` ends every remembered process still
alive and whatever it started since. Where the group has a cgroup, the cgroup is
the whole answer; without one, a process started in the last look's interval
before the group died can escape.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal

__all__ = ["become_subreaper", "descendants", "kill_tree", "snapshot", "kill_remembered", "start_time"]

_PR_SET_CHILD_SUBREAPER = 36  # linux/prctl.h


def become_subreaper() -> bool:
    """Adopt this process's orphaned descendants; False where the kernel does not offer it."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return bool(libc.prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0)
    except (OSError, AttributeError):
        return False


def descendants(pid: int) -> list[int]:
    """Every living descendant of ``pid`` (children first), read from /proc."""
    found: list[int] = []
    todo = [pid]
    while todo:
        parent = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{parent}/task")
        except OSError:
            continue
        for task in tasks:
            try:
                with open(f"/proc/{parent}/task/{task}/children") as children:
                    kids = [int(kid) for kid in children.read().split()]
            except (OSError, ValueError):
                continue
            for kid in kids:
                if kid not in found:
                    found.append(kid)
                    todo.append(kid)
    return found


def kill_tree(pid: int, include_root: bool = True) -> None:
    """SIGKILL ``pid`` and all its descendants.

    The root is stopped first (SIGSTOP) so that it cannot start more while its tree
    is read; the tree is read twice to catch a child forked by a descendant meanwhile.
    """
    if include_root:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, signal.SIGSTOP)
    for _ in range(2):
        for child in descendants(pid):
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(child, signal.SIGKILL)
    if include_root:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, signal.SIGKILL)


def start_time(pid: int) -> int | None:
    """When ``pid`` started (clock ticks since boot, field 22 of ``/proc/<pid>/stat``); None if gone."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rsplit(") ", 1)[1].split()
        return int(fields[19])
    except (OSError, IndexError, ValueError):
        return None


def snapshot(pid: int) -> dict[int, int]:
    """``pid``'s living descendants, each with its start time (see :func:`kill_remembered`)."""
    found: dict[int, int] = {}
    for kid in descendants(pid):
        started = start_time(kid)
        if started is not None:
            found[kid] = started
    return found


def kill_remembered(remembered: dict[int, int]) -> int:
    """SIGKILL each process of ``remembered`` (pid -> start time) that is still the same process,
    with everything it started; returns how many were killed. Used once a group's process is
    dead and its orphans were re-parented away from it."""
    killed = 0
    for pid, started in remembered.items():
        if start_time(pid) != started:
            continue  # gone, or the pid now belongs to another process
        kill_tree(pid)
        killed += 1
    return killed
