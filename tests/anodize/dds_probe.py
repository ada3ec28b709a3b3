"""A probe process for test_netns.py, run on one side of a simulated network.

    dds_probe.py pub DOMAIN TOPIC COUNT   wait for a reader, write 0..COUNT-1 reliably, wait for acks
    dds_probe.py sub DOMAIN TOPIC COUNT   take samples until COUNT have come
    dds_probe.py ping ADDRESS COUNT       ICMP echo, as ping(8) does (which minimal images lack)

Each prints one JSON object on stdout. Every wait is bounded by DEADLINE, so a probe that
cannot finish says so and exits rather than hanging its test.
"""

from __future__ import annotations

import json
import os
import select
import socket
import struct
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

DEADLINE = 60.0  # seconds for a probe's whole job; Cyclone re-announces participants every 30 s
PING_INTERVAL = 0.002  # seconds between echo requests: fast, yet never more than a few in flight
PING_GRACE = 0.5  # seconds to wait for the last replies (a veth answers in microseconds)


def _dds() -> tuple[type, object]:
    """The sample type and the QoS, imported here so that ``ping`` runs without Cyclone."""
    from cyclonedds.core import Policy, Qos
    from cyclonedds.idl import IdlStruct
    from cyclonedds.util import duration

    @dataclass
    class Sample(IdlStruct, typename="probe::Sample"):
        seq: int

    return Sample, Qos(Policy.Reliability.Reliable(duration(seconds=10)), Policy.History.KeepAll)


def _until(ready: Callable[[], object], deadline: float) -> bool:
    """Poll ``ready`` until it is true or the deadline passes."""
    while not ready():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def publish(domain: int, topic: str, count: int) -> dict[str, object]:
    """Write ``count`` samples once a reader has matched, and report whether it acknowledged them all."""
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    sample, qos = _dds()
    participant = DomainParticipant(domain)
    writer = DataWriter(participant, Topic(participant, topic, sample), qos=qos)
    deadline = time.monotonic() + DEADLINE
    if not _until(writer.get_matched_subscriptions, deadline):
        return {"matched": False, "acked": False}
    for seq in range(count):
        writer.write(sample(seq=seq))
    acked = writer.wait_for_acks(duration(seconds=max(0.0, deadline - time.monotonic())))
    return {"matched": True, "acked": bool(acked)}


def subscribe(domain: int, topic: str, count: int) -> dict[str, object]:
    """Take samples until ``count`` have come (or the deadline passes) and report them in arrival order."""
    from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    sample, qos = _dds()
    participant = DomainParticipant(domain)
    reader = DataReader(participant, Topic(participant, topic, sample), qos=qos)
    waitset = WaitSet(participant)
    waitset.attach(ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any))
    deadline = time.monotonic() + DEADLINE
    received: list[int] = []
    while len(received) < count and (left := deadline - time.monotonic()) > 0:
        waitset.wait(duration(seconds=left))
        received.extend(s.seq for s in reader.take(N=count) if s.sample_info.valid_data)
    return {"received": received}


def _checksum(data: bytes) -> int:
    """The Internet checksum (RFC 1071)."""
    data += b"\0" * (len(data) % 2)
    total = sum(struct.unpack(f"!{len(data) // 2}H", data))
    while total >> 16:
        total = (total & 0xFFFF) + (total >> 16)
    return ~total & 0xFFFF


def _echo_request(ident: int, seq: int) -> bytes:
    payload = b"anodize netns probe"
    header = struct.pack("!BBHHH", 8, 0, 0, ident, seq)
    return struct.pack("!BBHHH", 8, 0, _checksum(header + payload), ident, seq) + payload


def _replies(sock: socket.socket, ident: int, until: float, replied: set[int]) -> None:
    """Collect the sequence numbers of our echo replies arriving before ``until``."""
    while (left := until - time.monotonic()) > 0 and select.select([sock], [], [], left)[0]:
        packet = sock.recv(65536)
        icmp = packet[(packet[0] & 0x0F) * 4:]  # after the IP header
        kind, _, _, their_ident, seq = struct.unpack("!BBHHH", icmp[:8])
        if kind == 0 and their_ident == ident:
            replied.add(seq)


def ping(address: str, count: int) -> dict[str, object]:
    """Send ``count`` ICMP echo requests to ``address`` and count the distinct replies."""
    ident, replied = os.getpid() & 0xFFFF, set[int]()
    with socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_ICMP) as sock:
        for seq in range(count):
            sock.sendto(_echo_request(ident, seq), (address, 0))
            _replies(sock, ident, time.monotonic() + PING_INTERVAL, replied)
        _replies(sock, ident, time.monotonic() + PING_GRACE, replied)
    return {"sent": count, "received": len(replied)}


def main(argv: list[str]) -> int:
    match argv:
        case ["pub", domain, topic, count]:
            result = publish(int(domain), topic, int(count))
        case ["sub", domain, topic, count]:
            result = subscribe(int(domain), topic, int(count))
        case ["ping", address, count]:
            result = ping(address, int(count))
        case _:
            sys.stderr.write(__doc__ or "")
            return 2
    print(json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
