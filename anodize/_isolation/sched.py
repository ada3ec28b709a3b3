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

from ..errors import ConfigurationError

__all__ = ["apply_thread_scheduling", "nice_for", "lower_thread_priority", "side_work_priority", "SIDE_WORK_NICE",
           "SIDE_WORK_RT", "NICE_MIN", "NICE_MAX", "ThreadScheduling", "thread_scheduling", "restore_thread_scheduling"]

SIDE_WORK_NICE = 19  # the weakest nice value: side work in a process that is not real time
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
    """Put a thread of side work (the live view, a recording's writer) below every group that
    matters, yet where it cannot hold up the threads it shares a process with; describe what
    was applied.

    A thread of a real-time group (SCHED_FIFO/RR, inherited from the group) gets SCHED_FIFO
    :data:`SIDE_WORK_RT` (1), the lowest real-time priority: below every group with a higher
    one, above every process that is not real time. Any other thread gets SCHED_OTHER at nice
    :data:`SIDE_WORK_NICE` (19), the weakest share of the CPU that is still a share.

    Not SCHED_IDLE, though it is lower still: a Python thread holds the GIL (and the locks it
    shares with the roles) while it runs, and a SCHED_IDLE thread preempted while holding it
    waits for every other thread on its CPU, whichever process it is in, so the group's own
    roles would wait behind the machine's load for it (measured with bench/criticality.py's
    recording scenario: the control loop's period stretched to hundreds of milliseconds).

    Args:
        thread: the native id of the thread (``threading.get_native_id()`` of it, or a task
            id from ``/proc/self/task``); None, the calling thread.
    """
    tid = threading.get_native_id() if thread is None else thread
    target = 0 if thread is None else tid  # 0: the calling thread, on Linux
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
        os.setpriority(os.PRIO_PROCESS, tid, SIDE_WORK_NICE)
    except OSError as error:
        return f"unchanged (nice {SIDE_WORK_NICE} refused: {_reason(error)}){refused}"
    return f"nice {SIDE_WORK_NICE}{refused}"


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
