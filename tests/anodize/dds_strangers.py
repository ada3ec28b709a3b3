"""DDS endpoints that are not the run's, for the isolation tests: run as ``python dds_strangers.py
MODE DOMAIN RUN_ID READY_FILE`` (MODE ``stray``, ``forger`` or ``wildcard``); the file appears once
the endpoints exist, and the process lives at most two minutes (the test kills it sooner).

- ``stray``: readers of another run on the channel P->C that never take their samples (reliable,
  keep-all, room for one sample): one where a run of the same name but another version would sit
  (the default partition), one in another run's partition.
- ``forger``: before the run starts, a writer and a reader that claim the run's groups (producing,
  consuming, incarnation 0) on P->C; the writer writes garbage every 10 ms. And a writer on the
  supervisors' topic that claims host A and says "stop" every 10 ms.
- ``wildcard``: a reader that never takes, subscribed to every partition (``*``): a reader of
  *this* run as far as DDS can tell; the run's report must name it.
"""

from __future__ import annotations

import os
import socket
import sys
import time
from pathlib import Path

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from anodize._transport.dds import Frame, topic_name

LIFETIME = 120.0
STOP = b'{"kind": "stop", "why": "a forger says so"}'


def _reader_qos(userdata: bytes, partition: str | None) -> Qos:
    policies = [Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepAll,
                Policy.ResourceLimits(max_samples=1), Policy.Userdata(userdata)]
    if partition is not None:
        policies.append(Policy.Partition([partition]))
    return Qos(*policies)


def main(mode: str, domain: int, run_id: str, ready: Path) -> None:
    participant = DomainParticipant(domain)
    topic = Topic(participant, topic_name(run_id, "P", "C"), Frame)
    keep: list[object] = []
    writer = supervisors = None
    if mode == "stray":
        keep.extend(DataReader(participant, topic, qos=_reader_qos(b"anodize1;another_run;consuming;0;X;1", partition))
                    for partition in (None, "anodize/another_run"))
    elif mode == "wildcard":
        keep.append(DataReader(participant, topic, qos=_reader_qos(b"anodize1;a_recorder;spy;0;X;1", "*")))
    else:
        host, pid = socket.gethostname(), os.getpid()
        writer = DataWriter(participant, topic, qos=Qos(
            Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepAll,
            Policy.Liveliness.Automatic(duration(seconds=1)),
            Policy.Userdata(f"anodize1;{run_id};producing;0;{host};{pid}".encode())))
        supervisors = DataWriter(participant, Topic(participant, topic_name(run_id, "supervisors", "all"), Frame),
                                 qos=Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepAll,
                                         Policy.Userdata(f"anodize-supervisor1;{run_id};A;{pid}".encode())))
        keep.append(DataReader(participant, topic, qos=Qos(
            Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1),
            Policy.Userdata(f"anodize1;{run_id};consuming;0;{host};{pid}".encode()))))
    ready.write_text("ready")
    end = time.monotonic() + LIFETIME
    while time.monotonic() < end:
        if writer is not None and supervisors is not None:
            writer.write(Frame(data=list(os.urandom(24))))  # type: ignore[arg-type]  # not even a frame: garbage
            supervisors.write(Frame(data=list(len(STOP).to_bytes(4, "little") + STOP)))  # type: ignore[arg-type]
        time.sleep(0.01)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), sys.argv[3], Path(sys.argv[4]))
