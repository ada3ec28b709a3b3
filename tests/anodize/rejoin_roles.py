"""Roles for the tests of a host cut off and back (imported by name in the groups' processes)."""

from __future__ import annotations

import os

from anodize import Endpoint


def pausing_producer(ep: Endpoint) -> None:
    """Send 0, make the file $REJOIN_FLOWING, then pause $REJOIN_PAUSE seconds, touching nothing
    (the first incarnation only: $REJOIN_MARKER does not exist yet), so that a cut and a heal
    pass unnoticed here; then send 1..$DDS_TEST_COUNT-1 and stop."""
    first = not os.path.exists(os.environ["REJOIN_MARKER"])
    if first:
        with open(os.environ["REJOIN_MARKER"], "w", encoding="utf-8"):
            pass
    ep.send("C", "data", 0)
    if first:
        with open(os.environ["REJOIN_FLOWING"], "w", encoding="utf-8"):
            pass
        ep.sleep(float(os.environ.get("REJOIN_PAUSE", "40")))
    for i in range(1, int(os.environ.get("DDS_TEST_COUNT", "100"))):
        ep.send("C", "data", i)
    ep.send("C", "stop")


def few_ticks(ep: Endpoint) -> None:
    """Tick 100 times, 20 ms apart (about 2 s, longer than a failure elsewhere takes to act), then done."""
    for i in range(100):
        ep.send("R", "tick", i)
        ep.sleep(0.02)
    ep.send("R", "done")
