"""Roles of the mixed-criticality example (see system.toml and README.md here).

``control`` runs a 100 Hz loop for ``SECONDS``; ``planner`` leaks 8 MiB every
0.2 s until its group's memory bound stops it; ``logger`` notices the planner is
gone and ends cleanly.
"""

from __future__ import annotations

import math
import time

from anodize import Endpoint, PeerFailedError

SECONDS = 6.0
PERIOD = 0.01  # 100 Hz


def control(ep: Endpoint) -> None:
    """Send a twist every period, on an absolute schedule (sleeping, never spinning)."""
    start = time.monotonic()
    ticks = int(SECONDS / PERIOD)
    for tick in range(ticks):
        ep.send("Motor", "twist", math.sin(tick * PERIOD))
        time.sleep(max(0.0, start + (tick + 1) * PERIOD - time.monotonic()))
    ep.send("Motor", "halt")


def motor(ep: Endpoint) -> None:
    while ep.recv("Control").label == "twist":
        pass


def planner(ep: Endpoint) -> None:
    """A planner with a leak: every plan keeps 8 MiB (touched, so it is really used)."""
    leaked = []
    for plan in range(10_000):
        leaked.append(bytearray(8 * 2**20))
        ep.send("Logger", "plan", plan)
        time.sleep(0.2)
    ep.send("Logger", "done")


def logger(ep: Endpoint) -> None:
    try:
        while ep.recv("Planner").label == "plan":
            pass
    except PeerFailedError as error:
        print(f"logger: {error}; carrying on without plans")
