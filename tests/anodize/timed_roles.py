"""Roles of the timed-monitor runs (tests/anodize/session/test_timed_monitor.py), importable
by a group's process: a controller that is late or out of range, and the motor it drives."""

from __future__ import annotations

import anodize

# C sends cmd(v) in a loop, then stop; M takes them. The tests put `within`, a refinement, on cmd.
CONTROL = "global G(C, M) = mu t. C -> M : { cmd(v: int). t, stop. end }"


def punctual(ep: anodize.Endpoint) -> None:
    for v in range(3):
        ep.send("M", "cmd", {"v": v})
    ep.send("M", "stop")


def late(ep: anodize.Endpoint) -> None:
    ep.send("M", "cmd", {"v": 1})
    ep.sleep(1.0)  # far past the deadline the tests give cmd: the next send is refused, blaming C
    ep.send("M", "cmd", {"v": 2})
    ep.send("M", "stop")


def out_of_range(ep: anodize.Endpoint) -> None:
    ep.send("M", "cmd", {"v": 1})
    ep.send("M", "cmd", {"v": 99})  # above the bound the tests give v
    ep.send("M", "stop")


def motor(ep: anodize.Endpoint) -> None:
    while ep.recv("C").label == "cmd":
        pass
