"""Pose conventions shared by the renderer, the VO and the planner."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from tinman.geometry import CAMERA_HEIGHT, camera_pose, matrix_from_quaternion, quaternion_from_matrix, robot_pose

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


@given(st.tuples(*[st.floats(-1, 1)] * 4).filter(any))
# Squares that underflow to 0: normalising by the root of their sum once divided by zero.
@example((0.0, 0.0, 1e-170, 1e-170))
@example((5e-324, 0.0, 0.0, 0.0))
@example((0.0, 0.0, 5e-324, 5e-324))  # subnormal: its length, 7e-324, rounds to 5e-324
def test_quaternions_and_matrices_round_trip(q: tuple[float, float, float, float]) -> None:
    rotation = matrix_from_quaternion(q)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-9)
    assert math.isclose(np.linalg.det(rotation), 1.0, abs_tol=1e-9)
    back = quaternion_from_matrix(rotation)
    assert back[3] >= 0
    np.testing.assert_allclose(matrix_from_quaternion(back), rotation, atol=1e-9)


@pytest.mark.parametrize("q", [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, math.nan, 1.0), (math.inf, 0.0, 0.0, 1.0)])
def test_a_quaternion_of_no_length_or_not_finite_is_refused(q: tuple[float, float, float, float]) -> None:
    got = re.escape(repr(q))
    with pytest.raises(ValueError, match=rf"^expected a quaternion of finite, non-zero length, got {got}$"):
        matrix_from_quaternion(q)
