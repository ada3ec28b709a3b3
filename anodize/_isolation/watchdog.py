"""The real-time guard: a runaway SCHED_FIFO group must not starve the machine.

Two layers. The kernel's RT throttling (``/proc/sys/kernel/sched_rt_runtime_us``)
keeps a share of every period for ordinary tasks; where it is disabled (-1) a
spinning FIFO thread owns its CPU for good. On top of it, :class:`Watchdog`
samples the CPU time the real-time threads of every group process use (a thread
counts while it runs at SCHED_FIFO: at its group's priority, or at one a waiter
lent it by priority inheritance, so a group of no priority that spins while
boosted is caught too) and, when they have kept a CPU busy for ``limit``
seconds (on average over that window), demotes all of its threads to
SCHED_OTHER and records why. The limit is kept
below the kernel's throttling window: once RT tasks have used their share of a
period, the kernel pauses *every* RT task on that CPU, the high-priority ones
too, so a runaway must be demoted before that happens. The watchdog's own thread asks for
SCHED_FIFO 99 so that it still runs when FIFO groups fill every CPU; it sleeps
between samples, so it never competes for long.

:func:`prioritise_watcher` places the supervisor's own watching loop just above
ordinary work (SCHED_FIFO 1): CPU hogs at normal priority cannot blind it, and it
never delays a real-time group; a FIFO group that keeps the CPUs from it is what
the watchdog demotes.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections import deque
from collections.abc import Callable

from .procstat import thread_times

__all__ = ["Watchdog", "RealTimeMeter", "rt_throttling", "BUSY_SHARE", "prioritise_watcher", "WATCHER_PRIORITY"]

WATCHER_PRIORITY = 1  # SCHED_FIFO: above every ordinary task, below every real-time group

BUSY_SHARE = 0.9  # of one CPU, on average over the window, counts as spinning
_SAMPLE = 0.1  # seconds


def rt_throttling() -> str:
    """The kernel's RT throttling, described (``"off"`` when disabled or unknown)."""
    try:
        with open("/proc/sys/kernel/sched_rt_runtime_us") as r, open("/proc/sys/kernel/sched_rt_period_us") as p:
            runtime, period = int(r.read()), int(p.read())
    except (OSError, ValueError):
        return "unknown"
    if runtime < 0:
        return "off"
    return f"{runtime / period:.0%} of each {period / 1e6:g} s for real-time tasks"


def prioritise_watcher() -> tuple[str, Callable[[], None]]:
    """Raise the calling thread to SCHED_FIFO ``WATCHER_PRIORITY``; describe what was applied
    and return how to undo it.

    The policy is reset on fork (``SCHED_RESET_ON_FORK``), so the group processes and
    threads this thread starts keep the scheduling they had before. Meant for a loop that
    sleeps between looks (never one that busy-waits). Where SCHED_FIFO is refused the
    thread stays as it is and the description says so.
    """
    if os.environ.get("ANODIZE_NO_RT"):
        return "SCHED_OTHER (SCHED_FIFO disabled by ANODIZE_NO_RT)", _nothing
    tid = threading.get_native_id()  # the undoing may run on another thread
    try:
        policy, param = os.sched_getscheduler(tid), os.sched_getparam(tid)
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(WATCHER_PRIORITY))
    except (OSError, AttributeError) as error:
        reason = getattr(error, "strerror", None) or "not supported here"
        return f"SCHED_OTHER (SCHED_FIFO refused: {reason})", _nothing

    def restore() -> None:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(tid, policy, param)

    return f"SCHED_FIFO {WATCHER_PRIORITY}", restore


def _nothing() -> None:
    """Nothing to undo."""


def demote(pid: int) -> int:
    """Move every thread of ``pid`` to SCHED_OTHER; returns how many were moved."""
    moved = 0
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return 0
    for tid in tids:
        try:
            os.sched_setscheduler(int(tid), os.SCHED_OTHER, os.sched_param(0))
            moved += 1
        except OSError:
            pass
    return moved


class RealTimeMeter:
    """The CPU seconds a process's threads have used while under a real-time policy, added
    up from one reading to the next (a thread's time between two readings counts when it is
    real time at the second: a boost that began a moment ago brings none of the thread's past)."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.used = 0.0
        self._last: dict[int, float] = {}

    def read(self) -> float | None:
        """The real-time CPU seconds so far; None once the process is gone."""
        times = thread_times(self.pid)
        if times is None:
            return None
        for tid, (cpu, realtime) in times.items():
            before = self._last.get(tid)
            if realtime and before is not None:
                self.used += max(0.0, cpu - before)
        self._last = {tid: cpu for tid, (cpu, _) in times.items()}
        return self.used


class Watchdog:
    """Demotes FIFO group processes that keep a CPU busy for ``limit`` seconds.

    Args:
        limit: seconds of uninterrupted spinning tolerated.
        on_demote: called with (group name, description) after a demotion.
    """

    def __init__(self, limit: float, on_demote: Callable[[str, str], None]) -> None:
        self.limit = limit
        self.on_demote = on_demote
        self._watched: dict[str, tuple[RealTimeMeter, deque[tuple[float, float]]]] = {}
        self._lock = threading.Lock()
        self._stopped = threading.Event()
        self._thread = threading.Thread(target=self._run, name="anodize-watchdog", daemon=True)
        self.scheduling = ""

    def watch(self, group: str, pid: int) -> None:
        """Watch ``pid``, group ``group``'s process, whatever its scheduling now: a boost can
        make its threads real time later."""
        with self._lock:
            self._watched[group] = (RealTimeMeter(pid), deque())
        if not self._thread.is_alive() and not self._stopped.is_set():
            self._thread.start()

    def forget(self, group: str) -> None:
        with self._lock:
            self._watched.pop(group, None)

    def stop(self) -> None:
        self._stopped.set()

    def _run(self) -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(99))
            self.scheduling = "SCHED_FIFO 99"
        except (OSError, AttributeError):
            self.scheduling = "SCHED_OTHER (SCHED_FIFO refused)"
        while not self._stopped.wait(_SAMPLE):
            with self._lock:
                watched = list(self._watched.items())
            for group, (meter, samples) in watched:
                self.check(group, meter.pid, samples, time.monotonic(), meter.read())

    def check(self, group: str, pid: int, samples: deque[tuple[float, float]], now: float,
              used: float | None) -> bool:
        """Record one sample (``used``: the real-time CPU seconds so far, None once the
        process is gone); demote and report when the window shows spinning."""
        if used is None:
            self.forget(group)
            return False
        samples.append((now, used))
        while samples and now - samples[0][0] > self.limit + _SAMPLE:
            samples.popleft()
        if len(samples) < 2 or now - samples[0][0] < self.limit:
            return False
        (t0, u0), (t1, u1) = samples[0], samples[-1]
        # The mean, not every sample: the kernel's RT throttling pauses a spinner briefly.
        if t1 <= t0 or (u1 - u0) / (t1 - t0) < BUSY_SHARE:
            return False
        moved = demote(pid)
        self.forget(group)
        self.on_demote(group, f"watchdog demoted {moved} threads to SCHED_OTHER: a CPU stayed "
                              f"busy at SCHED_FIFO for {self.limit:g} s")
        return True
