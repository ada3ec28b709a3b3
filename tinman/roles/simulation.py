"""The simulation and view group (priority 10): Gazebo and Visualizer."""

from __future__ import annotations

import time

from anodize import Endpoint

from ..faults import start_faults
from ..messages import PoseStamped, Twist, seconds
from ..picture import draw_run
from ..records import save_record
from ..settings import current
from ..sim import DiffDrive
from ..world import DEFAULT_WORLD

__all__ = ["gazebo", "visualizer", "REDRAW_PERIOD"]

REDRAW_PERIOD = 5.0  # seconds between two live pictures


def gazebo(ep: Endpoint) -> None:
    """The robot in the room: each command drives it for one control period (lockstep)."""
    settings = current()
    start_faults("Gazebo")
    robot = DiffDrive(DEFAULT_WORLD)
    period = 1.0 / settings.control_rate
    start = time.monotonic()
    trace: list[list[float]] = []
    try:
        while True:
            twist: Twist = ep.recv("Move").payload
            x, y, theta = robot.step(twist.linear.x, twist.angular.z, period)
            trace.append([round(time.monotonic() - start, 3), round(x, 4), round(y, 4), round(theta, 4),
                          round(robot.velocity[0], 3), round(robot.velocity[1], 3)])
    finally:
        save_record("Gazebo", {"trajectory": trace, "odometer_m": robot.odometer, "bumps": robot.bumps,
                               "columns": ["t", "x", "y", "theta", "v", "w"]})


def visualizer(ep: Endpoint) -> None:
    """Keeps the estimated trajectory and redraws the live picture every few seconds."""
    settings = current()
    start_faults("Visualizer")
    estimate: list[tuple[float, float, float, float]] = []
    last_stamp: float | None = None
    next_draw = time.monotonic() + REDRAW_PERIOD
    live = settings.records / "live.png"
    try:
        while True:
            pose: PoseStamped = ep.recv("VisOdom").payload
            stamp = seconds(pose.header.stamp)
            if stamp != last_stamp:  # a dropped frame repeats the last estimate
                last_stamp = stamp
                p = pose.pose.position
                estimate.append((stamp, p.x, p.y, p.z))
            if time.monotonic() >= next_draw:
                draw_run(live, settings, estimate=estimate)
                next_draw = time.monotonic() + REDRAW_PERIOD
    finally:
        save_record("Visualizer", {"poses_received": len(estimate)})
