"""Roles for the ROS topic tests (module level: group processes import them by name).

Settings come from the environment: ``ROS_TEST_COUNT`` (how many rounds), ``ROS_TEST_OUT``
(a folder where a role writes what it received, as JSON, for the test to read).
"""

from __future__ import annotations

import json
import os

import numpy as np
from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as Twist
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Vector3 as Vector3
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Joy as Joy
from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header

from anodize import Endpoint

CAMERA = """
type Image = "ros:sensor_msgs/msg/Image"
type Twist = "ros:geometry_msgs/msg/Twist"
global Camera(C, V) = mu t. C -> V : {frame(int). C -> V : color(Image). C -> V : depth(Image).
                                     V -> C : cmd(Twist). t,
                                     stop}
"""
CAMERA_TOPICS = {"C->V:color": "/camera/color/image_raw", "C->V:depth": "/camera/depth/image_raw",
                 "V->C": "/cmd_vel"}

JOY = """
type Joy = "ros:sensor_msgs/msg/Joy"
type Twist = "ros:geometry_msgs/msg/Twist"
global Teleop(J, C, W) = mu t. J -> C : Joy. C -> W : Twist. t
"""
JOY_TOPICS = {"J->C": "/joy", "C->W": "/cmd_vel"}


def _count() -> int:
    return int(os.environ.get("ROS_TEST_COUNT", "20"))


def _write(name: str, value: object) -> None:
    out = os.environ.get("ROS_TEST_OUT")
    if out:
        with open(os.path.join(out, f"{name}.json"), "w", encoding="utf-8") as file:
            json.dump(value, file)


def header(i: int, frame: str) -> Header:
    return Header(stamp=Time(sec=i, nanosec=0), frame_id=frame)


def image(i: int, encoding: str, channels: int, dtype: type) -> Image:
    pixels = np.full((48, 64, channels), i % 250, dtype)
    return Image(header=header(i, "camera"), height=48, width=64, encoding=encoding, is_bigendian=0,
                 step=64 * channels * np.dtype(dtype).itemsize, data=pixels.reshape(-1).view(np.uint8))


def twist(i: int) -> Twist:
    return Twist(linear=Vector3(x=0.1 * i, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=-0.5 * i))


def camera(ep: Endpoint) -> None:
    """Colour and depth of each frame on their ROS topics; the commands that come back, recorded."""
    commands = []
    for i in range(_count()):
        ep.send("V", "frame", i)
        ep.send("V", "color", image(i, "rgb8", 3, np.uint8))
        ep.send("V", "depth", image(i, "16UC1", 1, np.uint16))
        command = ep.recv("V").payload
        commands.append([command.linear.x, command.angular.z])
    ep.send("V", "stop")
    _write("camera", commands)


def viewer(ep: Endpoint) -> None:
    """Check that colour and depth come in order and whole; answer each frame with a command."""
    seen = []
    while (message := ep.recv("C")).label == "frame":
        i = message.payload
        color, depth = ep.recv("C"), ep.recv("C")
        assert (color.label, depth.label) == ("color", "depth"), (color.label, depth.label)
        assert color.payload.encoding == "rgb8" and depth.payload.encoding == "16UC1"
        assert color.payload.header.stamp.sec == i and int(color.payload.data[0]) == i % 250
        assert depth.payload.data.view(np.uint16)[0] == i % 250
        seen.append(i)
        ep.send("C", "cmd", twist(i))
    _write("viewer", seen)


def controller(ep: Endpoint) -> None:
    """Teleop's C: a Twist for every Joy (from an external joystick node), recorded."""
    received = []
    while True:
        joy = ep.recv("J").payload
        received.append({"sec": int(joy.header.stamp.sec), "axes": [float(a) for a in joy.axes],
                         "buttons": [int(b) for b in joy.buttons]})
        _write("controller", received)
        ep.send("W", "Twist", twist(len(received)))


def wheels(ep: Endpoint) -> None:
    """Teleop's W, when anodize runs it: records the Twists."""
    received = []
    while True:
        command = ep.recv("C").payload
        received.append([command.linear.x, command.angular.z])
        _write("wheels", received)


def joystick(ep: Endpoint) -> None:
    """Teleop's J, when anodize runs it."""
    for i in range(_count()):
        ep.send("C", "Joy", Joy(header=header(i, "joy"), axes=np.array([0.1 * i, -0.5, 1.0], np.float32),
                                buttons=np.array([i % 2, 1, 0], np.int32)))
        ep.sleep(0.01)
    ep.sleep(30)  # the test stops the run
