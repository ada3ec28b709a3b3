"""TinMan's messages: the ROS 2 message types themselves, as rosbags defines them for Jazzy.

The protocol's sorts are ``"ros:pkg/msg/Name"`` (``tinman/tinman.proto``), which anodize
resolves to these very classes: payloads are checked field by field against the ROS
definition (exact classes, integer ranges, numpy dtypes) and travel as the CDR a ROS 2
node publishes. The classes are rosbags' generated dataclasses, re-exported under
TinMan's names; they are plain mutable dataclasses with no defaults, and primitive
arrays are numpy arrays (``Joy.axes`` float32, ``Joy.buttons`` int32, ``Image.data``
uint8, one dimension).

The functions below build and read them with values that fit their ROS types
(``Time.sec`` int32, ``nanosec`` uint32, ``Image.height``/``width``/``step`` uint32,
``is_bigendian`` uint8, floats as Python floats):

- time: :func:`stamp_now`, :func:`stamp_from_seconds`, :func:`seconds`;
- motion: :func:`twist_planar`;
- poses: :func:`pose_planar`, :func:`pose_from_matrix`, :func:`pose_matrix`, :func:`yaw`;
- wheel odometry: :func:`odometry_message`, :func:`odometry_planar`;
- paths: :func:`path_through`, :func:`path_points`;
- images: :func:`image_of`, :func:`image_array` (``"rgb8"`` colour, ``"16UC1"`` depth:
  the TUM/Kinect convention of 5000 units per metre, 0 = no reading);
- the gamepad: :func:`joy`.
"""

from __future__ import annotations

import math
import re
import sys
import time
from collections.abc import Iterable, Sequence

import numpy as np
from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Point as Point
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Pose as Pose
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__PoseStamped as PoseStamped
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__PoseWithCovariance as PoseWithCovariance
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Quaternion as Quaternion
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as Twist
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__TwistWithCovariance as TwistWithCovariance
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Vector3 as Vector3
from rosbags.typesys.stores.ros2_jazzy import nav_msgs__msg__Odometry as Odometry
from rosbags.typesys.stores.ros2_jazzy import nav_msgs__msg__Path as Path
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Joy as Joy
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__LaserScan as LaserScan
from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header

__all__ = ["Time", "Header", "Vector3", "Twist", "Point", "Quaternion", "Pose", "PoseStamped", "Path",
           "Joy", "Image", "LaserScan", "Odometry", "PoseWithCovariance", "TwistWithCovariance",
           "odometry_message", "odometry_planar",
           "stamp_now", "stamp_from_seconds", "seconds", "twist_planar", "pose_planar", "pose_from_matrix",
           "pose_matrix", "yaw", "path_through", "path_points", "image_of", "image_array", "image_layout", "joy"]

_INT32 = (-2**31, 2**31 - 1)
_UINT32_MAX = 2**32 - 1


# ---- time ------------------------------------------------------------------------------------

def stamp_from_seconds(s: float) -> Time:
    """``builtin_interfaces/Time`` of ``s`` seconds since the epoch (nanoseconds rounded).

    Raises:
        ValueError: ``s`` is not finite, or its whole seconds do not fit ``sec``'s int32.
    """
    if not math.isfinite(s):
        raise ValueError(f"a stamp needs a finite time, got {s!r}")
    whole = math.floor(s)
    nanosec = round((s - whole) * 1e9)
    if nanosec >= 1_000_000_000:  # rounded up to the next second
        whole, nanosec = whole + 1, 0
    if not _INT32[0] <= whole <= _INT32[1]:
        raise ValueError(f"{s!r} s does not fit a ROS 2 stamp (int32 seconds)")
    return Time(sec=int(whole), nanosec=int(nanosec))


def stamp_now() -> Time:
    """The wall clock, shared by every process on the machine (ROS's system time)."""
    return stamp_from_seconds(time.time())


def seconds(stamp: Time) -> float:
    """A stamp as float seconds since the epoch."""
    return stamp.sec + stamp.nanosec * 1e-9


# ---- motion and poses ------------------------------------------------------------------------

def twist_planar(v: float, w: float) -> Twist:
    """A ground robot's command: ``linear.x = v`` (m/s), ``angular.z = w`` (rad/s)."""
    return Twist(linear=Vector3(x=float(v), y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=float(w)))


def pose_planar(x: float, y: float, theta: float) -> Pose:
    """A pose on the floor: at ``(x, y, 0)``, heading ``theta`` about +z."""
    return Pose(position=Point(x=float(x), y=float(y), z=0.0),
                orientation=Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2)))


def pose_from_matrix(m: np.ndarray) -> Pose:
    """The pose of a 4x4 rigid transform (its rotation as a unit quaternion with ``w >= 0``)."""
    from .geometry import quaternion_from_matrix

    qx, qy, qz, qw = quaternion_from_matrix(m[:3, :3])
    px, py, pz = (float(v) for v in m[:3, 3])
    return Pose(position=Point(x=px, y=py, z=pz), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def pose_matrix(pose: Pose) -> np.ndarray:
    """The 4x4 rigid transform of a pose."""
    from .geometry import pose_matrix as matrix_of

    p, o = pose.position, pose.orientation
    return matrix_of((p.x, p.y, p.z), (o.x, o.y, o.z, o.w))


def yaw(pose: Pose) -> float:
    """The heading about +z of a floor pose (radians, -pi..pi)."""
    o = pose.orientation
    return math.atan2(2 * (o.w * o.z + o.x * o.y), 1 - 2 * (o.y * o.y + o.z * o.z))


# ---- wheel odometry --------------------------------------------------------------------------

def odometry_message(header: Header, pose: tuple[float, float, float], velocity: tuple[float, float],
                     covariance: Sequence[float] = (0.0,) * 36) -> Odometry:
    """A diff-drive's ``nav_msgs/Odometry``: its integrated floor ``pose`` ``(x, y, theta)`` and the
    ``velocity`` ``(v, w)`` measured, in the ``odom`` frame (``header.frame_id``) of ``base_link``."""
    return Odometry(header=header, child_frame_id="base_link",
                    pose=PoseWithCovariance(pose=pose_planar(*pose), covariance=np.asarray(covariance, np.float64)),
                    twist=TwistWithCovariance(twist=twist_planar(*velocity), covariance=np.zeros(36)))


def odometry_planar(message: Odometry) -> tuple[float, float, float]:
    """The floor pose ``(x, y, theta)`` of a ``nav_msgs/Odometry``."""
    pose = message.pose.pose
    return pose.position.x, pose.position.y, yaw(pose)


# ---- paths -----------------------------------------------------------------------------------

def path_through(points: Iterable[tuple[float, float]], header: Header) -> Path:
    """A path through floor points ``(x, y)``, every pose stamped with ``header``."""
    return Path(header=header,
                poses=[PoseStamped(header=header, pose=pose_planar(x, y, 0.0)) for x, y in points])


def path_points(path: Path) -> list[tuple[float, float]]:
    """The path on the floor: ``(x, y)`` of every pose, in order."""
    return [(p.pose.position.x, p.pose.position.y) for p in path.poses]


# ---- images ----------------------------------------------------------------------------------

# Named encodings of sensor_msgs/image_encodings.hpp: (numpy kind, channels).
_NAMED: dict[str, tuple[str, int]] = {
    "rgb8": ("u1", 3), "bgr8": ("u1", 3), "rgba8": ("u1", 4), "bgra8": ("u1", 4), "mono8": ("u1", 1),
    "rgb16": ("u2", 3), "bgr16": ("u2", 3), "rgba16": ("u2", 4), "bgra16": ("u2", 4), "mono16": ("u2", 1),
}
# OpenCV-style encodings, "16UC1", "32FC1", ...: bits, signedness, channels.
_CV = re.compile(r"(8|16|32|64)([USF])C([1-4])")
_CV_KINDS = {("8", "U"): "u1", ("8", "S"): "i1", ("16", "U"): "u2", ("16", "S"): "i2",
             ("32", "S"): "i4", ("32", "F"): "f4", ("64", "F"): "f8"}


def image_layout(encoding: str) -> tuple[np.dtype[np.generic], int]:
    """The pixel type (native byte order) and channel count of an image encoding.

    Raises:
        ValueError: an encoding TinMan cannot lay out (a Bayer or YUV one, say).
    """
    named = _NAMED.get(encoding)
    if named is None:
        match = _CV.fullmatch(encoding)
        kind = _CV_KINDS.get((match[1], match[2])) if match else None
        if match is None or kind is None:
            raise ValueError(f"unsupported image encoding {encoding!r}")
        named = (kind, int(match[3]))
    return np.dtype(named[0]), named[1]


def image_of(array: np.ndarray, encoding: str, header: Header) -> Image:
    """A ``sensor_msgs/Image`` of ``array`` (height x width [x channels]) in ``encoding``.

    ``data`` is the array's bytes as a 1-D uint8 array, a view without a copy when the
    array is C-contiguous (one copy otherwise); ``step`` is a row's bytes; ``is_bigendian``
    follows the array's byte order.

    Raises:
        ValueError: the array's shape or dtype does not fit ``encoding``, or its size
            does not fit the message's uint32 fields.
    """
    dtype, channels = image_layout(encoding)
    shape_fits = (array.ndim == 3 and array.shape[2] == channels) or (array.ndim == 2 and channels == 1)
    if not shape_fits or array.dtype.newbyteorder("=") != dtype.newbyteorder("="):
        raise ValueError(f"a {encoding} image is {dtype} height x width" + (f" x {channels}" if channels > 1 else "")
                         + f", got {array.dtype} {array.shape}")
    height, width = array.shape[:2]
    step = width * channels * dtype.itemsize
    if max(height, width, step) > _UINT32_MAX:
        raise ValueError(f"an image of {height} x {width} ({step} bytes a row) does not fit sensor_msgs/Image")
    order = array.dtype.byteorder
    bigendian = order == ">" or (order == "=" and sys.byteorder == "big")
    data = np.ascontiguousarray(array).reshape(-1).view(np.uint8)
    return Image(header=header, height=int(height), width=int(width), encoding=encoding,
                 is_bigendian=int(bigendian), step=int(step), data=data)


def image_array(image: Image) -> np.ndarray:
    """The pixels of ``image``: a view (no copy) of its data, height x width [x channels].

    The dtype is the encoding's (uint8 for ``rgb8``, uint16 for ``16UC1``, ...) in the
    byte order ``is_bigendian`` says; rows are ``step`` bytes apart.

    Raises:
        ValueError: an unsupported encoding, or ``step``/``data`` too short for the size.
    """
    dtype, channels = image_layout(image.encoding)
    dtype = dtype.newbyteorder(">" if image.is_bigendian else "<")
    height, width, step = int(image.height), int(image.width), int(image.step)
    row = width * channels * dtype.itemsize
    data = np.asarray(image.data, dtype=np.uint8).reshape(-1)
    needed = step * (height - 1) + row if height else 0
    if step < row or data.size < needed:
        raise ValueError(f"a {image.encoding} image of {height} x {width} needs a step of at least {row} bytes "
                         f"and {needed} bytes of data, got a step of {step} and {data.size} bytes")
    shape = (height, width) if channels == 1 else (height, width, channels)
    strides = (step, dtype.itemsize) if channels == 1 else (step, channels * dtype.itemsize, dtype.itemsize)
    return np.ndarray(shape, dtype=dtype, buffer=data, strides=strides)


# ---- the gamepad -----------------------------------------------------------------------------

def joy(header: Header, axes: Sequence[float] | np.ndarray, buttons: Sequence[int] | np.ndarray) -> Joy:
    """A ``sensor_msgs/Joy``: axes as float32, buttons as int32.

    Raises:
        OverflowError, ValueError: a button does not fit an int32.
    """
    if any(not _INT32[0] <= int(b) <= _INT32[1] for b in buttons):
        raise ValueError(f"buttons must fit an int32, got {list(buttons)}")
    return Joy(header=header, axes=np.asarray(axes, dtype=np.float32), buttons=np.asarray(buttons, dtype=np.int32))
