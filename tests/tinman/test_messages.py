"""TinMan's messages: ROS 2 layouts, pose conversions, and crossing a process boundary."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from anodize.session.payloads import with_field_classes
from anodize.transport.codec import HEADER, Codec
from tinman.geometry import camera_pose
from tinman.messages import Header, Image, Joy, Path, Pose, PoseStamped, RGBDFrame, Time, Twist


def test_field_layouts_follow_the_ros2_messages() -> None:
    def names(kind: type) -> list[str]:
        return [f.name for f in dataclasses.fields(kind)]

    assert names(Joy) == ["header", "axes", "buttons"]
    assert names(Twist) == ["linear", "angular"]
    assert names(Pose) == ["position", "orientation"]
    assert names(PoseStamped) == ["header", "pose"]
    assert names(Path) == ["header", "poses"]
    assert names(Image) == ["header", "height", "width", "encoding", "is_bigendian", "step", "data"]
    assert names(Header) == ["stamp", "frame_id"]
    assert names(Time) == ["sec", "nanosec"]


@given(st.floats(0, 4e9, allow_nan=False))
def test_time_keeps_seconds_to_the_microsecond(seconds: float) -> None:
    stamp = Time.from_seconds(seconds)
    assert 0 <= stamp.nanosec <= 999_999_999
    assert abs(stamp.seconds() - seconds) < 1e-6


@given(st.floats(-5, 5), st.floats(-5, 5), st.floats(-math.pi, math.pi))
def test_a_pose_from_a_camera_matrix_gives_that_matrix_back(x: float, y: float, theta: float) -> None:
    matrix = camera_pose(x, y, theta)
    np.testing.assert_allclose(Pose.from_matrix(matrix).matrix(), matrix, atol=1e-9)


@given(st.floats(-math.pi + 1e-6, math.pi - 1e-6))
def test_a_planar_pose_has_its_heading_as_yaw(theta: float) -> None:
    assert math.isclose(Pose.planar(1.0, 2.0, theta).yaw(), theta, abs_tol=1e-9)


def test_messages_cross_a_process_boundary_field_by_field() -> None:
    codec = Codec(with_field_classes([RGBDFrame, Path, Joy, Twist]))
    rgb = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3)
    depth = np.arange(20, dtype=np.uint16).reshape(4, 5)
    stamp = Header(Time(12, 34), "camera")
    messages = [
        RGBDFrame(stamp, Image.of(rgb, "rgb8", stamp), Image.of(depth, "16UC1", stamp), 7),
        Path(stamp, (PoseStamped(stamp, Pose.planar(1.0, 2.0, 0.5)),)),
        Joy(stamp, (0.0, 0.5), (0, 1)),
        Twist.planar(0.3, -0.2),
    ]
    for message in messages:
        frame = codec.message_frame("m", message)
        (length,) = HEADER.unpack(frame[:4])
        _, (label, decoded) = codec.decode_body(frame[4:4 + length])
        assert label == "m"
        if isinstance(message, RGBDFrame):
            assert decoded.rgb.encoding == "rgb8" and decoded.rgb.step == 15 and decoded.index == 7
            np.testing.assert_array_equal(decoded.rgb.data, rgb)
            np.testing.assert_array_equal(decoded.depth.data, depth)
        else:
            assert decoded == message
