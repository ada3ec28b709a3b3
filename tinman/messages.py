"""TinMan's messages: dataclasses with the field layouts of the ROS 2 messages they stand for.

Field names and nesting follow the ROS 2 interface definitions (``std_msgs/Header``,
``sensor_msgs/Joy``, ``sensor_msgs/Image``, ``geometry_msgs/Twist``, ``Pose``,
``PoseStamped``, ``nav_msgs/Path``), so a bridge to DDS or rclpy is a field-by-field
copy. Image data is a numpy array rather than a byte list: between groups it then
travels through shared memory without a copy. ``RGBDFrame`` pairs a colour and a depth
``Image`` taken together, as an RGB-D camera driver publishes them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Time", "Header", "Vector3", "Twist", "Point", "Quaternion", "Pose", "PoseStamped", "Path",
           "Joy", "Image", "RGBDFrame"]


@dataclass(frozen=True, slots=True)
class Time:
    """``builtin_interfaces/Time``: seconds and nanoseconds since the epoch."""

    sec: int = 0
    nanosec: int = 0

    @classmethod
    def from_seconds(cls, seconds: float) -> Time:
        whole = math.floor(seconds)
        return cls(int(whole), min(999_999_999, round((seconds - whole) * 1e9)))

    @classmethod
    def now(cls) -> Time:
        """The wall clock, shared by every process on the machine."""
        return cls.from_seconds(time.time())

    def seconds(self) -> float:
        return self.sec + self.nanosec * 1e-9


@dataclass(frozen=True, slots=True)
class Header:
    """``std_msgs/Header``: when the data was taken, and in which coordinate frame."""

    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass(frozen=True, slots=True)
class Vector3:
    """``geometry_msgs/Vector3``."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass(frozen=True, slots=True)
class Twist:
    """``geometry_msgs/Twist``: for a ground robot, ``linear.x`` (m/s) and ``angular.z`` (rad/s)."""

    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)

    @classmethod
    def planar(cls, forward: float, turn: float) -> Twist:
        return cls(Vector3(float(forward), 0.0, 0.0), Vector3(0.0, 0.0, float(turn)))


@dataclass(frozen=True, slots=True)
class Point:
    """``geometry_msgs/Point``."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass(frozen=True, slots=True)
class Quaternion:
    """``geometry_msgs/Quaternion`` (identity by default)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    w: float = 1.0


@dataclass(frozen=True, slots=True)
class Pose:
    """``geometry_msgs/Pose``: a position and an orientation."""

    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)

    @classmethod
    def from_matrix(cls, pose: np.ndarray) -> Pose:
        from .geometry import quaternion_from_matrix

        qx, qy, qz, qw = quaternion_from_matrix(pose[:3, :3])
        return cls(Point(*map(float, pose[:3, 3])), Quaternion(qx, qy, qz, qw))

    @classmethod
    def planar(cls, x: float, y: float, theta: float) -> Pose:
        """A pose on the floor: heading ``theta`` about +z."""
        return cls(Point(float(x), float(y), 0.0),
                   Quaternion(0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2)))

    def matrix(self) -> np.ndarray:
        from .geometry import pose_matrix

        o = self.orientation
        return pose_matrix((self.position.x, self.position.y, self.position.z), (o.x, o.y, o.z, o.w))

    def yaw(self) -> float:
        """The heading about +z of a floor pose."""
        o = self.orientation
        return math.atan2(2 * (o.w * o.z + o.x * o.y), 1 - 2 * (o.y * o.y + o.z * o.z))


@dataclass(frozen=True, slots=True)
class PoseStamped:
    """``geometry_msgs/PoseStamped``: a pose and when it held."""

    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@dataclass(frozen=True, slots=True)
class Path:
    """``nav_msgs/Path``: poses to drive through, in order."""

    header: Header = field(default_factory=Header)
    poses: tuple[PoseStamped, ...] = ()

    @classmethod
    def through(cls, points: list[tuple[float, float]], header: Header) -> Path:
        """A path through floor points ``(x, y)``, every pose stamped with ``header``."""
        return cls(header, tuple(PoseStamped(header, Pose.planar(x, y, 0.0)) for x, y in points))

    def points(self) -> list[tuple[float, float]]:
        """The path on the floor: ``(x, y)`` of every pose."""
        return [(p.pose.position.x, p.pose.position.y) for p in self.poses]


@dataclass(frozen=True, slots=True)
class Joy:
    """``sensor_msgs/Joy``: stick positions (-1..1) and button states (0/1)."""

    header: Header = field(default_factory=Header)
    axes: tuple[float, ...] = ()
    buttons: tuple[int, ...] = ()


@dataclass(frozen=True, slots=True)
class Image:
    """``sensor_msgs/Image``; ``data`` is the pixels as a numpy array (height x width [x channels]).

    ``encoding`` is ``"rgb8"`` for colour and ``"16UC1"`` for depth (TUM/Kinect
    convention: 5000 units per metre, 0 = no reading).
    """

    header: Header = field(default_factory=Header)
    height: int = 0
    width: int = 0
    encoding: str = ""
    is_bigendian: int = 0
    step: int = 0
    data: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.uint8))

    @classmethod
    def of(cls, array: np.ndarray, encoding: str, header: Header) -> Image:
        height, width = array.shape[:2]
        return cls(header, height, width, encoding, 0, int(array.strides[0]), array)


@dataclass(frozen=True, slots=True)
class RGBDFrame:
    """A colour and a depth image taken together; ``header.stamp`` is when it was published.

    The images' own headers keep the stamps they were captured with (for a replayed
    sequence, the dataset's timestamps), as a rosbag replay keeps them.
    """

    header: Header = field(default_factory=Header)
    rgb: Image = field(default_factory=Image)
    depth: Image = field(default_factory=Image)
    index: int = 0
