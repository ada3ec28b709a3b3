"""Roles for test_group_runtime.py (module level: group processes import them). A tells B how
its process's Python runs: whether A's own function is still among what the collector scans,
how many objects are frozen, and the GIL's switch interval."""

from __future__ import annotations

import gc
import os
import sys

from anodize import Endpoint

PROTOCOL = "global S(A, B) = A -> B : seen(scanned: bool, frozen: int, switch: float)"


def reporter(ep: Endpoint) -> None:
    scanned = any(thing is reporter for thing in gc.get_objects())  # every generation but the frozen one
    ep.send("B", "seen", {"scanned": scanned, "frozen": gc.get_freeze_count(), "switch": sys.getswitchinterval()})


def checker(ep: Endpoint) -> None:
    """Checks what A said against ``RUNTIME_TEST_SWITCH`` (the switch interval A's group should have)."""
    seen = ep.recv("A").payload
    if seen["scanned"] or seen["frozen"] < 10_000:
        raise AssertionError(f"the group's start was not frozen: {seen}")
    if seen["switch"] != float(os.environ["RUNTIME_TEST_SWITCH"]):
        raise AssertionError(f"A's switch interval is {seen['switch']}, not {os.environ['RUNTIME_TEST_SWITCH']}")
