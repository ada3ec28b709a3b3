"""The roles of examples/fleet: a robot that patrols, and the base station's monitor of it."""

from __future__ import annotations

import math

from anodize import Endpoint


def robot(ep: Endpoint, drain: float = 5.0, step: float = 0.5) -> None:
    """Drive a leg around a circle, report where it is and what battery it has left, and go on
    until the monitor says stop; each leg costs ``drain`` percent of the battery."""
    battery, leg = 100.0, 0
    while True:
        leg += 1
        battery -= drain
        angle = leg * step
        ep.send("Monitor", "report", {"leg": leg, "x": math.cos(angle), "y": math.sin(angle), "battery": battery})
        if ep.recv("Monitor").label == "stop":
            ep.logger.warning("stopped by the base station after leg %d, battery %.0f%%", leg, battery)
            return
        ep.sleep(0.05)  # the leg's drive


def monitor(ep: Endpoint, low: float = 30.0) -> None:
    """Let the robot go on while its battery is above ``low`` percent; then stop it."""
    while True:
        report = ep.recv("Robot").payload
        if report["battery"] < low:
            ep.logger.warning("battery %.0f%% after leg %d, below %.0f%%: stop", report["battery"], report["leg"],
                              low)
            ep.send("Robot", "stop")
            return
        ep.send("Robot", "go")
