"""Channels as ROS 2 topics (``transport=Dds()``): what anodize publishes is what a ROS 2 node
publishes (topic ``rt/<name>``, type ``pkg::msg::dds_::Name_``, plain CDR, the RIHS01 type hash in
USER_DATA), and a ROS 2 node can play a role. The "ROS node" here is a plain Cyclone DDS program
written against the ROS types; ``test_ros_interop.py`` does the same with Fast DDS."""

from __future__ import annotations

import json
import re
import threading
import time
from pathlib import Path

import pytest
import ros_topic_roles as roles
from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from dds_hosts import domain

import anodize
import sessiontypes
from anodize import ProtocolViolationError
from anodize._ros import ros_type
from anodize._transport.dds import ANY_SAMPLE, userdata_fields, userdata_of
from anodize._transport.dds.binding import matched_publications

pytestmark = pytest.mark.slow
CAMERA = sessiontypes.loads(roles.CAMERA, "camera.proto").globals["Camera"]
TELEOP = sessiontypes.loads(roles.JOY, "teleop.proto").globals["Teleop"]


@pytest.fixture
def ros_domain(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> int:
    """A ROS domain of this test run's own (never 0: real ROS nodes may be there)."""
    number = domain()
    monkeypatch.setenv("ROS_DOMAIN_ID", str(number))
    monkeypatch.setenv("ROS_TEST_OUT", str(tmp_path))
    return number


class RosNode:
    """A stand-in ROS 2 node: a participant with readers and writers of ROS types on ``rt/`` topics."""

    def __init__(self, number: int) -> None:
        self.participant = DomainParticipant(number)
        self.userdata: dict[str, bytes] = {}
        self._watching = True
        self._threads: list[threading.Thread] = []

    def reader(self, topic: str, type_name: str) -> DataReader[object]:
        kind = ros_type(type_name)
        reader: DataReader[object] = DataReader(
            self.participant, Topic(self.participant, "rt" + topic, kind.idl_class()),
            qos=Qos(Policy.Reliability.Reliable(0), Policy.History.KeepAll,
                    Policy.DataRepresentation(use_cdrv0_representation=True)))
        thread = threading.Thread(target=self._watch, args=(reader, topic), daemon=True)
        thread.start()
        self._threads.append(thread)
        return reader

    def _watch(self, reader: DataReader[object], topic: str) -> None:
        """Keep what the writers on ``topic`` say they are (gone once they are)."""
        while self._watching:
            for handle in matched_publications(reader):
                data = reader.get_matched_publication_data(handle)
                if data is not None:
                    self.userdata[topic] = userdata_of(data.qos)
            time.sleep(0.02)

    def writer(self, topic: str, type_name: str, userdata: bytes) -> DataWriter[object]:
        kind = ros_type(type_name)
        return DataWriter(self.participant, Topic(self.participant, "rt" + topic, kind.idl_class()),
                          qos=Qos(Policy.Reliability.Reliable(1_000_000_000), Policy.History.KeepAll,
                                  Policy.Userdata(userdata), Policy.DataRepresentation(use_cdrv0_representation=True)))

    def close(self) -> None:
        self._watching = False
        for thread in self._threads:
            thread.join(2)


def take_all(reader: DataReader[object], type_name: str) -> list[object]:
    kind = ros_type(type_name)
    samples = []
    while taken := ddspy_take(reader._ref, ANY_SAMPLE, 64):
        samples.extend(kind.deserialize(data) for data, info in taken if info.valid_data)
    return samples


def test_colour_and_depth_on_their_topics_and_commands_back_reach_ros_nodes_too(ros_domain: int,
                                                                                 tmp_path: Path) -> None:
    node = RosNode(ros_domain)
    color = node.reader("/camera/color/image_raw", "sensor_msgs/msg/Image")
    cmd = node.reader("/cmd_vel", "geometry_msgs/msg/Twist")
    system = anodize.System(CAMERA, transport=anodize.Dds(run_id="camera", wait=20),
                            ros=anodize.RosBridge(topics=roles.CAMERA_TOPICS))
    system.group("camera").role("C", roles.camera)
    system.group("viewer").role("V", roles.viewer)
    report = system.run(timeout=60)
    node.close()
    assert report.ok, report.summary()
    assert json.loads((tmp_path / "viewer.json").read_text()) == list(range(20))
    assert json.loads((tmp_path / "camera.json").read_text()) == [[0.1 * i, -0.5 * i] for i in range(20)]
    # What a ROS 2 subscriber on /camera/color/image_raw saw: every frame, a real sensor_msgs/Image.
    images = take_all(color, "sensor_msgs/msg/Image")
    assert [(m.header.stamp.sec, m.encoding, m.width, m.height, int(m.data[0])) for m in images] == [  # type: ignore[attr-defined]
        (i, "rgb8", 64, 48, i % 250) for i in range(20)]
    twists = take_all(cmd, "geometry_msgs/msg/Twist")
    assert [m.angular.z for m in twists] == [-0.5 * i for i in range(20)]  # type: ignore[attr-defined]
    # ... and what the writer told it about itself: the type hash as ROS 2 Iron+ does.
    fields = userdata_fields(node.userdata["/camera/color/image_raw"])
    assert fields["typehash"] == ros_type("sensor_msgs/msg/Image").type_hash
    # The claim: this run ("camera", with its token), group camera, incarnation 0 (decision 0032).
    assert re.match(r"anodize1,camera/[0-9a-f]+,camera,0,", fields["anodize"]), fields["anodize"]
    assert "DDS domain" in report.summary() and f"ROS 2 topics on domain {ros_domain}" in report.summary()


def _teleop(external: tuple[str, ...], wait: float = 20) -> anodize.System:
    system = anodize.System(TELEOP, transport=anodize.Dds(run_id="teleop", wait=wait),
                            ros=anodize.RosBridge(topics=roles.JOY_TOPICS, external=frozenset(external)))
    system.group("control").role("C", roles.controller)
    if "W" not in external:
        system.group("wheels").role("W", roles.wheels)
    return system


def _publish_joys(node: RosNode, userdata: bytes, stop: threading.Event) -> None:
    """Joy number i every 20 ms (at most 500) until stopped, once some reader has matched."""
    kind = ros_type("sensor_msgs/msg/Joy")
    writer = node.writer("/joy", "sensor_msgs/msg/Joy", userdata)
    while not writer.get_publication_matched_status().current_count and not stop.wait(0.02):
        pass
    for i in range(500):
        ddspy_write(writer._ref, kind.serialize(roles.Joy(
            header=roles.header(i, "joy"), axes=roles.np.array([0.1 * i, -0.5, 1.0], roles.np.float32),
            buttons=roles.np.array([i % 2, 1, 0], roles.np.int32))))
        if stop.wait(0.02):
            return


def _teleop_with_joystick(node: RosNode, userdata: bytes, timeout: float) -> anodize.RunReport:
    """Teleop with J played by a node publishing Joys with ``userdata``, W by ``node`` (a reader)."""
    stop = threading.Event()
    publisher = threading.Thread(target=_publish_joys, args=(node, userdata, stop), daemon=True)
    publisher.start()
    try:
        return _teleop(("J", "W")).run(timeout=timeout)
    finally:
        stop.set()
        publisher.join(5)
        node.close()


def test_an_external_ros_node_plays_a_role_and_is_checked_by_its_peers(ros_domain: int, tmp_path: Path) -> None:
    node = RosNode(ros_domain)
    cmd = node.reader("/cmd_vel", "geometry_msgs/msg/Twist")
    report = _teleop_with_joystick(node, f"typehash={ros_type('sensor_msgs/msg/Joy').type_hash};".encode(), 4)
    assert report.roles["C"].status == "stopped", report.summary()  # by the timeout: nobody failed
    # A volatile topic: what the node published before anodize discovered its writer is not
    # delivered (as to any ROS 2 subscriber). From then on, every Joy, in order, none twice.
    received = json.loads((tmp_path / "controller.json").read_text())
    first = received[0]["sec"]
    assert [r["sec"] for r in received] == list(range(first, first + len(received))) and len(received) > 20
    assert received[1] == {"sec": first + 1, "axes": [pytest.approx(0.1 * (first + 1)), -0.5, 1.0],
                           "buttons": [(first + 1) % 2, 1, 0]}
    # A Twist for each Joy (but perhaps the last: the run's timeout may stop C before it is sent).
    twists = [m.linear.x for m in take_all(cmd, "geometry_msgs/msg/Twist")]  # type: ignore[attr-defined]
    assert len(twists) >= len(received) - 1 and twists == [pytest.approx(0.1 * i) for i in range(1, len(twists) + 1)]
    assert "external roles, played by ROS 2 nodes: J, W" in report.summary()


def test_a_ros_node_built_against_another_joy_is_rejected_and_blamed(ros_domain: int, tmp_path: Path) -> None:
    node = RosNode(ros_domain)
    node.reader("/cmd_vel", "geometry_msgs/msg/Twist")
    report = _teleop_with_joystick(node, b"typehash=RIHS01_" + b"0" * 64 + b";", 20)
    error = report.roles["C"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert error.blame == "J" and "advertises type hash RIHS01_000" in str(error), str(error)
    assert not (tmp_path / "controller.json").exists()  # no wrong Joy ever reached the role


def test_an_external_role_that_never_appears_is_named_with_its_topic(ros_domain: int) -> None:
    report = _teleop(("J", "W"), wait=1.0).run(timeout=10)
    assert not report.ok
    assert "external role J (a ROS 2 node) (for J->C on ROS topic /joy)" in report.summary(), report.summary()
