"""Role functions for the liveness runs (module level: group processes import them)."""

from __future__ import annotations

import ctypes
import os
import re
import time
from pathlib import Path

from anodize import Endpoint


def _dir() -> Path:
    return Path(os.environ["ANODIZE_TEST_DIR"])


def server(ep: Endpoint) -> None:
    while (message := ep.recv("A")).label == "ping":
        ep.send("A", "pong", message.payload + 1)


def busy_until_released(ep: Endpoint) -> None:
    """Says where it runs, then keeps its CPU busy (in Python: the GIL changes hands) until the
    test releases it, and ends the session."""
    ep.send("B", "ping", 0)
    ep.recv("B")
    (_dir() / "pid").write_text(str(os.getpid()))
    released = _dir() / "released"
    while not released.exists():
        sum(range(10_000))
    ep.send("B", "stop")


def pings_for_a_while(ep: Endpoint) -> None:
    """Pings every 50 ms for four seconds, having said it started."""
    (_dir() / "started").write_text(str(os.getpid()))
    deadline = time.monotonic() + 4.0
    n = 0
    while time.monotonic() < deadline:
        ep.send("B", "ping", n)
        n = ep.recv("B").payload
        time.sleep(0.05)
    ep.send("B", "stop")


def holds_the_gil_on_the_cpu(ep: Endpoint) -> None:
    """A regular expression that backtracks for minutes: C code that never releases the GIL."""
    ep.send("B", "ping", 0)
    ep.recv("B")
    re.fullmatch(r"(a|aa)+b", "a" * 60)


def holds_the_gil_asleep(ep: Endpoint) -> None:
    """sleep(3) called through PyDLL, which keeps the GIL: blocked, not on the CPU."""
    ep.send("B", "ping", 0)
    ep.recv("B")
    ctypes.PyDLL(None).sleep(3600)
