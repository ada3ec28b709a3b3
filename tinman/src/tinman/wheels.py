"""Wheel odometry as a differential drive's encoders give it: integrated, with slip and noise.

A ROS diff-drive controller (``diff_drive_controller``, Gazebo's ``DiffDrive`` plugin)
integrates the wheels' turns into a pose in its ``odom`` frame and publishes it as
``nav_msgs/Odometry``. Its error is not white: a wheel whose radius is a little off turns
every metre into a little too much or too little, and one wheel differing from the other
turns a straight line into an arc. This model gives each wheel a fixed scale error (drawn
once, from the seed), adds a little slip to every step (a per-step scale noise on each
wheel) and a small heading noise (the floor's unevenness, the castor), and integrates the
measured wheel distances along arcs, as the plugin does.

The numbers (``WheelNoise``): each wheel's scale error uniform within +-3 %, slip 2 %
(one sigma) of each step's wheel distance, heading noise 0.002 rad (one sigma) per step
while moving, a track of 0.30 m. Over the default room's patrol (about 10 m) that drifts
a few tens of centimetres and several degrees: a robot steered by it alone would not
find its dock, which is why it is fused with the camera's odometry (:mod:`tinman.estimator`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .sim import arc_pose

__all__ = ["WheelNoise", "WheelOdometry"]


@dataclass(frozen=True)
class WheelNoise:
    """How wrong the wheels are.

    Attributes:
        scale: each wheel's fixed scale error is drawn uniformly in ``[-scale, scale]``.
        slip: one sigma of the per-step scale noise of each wheel's distance.
        heading: one sigma of the heading noise added per step while the robot moves (radians).
        track: the distance between the wheels (metres).
    """

    scale: float = 0.03
    slip: float = 0.02
    heading: float = 0.002
    track: float = 0.30


class WheelOdometry:
    """The pose a diff-drive's encoders integrate, in the odometry's frame (which starts at ``start``).

    Args:
        start: the pose the odometry starts from (the robot's dock).
        seed: draws the wheels' scale errors and the per-step noise.
        noise: the error model; ``WheelNoise()`` when omitted.

    Attributes:
        pose: ``(x, y, theta)`` the wheels have integrated so far.
        velocity: ``(v, w)`` the wheels measured over the last step.
        scales: the left and right wheels' fixed scale factors (``1 + error``).
    """

    def __init__(self, start: tuple[float, float, float], seed: int = 0, noise: WheelNoise | None = None) -> None:
        self.noise = noise or WheelNoise()
        self._random = np.random.default_rng([seed, 0x0D0])  # not the scanner's stream: its own
        left, right = self._random.uniform(-self.noise.scale, self.noise.scale, size=2)
        self.scales = (1.0 + float(left), 1.0 + float(right))
        self.pose: tuple[float, float, float] = start
        self.velocity: tuple[float, float] = (0.0, 0.0)

    def step(self, v: float, w: float, dt: float) -> tuple[float, float, float]:
        """The wheels turned as the robot truly moved, ``(v, w)`` for ``dt`` seconds: the new pose.

        Raises:
            ValueError: ``dt`` is not positive.
        """
        if not dt > 0:
            raise ValueError(f"a wheel odometry step needs a positive duration, got {dt}")
        half = self.noise.track / 2.0
        left, right = (v - w * half) * dt, (v + w * half) * dt  # the wheels' true distances
        if left == 0.0 and right == 0.0:
            self.velocity = (0.0, 0.0)
            return self.pose
        slip = self._random.normal(0.0, self.noise.slip, size=2)
        left *= self.scales[0] * (1.0 + slip[0])
        right *= self.scales[1] * (1.0 + slip[1])
        v_measured = (left + right) / 2.0 / dt
        w_measured = (right - left) / self.noise.track / dt + self._random.normal(0.0, self.noise.heading) / dt
        x, y, theta = arc_pose(*self.pose, v_measured, w_measured, dt)
        self.pose = (x, y, math.remainder(theta, math.tau))
        self.velocity = (v_measured, w_measured)
        return self.pose
