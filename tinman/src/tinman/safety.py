"""The safety layer: Move never drives the robot into what its scanner sees, whatever the pose says.

Every command Move sends, the teleop's as the path follower's, passes through
``SafetyLayer.limit`` with the latest scan (:mod:`tinman.scanner`, taken from the
robot's true pose) and its age. The robot has moved since the scan was taken: at
most at the speed last commanded, so that much less of the free distance is left.
With no scan, or one older than ``STALE_SCAN``, the robot may turn but not drive
(counted in ``blind``): a scanner that stopped is no licence to move. The scan is the robot's own sensing:
it does not go through visual odometry, the map or the planner, so no failure of
those can drive the robot into a wall or a box. Only the linear speed is limited;
turning on the spot is always allowed (it moves the disc-shaped footprint nowhere).

The robot's footprint, a disc of ``ROBOT_RADIUS`` grown by ``FOOTPRINT_MARGIN``,
sweeps a corridor along its heading (ahead when driving forward, behind when
reversing). The free distance is how far the footprint can go before the first
scan point in that corridor, less ``STOP_MARGIN``. A command of speed ``v`` is let
through only if the robot can still stop within the free distance after driving
one more period at ``v``:

    v * period + v**2 / (2 * BRAKE_DECEL) <= free

Faster commands are cut to the fastest speed that satisfies it (the robot slows);
when none does, the robot stops (a *safety stop*). Since each period's command keeps
the inequality, the next period's does too with the base decelerating at
``BRAKE_DECEL``, below the base's own limit: a braking already begun can always be
finished. The numbers, and why, are in docs/decisions (the safety layer's record).
"""

from __future__ import annotations

import math

import numpy as np

from .messages import LaserScan
from .scanner import scan_points
from .world import ROBOT_RADIUS

__all__ = ["SafetyLayer", "BRAKE_DECEL", "STOP_MARGIN", "FOOTPRINT_MARGIN", "MOVING", "STALE_SCAN"]

BRAKE_DECEL = 0.8        # m/s^2: 80% of the base's 1.0 m/s^2 limit (tinman.sim.DiffDrive)
STOP_MARGIN = 0.05       # metres left between the footprint and the nearest reading once stopped
FOOTPRINT_MARGIN = 0.02  # metres the corridor is wider than the robot on each side
MOVING = 1e-3            # m/s: a command this slow asks for no motion (tinman.mixer.IDLE_EPSILON)
STALE_SCAN = 0.25        # seconds: a scan older than this is none (six scanner periods at 25 Hz)


class SafetyLayer:
    """Limits each command's linear speed to what the latest scan allows.

    Args:
        period: seconds each command drives (the control period).

    Attributes:
        stops: safety stops: how often a command to move was cut to standing still (one
            per stop, however many periods it lasts, until the layer lets the robot move).
        slowed: commands whose speed was reduced, but not to zero.
        blind: commands to move held to standing still for want of a scan younger than
            ``STALE_SCAN``.
        free: the free distance ahead (or behind) at the last command that moved (metres).
    """

    def __init__(self, period: float) -> None:
        if period <= 0:
            raise ValueError(f"the control period must be positive, got {period}")
        self.period = period
        self.stops = 0
        self.slowed = 0
        self.blind = 0
        self.free = math.inf
        self._holding = False
        self._speed = 0.0  # the last command's linear speed let through (m/s, magnitude)

    def limit(self, v: float, w: float, scan: LaserScan | None, age: float = 0.0) -> tuple[float, float]:
        """The command ``(v, w)`` (m/s, rad/s) as the scan, taken ``age`` seconds ago, allows it
        to be driven (None: no scan yet)."""
        v, w = self._limit(v, w, scan, age)
        self._speed = abs(v)
        return v, w

    def _limit(self, v: float, w: float, scan: LaserScan | None, age: float) -> tuple[float, float]:
        if abs(v) <= MOVING:
            self._holding = False
            return v, w
        if scan is None or age > STALE_SCAN:
            self.blind += 1
            return 0.0, w
        forward, left = scan_points(scan)
        # Since the scan the robot drove on, at most at the speed last let through.
        self.free = free_distance(forward if v > 0 else -forward, left) - self._speed * max(0.0, age)
        allowed = safe_speed(self.free, self.period)
        if abs(v) <= allowed:
            self._holding = False
            return v, w
        if allowed <= MOVING:
            self.stops += not self._holding
            self._holding = True
            return 0.0, w
        self._holding = False
        self.slowed += 1
        return math.copysign(allowed, v), w


def free_distance(forward: np.ndarray, left: np.ndarray, radius: float = ROBOT_RADIUS) -> float:
    """How far the robot can drive straight ahead before its grown footprint is ``STOP_MARGIN``
    from the nearest point ``(forward, left)`` (robot frame, metres); ``inf`` with none in the way."""
    reach = radius + FOOTPRINT_MARGIN
    ahead = (forward > 0) & (np.abs(left) < reach)
    if not ahead.any():
        return math.inf
    contact = forward[ahead] - np.sqrt(reach * reach - left[ahead] ** 2)
    return float(contact.min()) - STOP_MARGIN


def safe_speed(free: float, period: float) -> float:
    """The fastest speed from which the robot, after one more ``period``, stops within ``free``
    metres braking at ``BRAKE_DECEL`` (the positive root of ``v*period + v**2/(2a) = free``)."""
    if free <= 0:
        return 0.0
    if math.isinf(free):
        return math.inf
    a = BRAKE_DECEL
    return a * (math.sqrt(period * period + 2.0 * free / a) - period)
