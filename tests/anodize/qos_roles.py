"""Roles for the QoS tests (module level: group processes import them by name).

``SENSE``: S streams numbered scans to R on a lossy topic while it counts to C on a
reliable one; both loops run until the run's timeout stops them. ``QOS_TEST_OUT`` (a
folder): where R and C write what they saw, as JSON, for the test to read; ``QOS_TEST_SLOW``
(seconds): how long R dwells on each scan (a reader that falls behind).
"""

from __future__ import annotations

import json
import os
import time

import numpy as np
from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__LaserScan as LaserScan
from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header

from anodize import Endpoint, RoleStopped

SENSE = """
type Scan = "ros:sensor_msgs/msg/LaserScan"
global Sense(S, R, C) = ( mu s. S -> R : Scan. s || mu c. S -> C : count(int). c )
"""
SENSE_TOPICS = {"S->R": "/scan"}
BEAMS = 360  # about 1.5 KB a scan: one UDP datagram, so a dropped datagram is a lost scan


def scan(i: int) -> LaserScan:
    """Scan number ``i`` (its number in the stamp's seconds)."""
    return LaserScan(header=Header(stamp=Time(sec=i, nanosec=0), frame_id="laser"), angle_min=-3.14,
                     angle_max=3.14, angle_increment=0.0175, time_increment=0.0, scan_time=0.1, range_min=0.1,
                     range_max=10.0, ranges=np.full(BEAMS, 1.0 + i % 7, np.float32),
                     intensities=np.zeros(0, np.float32))


def _write(name: str, value: object) -> None:
    out = os.environ.get("QOS_TEST_OUT")
    if out:
        with open(os.path.join(out, f"{name}.json.tmp"), "w", encoding="utf-8") as file:
            json.dump(value, file)
        os.replace(os.path.join(out, f"{name}.json.tmp"), os.path.join(out, f"{name}.json"))


def sensor(ep: Endpoint) -> None:
    """A scan to R and a count to C, about 500 times a second, until stopped."""
    i = 0
    while True:
        ep.send("R", "Scan", scan(i))
        ep.send("C", "count", i)
        i += 1
        ep.sleep(0.002)


def scans(ep: Endpoint) -> None:
    """Take scans until stopped: each newer than the last (gaps allowed and counted); write the tally."""
    last, received, gaps = -1, 0, 0
    first_at = last_at = 0.0  # time.monotonic() of the first and the last scan taken
    dwell = float(os.environ.get("QOS_TEST_SLOW", "0"))
    try:
        while True:
            number = ep.recv("S").payload.header.stamp.sec
            last_at = time.monotonic()
            first_at = first_at or last_at
            if number <= last:
                raise AssertionError(f"scan {number} after scan {last}: duplicated or reordered")
            gaps += number - last - 1
            last, received = number, received + 1
            if dwell:
                ep.sleep(dwell)
    except RoleStopped:
        _write("scans", {"received": received, "gaps": gaps, "last": last, "taking_s": last_at - first_at})
        raise


def counter(ep: Endpoint) -> None:
    """Take counts until stopped: every number once, in order (the reliable channel loses nothing)."""
    expected = 0
    try:
        while True:
            value = ep.recv("S").payload
            if value != expected:
                raise AssertionError(f"count {value} where {expected} was due: the reliable channel lost one")
            expected += 1
    except RoleStopped:
        _write("counts", {"received": expected})
        raise
