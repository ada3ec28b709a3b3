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


# S sends r, waits for M's count, stalls past M's deadline, and goes on; M counts the timeouts it
# takes and sends each count back: what M sends depends on where its waits expired.
WATCH = "global W(S, M) = mu t. S -> M : { r(c: int). M -> S : seen(n: int). t, stop } within 50ms else timeout"


def stalling_sensor(ep: anodize.Endpoint) -> None:
    for c in range(3):
        ep.send("M", "r", {"c": c})
        ep.recv("M")
        ep.sleep(0.3 * c)  # 0, then at least two of M's 50 ms, then at least four (room for late wakes)
    ep.send("M", "stop")


def counting_monitor(ep: anodize.Endpoint) -> None:
    timeouts = 0
    while (message := ep.recv("S")).label != "stop":
        if message.label == anodize.TIMEOUT:
            timeouts += 1
        else:
            ep.send("S", "seen", {"n": timeouts})
