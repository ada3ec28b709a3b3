"""Role functions that take parameters (module level: group processes import them)."""

from __future__ import annotations

import json
from pathlib import Path

from anodize import Endpoint


def producer(ep: Endpoint, *, count: int = 3, gain: float = 1.0, tag: str = "", flags: list[bool] | None = None,
             out: str = "") -> None:
    """Send ``count`` data messages, then stop; write what it was given to ``out`` (JSON), if named."""
    if out:
        given = {"count": count, "gain": gain, "gain_type": type(gain).__name__, "tag": tag, "flags": flags}
        Path(out).write_text(json.dumps(given), encoding="utf-8")
    for i in range(count):
        ep.send("C", "data", i)
    ep.send("C", "stop")


def consumer(ep: Endpoint, *, out: str = "") -> None:
    """Count data messages until stop; write the count to ``out``, if named."""
    seen = 0
    while ep.recv("P").label == "data":
        seen += 1
    if out:
        Path(out).write_text(str(seen), encoding="utf-8")


def needs_rate(ep: Endpoint, *, rate: float) -> None:
    """A role whose parameter has no default."""
    ep.send("C", "stop")


def ros_producer(ep: Endpoint, *, count: int = 3, out: str = "") -> None:
    """As :func:`producer`, with ROS messages (``std_msgs/msg/Int32``), for channels on ROS topics."""
    from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Int32 as Int32

    for i in range(count):
        ep.send("C", "data", Int32(data=i))
    ep.send("C", "stop", Int32(data=count))
