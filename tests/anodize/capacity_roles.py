"""Roles for the channel capacity tests (module level: group processes import them by name).

``CAPACITY_TEST_COUNT`` is how many numbers the producer sends (default 200)."""

from __future__ import annotations

import os

from anodize import Endpoint

STREAM = "global Stream(P, C) = mu t. P -> C : {data(int). t, stop}"


def _count() -> int:
    return int(os.environ.get("CAPACITY_TEST_COUNT", "200"))


def eager_producer(ep: Endpoint) -> None:
    """Send as fast as sends return."""
    for i in range(_count()):
        ep.send("C", "data", i)
    ep.send("C", "stop")


def slow_consumer(ep: Endpoint) -> None:
    """Take each number 1 ms apart, checking the order."""
    expected = 0
    while (message := ep.recv("P")).label == "data":
        if message.payload != expected:
            raise AssertionError(f"expected {expected}, got {message.payload}")
        expected += 1
        ep.sleep(0.001)


def stuck_consumer(ep: Endpoint) -> None:
    """Take one number, then never again: the producer fills the channel and waits."""
    ep.recv("P")
    ep.sleep(3600)


def failing_consumer(ep: Endpoint) -> None:
    """Take one number, wait a moment (the producer fills the channel), then fail."""
    ep.recv("P")
    ep.sleep(0.5)
    raise RuntimeError("the consumer gives up")


def silent_producer(ep: Endpoint) -> None:
    """Send nothing: wait for the run to stop."""
    ep.sleep(3600)


def waiting_consumer(ep: Endpoint) -> None:
    """Wait for a number that never comes."""
    ep.recv("P")
