"""Drive (ros.proto) written against its generated typed states, with rosbags' Twist (checked by mypy --strict)."""

from __future__ import annotations

import drive_base
import drive_pilot
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as Twist
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Vector3 as Vector3


def pilot(start: drive_pilot.Initial) -> drive_pilot.End:
    twist = Twist(linear=Vector3(x=0.5, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.25))
    return start.send_cmd(twist).recv_done()


def base(start: drive_base.Initial) -> drive_base.End:
    twist, state = start.recv_cmd()
    assert (twist.linear.x, twist.angular.z) == (0.5, 0.25)
    return state.send_done()
