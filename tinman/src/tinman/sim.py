"""A differential-drive robot on the floor of a ``World``: exact kinematics, limits, bumps.

The simulator stands in for the motors and wheel odometry. Commands are clamped to
the robot's speed limits, then to its acceleration limits (a real base cannot jump
from rest to full speed), and the pose is advanced along the exact circular arc the
wheels trace at constant ``(v, w)`` over the step, so the result does not depend on
the step size the way Euler integration would.
"""

from __future__ import annotations

import math

from .world import ROBOT_RADIUS, World

__all__ = ["DiffDrive", "arc_pose"]

# Arc points checked for collisions are at most this far apart, so a long step cannot
# jump over a thin obstacle.
_COLLISION_SAMPLE = 0.02  # metres


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


def _wrap(angle: float) -> float:
    """The angle in ``[-pi, pi)``."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def arc_pose(x: float, y: float, theta: float, v: float, w: float, dt: float) -> tuple[float, float, float]:
    """Where constant ``(v, w)`` for ``dt`` seconds takes a robot at ``(x, y, theta)``.

    Args:
        x, y, theta: the start pose (metres, radians).
        v, w: linear (m/s) and angular (rad/s) velocity.
        dt: duration (s).

    Returns:
        The end pose ``(x, y, theta)``, theta wrapped to ``[-pi, pi)``.
    """
    turn = w * dt
    if abs(turn) < 1e-9:
        # Straight line; the arc formula divides by w.
        return x + v * dt * math.cos(theta), y + v * dt * math.sin(theta), _wrap(theta + turn)
    radius = v / w
    end = theta + turn
    return (x + radius * (math.sin(end) - math.sin(theta)),
            y - radius * (math.cos(end) - math.cos(theta)),
            _wrap(end))


class DiffDrive:
    """A disc-shaped differential-drive robot in ``world``.

    Attributes:
        pose: ``(x, y, theta)`` now.
        velocity: ``(v, w)`` the robot moved with during the last step (0, 0 after a bump).
        odometer: distance travelled (metres, always increasing).
        bumps: steps refused because the motion would have hit a wall or a box.
    """

    def __init__(self, world: World, pose: tuple[float, float, float] | None = None,
                 max_linear: float = 0.5, max_angular: float = 1.5,
                 max_linear_accel: float = 1.0, max_angular_accel: float = 3.0,
                 radius: float = ROBOT_RADIUS) -> None:
        """A robot at rest.

        Args:
            world: the room; its ``collides`` decides what the robot bumps into.
            pose: the start pose; ``world.start`` when omitted.
            max_linear, max_angular: speed limits (m/s, rad/s).
            max_linear_accel, max_angular_accel: acceleration limits (m/s^2, rad/s^2);
                ``math.inf`` for none.
            radius: the robot's footprint (metres).

        Raises:
            ValueError: a limit is not positive, or the start pose collides.
        """
        if min(max_linear, max_angular, max_linear_accel, max_angular_accel, radius) <= 0:
            raise ValueError("speed, acceleration limits and radius must be positive")
        self.world = world
        x, y, theta = world.start if pose is None else pose
        if world.collides(x, y, radius):
            raise ValueError(f"start pose ({x:.3f}, {y:.3f}) collides with the world")
        self.pose: tuple[float, float, float] = (float(x), float(y), _wrap(float(theta)))
        self.velocity: tuple[float, float] = (0.0, 0.0)
        self.odometer = 0.0
        self.bumps = 0
        self.max_linear = max_linear
        self.max_angular = max_angular
        self.max_linear_accel = max_linear_accel
        self.max_angular_accel = max_angular_accel
        self.radius = radius

    def step(self, v: float, w: float, dt: float) -> tuple[float, float, float]:
        """Drive with the command ``(v, w)`` for ``dt`` seconds.

        Args:
            v, w: commanded linear (m/s) and angular (rad/s) velocity.
            dt: step length (s).

        Returns:
            The new pose. A motion that would hit a wall or a box is refused whole:
            the robot stays where it was, stops, and ``bumps`` grows by one.

        Raises:
            ValueError: ``dt`` is negative.
        """
        if dt < 0:
            raise ValueError(f"dt must not be negative, got {dt}")
        v = _clamp(v, self.max_linear)
        w = _clamp(w, self.max_angular)
        v_now, w_now = self.velocity
        v = v_now + _clamp(v - v_now, self.max_linear_accel * dt)
        w = w_now + _clamp(w - w_now, self.max_angular_accel * dt)
        distance = abs(v) * dt
        if distance > 0 and self._arc_collides(v, w, dt, distance):
            self.bumps += 1
            self.velocity = (0.0, 0.0)
            return self.pose
        self.pose = arc_pose(*self.pose, v, w, dt)
        self.velocity = (v, w)
        self.odometer += distance
        return self.pose

    def _arc_collides(self, v: float, w: float, dt: float, distance: float) -> bool:
        samples = max(1, math.ceil(distance / _COLLISION_SAMPLE))
        for i in range(1, samples + 1):
            x, y, _ = arc_pose(*self.pose, v, w, dt * i / samples)
            if self.world.collides(x, y, self.radius):
                return True
        return False
