"""Roles for the introspection tests (module level: group processes import them by name).

``T`` sends ``L`` a laser scan (360 ranges: an array ``anodize echo`` summarizes) then a
tick, about 50 times a second, until the run is stopped (or, ``burst``, a stop); ``L`` tells ``M`` each tick
(``L -> M`` is a channel inside a group). ``burst`` sends :data:`BURST` ticks as fast as
it can once :data:`GO` is set (inproc only: the test sets it once its client watches).
"""

from __future__ import annotations

import threading

import numpy as np
from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__LaserScan as LaserScan
from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header

from anodize import Endpoint

PROTOCOL = """
type Scan = "ros:sensor_msgs/msg/LaserScan"
global Watched(T, L, M) =
  mu t. T -> L : scan(Scan). T -> L : { tick(int). L -> M : seen(int). t,
                                        stop. L -> M : stop }
"""
SYSTEM = """
protocol = "watched.proto"
global = "Watched"
transport = "{transport}"
timeout = 120

[groups.talker]
roles = {{ T = "introspect_roles:talker" }}

[groups.listener]
roles = {{ L = "introspect_roles:listener", M = "introspect_roles:mirror" }}

[ros.topics]
"T->L:scan" = "/scan"
"""
PERIOD = 0.02
BURST = 20000
GO = threading.Event()
GO_WITHIN = 30.0  # seconds burst waits for the test's client before it sends anyway


def _scan(n: int) -> LaserScan:
    return LaserScan(header=Header(stamp=Time(sec=n, nanosec=0), frame_id="laser"), angle_min=-3.14,
                     angle_max=3.14, angle_increment=0.0175, time_increment=0.0, scan_time=0.1, range_min=0.1,
                     range_max=10.0, ranges=np.full(360, 2.5, np.float32), intensities=np.zeros(0, np.float32))


def talker(ep: Endpoint) -> None:
    n = 0
    while True:
        ep.send("L", "scan", _scan(n))
        ep.send("L", "tick", n)
        n += 1
        ep.sleep(PERIOD)


def listener(ep: Endpoint) -> None:
    while True:
        ep.recv("T")
        message = ep.recv("T")
        if message.label == "stop":
            break
        ep.send("M", "seen", message.payload)
    ep.send("M", "stop")


def mirror(ep: Endpoint) -> None:
    while ep.recv("L").label == "seen":
        pass


def burst(ep: Endpoint) -> None:
    GO.wait(GO_WITHIN)
    scan = _scan(0)
    for n in range(BURST):
        ep.send("L", "scan", scan)
        ep.send("L", "tick", n)
    ep.send("L", "scan", scan)
    ep.send("L", "stop")
