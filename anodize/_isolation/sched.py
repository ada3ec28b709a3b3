"""Priorities and CPU affinity for the calling thread, with honest fallbacks.

``priority`` 1..99 asks for SCHED_FIFO at that priority. Where the OS refuses
(no privilege, or ``ANODIZE_NO_RT=1``), the thread gets a nice value of the
same rank instead, and the returned description says so: the run report
never claims real-time scheduling that was not applied.
"""

from __future__ import annotations

import contextlib
import errno
import os
import threading
from collections.abc import Callable
from typing import Any

from ..errors import ConfigurationError

__all__ = ["apply_thread_scheduling", "nice_for", "lower_thread_priority", "side_work_priority",
           "start_side_work_thread", "SIDE_WORK_BELOW", "SIDE_WORK_RT", "NICE_MIN", "NICE_MAX", "ThreadScheduling",
           "thread_scheduling", "restore_thread_scheduling"]

SIDE_WORK_BELOW = 5  # nice steps side work runs below the thread it came from (not real time)
SIDE_WORK_RT = 1     # the lowest SCHED_FIFO priority: side work in a real-time group's process
NICE_MIN, NICE_MAX = -20, 19  # a group's nice value (ordinary scheduling, no priority)


def nice_for(priority: int) -> int:
    """Map priority 1..99 (higher is more urgent) to nice 19..-20."""
    return round(19 - (priority - 1) * 39 / 98)


def _reason(error: OSError) -> str:
    return errno.errorcode.get(error.errno or 0, str(error))


def apply_thread_scheduling(priority: int | None, cpus: frozenset[int] | None = None,
                            nice: int | None = None) -> str:
    """Apply ``priority`` (or, with none, ``nice``) and ``cpus`` to the calling thread; describe
    what was applied. Threads it starts afterwards inherit both.

    Raises:
        ValueError: ``priority`` is outside 1..99, ``nice`` outside -20..19.
    """
    notes: list[str] = []
    if cpus:
        try:
            os.sched_setaffinity(0, cpus)  # 0: the calling thread on Linux
            notes.append(f"cpus {','.join(map(str, sorted(cpus)))}")
        except OSError as error:
            notes.append(f"cpus unchanged (affinity refused: {_reason(error)})")
    if priority is None and nice is None:
        described = "SCHED_OTHER (no priority asked)"
    elif priority is None:
        described = _apply_nice(nice)
    else:
        if not 1 <= priority <= 99:
            raise ConfigurationError(f"priority must be 1..99, got {priority}")
        described = _apply_priority(priority)
    return "; ".join([described, *notes])


def _apply_nice(nice: int | None) -> str:
    if nice is None or not NICE_MIN <= nice <= NICE_MAX:
        raise ConfigurationError(f"nice must be {NICE_MIN}..{NICE_MAX}, got {nice}")
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
    except OSError as error:
        return f"unchanged (nice {nice} refused: {_reason(error)})"
    return f"SCHED_OTHER nice {nice}"


def _apply_priority(priority: int) -> str:
    if os.environ.get("ANODIZE_NO_RT"):
        refused = "disabled by ANODIZE_NO_RT"
    elif not hasattr(os, "sched_setscheduler"):
        refused = "not supported on this OS"
    else:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            return f"SCHED_FIFO {priority}"
        except OSError as error:
            refused = _reason(error)
    nice = nice_for(priority)
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
    except OSError as error:
        return f"unchanged (SCHED_FIFO refused: {refused}; nice {nice} refused: {_reason(error)})"
    return f"nice {nice} (SCHED_FIFO refused: {refused})"


def lower_thread_priority(nice: int = 10) -> None:
    """The calling thread at ordinary priority, niced: for a helper thread of a role (TinMan's
    live picture) that inherited its group's real-time priority and must not delay its roles.
    anodize's own side work (recording, the live view) uses :func:`side_work_priority`."""
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))  # 0: the calling thread, on Linux
    with contextlib.suppress(OSError, AttributeError):
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)


def side_work_priority(thread: int | None = None) -> str:
    """Put a thread of side work (the live view, a recording's writer) just below the group it
    serves, yet where it cannot hold up the threads it shares a process with; describe what
    was applied. The thread is one the group started: it has the group's scheduling.

    A thread of a real-time group (SCHED_FIFO/RR, inherited from the group) gets SCHED_FIFO
    :data:`SIDE_WORK_RT` (1), the lowest real-time priority: below every group with a higher
    one, above every process that is not real time. Any other thread gets SCHED_OTHER at
    :data:`SIDE_WORK_BELOW` (5) nice steps above the nice it had (at most 19): when it and a
    role of its group both want a CPU, the role gets three quarters of it; the side work's own
    need is bounded by what the group sends, so it keeps up on a busy machine.

    Not nice 19 whatever the group's nice (as before decision 0064): below the whole machine's
    load, a writer whose group is busy (TinMan's simulation renders without pause) got a
    fraction of a percent of a CPU beside two CPU hogs and fell its whole backlog behind. And
    not SCHED_IDLE, though it is lower still: a Python thread holds the GIL (and the locks it
    shares with the roles) while it runs, and a thread preempted while holding it keeps its
    process's roles waiting until it runs again; the weaker its share, the longer they wait
    (measured with bench/criticality.py's recording scenario at SCHED_IDLE: the control loop's
    period stretched to hundreds of milliseconds).

    A thread side work started (:func:`start_side_work_thread`) has its creator's scheduling
    already and keeps it; so does a thread (by ``thread``) this function lowered before. Side
    work that starts threads, or a second call, does not push them further down. (A thread id
    the kernel gives again to a new thread that happens to have what the old one was given is
    taken as lowered already.)

    Args:
        thread: the native id of the thread (``threading.get_native_id()`` of it, or a task
            id from ``/proc/self/task``); None, the calling thread.
    """
    tid = threading.get_native_id() if thread is None else thread
    target = 0 if thread is None else tid  # 0: the calling thread, on Linux
    current = _describe(target)
    if tid in _INHERITING or current == _LOWERED.get(tid):
        return current
    refused = ""
    with contextlib.suppress(OSError, AttributeError):
        if os.sched_getscheduler(target) in (os.SCHED_FIFO, os.SCHED_RR):
            try:
                os.sched_setscheduler(target, os.SCHED_FIFO, os.sched_param(SIDE_WORK_RT))
                return f"SCHED_FIFO {SIDE_WORK_RT}"
            except OSError as error:
                refused = f" (SCHED_FIFO {SIDE_WORK_RT} refused: {_reason(error)})"
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setscheduler(target, os.SCHED_OTHER, os.sched_param(0))
    try:
        nice = min(NICE_MAX, os.getpriority(os.PRIO_PROCESS, tid) + SIDE_WORK_BELOW)
        os.setpriority(os.PRIO_PROCESS, tid, nice)
    except OSError as error:
        return f"unchanged (nice +{SIDE_WORK_BELOW} refused: {_reason(error)}){refused}"
    _LOWERED[tid] = f"nice {nice}"
    return f"nice {nice}{refused}"


_INHERITING: set[int] = set()  # threads side work started, while they run: they have its scheduling
_LOWERED: dict[int, str] = {}  # thread id -> what it was given (a thread that has it still is not lowered again)


def _describe(target: int) -> str:
    """A thread's scheduling as side_work_priority says it (0: the calling thread)."""
    try:
        if os.sched_getscheduler(target) in (os.SCHED_FIFO, os.SCHED_RR):
            return f"SCHED_FIFO {os.sched_getparam(target).sched_priority}"
        return f"nice {os.getpriority(os.PRIO_PROCESS, target or threading.get_native_id())}"
    except OSError:
        return "unknown"


def start_side_work_thread(target: Callable[..., object], name: str, args: tuple[Any, ...] = ()) -> threading.Thread:
    """Start a daemon thread from a thread of side work: it inherits its creator's scheduling (already
    below the group), and :func:`side_work_priority` in it keeps that rather than going lower."""

    def run() -> None:
        tid = threading.get_native_id()
        _INHERITING.add(tid)
        try:
            target(*args)
        finally:
            _INHERITING.discard(tid)

    thread = threading.Thread(target=run, name=name, daemon=True)
    thread.start()
    return thread


ThreadScheduling = tuple[int, int, int]  # policy, real-time priority, nice


def thread_scheduling() -> ThreadScheduling | None:
    """The calling thread's policy, real-time priority and nice value (None where unreadable)."""
    try:
        tid = threading.get_native_id()
        return (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority,
                os.getpriority(os.PRIO_PROCESS, tid))
    except (OSError, AttributeError):
        return None


def restore_thread_scheduling(thread: int, saved: ThreadScheduling | None) -> None:
    """Give thread ``thread`` (a native id) back the scheduling :func:`thread_scheduling` saved,
    as far as the kernel allows (best effort: a refusal leaves it where it is)."""
    if saved is None:
        return
    policy, priority, nice = saved
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setscheduler(thread, policy, os.sched_param(priority))
    with contextlib.suppress(OSError, AttributeError):
        os.setpriority(os.PRIO_PROCESS, thread, nice)
