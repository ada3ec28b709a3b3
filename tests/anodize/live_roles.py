"""Roles for the live view tests (module level: group processes import them by name).

``P`` sends a joystick state and a camera image 50 times a second; once a Foxglove
client's Joy has reached it (:func:`anodize._live.client_input`) it sends that Joy
instead, three times, then stops the run (telling ``L``, which tells ``R``). ``R`` writes
the axes of every Joy it got to ``$LIVE_TEST_OUT/robot.json``; ``R -> L`` is a channel
inside a group.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np
from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Joy as Joy
from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header

from anodize import Endpoint
from anodize._live import client_input

PROTOCOL = """
type Joy = "ros:sensor_msgs/msg/Joy"
type Image = "ros:sensor_msgs/msg/Image"
global Pad(P, R, L) =
  mu t. P -> L : { go. L -> R : go. P -> R : joy(Joy). P -> R : image(Image). R -> L : seen(int). t,
                   stop. L -> R : stop }
"""
SYSTEM = """
protocol = "pad.proto"
global = "Pad"
transport = "process"

[groups.pad]
priority = 60
roles = { P = "live_roles:pad" }

[groups.robot]
priority = 40
roles = { R = "live_roles:robot", L = "live_roles:log" }

[ros.topics]
"P->R:joy" = "/joy"
"P->R:image" = "/camera/image"
"""
CLIENT_TAKES = 3      # client Joys P sends before it stops
GIVE_UP_AFTER = 15.0  # seconds without a client Joy before P stops anyway


def _header() -> Header:
    now = time.time_ns()
    return Header(stamp=Time(sec=now // 10**9, nanosec=now % 10**9), frame_id="pad")


def pad(ep: Endpoint) -> None:
    client = client_input(ep, "R", "joy")  # None without a live view
    start = time.monotonic()
    taken = 0
    pixels = np.zeros((48, 64, 3), np.uint8)
    while taken < CLIENT_TAKES and time.monotonic() - start < GIVE_UP_AFTER:
        state = client.latest(max_age=0.5) if client is not None else None
        if isinstance(state, Joy):
            taken += 1
            joy = Joy(header=_header(), axes=np.array(state.axes, np.float32),
                      buttons=np.array(state.buttons, np.int32))
        else:
            joy = Joy(header=_header(), axes=np.zeros(2, np.float32), buttons=np.zeros(1, np.int32))
        ep.send("L", "go")
        ep.send("R", "joy", joy)
        ep.send("R", "image", Image(header=_header(), height=48, width=64, encoding="rgb8", is_bigendian=0,
                                    step=64 * 3, data=pixels.reshape(-1)))
        ep.sleep(0.02)
    ep.send("L", "stop")


def robot(ep: Endpoint) -> None:
    seen: list[list[float]] = []
    while ep.recv("L").label == "go":
        seen.append([float(a) for a in ep.recv("P").payload.axes])
        ep.recv("P")  # the image
        ep.send("L", "seen", len(seen))
    out = os.environ.get("LIVE_TEST_OUT")
    if out:
        with open(os.path.join(out, "robot.json"), "w", encoding="utf-8") as file:
            json.dump(seen, file)


def log(ep: Endpoint) -> None:
    while ep.recv("P").label == "go":
        ep.send("R", "go")
        ep.recv("R")  # seen
    ep.send("R", "stop")
