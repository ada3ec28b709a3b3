"""Poses and cameras: the conventions every TinMan module shares.

World frame: x and y on the floor, z up (metres). The robot's pose on the floor is
``(x, y, theta)``, theta the heading from +x, counter-clockwise. The camera sits
on the robot at ``CAMERA_HEIGHT`` looking along the heading, in the optical frame
the TUM RGB-D benchmark uses: x right, y down, z forward. A camera pose is the
4x4 matrix ``T_wc`` taking camera coordinates to world coordinates; TUM's
groundtruth.txt lines are ``t tx ty tz qx qy qz qw`` of that same transform.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Intrinsics", "FR1", "CAMERA_HEIGHT", "DEPTH_SCALE", "camera_pose", "robot_pose", "depth_metres",
           "quaternion_from_matrix", "matrix_from_quaternion", "pose_matrix"]

CAMERA_HEIGHT = 0.5   # metres above the floor
DEPTH_SCALE = 5000.0  # TUM depth PNGs: 16-bit, 5000 units per metre (0 = no reading)


@dataclass(frozen=True)
class Intrinsics:
    """A pinhole camera: focal lengths and principal point in pixels, image size."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


# The Kinect of the TUM "freiburg1" sequences (vision.in.tum.de/data/datasets/rgbd-dataset/file_formats).
FR1 = Intrinsics(fx=517.3, fy=516.5, cx=318.6, cy=255.3, width=640, height=480)

# Camera axes (x right, y down, z forward) in robot axes (x forward, y left, z up).
_ROBOT_FROM_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def depth_metres(raw: np.ndarray) -> np.ndarray:
    """Stored 16-bit depth (``DEPTH_SCALE`` per metre, 0 = none) as float32 metres."""
    return raw.astype(np.float32) * np.float32(1.0 / DEPTH_SCALE)


def camera_pose(x: float, y: float, theta: float, height: float = CAMERA_HEIGHT) -> np.ndarray:
    """``T_wc`` of the camera on a robot at ``(x, y, theta)``."""
    c, s = math.cos(theta), math.sin(theta)
    yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    pose = np.eye(4)
    pose[:3, :3] = yaw @ _ROBOT_FROM_OPTICAL
    pose[:3, 3] = (x, y, height)
    return pose


def robot_pose(t_wc: np.ndarray) -> tuple[float, float, float]:
    """The floor pose ``(x, y, theta)`` under a camera pose (its optical axis gives the heading)."""
    forward = t_wc[:3, 2]
    return float(t_wc[0, 3]), float(t_wc[1, 3]), math.atan2(float(forward[1]), float(forward[0]))


def pose_matrix(position: np.ndarray | Sequence[float], quaternion: np.ndarray | Sequence[float]) -> np.ndarray:
    """A 4x4 pose from a position and a unit quaternion ``(qx, qy, qz, qw)``.

    Raises:
        ValueError: the quaternion has length 0 or a component that is not finite.
    """
    pose = np.eye(4)
    pose[:3, :3] = matrix_from_quaternion(quaternion)
    pose[:3, 3] = position
    return pose


def matrix_from_quaternion(q: np.ndarray | Sequence[float]) -> np.ndarray:
    """The rotation matrix of ``(qx, qy, qz, qw)`` (normalised first).

    Raises:
        ValueError: the quaternion has length 0 or a component that is not finite.
    """
    components = np.asarray(q, dtype=float)
    largest = float(np.abs(components).max())
    if not (0.0 < largest < math.inf):  # also false for nan
        raise ValueError(f"expected a quaternion of finite, non-zero length, got {tuple(components.tolist())}")
    # Scaled to a largest component of 1 first: squares of a tiny quaternion underflow to 0,
    # and the length of a subnormal one is too coarse to divide by.
    scaled = components / largest
    x, y, z, w = scaled / math.hypot(*scaled.tolist())
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def quaternion_from_matrix(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """``(qx, qy, qz, qw)`` with ``qw >= 0`` of a rotation matrix (Shepperd's method)."""
    m = np.asarray(rotation, dtype=float)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s
    # Divided by its length, negated when qw < 0 (q and -q are the same rotation).
    length = -math.hypot(*q) if q[3] < 0 else math.hypot(*q)
    qx, qy, qz, qw = (float(v / length) for v in q)
    return qx, qy, qz, qw
