"""The roles' log records on ROS 2's ``/rosout``, for ``ros2 topic echo /rosout`` and rqt_console.

On transport ``Dds`` the supervisor of each host publishes the records of its groups'
roles as ``rcl_interfaces/msg/Log`` on the DDS topic ``rt/rosout`` in the ROS domain (the
system's ROS bridge's, else the run's own DDS domain), in the default partition, with
the QoS rcl gives ``/rosout``: reliable, transient local, the last 1000. One writer for
the whole host: a record is one sample whose ``name`` is its role, as a node's records
carry the node's name. A write never waits for a reader (keep-last history).
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from typing import Any

from ..._ros import ros_type
from ..._session.logs import LOG_TYPE, ROSOUT, LogEntry, ros_log
from ..ros_lanes import dds_topic_of
from .binding import XCDR1, DataWriter, DDSException, DomainParticipant, Policy, Qos, Topic, delete, ref_of, write
from .frame import ros_sample

__all__ = ["RosoutWriter", "DEPTH"]

DEPTH = 1000  # records kept for a late reader, as rcl keeps on /rosout


class RosoutWriter:
    """The host's writer of ``/rosout`` on DDS domain ``domain`` (``distro``: the ROS 2 distribution
    whose definition of the message it writes, None for anodize's default)."""

    def __init__(self, domain: int, distro: str | None = None) -> None:
        self.kind = ros_type(LOG_TYPE, distro)
        self.participant: Any = DomainParticipant(domain)
        topic: Any = Topic(self.participant, dds_topic_of(ROSOUT), self.kind.idl_class())
        userdata = Policy.Userdata(f"typehash={self.kind.type_hash};".encode())
        self.writer: Any = DataWriter(self.participant, topic, qos=Qos(
            Policy.Reliability.Reliable(0), Policy.History.KeepLast(DEPTH), Policy.Durability.TransientLocal,
            userdata, *XCDR1))
        self.ref = ref_of(self.writer)  # looked up once, as a lane does
        self.written = 0
        self.failed = 0

    def log(self, entries: Sequence[LogEntry]) -> None:
        """Publish ``entries`` (a write that fails is counted, never raised: logging is no reason to stop)."""
        for entry in entries:
            try:
                ret = write(self.ref, ros_sample(self.kind.serialize(ros_log(entry))))
            except Exception:  # a record that cannot go (DDSException, a bad value) is counted
                ret = -1
            if ret == 0:
                self.written += 1
            else:
                self.failed += 1

    def close(self) -> None:
        """Delete the writer and its participant."""
        with contextlib.suppress(DDSException):
            delete(self.writer)
            delete(self.participant)
