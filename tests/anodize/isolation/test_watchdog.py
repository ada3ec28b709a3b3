"""The real-time watchdog's decision, on recorded CPU samples (nothing spins here)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections import deque

import pytest

from anodize._isolation.procstat import cpu_seconds
from anodize._isolation.watchdog import Watchdog, rt_throttling


def feed(dog: Watchdog, samples: list[tuple[float, float]], pid: int = 0) -> bool:
    window: deque[tuple[float, float]] = deque()
    return any(dog.check("g", pid, window, t, used) for t, used in samples)


def test_a_group_busy_for_the_whole_window_is_demoted_and_reported() -> None:
    demoted: list[tuple[str, str]] = []
    dog = Watchdog(1.0, lambda group, why: demoted.append((group, why)))
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        # 98% of a CPU for 1.1 s, with one sample halved (the kernel's RT throttling pause)
        spinning = [(t * 0.1, t * 0.1 * 0.98 - (0.05 if t >= 6 else 0.0)) for t in range(12)]
        assert feed(dog, spinning, sleeper.pid)
        assert demoted and demoted[0][0] == "g" and "SCHED_OTHER" in demoted[0][1]
        assert os.sched_getscheduler(sleeper.pid) == os.SCHED_OTHER
    finally:
        sleeper.kill()
        sleeper.wait()


def test_a_busy_spell_shorter_than_the_limit_or_a_loop_that_sleeps_is_left_alone() -> None:
    dog = Watchdog(1.0, lambda group, why: None)
    short = [(t * 0.1, t * 0.1) for t in range(10)]  # busy, but only 0.9 s
    assert not feed(dog, short)
    working = [(t * 0.1, t * 0.1 * 0.6) for t in range(40)]  # a heavy loop that still sleeps 40%
    assert not feed(dog, working)


def test_cpu_time_and_throttling_are_read_from_proc() -> None:
    assert cpu_seconds(os.getpid()) is not None and cpu_seconds(os.getpid()) > 0
    assert rt_throttling() == "off" or "real-time tasks" in rt_throttling() or rt_throttling() == "unknown"


def test_the_meter_counts_only_time_spent_real_time_and_no_past_of_a_thread_just_boosted(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from anodize._isolation import watchdog

    readings = iter([
        {1: (10.0, True), 2: (50.0, False)},   # 1: the group's real-time thread; 2: ordinary, 50 s of past
        {1: (10.4, True), 2: (50.3, False)},   # 2's 0.3 s is ordinary work: not counted
        {1: (10.5, True), 2: (50.9, True)},    # 2 was boosted: its 0.6 s since the last reading counts, not its 50 s
        {1: (10.5, True), 2: (51.0, False), 3: (7.0, True)},  # 3 is new: nothing of it yet
        {1: (10.6, True), 3: (7.2, True)},     # 2 ended
        None,                                  # the process is gone
    ])
    monkeypatch.setattr(watchdog, "thread_times", lambda pid: next(readings))
    meter = watchdog.RealTimeMeter(1234)
    used = [meter.read() for _ in range(6)]
    assert used[:5] == pytest.approx([0.0, 0.4, 0.4 + 0.1 + 0.6, 1.1, 1.1 + 0.1 + 0.2])
    assert used[5] is None


def test_thread_times_reads_each_thread_s_policy() -> None:
    from anodize._isolation.procstat import thread_times

    times = thread_times(os.getpid())
    assert times is not None and threading.get_native_id() in times
    cpu, realtime = times[threading.get_native_id()]
    assert cpu > 0 and realtime == (os.sched_getscheduler(0) in (os.SCHED_FIFO, os.SCHED_RR))
    assert thread_times(2**22 + 1) is None  # beyond pid_max: no such process
