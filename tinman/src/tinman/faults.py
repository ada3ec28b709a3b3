"""Faults ``anodize run tinman --inject FAULT=GROUP`` puts into a group, to watch isolation work."""

from __future__ import annotations

import threading
import time

from .settings import current

__all__ = ["start_faults", "memory_hog", "blinded", "BLIND_FROM", "BLIND_UNTIL"]

HOG_STEP = 16 * 2**20  # bytes kept per step
HOG_PERIOD = 0.1       # seconds between steps: 160 MiB/s
HOG_DELAY = 3.0        # seconds of normal running first, so the report shows the group before and after
BLIND_FROM, BLIND_UNTIL = 3.0, 5.0  # seconds into the run: "blind-camera" covers the lens then


def start_faults(role: str) -> None:
    """Start the fault injected into ``role``'s group, if any (call once per role, at its start)."""
    if current().fault_for(role) == "memory-hog":
        threading.Thread(target=memory_hog, name=f"{role}-memory-hog", daemon=True).start()


def blinded(role: str, elapsed: float) -> bool:
    """Whether ``role``'s camera is blinded ``elapsed`` seconds into the run ("blind-camera": its
    frames are black and read no depth, as with a covered lens, from 3 s to 5 s)."""
    return current().fault_for(role) == "blind-camera" and BLIND_FROM <= elapsed < BLIND_UNTIL


def memory_hog() -> None:
    """Allocate and touch memory without end, as a leaking planner would.

    The group's memory bound stops the whole group; nothing here catches that.
    """
    time.sleep(HOG_DELAY)
    kept = []
    while True:
        kept.append(bytearray(HOG_STEP))  # bytearray() zero-fills: the pages are really used
        time.sleep(HOG_PERIOD)
