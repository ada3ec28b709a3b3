"""Pose conventions shared by the renderer, the VO and the planner."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from tinman.geometry import (CAMERA_HEIGHT, camera_pose, matrix_from_quaternion, quaternion_from_matrix,
                             robot_pose)

angles = st.floats(-math.pi, math.pi, allow_nan=False)


def test_the_camera_looks_along_the_heading_with_image_y_down() -> None:
    pose = camera_pose(1.0, 2.0, math.pi / 2)
    np.testing.assert_allclose(pose[:3, 2], [0.0, 1.0, 0.0], atol=1e-12)   # optical axis: +y, the heading
    np.testing.assert_allclose(pose[:3, 1], [0.0, 0.0, -1.0], atol=1e-12)  # image down: world down
    np.testing.assert_allclose(pose[:3, 0], [1.0, 0.0, 0.0], atol=1e-12)   # image right: the robot's right
    np.testing.assert_allclose(pose[:3, 3], [1.0, 2.0, CAMERA_HEIGHT])


@given(st.floats(-10, 10), st.floats(-10, 10), angles)
def test_robot_pose_inverts_camera_pose(x: float, y: float, theta: float) -> None:
    rx, ry, rtheta = robot_pose(camera_pose(x, y, theta))
    assert (rx, ry) == (x, y)
    assert math.isclose(math.remainder(rtheta - theta, math.tau), 0.0, abs_tol=1e-9)


@given(st.tuples(*[st.floats(-1, 1)] * 4).filter(lambda q: sum(v * v for v in q) > 1e-3))
def test_quaternions_and_matrices_round_trip(q: tuple[float, float, float, float]) -> None:
    rotation = matrix_from_quaternion(q)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-9)
    assert math.isclose(np.linalg.det(rotation), 1.0, abs_tol=1e-9)
    back = quaternion_from_matrix(rotation)
    assert back[3] >= 0
    np.testing.assert_allclose(matrix_from_quaternion(back), rotation, atol=1e-9)
