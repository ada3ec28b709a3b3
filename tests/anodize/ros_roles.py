"""Role functions sending ROS 2 messages between group processes (module level: the groups import them)."""

from __future__ import annotations

from typing import Any

import numpy as np

from anodize import Endpoint
from anodize._ros import ros_type

Time = ros_type("builtin_interfaces/msg/Time").cls
Header = ros_type("std_msgs/msg/Header").cls
Vector3 = ros_type("geometry_msgs/msg/Vector3").cls
Point = ros_type("geometry_msgs/msg/Point").cls
Twist = ros_type("geometry_msgs/msg/Twist").cls
Image = ros_type("sensor_msgs/msg/Image").cls

HEIGHT, WIDTH = 480, 640


def twist() -> object:
    return Twist(linear=Vector3(x=0.5, y=-0.25, z=0.0), angular=Vector3(x=0.0, y=0.0, z=1.5))


def image() -> object:
    pixels = (np.arange(HEIGHT * WIDTH * 3, dtype=np.uint32) % 251).astype(np.uint8)
    return Image(header=Header(stamp=Time(sec=1_700_000_000, nanosec=5), frame_id="camera"),
                 height=HEIGHT, width=WIDTH, encoding="rgb8", is_bigendian=0, step=WIDTH * 3, data=pixels)


def same_image(a: Any, b: Any) -> bool:
    return (type(a) is type(b) is Image and a.header == b.header
            and (a.height, a.width, a.encoding, a.step) == (b.height, b.width, b.encoding, b.step)
            and np.array_equal(a.data, b.data) and a.data.dtype == np.uint8)


def pilot(ep: Endpoint) -> None:
    """Sends a Twist and a 640x480 RGB image, and checks what comes back."""
    ep.send("Base", "cmd", twist())
    ep.send("Base", "frame", image())
    back = ep.recv("Base").payload
    assert type(back) is Twist and back == twist(), back
    assert same_image(ep.recv("Base").payload, image())


def base(ep: Endpoint) -> None:
    """Receives a Twist and an image, checks them, and sends them back."""
    received = ep.recv("Pilot").payload
    assert type(received) is Twist and received == twist(), received
    frame = ep.recv("Pilot").payload
    assert same_image(frame, image())
    ep.send("Pilot", "cmd", received)
    ep.send("Pilot", "frame", frame)


def wrong_pilot(ep: Endpoint) -> None:
    """Sends a Twist whose linear velocity is a Point: the sender's monitor refuses it."""
    ep.send("Base", "cmd", Twist(linear=Point(x=0.5, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0)))


def waiting_base(ep: Endpoint) -> None:
    """Waits for the Twist that never comes (its pilot fails)."""
    ep.recv("Pilot")
