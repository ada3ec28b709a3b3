"""Faults ``anodize run tinman --inject FAULT=GROUP`` puts into a group, to watch isolation work."""

from __future__ import annotations

import math
import threading
import time

import numpy as np

from .settings import current
from .world import DEFAULT_WORLD

__all__ = ["start_faults", "memory_hog", "blinded", "BLIND_FROM", "BLIND_UNTIL", "lied", "LIE_TURN", "overspeed",
           "OVERSPEED", "OVERSPEED_AFTER", "STALL_FROM", "STALL_FOR"]

HOG_STEP = 16 * 2**20  # bytes kept per step
HOG_PERIOD = 0.1       # seconds between steps: 160 MiB/s
HOG_DELAY = 3.0        # seconds of normal running first, so the report shows the group before and after
BLIND_FROM, BLIND_UNTIL = 3.0, 5.0  # seconds into the run: "blind-camera" covers the lens then
OVERSPEED = 2.0  # m/s: "overspeed" commands this, four times the protocol's limit of 0.5 m/s
OVERSPEED_AFTER = 2.0  # seconds of normal commands first
# "stalled-pose" (perception): VisOdom holds its next pose to Move back, once, STALL_FROM seconds into its
# run, for STALL_FOR seconds, as a tracker stuck in a long optimisation would
STALL_FROM = 3.0  # seconds into VisOdom's run
STALL_FOR = 2.0  # seconds the pose is held back (four times Move's patience of 500 ms)
LIE_TURN = math.pi / 2  # "lying-pose": the estimate's whole map is turned this far about the dock


def start_faults(role: str) -> None:
    """Start the fault injected into ``role``'s group, if any (call once per role, at its start)."""
    if current().fault_for(role) == "memory-hog":
        threading.Thread(target=memory_hog, name=f"{role}-memory-hog", daemon=True).start()


def blinded(role: str, elapsed: float) -> bool:
    """Whether ``role``'s camera is blinded ``elapsed`` seconds into the run ("blind-camera": its
    frames are black and read no depth, as with a covered lens, from 3 s to 5 s)."""
    return current().fault_for(role) == "blind-camera" and BLIND_FROM <= elapsed < BLIND_UNTIL


def lied(role: str, t_wc: np.ndarray) -> np.ndarray:
    """The camera pose ``t_wc`` as ``role`` reports it: unchanged, or with "lying-pose" injected
    into its group, turned ``LIE_TURN`` (counter-clockwise) about the dock.

    The lie is self-consistent, as a wrong map alignment or a false loop closure is: every motion
    the estimate reports is a real one, turned. The robot leaves its dock facing east and believes
    it faces north; steering east by that belief drives it south, at the wall 0.8 m away. Only a
    sensor that does not go through the estimate (the safety layer's scan) can stop it.
    """
    if current().fault_for(role) != "lying-pose":
        return t_wc
    x, y, _ = DEFAULT_WORLD.start
    c, s = math.cos(LIE_TURN), math.sin(LIE_TURN)
    turn = np.array([[c, -s, 0.0, x - c * x + s * y], [s, c, 0.0, y - s * x - c * y],
                     [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    turned: np.ndarray = turn @ t_wc
    return turned


_started: dict[str, float] = {}  # per role, when overspeed first saw a command


def overspeed(role: str, v: float, w: float) -> tuple[float, float]:
    """The command ``(v, w)`` as ``role`` sends it: unchanged, or with "overspeed" injected into its
    group, ``OVERSPEED`` forward from ``OVERSPEED_AFTER`` seconds after the first command on, as a
    controller with a wrong gain would (the protocol's refinement refuses it: nothing leaves)."""
    if current().fault_for(role) != "overspeed":
        return v, w
    now = time.monotonic()
    start = _started.setdefault(role, now)
    return (OVERSPEED, w) if now - start >= OVERSPEED_AFTER else (v, w)


def memory_hog() -> None:
    """Allocate and touch memory without end, as a leaking planner would.

    The group's memory bound stops the whole group; nothing here catches that.
    """
    time.sleep(HOG_DELAY)
    kept = []
    while True:
        kept.append(bytearray(HOG_STEP))  # bytearray() zero-fills: the pages are really used
        time.sleep(HOG_PERIOD)
