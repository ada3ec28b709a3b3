"""A group's process tree: every process a group started goes when the group goes.

A group process is a *child subreaper* (``PR_SET_CHILD_SUBREAPER``): a process
its roles start and then abandon (``os.system("x &")``, a double fork) is
re-parented to the group process instead of to init, so the group's tree, read
from ``/proc/<pid>/task/*/children``, holds every process the group started.
(A process group would not do: a group reading the terminal, as TinMan's
keyboard teleop does, must stay in the terminal's foreground process group.)
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal

__all__ = ["become_subreaper", "descendants", "kill_tree"]

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
