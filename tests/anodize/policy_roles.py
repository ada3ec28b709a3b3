"""Role functions for the supervision tests (module level: group processes import them)."""

from __future__ import annotations

import math
import os
from pathlib import Path

from anodize import Endpoint

TICKS = 20
TICK_PERIOD = 0.05  # seconds: the independent pair runs about 1 s


def client(ep: Endpoint) -> None:
    for i in range(5):
        ep.send("B", "ping", i)
        if ep.recv("B").payload != i + 1:
            raise AssertionError("wrong pong")
    ep.send("B", "stop")


def server(ep: Endpoint) -> None:
    while (message := ep.recv("A")).label == "ping":
        ep.send("A", "pong", message.payload + 1)


def failing_client(ep: Endpoint) -> None:
    ep.send("B", "ping", 0)
    ep.recv("B")
    raise RuntimeError("the sensor is unplugged")  # FAILING_LINE


def once_failing_client(ep: Endpoint) -> None:
    """Fails in its first incarnation (a marker file remembers), conforms after."""
    marker = Path(os.environ["ANODIZE_TEST_MARKER"])
    if not marker.exists():
        marker.write_text("failed once")
        raise RuntimeError("first incarnation fails")
    client(ep)


def ping_then_sleep(ep: Endpoint) -> None:
    ep.send("B", "ping", 0)
    ep.recv("B")
    ep.sleep(math.inf)


def ping_without_pong(ep: Endpoint) -> None:
    ep.recv("A")
    ep.sleep(math.inf)


def ticker(ep: Endpoint) -> None:
    for i in range(TICKS):
        ep.send("D", "tick", i)
        ep.sleep(TICK_PERIOD)
    ep.send("D", "fin")


def endless_ticker(ep: Endpoint) -> None:
    """Ticks until stopped: a group that is still running whenever a stop comes, however late."""
    i = 0
    while True:
        ep.send("D", "tick", i)
        i += 1
        ep.sleep(TICK_PERIOD)


def tick_sink(ep: Endpoint) -> None:
    while ep.recv("C").label == "tick":
        pass
