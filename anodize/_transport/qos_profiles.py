"""The QoS of a ROS topic on DDS: reliability, history and durability, and ROS 2's named profiles.

Every channel is reliable with keep-all history unless the system file says otherwise
(``[ros.qos]`` per ROS topic, ``qos`` in ``[channels."A->B"]``): that is what lets the
monitors hold a run to its protocol, since a lost message would leave its receiver in
another state than its sender believes. A topic may be given a ROS 2 profile by name or
as an inline table ``{ reliability = "best_effort", history = "keep_last", depth = 5,
durability = "volatile" }``. The named profiles are rmw's (``rmw/qos_profiles.h`` of
ros2/rmw, commit 33118c9d); see docs/guide/ros2.md, "QoS per topic".
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import ConfigurationError

__all__ = ["QosProfile", "QosError", "PROFILES", "RELIABLE_KEEP_ALL", "qos_profile"]

_RELIABILITY = ("reliable", "best_effort")
_HISTORY = ("keep_all", "keep_last")
_DURABILITY = ("volatile", "transient_local")
_KEYS = ("reliability", "history", "depth", "durability")
MAX_DEPTH = 100_000  # samples a keep-last history holds; beyond that a writer's memory is the bound


class QosError(ConfigurationError):
    """A QoS that cannot be: ``key`` is where it is given (``ros.qos."/scan"``), ``problem`` what is wrong."""

    def __init__(self, key: str, problem: str) -> None:
        self.key = key
        self.problem = problem
        super().__init__(f"{key}: {problem}")


@dataclass(frozen=True)
class QosProfile:
    """The QoS of one ROS topic, both ends.

    Attributes:
        reliability: ``"reliable"`` or ``"best_effort"`` (a lost sample is not sent again).
        history: ``"keep_all"`` or ``"keep_last"`` (only the newest ``depth`` samples are kept:
            a reader that falls further behind loses the older ones).
        depth: with ``keep_last``, how many samples are kept (0 with ``keep_all``).
        durability: ``"volatile"`` or ``"transient_local"`` (the writer keeps its last ``depth``
            samples for readers that join later, as ROS 2's latched topics do).
        name: the profile's name (``"sensor_data"``), or ``""`` for an inline table.
    """

    reliability: str = "reliable"
    history: str = "keep_all"
    depth: int = 0
    durability: str = "volatile"
    name: str = ""

    @property
    def lossy(self) -> bool:
        """Whether the topic may lose a message: best effort, or a keep-last history a slow reader overruns."""
        return self.reliability == "best_effort" or self.history == "keep_last"

    def describe(self) -> str:
        """``sensor_data (best_effort, keep_last 5, volatile)``, for messages and reports."""
        history = f"keep_last {self.depth}" if self.history == "keep_last" else "keep_all"
        shape = f"{self.reliability}, {history}, {self.durability}"
        return f"{self.name} ({shape})" if self.name else shape

    def yaml(self) -> str:
        """One entry of rosbag2's ``offered_qos_profiles`` (metadata version 9) for this profile."""
        infinite = "{sec: 9223372036, nsec: 854775807}"
        return (f"- history: {self.history}\n  depth: {self.depth}\n  reliability: {self.reliability}\n"
                f"  durability: {self.durability}\n  deadline: {infinite}\n  lifespan: {infinite}\n"
                f"  liveliness: automatic\n  liveliness_lease_duration: {infinite}\n"
                "  avoid_ros_namespace_conventions: false")


RELIABLE_KEEP_ALL = QosProfile()  # anodize's own: nothing lost, duplicated or reordered

# rmw/include/rmw/qos_profiles.h (ros2/rmw). system_default leaves every policy to the DDS
# implementation; Cyclone's defaults are a reliable writer, a best-effort reader and keep-last 1,
# so a pair of them delivers best effort: that is what the name means here.
PROFILES: Mapping[str, QosProfile] = {
    "sensor_data": QosProfile("best_effort", "keep_last", 5, "volatile", "sensor_data"),
    "default": QosProfile("reliable", "keep_last", 10, "volatile", "default"),
    "services_default": QosProfile("reliable", "keep_last", 10, "volatile", "services_default"),
    "parameters": QosProfile("reliable", "keep_last", 1000, "volatile", "parameters"),
    "parameter_events": QosProfile("reliable", "keep_last", 1000, "volatile", "parameter_events"),
    "system_default": QosProfile("best_effort", "keep_last", 1, "volatile", "system_default"),
}


def qos_profile(value: Any, key: str) -> QosProfile:
    """A profile given by name or as an inline table (``key``: where it was given, for messages).

    Raises:
        QosError: an unknown name, an unknown key, a value out of range, or a
            transient-local keep-all history (it would keep every message of the run).
    """
    if isinstance(value, str):
        if value not in PROFILES:
            raise QosError(key, f"expected a ROS 2 profile ({', '.join(map(repr, PROFILES))}) or a "
                                     f"table such as {{ reliability = \"best_effort\", history = \"keep_last\", "
                                     f"depth = 5 }}, got {value!r}")
        return PROFILES[value]
    if not isinstance(value, Mapping):
        raise QosError(key, f"expected a profile name such as \"sensor_data\" or a table, got "
                                 f"a {type(value).__name__}")
    for name in value:
        if name not in _KEYS:
            raise QosError(f"{key}.{name}", f"unknown key; expected one of {', '.join(_KEYS)}")
    reliability = _choice(value, "reliability", _RELIABILITY, key)
    history = _choice(value, "history", _HISTORY, key)
    durability = _choice(value, "durability", _DURABILITY, key)
    depth: Any = value.get("depth", 0 if history == "keep_all" else 10)
    if history == "keep_all":
        if "depth" in value and depth != 0:
            raise QosError(f"{key}.depth", f"a keep_all history has no depth; give history = \"keep_last\" "
                                     f"or leave depth out, got {depth!r}")
        if durability == "transient_local":
            raise QosError(f"{key}.durability", "a transient_local writer keeps its history for readers "
                                     "that join later; with keep_all that is every message of the run: give "
                                     "history = \"keep_last\" and a depth (a latched topic: depth = 1)")
        depth = 0
    elif isinstance(depth, bool) or not isinstance(depth, int) or not 1 <= depth <= MAX_DEPTH:
        raise QosError(f"{key}.depth", f"expected a whole number of samples 1..{MAX_DEPTH}, got {depth!r}")
    return QosProfile(reliability, history, depth, durability)


def _choice(table: Mapping[str, Any], name: str, allowed: tuple[str, ...], key: str) -> str:
    value = table.get(name, allowed[0])
    if value not in allowed:
        raise QosError(f"{key}.{name}", f"expected {' or '.join(map(repr, allowed))}, got {value!r}")
    return str(value)
