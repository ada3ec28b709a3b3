"""TinMan's messages: rosbags' ROS 2 Jazzy classes, the functions that build and read them,
and round trips through the CDR a ROS 2 node publishes."""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.stores import ros2_jazzy

from tinman.geometry import camera_pose
from tinman.messages import (
    Header,
    Image,
    Joy,
    Path,
    PoseStamped,
    Time,
    Twist,
    image_array,
    image_layout,
    image_of,
    joy,
    path_points,
    path_through,
    pose_from_matrix,
    pose_matrix,
    pose_planar,
    seconds,
    stamp_from_seconds,
    stamp_now,
    twist_planar,
    yaw,
)

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
HEADER = Header(stamp=Time(sec=1_305_031_102, nanosec=175_304_000), frame_id="camera_optical")


def same(a: Any, b: Any) -> bool:
    """Equal field by field, numpy arrays by dtype and value (``==`` cannot compare them)."""
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return type(a) is type(b) and all(same(getattr(a, f.name), getattr(b, f.name))
                                          for f in dataclasses.fields(a))
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and np.array_equal(a, b)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and bool(a == b)


def cdr_round_trip(message: Any) -> Any:
    data = TYPESTORE.serialize_cdr(message, message.__msgtype__)
    return TYPESTORE.deserialize_cdr(data, message.__msgtype__)


def test_the_classes_are_rosbags_jazzy_messages() -> None:
    assert Joy is ros2_jazzy.sensor_msgs__msg__Joy and Joy.__msgtype__ == "sensor_msgs/msg/Joy"
    assert Twist is ros2_jazzy.geometry_msgs__msg__Twist
    assert PoseStamped is ros2_jazzy.geometry_msgs__msg__PoseStamped
    assert Path is ros2_jazzy.nav_msgs__msg__Path
    assert Image is ros2_jazzy.sensor_msgs__msg__Image
    assert Header is ros2_jazzy.std_msgs__msg__Header and Time is ros2_jazzy.builtin_interfaces__msg__Time


# ---- time ------------------------------------------------------------------------------------

@given(st.floats(-2.0**31, 2.0**31 - 1, allow_nan=False))
def test_a_stamp_keeps_seconds_to_the_microsecond_in_ros_ranges(s: float) -> None:
    stamp = stamp_from_seconds(s)
    assert type(stamp.sec) is int and -2**31 <= stamp.sec < 2**31        # int32
    assert type(stamp.nanosec) is int and 0 <= stamp.nanosec <= 999_999_999  # uint32, below a second
    assert abs(seconds(stamp) - s) < 1e-6


def test_a_stamp_rounds_into_the_next_second_and_refuses_what_int32_cannot_hold() -> None:
    assert stamp_from_seconds(1.9999999999) == Time(sec=2, nanosec=0)
    assert stamp_from_seconds(-0.5) == Time(sec=-1, nanosec=500_000_000)
    for bad in (2.0**31, -2.0**31 - 1, math.nan, math.inf):
        with pytest.raises(ValueError, match="stamp"):
            stamp_from_seconds(bad)


def test_stamp_now_is_the_wall_clock() -> None:
    before = time.time()
    stamp = stamp_now()
    assert before - 1e-6 <= seconds(stamp) <= time.time() + 1e-6


# ---- motion and poses ------------------------------------------------------------------------

def test_a_planar_twist_drives_forward_and_turns_about_z() -> None:
    twist = twist_planar(0.3, -0.2)
    assert (twist.linear.x, twist.linear.y, twist.linear.z) == (0.3, 0.0, 0.0)
    assert (twist.angular.x, twist.angular.y, twist.angular.z) == (0.0, 0.0, -0.2)
    assert type(twist_planar(1, 2).angular.z) is float  # float64 fields hold Python floats, not ints


@given(st.floats(-5, 5), st.floats(-5, 5), st.floats(-math.pi, math.pi))
def test_a_pose_from_a_camera_matrix_gives_that_matrix_back(x: float, y: float, theta: float) -> None:
    matrix = camera_pose(x, y, theta)
    pose = pose_from_matrix(matrix)
    assert type(pose.position.x) is float and type(pose.orientation.w) is float
    np.testing.assert_allclose(pose_matrix(pose), matrix, atol=1e-9)


@given(st.floats(-math.pi + 1e-6, math.pi - 1e-6))
def test_a_planar_pose_has_its_heading_as_yaw(theta: float) -> None:
    pose = pose_planar(1.0, 2.0, theta)
    assert (pose.position.x, pose.position.y, pose.position.z) == (1.0, 2.0, 0.0)
    assert math.isclose(yaw(pose), theta, abs_tol=1e-9)


# ---- paths -----------------------------------------------------------------------------------

def test_a_path_goes_through_its_points_with_every_pose_stamped() -> None:
    header = Header(stamp=stamp_from_seconds(12.5), frame_id="map")
    points = [(0.0, 0.0), (1.0, 0.5), (2.0, -1.0)]
    path = path_through(points, header)
    assert path.header == header and all(p.header == header for p in path.poses)
    assert all(type(p) is PoseStamped for p in path.poses) and isinstance(path.poses, list)
    assert path_points(path) == points
    assert path_points(path_through([], header)) == []


# ---- images ----------------------------------------------------------------------------------

def test_a_colour_image_is_its_bytes_without_a_copy() -> None:
    rgb = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3)
    image = image_of(rgb, "rgb8", HEADER)
    assert (image.height, image.width, image.step, image.encoding, image.is_bigendian) == (4, 5, 15, "rgb8", 0)
    assert image.data.dtype == np.uint8 and image.data.shape == (60,)
    assert np.shares_memory(image.data, rgb)
    pixels = image_array(image)
    assert pixels.dtype == np.uint8 and pixels.shape == (4, 5, 3) and np.shares_memory(pixels, rgb)
    np.testing.assert_array_equal(pixels, rgb)


def test_a_depth_image_is_16uc1_and_reads_back_as_uint16() -> None:
    depth = (np.arange(20, dtype=np.uint16) * 5000).reshape(4, 5)  # 0..19 m at 5000 units per metre
    image = image_of(depth, "16UC1", HEADER)
    assert (image.step, image.is_bigendian, image.data.size) == (10, int(sys.byteorder == "big"), 40)
    pixels = image_array(image)
    assert pixels.dtype == np.uint16 and pixels.shape == (4, 5)
    np.testing.assert_array_equal(pixels, depth)


def test_a_big_endian_image_says_so_and_reads_back_right() -> None:
    depth = (np.arange(20, dtype=np.uint16) * 300).astype(">u2").reshape(4, 5)
    image = image_of(depth, "16UC1", HEADER)
    assert image.is_bigendian == 1
    assert image.data[:4].tolist() == [0, 0, 1, 44]  # 0 and 300, most significant byte first
    np.testing.assert_array_equal(image_array(image), depth)


def test_a_strided_array_is_copied_once_and_padded_rows_are_read() -> None:
    big = np.arange(6 * 8 * 3, dtype=np.uint8).reshape(6, 8, 3)
    part = big[1:5, 2:7]  # not contiguous
    image = image_of(part, "rgb8", HEADER)
    assert image.step == 15 and not np.shares_memory(image.data, big)
    np.testing.assert_array_equal(image_array(image), part)
    # A driver may pad its rows: step is then more than width x channels.
    padded = Image(header=HEADER, height=6, width=5, encoding="rgb8", is_bigendian=0, step=24,
                   data=big.reshape(-1)[: 5 * 24 + 15].copy())
    np.testing.assert_array_equal(image_array(padded), big[:, :5])


def test_images_that_do_not_fit_their_encoding_are_refused() -> None:
    with pytest.raises(ValueError, match="rgb8"):
        image_of(np.zeros((4, 5), np.uint8), "rgb8", HEADER)
    with pytest.raises(ValueError, match="16UC1"):
        image_of(np.zeros((4, 5), np.float32), "16UC1", HEADER)
    with pytest.raises(ValueError, match="encoding"):
        image_of(np.zeros((4, 5), np.uint8), "bayer_rggb8", HEADER)
    short = Image(header=HEADER, height=4, width=5, encoding="16UC1", is_bigendian=0, step=10,
                  data=np.zeros(39, np.uint8))
    with pytest.raises(ValueError, match="bytes of data"):
        image_array(short)
    assert image_layout("32FC1") == (np.dtype(np.float32), 1)
    assert image_layout("bgra8") == (np.dtype(np.uint8), 4)


# ---- the gamepad -----------------------------------------------------------------------------

def test_joy_holds_float32_axes_and_int32_buttons() -> None:
    message = joy(HEADER, (0.0, 0.5, -1.0), [0, 1])
    assert message.axes.dtype == np.float32 and message.axes.tolist() == [0.0, 0.5, -1.0]
    assert message.buttons.dtype == np.int32 and message.buttons.tolist() == [0, 1]
    with pytest.raises(ValueError, match="int32"):
        joy(HEADER, (), (2**31,))


# ---- the wire --------------------------------------------------------------------------------

def messages() -> list[Any]:
    rgb = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3)
    depth = np.arange(20, dtype=np.uint16).reshape(4, 5) * np.uint16(250)
    header = Header(stamp=stamp_from_seconds(1_305_031_102.175304), frame_id="map")
    return [
        joy(header, (0.0, 0.5, 0.0, -0.25, 0.0, 0.0), (0, 0, 0, 0, 1, 0, 0, 0)),
        twist_planar(0.3, -0.2),
        PoseStamped(header=header, pose=pose_from_matrix(camera_pose(1.0, 2.0, 0.5))),
        path_through([(0.0, 0.0), (1.0, 0.5), (2.0, -1.0)], header),
        image_of(rgb, "rgb8", HEADER),
        image_of(depth, "16UC1", HEADER),
    ]


@pytest.mark.parametrize("message", messages(), ids=lambda m: type(m).__msgtype__)
def test_messages_survive_a_round_trip_through_ros2_cdr(message: Any) -> None:
    decoded = cdr_round_trip(message)
    assert same(decoded, message)
    if isinstance(message, Image):
        np.testing.assert_array_equal(image_array(decoded), image_array(message))


@pytest.mark.parametrize("message", messages(), ids=lambda m: type(m).__msgtype__)
def test_messages_fit_their_ros_definitions_as_anodize_checks_them(message: Any) -> None:
    ros = pytest.importorskip("anodize._ros")
    kind = ros.ros_type(type(message).__msgtype__)
    assert kind.cls is type(message)
    assert kind.check(message) is None
