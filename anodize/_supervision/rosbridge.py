"""The ROS 2 side of a system: which channels are ROS 2 topics, and which roles ROS 2 nodes play."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace

from sessiontypes import StateMachine

from .._transport.qos_profiles import QosProfile, qos_profile
from .._transport.ros_lanes import RosSettings, ros_settings
from ..errors import ConfigurationError
from .rosnames import check_namespace, check_relative_name, resolve_name, resolve_topics

__all__ = ["RosBridge"]


@dataclass(frozen=True)
class RosBridge:
    """A system's channels named as ROS 2 topics: ``System(g, transport=Dds(...), ros=RosBridge(...))``.

    On :class:`~anodize.Dds` the named labels *are* those ROS 2 topics, on the ROS
    domain, and external roles are ROS 2 nodes. On every transport a recording and
    the live view name those labels' channels by their topics.

    Args:
        topics: ``{"Move->Gazebo": "/cmd_vel", "Camera->VisOdom:color": "/camera/color/image_raw"}``
            (a channel with one label may leave the label out). A name without a leading ``/``
            (``"cmd_vel"``) is relative: it is resolved in the namespace, as ROS resolves a node's.
        external: roles that ROS 2 nodes play (they need :class:`~anodize.Dds` or :class:`~anodize.Zenoh`); anodize
            runs no code for them, and every message to or from them must be on a topic.
        distro: the ROS 2 distribution whose message definitions are used ("" for Jazzy).
        domain: the ROS domain when ``ROS_DOMAIN_ID`` is not set (None: 0, as for every node).
        qos: per ROS topic (``"/scan"``) or channel (``"Gazebo->Move"``), its QoS on DDS: a ROS 2
            profile's name (``"sensor_data"``), a table ``{"reliability": "best_effort", "history":
            "keep_last", "depth": 5, "durability": "volatile"}`` or a :class:`QosProfile`; the
            others stay reliable, keep-all, volatile. A QoS that may lose messages is refused
            where the protocol cannot lose one (docs/guide/ros2.md, "QoS per topic").
        namespace: the system's ROS namespace (``"/robot1"``), in which relative topic names
            (and relative group namespaces, ``System.group(namespace=...)``) are resolved.
        remap: ``{"/cmd_vel": "/r1/cmd_vel"}``: topics renamed after the namespaces are applied
            (each side resolved in ``namespace``), as ``ros2 run ... --remap from:=to``.

    Raises:
        ConfigurationError: a field of the wrong type or range, naming what was expected.
    """

    topics: Mapping[str, str] = field(default_factory=dict)
    external: frozenset[str] = frozenset()
    distro: str = ""
    domain: int | None = None
    qos: Mapping[str, QosProfile | str | Mapping[str, object]] = field(default_factory=dict)
    namespace: str = ""
    remap: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        topics = self.topics
        if not isinstance(topics, Mapping) or not all(
                isinstance(k, str) and isinstance(v, str) for k, v in topics.items()):
            raise ConfigurationError(f'RosBridge topics: expected a mapping such as {{"Move->Gazebo": "/cmd_vel"}}, '
                                     f"got {topics!r}")
        external: object = self.external  # given as any iterable of names, kept as a frozenset
        if isinstance(external, str) or not isinstance(external, Iterable) or not all(
                isinstance(r, str) and r for r in external):
            raise ConfigurationError(f'RosBridge external: expected role names such as ("Joy",), got {external!r}')
        if not isinstance(self.distro, str):
            raise ConfigurationError(f'RosBridge distro: expected a ROS 2 distribution such as "jazzy", '
                                     f"got {self.distro!r}")
        domain = self.domain
        if domain is not None and (isinstance(domain, bool) or not isinstance(domain, int)
                                   or not 0 <= domain <= 232):
            raise ConfigurationError(f"RosBridge domain: expected a DDS domain id 0..232 or None, got {domain!r}")
        if not isinstance(self.qos, Mapping) or not all(isinstance(k, str) for k in self.qos):
            raise ConfigurationError(f'RosBridge qos: expected a mapping such as {{"/scan": "sensor_data"}}, '
                                     f"got {self.qos!r}")
        profiles = {key: value if isinstance(value, QosProfile) else qos_profile(value, f"RosBridge qos {key!r}")
                    for key, value in self.qos.items()}
        object.__setattr__(self, "qos", profiles)
        problem = check_namespace(self.namespace)
        if problem is not None:
            raise ConfigurationError(f"RosBridge namespace {self.namespace!r}: {problem}")
        remap = self.remap
        if not isinstance(remap, Mapping):
            raise ConfigurationError(f'RosBridge remap: expected a mapping such as {{"/cmd_vel": "/r1/cmd_vel"}}, '
                                     f"got {remap!r}")
        for name in (*remap.keys(), *remap.values()):
            problem = check_relative_name(name)
            if problem is not None:
                raise ConfigurationError(f"RosBridge remap {name!r}: {problem}")
        for key, name in topics.items():
            problem = check_relative_name(name)
            if problem is not None:
                raise ConfigurationError(f"ros topic {key!r} = {name!r}: {problem}")
        # A copy: the caller's dict changing later must not change the value.
        object.__setattr__(self, "remap", dict(remap))
        object.__setattr__(self, "topics", dict(topics))
        object.__setattr__(self, "external", frozenset(external))

    def __hash__(self) -> int:
        return hash((tuple(sorted(self.topics.items())), self.external, self.distro, self.domain, self.namespace,
                     tuple(sorted(self.remap.items())), tuple(sorted(self.qos.items(), key=lambda item: item[0]))))

    def resolved(self, namespace_of: Mapping[str, str]) -> RosBridge:
        """The bridge with every topic fully qualified: namespaces then remaps applied (resolving
        it again changes nothing: its names are absolute, its remaps applied).

        Args:
            namespace_of: role -> its group's namespace ("" for the system's).

        Raises:
            ConfigurationError: a remap whose source is no topic of the system.
        """
        if not self.namespace and not self.remap and not any(namespace_of.values()) and all(
                name.startswith("/") for name in self.topics.values()) and all(
                key.startswith("/") or "->" in key for key in self.qos):
            return self
        topics = resolve_topics(self.topics, self.namespace, namespace_of, self.remap)
        # The namespace stays: it names the run (Dds run_id).
        return replace(self, topics=topics, remap={}, qos=self._resolved_qos(topics))

    def _resolved_qos(self, resolved: Mapping[str, str]) -> dict[str, QosProfile | str | Mapping[str, object]]:
        """The QoS entries keyed by resolved topic names: an entry written as a topic of
        ``[ros.topics]`` follows that topic (namespaces, remaps); another is resolved in the
        system's namespace when a topic is named so, else kept as written (and refused so); a
        channel's entry (``"A->B"``) stays."""
        qos: dict[str, QosProfile | str | Mapping[str, object]] = {}
        for key, profile in self.qos.items():
            if "->" in key:
                qos[key] = profile
                continue
            names = {resolved[entry] for entry, written in self.topics.items() if written == key}
            if not names and resolve_name(key, self.namespace) in resolved.values():
                names = {resolve_name(key, self.namespace)}
            for name in names or {key}:  # a key on no topic stays as written, to be refused by that name
                qos[name] = profile
        return qos

    def settings(self, machines: Mapping[str, StateMachine], channels: Iterable[tuple[str, str]]) -> RosSettings:
        """The bridge checked against a protocol, with its lanes worked out.

        Raises:
            ConfigurationError: a topic entry that cannot be, naming it.
        """
        return ros_settings(machines, channels, self.topics, self.external, self.distro, self.domain,
                            self.profiles)

    @property
    def profiles(self) -> Mapping[str, QosProfile]:
        """``qos``, each entry as a :class:`QosProfile` (they are converted when the bridge is made)."""
        return {key: value for key, value in self.qos.items() if isinstance(value, QosProfile)}

    def topic_names(self, machines: Mapping[str, StateMachine],
                    channels: Iterable[tuple[str, str]]) -> dict[tuple[str, str, str], str]:
        """``(sender, receiver, label) -> ROS topic`` of the labels the bridge names."""
        if not self.topics:
            return {}
        return {key: topic.name for key, topic in self.settings(machines, channels).topics.items()}
