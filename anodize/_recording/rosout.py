"""The roles' log records in a recording: ``rcl_interfaces/msg/Log`` messages on ``/rosout``.

As ``ros2 bag record`` records a ROS system's ``/rosout``, a recorded run holds every
record its roles logged that reached the supervisor (:mod:`anodize._session.logs`), in
their part file (:func:`write_part`), merged with the groups' parts by time. The channel's
metadata marks it (:data:`LOG_KEY`): ``anodize verify`` passes over it, as over the clock
channels (no channel of the protocol), and ``rosbags`` or Foxglove read it as any bag's.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from .._extras import import_extra
from .._ros import ros_type
from .._session.logs import LOG_TYPE, ROSOUT, LogEntry, ros_log

__all__ = ["LOG_KEY", "PART", "ROSOUT_QOS", "write_part"]

FEATURE = "recording a run (--record)"
LOG_KEY = "anodize.log"  # the log channel's metadata key (its value: "1")
PART = "rosout.mcap"    # the part's file name among the groups' parts
# What ROS 2 offers on /rosout (rcl's default), as rosbag2 writes it: reliable, transient local, last 1000.
ROSOUT_QOS = """- history: keep_last
  depth: 1000
  reliability: reliable
  durability: transient_local
  deadline: {sec: 9223372036, nsec: 854775807}
  lifespan: {sec: 10, nsec: 0}
  liveliness: automatic
  liveliness_lease_duration: {sec: 9223372036, nsec: 854775807}
  avoid_ros_namespace_conventions: false"""


def write_part(parts: Path, entries: Sequence[LogEntry], protocol: str) -> None:
    """Write ``entries`` (in the order they came) as the part :data:`PART` in the folder ``parts``."""
    import_extra("mcap.writer", "record", FEATURE)
    from mcap.writer import CompressionType, Writer

    log_type = ros_type(LOG_TYPE)
    parts.mkdir(parents=True, exist_ok=True)
    with (parts / PART).open("wb") as stream:
        writer = Writer(stream, use_chunking=False, compression=CompressionType.NONE)
        writer.start(profile="ros2", library="anodize")
        schema = writer.register_schema(LOG_TYPE, "ros2msg", log_type.message_definition().encode())
        channel = writer.register_channel(ROSOUT, "cdr", schema, {
            "offered_qos_profiles": ROSOUT_QOS, "topic_type_hash": log_type.type_hash,
            "anodize.protocol": protocol, LOG_KEY: "1"})
        # The merge takes each part in time order: the records by the time they were logged.
        for sequence, entry in enumerate(sorted(entries, key=lambda e: e.wall)):
            stamp = int(entry.wall * 1e9)
            writer.add_message(channel, stamp, log_type.serialize(ros_log(entry)), stamp, sequence)
        writer.finish()  # type: ignore[no-untyped-call]
