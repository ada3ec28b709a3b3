"""Roles for the introspection tests (module level: group processes import them by name).

``T`` sends ``L`` a laser scan (360 ranges: an array ``anodize echo`` summarizes) then a
tick, about 50 times a second, until the run is stopped (or, ``burst``, a stop); ``L`` tells ``M`` each tick
(``L -> M`` is a channel inside a group). ``burst`` sends :data:`BURST` ticks as fast as
it can once :data:`GO` is set (inproc only: the test sets it once its client watches), calling
:data:`PACE` every :data:`PACE_EVERY` scans (the test waits there until its group's tap has
forwarded them, so what the client misses is dropped by its watcher, whatever the load).
"""

from __future__ import annotations

import threading
from collections.abc import Callable

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
PACE_EVERY = 500  # scans: fewer than a tap's queue holds (anodize._live.tap.QUEUE)
PACE: list[Callable[[], None]] = []  # what burst calls every PACE_EVERY scans (set by the test)


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
        if n % PACE_EVERY == PACE_EVERY - 1:
            for pace in PACE:
                pace()
    ep.send("L", "scan", scan)
    ep.send("L", "stop")
