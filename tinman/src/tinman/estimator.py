"""One estimate of the robot's pose: an EKF on ``(x, y, theta)`` fusing wheel and visual odometry
and the poses the range scan finds on the known map.

Wheel odometry (:mod:`tinman.wheels`, ``nav_msgs/Odometry``) comes often and never loses
track, but drifts: each motion it reports is the prediction, the motion between two of
its readings composed onto the estimate, with noise that grows with the distance and
the turn (``OdometryNoise``). Visual odometry's poses come at the camera's rate and
drift less, but come late (a frame's pose is known tens of milliseconds after its
capture) and sometimes not at all (a covered lens, a plain wall): each is a measurement
of the whole pose, ``H = I``.

A late measurement is carried forward to the estimate's time by what the wheels
measured since its capture (the odometry's own poses are kept for ``HISTORY`` seconds):
the pose at capture composed with the wheels' motion from then to now. That adds the
wheels' error over tens of milliseconds, which is far below the camera's.

The range scanner's poses on the known map (:mod:`tinman.scan_match`, AMCL's part on a real
robot) are measurements of the whole pose too, each with its own covariance (:meth:`PoseFilter.locate`):
they bound the drift of both odometries, which nothing absolute bounded before.

A measurement further than ``GATE`` (Mahalanobis, chi-square with 3 degrees of freedom
at 0.999) from the estimate is refused as a false fix. The gate widens as the wheels
alone carry the estimate (their covariance grows with every motion), so a camera that
is refused ``MAX_REFUSED`` times in a row disagrees with everything the estimate knows:
its odometry is what went astray (a relocalisation that matched the wrong place), and
``refused_in_a_row`` tells its caller to set it right (VisOdom re-anchors it on the estimate).

The estimate is the robot's pose in the map, the frame both odometries start in (the
dock). Pure: no clock, no threads; the VisOdom role calls it from its threads under a lock.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["OdometryNoise", "PoseFilter", "compose", "between", "GATE", "MAX_REFUSED", "HISTORY",
           "MAP_SIGMA_FLOOR", "MAP_RELOCATE"]

Pose = tuple[float, float, float]

GATE = 16.27  # chi-square, 3 degrees of freedom, 0.999
MAP_RELOCATE = 5  # map matches refused in a row (half a second of scans) before the map sets the estimate
MAX_REFUSED = 15  # measurements refused in a row before the camera is believed (half a second at 30 fps)
HISTORY = 2.0  # seconds of wheel odometry kept to carry late measurements forward
# The least sigma of a pose found on the map (metres, metres, radians): the matcher's own covariance
# takes the beams as independent, which they are not (one wall, one map error), and is far smaller.
MAP_SIGMA_FLOOR = (0.01, 0.01, 0.01)


def compose(a: Pose, b: Pose) -> Pose:
    """The planar pose ``b`` (given in ``a``'s frame) in ``a``'s parent frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], math.remainder(a[2] + b[2], math.tau))


def between(a: Pose, b: Pose) -> Pose:
    """The motion from ``a`` to ``b`` in ``a``'s frame: ``compose(a, between(a, b)) == b``."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, math.remainder(b[2] - a[2], math.tau))


@dataclass(frozen=True)
class OdometryNoise:
    """How much a wheel odometry motion is trusted (one sigma), the classic odometry motion model.

    Attributes:
        per_metre: translation error per metre travelled (the wheels' scale error and slip).
        heading_per_metre: heading error per metre travelled (one wheel differing from the other).
        heading_per_radian: heading error per radian turned.
        floor: the least of each sigma per motion (metres, radians), so the covariance never collapses.
    """

    per_metre: float = 0.05
    heading_per_metre: float = 0.12
    heading_per_radian: float = 0.05
    floor: float = 1e-4


class PoseFilter:
    """An extended Kalman filter on the robot's planar pose.

    Args:
        start: the pose the robot starts at (its dock), known.
        vo_sigma: one sigma of a visual odometry pose, ``(x, y, theta)`` (metres, radians).
        noise: the wheel odometry's motion model.

    Attributes:
        pose: the estimate, at ``stamp``.
        covariance: its 3x3 covariance.
        stamp: the time of the last wheel odometry reading (None before any).
        predictions, updates, refused: how many odometry motions were applied, VO poses taken,
            VO poses refused by the gate.
        refused_in_a_row: VO poses refused since the last one taken.
        located, map_refused: poses found on the map (:meth:`locate`) taken, refused by the gate.
    """

    def __init__(self, start: Pose, vo_sigma: Pose = (0.03, 0.03, 0.03), noise: OdometryNoise | None = None) -> None:
        self.pose: Pose = start
        self.covariance = np.diag([1e-6, 1e-6, 1e-6])
        self.stamp: float | None = None
        self.noise = noise or OdometryNoise()
        self.measurement_covariance = np.diag(np.square(vo_sigma))
        self.predictions = self.updates = self.refused = 0
        self.located = self.map_refused = 0
        self.map_refused_in_a_row = 0
        self.relocated = 0  # times the map, refused MAP_RELOCATE times in a row, set the estimate
        self.refused_in_a_row = 0
        self._odometry_stamps: list[float] = []
        self._odometry_poses: list[Pose] = []

    # ---- the prediction --------------------------------------------------------------------

    def odometry(self, stamp: float, pose: Pose) -> None:
        """A wheel odometry reading: its integrated ``pose`` (in its own frame) at ``stamp``.

        The motion since the last reading moves the estimate; an older stamp than the last
        one's is ignored (readings come in order; a repeated one is no news)."""
        if not (math.isfinite(stamp) and all(math.isfinite(v) for v in pose)):
            self.refused += 1  # a reading from the network may say anything: none may poison the estimate
            return
        if self._odometry_stamps and stamp <= self._odometry_stamps[-1]:
            return
        if self._odometry_poses:
            self._predict(between(self._odometry_poses[-1], pose))
        self._odometry_stamps.append(stamp)
        self._odometry_poses.append(pose)
        self.stamp = stamp
        drop = bisect.bisect_left(self._odometry_stamps, stamp - HISTORY)
        if drop > 0:
            del self._odometry_stamps[:drop], self._odometry_poses[:drop]

    def _predict(self, motion: Pose) -> None:
        dx, dy, dtheta = motion
        theta = self.pose[2]
        c, s = math.cos(theta), math.sin(theta)
        jacobian = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0.0, 0.0, 1.0]])
        distance = math.hypot(dx, dy)
        n = self.noise
        along = max(n.per_metre * distance, n.floor)
        across = max(0.2 * n.per_metre * distance, n.floor)
        turn = max(n.heading_per_metre * distance + n.heading_per_radian * abs(dtheta), n.floor)
        rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # the motion's noise is in the robot's frame
        process = rotation @ np.diag([along ** 2, across ** 2, turn ** 2]) @ rotation.T
        self.covariance = jacobian @ self.covariance @ jacobian.T + process
        self.pose = compose(self.pose, motion)
        self.predictions += 1

    # ---- the measurement -------------------------------------------------------------------

    def pose_at(self, stamp: float) -> Pose:
        """The estimate carried back (or forward) to ``stamp`` by the wheels' motion in between."""
        return compose(self.pose, between(self._odometry_at(self.stamp if self.stamp is not None else stamp),
                                          self._odometry_at(stamp)))

    def measure(self, stamp: float, pose: Pose) -> bool:
        """A visual odometry pose of the robot, captured at ``stamp``: whether it was taken.

        Carried forward to the estimate's time by the wheels' motion since ``stamp``; refused
        when it lies beyond ``GATE``."""
        if not self._update(stamp, pose, self.measurement_covariance):
            self.refused_in_a_row += 1
            self.refused += 1
            return False
        self.refused_in_a_row = 0
        self.updates += 1
        return True

    def locate(self, stamp: float, pose: Pose, covariance: np.ndarray) -> bool:
        """A pose found on the known map (:mod:`tinman.scan_match`) from a scan taken at ``stamp``,
        with its ``covariance`` (floored at ``MAP_SIGMA_FLOOR``): whether it was taken.

        An absolute measurement, as the camera's, carried forward and gated the same way; it is
        counted apart (``located``, ``map_refused``) and never counts towards ``refused_in_a_row``,
        which is the camera's odometry's business."""
        floor = np.diag(np.square(MAP_SIGMA_FLOOR))
        measurement_covariance = np.asarray(covariance, dtype=np.float64) + floor
        if self._update(stamp, pose, measurement_covariance):
            self.located += 1
            self.map_refused_in_a_row = 0
            return True
        self.map_refused_in_a_row += 1
        # The map has disagreed, match after match, with an estimate that the camera's poses kept
        # pulling away (each within the gate, all of them astray): the estimate went wrong, not the
        # room. Relocalise on the map: its pose, with its uncertainty, from here on.
        carried = self._carried(stamp, pose)
        if (self.map_refused_in_a_row < MAP_RELOCATE or carried is None
                or not np.isfinite(measurement_covariance).all()):
            self.map_refused += 1
            return False
        self.pose = carried
        self.covariance = measurement_covariance
        self.map_refused_in_a_row = 0
        self.relocated += 1
        return True

    def _carried(self, stamp: float, pose: Pose) -> Pose | None:
        """``pose``, measured at ``stamp``, carried forward to the estimate's time by the wheels'
        motion since; None when it is not a number."""
        if not (math.isfinite(stamp) and all(math.isfinite(v) for v in pose)):
            return None
        now = self._odometry_at(self.stamp) if self.stamp is not None else None
        return pose if now is None else compose(pose, between(self._odometry_at(stamp), now))

    def _update(self, stamp: float, pose: Pose, measurement_covariance: np.ndarray) -> bool:
        """The Kalman update by a whole-pose measurement (``H = I``) captured at ``stamp``;
        False, and the estimate untouched, when it lies beyond ``GATE`` or is not a number."""
        measured = self._carried(stamp, pose)
        if measured is None:
            return False
        innovation = np.array([measured[0] - self.pose[0], measured[1] - self.pose[1],
                               math.remainder(measured[2] - self.pose[2], math.tau)])
        spread = self.covariance + measurement_covariance
        distance = float(innovation @ np.linalg.solve(spread, innovation))
        if not math.isfinite(distance) or distance > GATE:  # NaN compares False with anything: refuse it
            return False
        gain = self.covariance @ np.linalg.inv(spread)
        correction = gain @ innovation
        self.pose = (self.pose[0] + float(correction[0]), self.pose[1] + float(correction[1]),
                     math.remainder(self.pose[2] + float(correction[2]), math.tau))
        identity = np.eye(3)
        # Joseph form: stays symmetric and positive definite whatever the rounding.
        self.covariance = ((identity - gain) @ self.covariance @ (identity - gain).T
                           + gain @ measurement_covariance @ gain.T)
        return True

    def _odometry_at(self, stamp: float) -> Pose:
        """The wheel odometry's pose at ``stamp``, interpolated between the readings around it
        (the first or last reading outside them); the start's origin before any reading."""
        stamps, poses = self._odometry_stamps, self._odometry_poses
        if not stamps:
            return (0.0, 0.0, 0.0)
        i = bisect.bisect_left(stamps, stamp)
        if i == 0:
            return poses[0]
        if i == len(stamps):
            return poses[-1]
        t0, t1 = stamps[i - 1], stamps[i]
        fraction = (stamp - t0) / (t1 - t0)
        a, b = poses[i - 1], poses[i]
        step = between(a, b)
        return compose(a, (step[0] * fraction, step[1] * fraction, step[2] * fraction))
