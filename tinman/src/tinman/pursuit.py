"""Pure pursuit: the velocity command that steers a differential-drive robot along a path.

Classic pure pursuit (Coulter, CMU-RI-TR-92-01): pick the point a lookahead distance
ahead along the path, and drive the circular arc through the robot and that point,
curvature ``2 y / d^2`` with ``y`` the point's sideways offset in the robot's frame and
``d`` its distance. A target behind the robot (more than ``turn_in_place_angle`` off
the heading) is faced first by turning on the spot, which a differential drive can do
and an arc cannot. The robot slows down over the last ``slowdown_distance`` of the path
and stops within ``goal_tolerance`` of its end.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

__all__ = ["PurePursuit"]

Pose = tuple[float, float, float]
Point = tuple[float, float]


def _closest_on_path(x: float, y: float, path: Sequence[Point], s_min: float, s_max: float) -> float:
    """The arc length, within ``[s_min, s_max]``, of the path point nearest to ``(x, y)`` (the first, on ties)."""
    best_distance, best_s, s = math.inf, s_min, 0.0
    for (ax, ay), (bx, by) in itertools.pairwise(path):
        span = math.hypot(bx - ax, by - ay)
        if s + span >= s_min and s <= s_max:
            # Metres along the segment, from its unit direction: never divide by span
            # squared, which is subnormal below about 1e-154 m and 0 below 1e-162 m.
            along, ux, uy = 0.0, 0.0, 0.0
            if span > 0:
                ux, uy = (bx - ax) / span, (by - ay) / span
                along = min(span, s_max - s, max(0.0, s_min - s, (x - ax) * ux + (y - ay) * uy))
            distance = math.hypot(ax + along * ux - x, ay + along * uy - y)
            if distance < best_distance:
                best_distance, best_s = distance, s + along
        s += span
    return best_s


def _point_at_length(path: Sequence[Point], s: float) -> Point:
    """The point ``s`` metres along the path (its end when ``s`` is past it)."""
    for (ax, ay), (bx, by) in itertools.pairwise(path):
        span = math.hypot(bx - ax, by - ay)
        if s <= span and span > 0:
            t = s / span
            return ax + t * (bx - ax), ay + t * (by - ay)
        s -= span
    return float(path[-1][0]), float(path[-1][1])


class PurePursuit:
    """A pure-pursuit controller with turn-in-place for targets behind the robot.

    The controller remembers how far along the current path the robot has come and
    looks for the nearest path point only from there to a little way ahead, so a path
    that turns back on itself or passes near its own start is followed in order. A
    different path starts again from its beginning.

    Attributes:
        lookahead: how far along the path, past the nearest path point, the target lies (metres).
        speed: cruising speed (m/s).
        max_angular: turning-rate limit (rad/s); arcs tighter than ``speed`` allows are
            driven slower rather than left.
        goal_tolerance: distance to the path's end that counts as arrived (metres).
    """

    def __init__(self, lookahead: float = 0.5, speed: float = 0.35, max_angular: float = 1.5,
                 goal_tolerance: float = 0.15, turn_in_place_angle: float = math.radians(60.0),
                 slowdown_distance: float = 0.5, turn_gain: float = 2.0, min_speed: float = 0.05) -> None:
        """A controller.

        Args:
            lookahead, speed, max_angular, goal_tolerance: see the class attributes.
            turn_in_place_angle: a target further off the heading than this (radians)
                is faced by turning on the spot first.
            slowdown_distance: over this last stretch of the path (metres) the speed
                falls in proportion to the distance left, to ``min_speed``.
            turn_gain: turning rate per radian of heading error when turning in place.
            min_speed: the slowest approach speed (m/s), so the goal is reached.

        Raises:
            ValueError: a distance, speed or gain is not positive.
        """
        if min(lookahead, speed, max_angular, goal_tolerance, turn_in_place_angle, slowdown_distance,
               turn_gain, min_speed) <= 0:
            raise ValueError("pure pursuit's distances, speeds and gains must be positive")
        self.lookahead = lookahead
        self.speed = speed
        self.max_angular = max_angular
        self.goal_tolerance = goal_tolerance
        self.turn_in_place_angle = turn_in_place_angle
        self.slowdown_distance = slowdown_distance
        self.turn_gain = turn_gain
        # Far enough to catch up after a few control periods or a hand-driven detour.
        self.search_window = 2.0 + 2.0 * lookahead
        self.min_speed = min(min_speed, speed)
        self._path: tuple[tuple[float, float], ...] = ()
        self._progress = 0.0

    def reset(self) -> None:
        """Forget the progress along the current path."""
        self._path = ()
        self._progress = 0.0

    def at_goal(self, pose: Sequence[float], path: Sequence[Point]) -> bool:
        """Whether the robot is within ``goal_tolerance`` of the path's end (True for an empty path)."""
        if not path:
            return True
        return math.hypot(path[-1][0] - pose[0], path[-1][1] - pose[1]) <= self.goal_tolerance

    def target(self, pose: Sequence[float], path: Sequence[Point]) -> Point:
        """The lookahead point: ``lookahead`` metres along the path past its point nearest the robot.

        The nearest point is sought from the progress made so far along this path to
        ``search_window`` ahead of it, and becomes the new progress.

        Raises:
            ValueError: the path is empty.
        """
        if not path:
            raise ValueError("cannot pursue an empty path")
        if len(path) == 1:
            return float(path[0][0]), float(path[0][1])
        key = tuple((float(px), float(py)) for px, py in path)
        if key != self._path:
            self._path, self._progress = key, 0.0
        self._progress = _closest_on_path(pose[0], pose[1], key, self._progress,
                                          self._progress + self.search_window)
        return _point_at_length(key, self._progress + self.lookahead)

    def command(self, pose: Sequence[float], path: Sequence[Point]) -> tuple[float, float]:
        """The velocity ``(v, w)`` that follows ``path`` from ``pose``.

        Args:
            pose: the robot's ``(x, y, theta)``.
            path: floor points ``(x, y)`` from (about) the robot to the goal.

        Returns:
            ``(v, w)`` in m/s and rad/s; ``(0.0, 0.0)`` at the goal or for an empty path.
        """
        if self.at_goal(pose, path):
            return 0.0, 0.0
        x, y, theta = pose[0], pose[1], pose[2]
        tx, ty = self.target(pose, path)
        cos_t, sin_t = math.cos(theta), math.sin(theta)
        ahead = (tx - x) * cos_t + (ty - y) * sin_t
        left = -(tx - x) * sin_t + (ty - y) * cos_t
        bearing = math.atan2(left, ahead)
        if abs(bearing) > self.turn_in_place_angle:
            return 0.0, math.copysign(min(self.max_angular, self.turn_gain * abs(bearing)), bearing)
        remaining = math.hypot(path[-1][0] - x, path[-1][1] - y)
        v = max(self.min_speed, self.speed * min(1.0, remaining / self.slowdown_distance))
        distance_squared = ahead * ahead + left * left
        if distance_squared < 1e-12:
            return v, 0.0  # the target is under the robot: any heading is as good
        w = v * 2.0 * left / distance_squared
        if abs(w) > self.max_angular:
            # Keep the arc, drive it slower.
            v *= self.max_angular / abs(w)
            w = math.copysign(self.max_angular, w)
        return v, w
