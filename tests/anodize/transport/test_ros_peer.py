"""The Fast DDS ROS 2 peer (ros_peer.py, ros_peer/main.cpp) speaks ROS 2 on the wire: checked against
the Cyclone DDS Python binding, with the message types declared here by their ROS 2 (Jazzy) layouts.

They also pin down what anodize relies on to write ROS topics from Cyclone: Fast DDS 2.9 matches a
Cyclone endpoint that sends XTypes type information, decodes raw CDR written with ``ddspy_write``
(encapsulation 00 01 00 00: XCDR1, little endian, which the binding uses by default for these
types), and does not match a writer that offers only XCDR2. A sample of another layout published
under a ROS type name is matched by name but dropped by the Cyclone Python reader's own check of the
CDR, before the application can take it. Images (900 KB samples) reach a Fast DDS reader at camera
rates only when its UDP receive buffer is larger than Linux's default.

No ``from __future__ import annotations``: the binding reads the IdlStruct annotations itself.
"""

import json
import struct
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Annotated

import pytest
from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.core import InstanceState, Policy, Qos, SampleState, ViewState
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float32, float64, int32, sequence, uint8, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration
from dds_hosts import domain
from ros_peer import finish_peer, ros_peer_binary, start_peer

from anodize._transport.dds import userdata_of
from anodize._transport.dds.binding import matched_publications, matched_subscriptions

ANY = SampleState.Any | ViewState.Any | InstanceState.Any
XCDR1_LE = b"\x00\x01\x00\x00"  # the encapsulation header of plain little-endian CDR
JOY_HASH = "RIHS01_0d356c79cad3401e35ffeb75a96a96e08be3ef896b8b83841d73e890989372c5"  # sensor_msgs/msg/Joy, Jazzy


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


# The binding's sequence[T] is Annotated[typing.Sequence[T], sequence(T)] (array[T, n] likewise),
# which mypy cannot see through: spelt out, mypy reads it as Sequence[T]. (A plain list[T] serializes,
# but the binding cannot build the XTypes type information of its topic from it.)
@dataclass
class Joy(IdlStruct, typename="sensor_msgs::msg::dds_::Joy_"):
    header: Header = field(default_factory=Header)
    axes: Annotated[Sequence[float32], sequence(float32)] = field(default_factory=list)
    buttons: Annotated[Sequence[int32], sequence(int32)] = field(default_factory=list)


@dataclass
class OtherJoy(IdlStruct, typename="sensor_msgs::msg::dds_::Joy_"):
    """The layout ``ros_peer publish-bad-joy`` sends under the ROS name of Joy."""

    junk: Annotated[Sequence[uint8], array(uint8, 3)]


@dataclass
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    encoding: str = ""
    is_bigendian: uint8 = 0
    step: uint32 = 0
    data: Annotated[Sequence[uint8], sequence(uint8)] = field(default_factory=list)


def ros_qos(*extra: object) -> Qos:
    """The default QoS of ROS 2 (rmw_qos_profile_default)."""
    return Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile,
               Policy.History.KeepLast(10), *extra)


def float32_of(value: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", value))[0])


def wait_until(condition: Callable[[], object], seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def take_raw(reader: DataReader, count: int, seconds: float) -> list[bytes]:  # type: ignore[type-arg]
    """The raw CDR of up to ``count`` valid samples (waiting at most ``seconds``)."""
    samples: list[bytes] = []

    def more() -> bool:
        samples.extend(data for data, info in ddspy_take(reader._ref, ANY, 16) if info.valid_data)
        return len(samples) >= count

    wait_until(more, seconds)
    return samples


@pytest.fixture
def participant() -> Iterator[DomainParticipant]:
    """A Cyclone participant on this test process's domain, deleted with all it holds afterwards."""
    ros_peer_binary()  # skip (or fail on a broken build) before creating anything
    dp = DomainParticipant(domain())
    yield dp
    dp.__del__()


@pytest.mark.parametrize("how", ["idl", "raw"])
def test_listen_twist_prints_what_a_cyclone_writer_wrote(participant: DomainParticipant, how: str) -> None:
    """``how``: the binding's ``DataWriter.write`` of an IdlStruct, or CDR bytes through
    ``ddspy_write`` (as anodize writes its samples)."""
    peer = start_peer("listen-twist", topic="rt/cmd_vel", domain=domain(), count=3, timeout=20)
    writer = DataWriter(participant, Topic(participant, "rt/cmd_vel", Twist), qos=ros_qos())
    try:
        assert wait_until(lambda: matched_subscriptions(writer), 15), "ros_peer's reader never matched"
        time.sleep(0.3)  # the peer may learn of this writer a little after we learnt of its reader
        sent = [Twist(Vector3(0.5 * i, -1.25, 3.0), Vector3(0.0, 1e-9 * i, -2.5)) for i in range(3)]
        for twist in sent:
            cdr = twist.serialize()
            assert cdr[:4] == XCDR1_LE  # the binding's default for these (final) types: XCDR1
            if how == "idl":
                writer.write(twist)
            else:
                assert ddspy_write(writer._ref, cdr + b"\0" * (-len(cdr) % 4)) == 0
    finally:
        code, out, err = finish_peer(peer, 30)
    assert code == 0, out + err
    assert [json.loads(line) for line in out.splitlines()] == [
        {"linear": [t.linear.x, t.linear.y, t.linear.z], "angular": [t.angular.x, t.angular.y, t.angular.z]}
        for t in sent]


@pytest.mark.slow
def test_fast_dds_does_not_match_a_writer_offering_only_xcdr2(participant: DomainParticipant) -> None:
    """Fast DDS 2.9 reads XCDR1 only: a Cyclone writer must keep the binding's default (XCDR1) for ROS topics."""
    peer = start_peer("listen-twist", topic="rt/cmd_vel", domain=domain(), count=1, timeout=4)
    qos = ros_qos(Policy.DataRepresentation(use_xcdrv2_representation=True))
    writer = DataWriter(participant, Topic(participant, "rt/cmd_vel", Twist), qos=qos)
    matched = wait_until(lambda: matched_subscriptions(writer), 3)
    writer.write(Twist())
    code, out, err = finish_peer(peer, 20)
    assert not matched
    assert code == 2 and out == "", out + err


@pytest.mark.slow
def test_publish_joy_delivers_ros_joy_with_its_type_hash(participant: DomainParticipant) -> None:
    reader = DataReader(participant, Topic(participant, "rt/joy", Joy), qos=ros_qos())
    peer = start_peer("publish-joy", topic="rt/joy", domain=domain(), count=5, period_ms=50, wait_match=15,
                      typehash=JOY_HASH)
    try:
        assert wait_until(lambda: matched_publications(reader), 15), "ros_peer's writer never matched"
        publication = reader.get_matched_publication_data(matched_publications(reader)[0])
        samples = take_raw(reader, 5, 15)
    finally:
        code, out, err = finish_peer(peer, 30)
    assert code == 0, out + err
    assert publication is not None and publication.type_name == "sensor_msgs::msg::dds_::Joy_"
    assert userdata_of(publication.qos) == f"typehash={JOY_HASH};".encode()
    assert len(samples) == 5, f"{len(samples)} of 5 Joy samples arrived; peer said:\n{out}{err}"
    for i, cdr in enumerate(samples):
        assert cdr[:4] == XCDR1_LE
        joy = Joy.deserialize(cdr)
        assert joy.header == Header(Time(sec=i, nanosec=0), "joy")
        assert joy.axes == [float32_of(0.1 * i), -0.5, 1.0]
        assert joy.buttons == [i % 2, 1, 0]


@pytest.mark.slow
def test_a_joy_of_another_layout_is_matched_by_name_but_never_delivered(
        participant: DomainParticipant, capfd: pytest.CaptureFixture[str]) -> None:
    """A node built against another definition of sensor_msgs/Joy: its writer (no XTypes type
    information) matches a reader of the real Joy by type name, and the Cyclone Python binding
    drops its samples, which fail its check of the CDR against Joy ("deserialization ...
    failed" on stderr); a reader of that other layout gets them, and they do not decode as Joy."""
    joy_topic = Topic(participant, "rt/joy", Joy)
    reader = DataReader(participant, joy_topic, qos=ros_qos())
    other = DataReader(participant, Topic(participant, "rt/joy", OtherJoy), qos=ros_qos())
    peer = start_peer("publish-bad-joy", topic="rt/joy", domain=domain(), count=3, period_ms=50, wait_match=15)
    try:
        assert wait_until(lambda: matched_publications(reader), 15), "ros_peer's writer never matched the Joy reader"
        publication = reader.get_matched_publication_data(matched_publications(reader)[0])
        raw = take_raw(other, 3, 15)
        delivered = take_raw(reader, 1, 0.5)
    finally:
        code, out, err = finish_peer(peer, 30)
    assert code == 0, out + err
    assert publication is not None and publication.type_name == "sensor_msgs::msg::dds_::Joy_"
    assert delivered == []
    assert len(raw) == 3, f"{len(raw)} of 3 samples arrived; peer said:\n{out}{err}"
    for i, cdr in enumerate(raw):
        assert cdr[:4] == XCDR1_LE and len(cdr) in (7, 8) and cdr[4:7] == bytes([0xAB, 0xCD, i])
        with pytest.raises(struct.error):  # the header's nanosec would lie beyond the sample's end
            Joy.deserialize(cdr)
    assert "deserialization rt/joy/sensor_msgs::msg::dds_::Joy_ failed" in capfd.readouterr().err


@pytest.mark.slow
def test_listen_image_receives_vga_rgb_images(participant: DomainParticipant) -> None:
    """900 KB samples. Fast DDS with the OS's default UDP receive buffer (Linux: 208 KB) loses most
    of the ~690 fragments Cyclone sends of each in one burst and recovers by whole-sample
    retransmission: 2 to 3 images a second arrived here when 20 were sent. A 4 MB buffer (within
    Linux's usual rmem_max; a smaller cap only slows this down) takes them at camera rates."""
    count = 10
    peer = start_peer("listen-image", topic="rt/camera/color/image_raw", domain=domain(), count=count, timeout=30,
                      rcvbuf=4 << 20)
    topic = Topic(participant, "rt/camera/color/image_raw", Image)
    writer = DataWriter(participant, topic, qos=ros_qos())
    pixels = bytes((7 * i) % 251 for i in range(640 * 480 * 3))
    image = Image(Header(Time(12, 345), "camera"), height=480, width=640, encoding="rgb8", step=640 * 3,
                   data=list(pixels))
    cdr = image.serialize()
    assert cdr[:4] == XCDR1_LE
    try:
        assert wait_until(lambda: matched_subscriptions(writer), 15), "ros_peer's reader never matched"
        time.sleep(0.3)
        for _ in range(count):
            assert ddspy_write(writer._ref, cdr + b"\0" * (-len(cdr) % 4)) == 0
            time.sleep(0.05)
    finally:
        code, out, err = finish_peer(peer, 60)
    assert code == 0, out + err
    *images, summary = [json.loads(line) for line in out.splitlines()]
    assert images == [{"width": 640, "height": 480, "encoding": "rgb8", "bytes": len(pixels),
                       "sum": sum(pixels) % 2**32}] * count
    assert summary["images"] == count and summary["seconds"] > 0
