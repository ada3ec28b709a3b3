"""A group's DDS participant and the QoS of its endpoints.

Every channel is reliable with keep-all history on both ends (nothing lost, duplicated
or reordered); writers assert liveliness automatically with a lease of the settings'
``lease`` seconds, and the participant's discovery lease is the same, so a group whose
process dies, freezes or is cut off loses its endpoints within about one lease. Every
endpoint carries its identity (:mod:`.identity`) in its USER_DATA, and every endpoint
on anodize's own topics is in the run's partition (:attr:`.settings.DdsSettings.partition`),
so it never meets another run's. Endpoints on ROS topics are in the default partition,
where ROS 2 tools look, with the topic's QoS (:mod:`anodize._transport.qos_profiles`):
reliable, keep-all and volatile unless the system file gives another.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ..qos_profiles import RELIABLE_KEEP_ALL, QosProfile
from ..ros_lanes import RosTopic, dds_topic_of
from .binding import XCDR1, DomainParticipant, Policy, Qos, Topic, duration
from .flow import READER_SAMPLES
from .frame import Frame
from .identity import identity_of, ros_userdata
from .settings import DdsSettings, participant_config, topic_name

if TYPE_CHECKING:
    from ..._ros import RosType

__all__ = ["Endpoints", "WRITE_BLOCK"]

WRITE_BLOCK = duration(milliseconds=2)  # the longest a write holds the GIL waiting for room


class Endpoints:
    """A group's participant, the QoS of its channels, and their topics."""

    def __init__(self, settings: DdsSettings, group: str, incarnation: int,
                 report: Callable[[str], None] = lambda line: None) -> None:
        self.settings = settings
        self.incarnation = incarnation
        self.report = report  # a line for the group's report (e.g. a rejected writer)
        # Ours last: Cyclone merges comma-separated configurations, later ones winning.
        previous = os.environ.get("CYCLONEDDS_URI", "")
        os.environ["CYCLONEDDS_URI"] = ",".join(p for p in (previous, participant_config(settings.lease)) if p)
        self.participant = DomainParticipant(settings.domain)
        lease = duration(seconds=settings.lease)
        self.identity = identity_of(settings.claim_run, group, incarnation, settings.host)
        # Only endpoints in the run's partition ever match ours (see DdsSettings.partition).
        partition = Policy.Partition([settings.partition])
        self.writer_qos = Qos(Policy.Reliability.Reliable(WRITE_BLOCK), Policy.History.KeepAll,
                              Policy.Liveliness.Automatic(lease), Policy.Userdata(self.identity), partition)
        self.reader_qos = Qos(Policy.Reliability.Reliable(WRITE_BLOCK), Policy.History.KeepAll,
                              Policy.ResourceLimits(max_samples=READER_SAMPLES),
                              Policy.Liveliness.Automatic(lease), Policy.Userdata(self.identity), partition)
        self.credit_qos = Qos(Policy.Reliability.Reliable(WRITE_BLOCK), Policy.History.KeepLast(1),
                              Policy.Liveliness.Automatic(lease), Policy.Userdata(self.identity), partition)
        self.topics: dict[str, Topic[Any]] = {}

    def topic(self, pair: tuple[str, str], suffix: str = "") -> Topic[Frame]:
        """The topic of a channel (``suffix`` "/credit": of its credits)."""
        name = topic_name(self.settings.run_id, *pair) + suffix
        if name not in self.topics:
            self.topics[name] = Topic(self.participant, name, Frame)
        return self.topics[name]

    def ros_topic(self, topic: RosTopic) -> tuple[Topic[Any], RosType]:
        """The DDS topic of a ROS topic (``rt/...``, the ROS type's DDS name and layout)."""
        from ..._ros import ros_type  # only a run with ROS topics needs the message definitions

        assert self.settings.ros is not None
        kind = ros_type(topic.type_name, self.settings.ros.distro or None)
        name = dds_topic_of(topic.name)
        if name not in self.topics:
            self.topics[name] = Topic(self.participant, name, kind.idl_class())
        return self.topics[name], kind

    def ros_qos(self, kind: RosType, writer: bool, profile: QosProfile = RELIABLE_KEEP_ALL) -> Qos:
        """The topic's QoS (by default reliable, keep-all, volatile, which ROS 2's default and
        sensor-data profiles both match). Writers assert liveliness as on anodize's own topics;
        readers ask for none, since a ROS 2 writer offers an infinite lease and a reader asking
        for less would not match it. A transient-local writer keeps its last samples for ROS 2
        tools that join late; anodize's own readers ask for volatile (they match before the first
        write, and a restarted receiver must not take again what its predecessor took)."""
        userdata = Policy.Userdata(ros_userdata(kind.type_hash, self.identity))
        reliability = (Policy.Reliability.Reliable(WRITE_BLOCK) if profile.reliability == "reliable"
                       else Policy.Reliability.BestEffort)
        history = Policy.History.KeepLast(profile.depth) if profile.history == "keep_last" else Policy.History.KeepAll
        if writer:
            durability = (Policy.Durability.TransientLocal if profile.durability == "transient_local"
                          else Policy.Durability.Volatile)
            return Qos(reliability, history, durability,
                       Policy.Liveliness.Automatic(duration(seconds=self.settings.lease)), userdata, *XCDR1)
        bound = () if profile.history == "keep_last" else (Policy.ResourceLimits(max_samples=READER_SAMPLES),)
        return Qos(reliability, history, Policy.Durability.Volatile, *bound, userdata, *XCDR1)
