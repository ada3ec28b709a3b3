"""How long ago this process started: a group's start barrier counts its wait from there, so
``--wait`` bounds a group's whole start (importing its roles, then the barrier)."""

from __future__ import annotations

import os
import time

__all__ = ["since_process_start"]


def since_process_start() -> float:
    """Seconds since this process started (0 where /proc cannot say)."""
    try:
        with open("/proc/self/stat", encoding="ascii") as stat:
            ticks = int(stat.read().rsplit(")", 1)[1].split()[19])  # field 22: starttime, in ticks since boot
        return max(0.0, time.clock_gettime(time.CLOCK_BOOTTIME) - ticks / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError, AttributeError):
        return 0.0
