"""ROS 2 message types for ``"ros:pkg/msg/Name"`` sorts: checked, serialised as ROS 2 does.

    >>> from anodize._ros import ros_type
    >>> twist = ros_type("geometry_msgs/msg/Twist")          # jazzy unless a distro is given
    >>> Twist, Vector3 = twist.cls, ros_type("geometry_msgs/msg/Vector3").cls
    >>> value = Twist(linear=Vector3(1.0, 0.0, 0.0), angular=Vector3(0.0, 0.0, 0.5))
    >>> twist.check(value) is None, twist.serialize(value)[:4].hex(), twist.dds_name
    (True, '00010000', 'geometry_msgs::msg::dds_::Twist_')
    >>> twist.check(Twist(linear=Vector3("fast", 0.0, 0.0), angular=Vector3(0.0, 0.0, 0.5)))
    "field linear.x: expected float64, got str 'fast'"

Needs rosbags (a dependency of anodize); :meth:`RosType.idl_class` needs the
Cyclone DDS binding. Neither is imported before a type is resolved.
"""

from .messages import DEFAULT_DISTRO, RosDecodeError, RosEncodeError, RosType, ros_type, rosbags_class

__all__ = ["DEFAULT_DISTRO", "RosType", "ros_type", "rosbags_class", "RosDecodeError", "RosEncodeError"]
