"""The real-time watchdog's decision, on recorded CPU samples (nothing spins here)."""

from __future__ import annotations

import os
import subprocess
import sys
from collections import deque

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
