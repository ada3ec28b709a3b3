"""Roles for test_gc_freeze.py (module level: group processes import them). A tells B whether
A's own function is still among what the collector scans, and how many objects are frozen."""

from __future__ import annotations

import gc

from anodize import Endpoint

PROTOCOL = "global S(A, B) = A -> B : seen(scanned: bool, frozen: int)"


def reporter(ep: Endpoint) -> None:
    scanned = any(thing is reporter for thing in gc.get_objects())  # every generation but the frozen one
    ep.send("B", "seen", {"scanned": scanned, "frozen": gc.get_freeze_count()})


def checker(ep: Endpoint) -> None:
    seen = ep.recv("A").payload
    if seen["scanned"] or seen["frozen"] < 10_000:
        raise AssertionError(f"the group's start was not frozen: {seen}")
