"""Roles for the spin then park tests (tests/anodize/transport/test_spin_process.py)."""

from __future__ import annotations

import time

from anodize import Endpoint

PROTOCOL = """
global Ping(A, B) = mu t. A -> B : {ping(nat). B -> A : pong(nat). t, stop}
global Steady(S, R) = mu t. S -> R : {tick(nat). t, fin}
"""

ROUND_TRIPS = 300
TICKS = 5000  # about 1.5 s at one every 0.3 ms: three times the watchdog's window


def client(ep: Endpoint) -> None:
    for n in range(ROUND_TRIPS):
        ep.send("B", "ping", n)
        assert ep.recv("B").payload == n
    ep.send("B", "stop")


def server(ep: Endpoint) -> None:
    while True:
        message = ep.recv("A")
        if message.label == "stop":
            return
        ep.send("A", "pong", message.payload)


def steady_sender(ep: Endpoint) -> None:
    """A tick every 0.3 ms or so (a sleep: this role burns no CPU): a peer fast enough
    that a 1 ms spin always pays, so only the allowance keeps the receiver off a busy CPU."""
    for n in range(TICKS):
        time.sleep(0.0002)
        ep.send("R", "tick", n)
    ep.send("R", "fin")


def counting_receiver(ep: Endpoint) -> None:
    expected = 0
    while ep.recv("S").label == "tick":
        expected += 1
    assert expected == TICKS
