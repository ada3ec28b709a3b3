"""A run on ``transport = "zenoh"`` whose channels are ROS topics, read as a ROS 2 node on rmw_zenoh
would read them: a raw Zenoh client of the run's router subscribes the rmw_zenoh key of
``/cmd_vel``, decodes each Twist with rosbags and checks the attachments' sequence numbers, and
watches the graph's liveliness tokens under ``@ros2_lv``."""

from __future__ import annotations

import json
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import ros_topic_roles as roles
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as Twist

import anodize
import sessiontypes
from anodize._ros import ros_type
from anodize._ros.rmw_zenoh import (
    Attachment,
    Entity,
    RmwQos,
    TopicInfo,
    encode_attachment,
    entity_gid,
    entity_key,
    parse_attachment,
    parse_entity_key,
    topic_key,
)

zenoh = pytest.importorskip("zenoh", reason="the zenoh extra is not installed")

CAMERA = sessiontypes.loads(roles.CAMERA, "camera.proto").globals["Camera"]
DOMAIN = 41  # not 0: a real ROS graph on this machine would be there
COUNT = 5
TWIST = ros_type("geometry_msgs/msg/Twist")
STORE = get_typestore(Stores.ROS2_JAZZY)


def _open(config: dict[str, Any]) -> Any:
    return zenoh.open(zenoh.Config.from_json5(json.dumps(config)))


@pytest.fixture(scope="module")
def router() -> Iterator[str]:
    """A Zenoh router in this process on a loopback port of its own; its endpoint."""
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{probe.getsockname()[1]}"
    session = _open({"mode": "router", "listen": {"endpoints": [endpoint]},
                     "scouting": {"multicast": {"enabled": False}}})
    yield endpoint
    session.close()


class RawRosNode:
    """What a ROS 2 node on rmw_zenoh reads of the run: samples on a topic's key, and the graph's tokens."""

    def __init__(self, router: str, key: str) -> None:
        self.session = _open({"mode": "client", "connect": {"endpoints": [router]},
                              "scouting": {"multicast": {"enabled": False}}})
        self.samples: list[tuple[bytes, bytes | None]] = []
        self.tokens: set[str] = set()
        self._lock = threading.Lock()
        self._subscriber = self.session.declare_subscriber(key, self._on_sample)
        self._graph = self.session.liveliness().declare_subscriber("@ros2_lv/**", self._on_token, history=True)

    def _on_sample(self, sample: Any) -> None:
        with self._lock:
            attachment = sample.attachment
            self.samples.append((sample.payload.to_bytes(), None if attachment is None else attachment.to_bytes()))

    def _on_token(self, sample: Any) -> None:
        with self._lock:
            self.tokens.add(str(sample.key_expr))

    def wait_for(self, count: int, seconds: float = 10.0) -> None:
        """Until ``count`` samples have come (bounded: the assertions then say what is missing)."""
        deadline = time.monotonic() + seconds
        while len(self.samples) < count and time.monotonic() < deadline:
            time.sleep(0.02)

    def close(self) -> None:
        self.session.close()


@pytest.mark.slow  # two group processes and a router: about 5 s
def test_cmd_vel_of_a_zenoh_run_is_read_as_rmw_zenoh_puts_it(router: str, monkeypatch: pytest.MonkeyPatch,
                                                             tmp_path: Path) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN))
    monkeypatch.setenv("ROS_TEST_COUNT", str(COUNT))
    monkeypatch.setenv("ROS_TEST_OUT", str(tmp_path))
    node = RawRosNode(router, topic_key(DOMAIN, "/cmd_vel", TWIST.dds_name, TWIST.type_hash))
    try:
        transport = anodize.Zenoh(mode="client", connect=(router,), run_id="r" + uuid.uuid4().hex[:12],
                                  scouting=False, wait=20)
        system = anodize.System(CAMERA, transport=transport, ros=anodize.RosBridge(topics=roles.CAMERA_TOPICS))
        system.group("camera").role("C", roles.camera)
        system.group("viewer").role("V", roles.viewer)
        report = system.run(timeout=60)
        assert report.ok, report.summary()
        node.wait_for(COUNT)  # the router may still be forwarding the last ones
    finally:
        node.close()
    assert json.loads((tmp_path / "viewer.json").read_text()) == list(range(COUNT))  # the run itself
    twists = [STORE.deserialize_cdr(payload, TWIST.name) for payload, _ in node.samples]
    assert all(isinstance(twist, Twist) for twist in twists)
    assert [(t.linear.x, t.angular.z) for t in twists] == [(0.1 * i, -0.5 * i) for i in range(COUNT)]
    attachments = [parse_attachment(raw) for _, raw in node.samples if raw is not None]
    assert [a.sequence for a in attachments] == list(range(1, COUNT + 1))
    assert len({a.gid for a in attachments}) == 1
    entities = [parse_entity_key(key) for key in node.tokens]
    assert all(e.domain == DOMAIN for e in entities)
    published = {(e.node, e.topic.name) for e in entities if e.kind == "MP" and e.topic is not None}
    assert published == {("viewer", "/cmd_vel"), ("camera", "/camera/color/image_raw"),
                         ("camera", "/camera/depth/image_raw")}
    nodes = {e.node for e in entities if e.kind == "NN"}
    assert nodes == {"camera", "viewer"}
    cmd_vel = next(e for e in entities if e.kind == "MP" and e.topic is not None and e.topic.name == "/cmd_vel")
    assert _gid(cmd_vel) == attachments[0].gid  # the attachment's GID is the publisher token's hash
    assert (f"ROS 2 topics in rmw_zenoh's format on ROS_DOMAIN_ID {DOMAIN}: /camera/color/image_raw "
            "(C->V: color, sensor_msgs/msg/Image)") in report.summary()


def _gid(entity: Entity) -> bytes:
    return entity_gid(entity_key(entity))


TELEOP = sessiontypes.loads(roles.JOY, "teleop.proto").globals["Teleop"]
JOY = ros_type("sensor_msgs/msg/Joy")


def _teleop(router: str, wait: float = 20) -> anodize.System:
    """Teleop with only C in anodize: J (a joystick) and W (the wheels) are ROS 2 nodes."""
    transport = anodize.Zenoh(mode="client", connect=(router,), run_id="t" + uuid.uuid4().hex[:12],
                              scouting=False, wait=wait)
    system = anodize.System(TELEOP, transport=transport,
                            ros=anodize.RosBridge(topics=roles.JOY_TOPICS, external=frozenset({"J", "W"})))
    system.group("control").role("C", roles.controller)
    return system


def _joystick(node: RawRosNode, type_hash: str, stop: threading.Event) -> None:
    """Play J and W as a ROS 2 node on rmw_zenoh: tokens for a node, a /joy publisher and a /cmd_vel
    subscription; once anodize's subscription of /joy is on the graph, Joy number i every 20 ms."""
    zid = str(node.session.zid())
    info = TopicInfo("/joy", JOY.dds_name, type_hash, RmwQos(history=2))  # reliable, keep all
    twist = TopicInfo("/cmd_vel", TWIST.dds_name, TWIST.type_hash, RmwQos(depth=10))
    tokens = [node.session.liveliness().declare_token(entity_key(entity)) for entity in (
        Entity(DOMAIN, zid, "0", "0", "NN", "/", "/", "joystick"),
        Entity(DOMAIN, zid, "0", "1", "MP", "/", "/", "joystick", info),
        Entity(DOMAIN, zid, "0", "2", "MS", "/", "/", "joystick", twist))]
    publisher_key = entity_key(Entity(DOMAIN, zid, "0", "1", "MP", "/", "/", "joystick", info))
    # As rmw_zenoh declares a reliable keep-all publisher: congestion blocks rather than drops.
    joy = node.session.declare_publisher(topic_key(DOMAIN, "/joy", JOY.dds_name, type_hash),
                                         reliability=zenoh.Reliability.RELIABLE,
                                         congestion_control=zenoh.CongestionControl.BLOCK)
    while not stop.wait(0.02):
        with node._lock:
            if any("/MS/" in key and "/%joy/" in key for key in node.tokens):
                break
    for i in range(500):
        message = JOY.serialize(roles.Joy(header=roles.header(i, "joy"),
                                          axes=roles.np.array([0.1 * i, -0.5, 1.0], roles.np.float32),
                                          buttons=roles.np.array([i % 2, 1, 0], roles.np.int32)))
        joy.put(message, attachment=encode_attachment(Attachment(i + 1, time.time_ns(), entity_gid(publisher_key))))
        if stop.wait(0.02):
            break
    joy.undeclare()
    for token in tokens:
        token.undeclare()


def _teleop_with_joystick(router: str, type_hash: str, timeout: float) -> tuple[anodize.RunReport, RawRosNode]:
    node = RawRosNode(router, topic_key(DOMAIN, "/cmd_vel", TWIST.dds_name, TWIST.type_hash))
    stop = threading.Event()
    joystick = threading.Thread(target=_joystick, args=(node, type_hash, stop), daemon=True)
    joystick.start()
    try:
        return _teleop(router).run(timeout=timeout), node
    finally:
        stop.set()
        joystick.join(5)
        node.close()


@pytest.mark.slow  # a group process and a router: about 6 s
def test_ros_nodes_on_zenoh_play_external_roles_checked_by_their_peers(
        router: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN))
    monkeypatch.setenv("ROS_TEST_OUT", str(tmp_path))
    report, node = _teleop_with_joystick(router, JOY.type_hash, 6)
    assert report.roles["C"].status == "stopped", report.summary()  # by the timeout: nobody failed
    received = json.loads((tmp_path / "controller.json").read_text())
    # Every Joy from the first, in order, none twice (how many depends on how soon the run starts).
    assert [r["sec"] for r in received] == list(range(len(received))) and len(received) >= 2
    assert received[1] == {"sec": 1, "axes": [pytest.approx(0.1), -0.5, 1.0], "buttons": [1, 1, 0]}
    twists = [STORE.deserialize_cdr(payload, TWIST.name) for payload, _ in node.samples]
    assert len(twists) >= len(received) - 1  # perhaps not the last: the timeout may stop C first
    assert [t.linear.x for t in twists] == [pytest.approx(0.1 * i) for i in range(1, len(twists) + 1)]
    assert "external roles, played by ROS 2 nodes on rmw_zenoh: J, W" in report.summary()


@pytest.mark.slow  # a group process and a router: about 5 s
def test_a_ros_node_on_zenoh_with_another_joy_is_rejected_and_blamed(
        router: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN))
    monkeypatch.setenv("ROS_TEST_OUT", str(tmp_path))
    report, _ = _teleop_with_joystick(router, "RIHS01_" + "0" * 64, 20)
    error = report.roles["C"].error
    assert isinstance(error, anodize.ProtocolViolationError), report.summary()
    assert error.blame == "J" and "type hash is RIHS01_000" in str(error), str(error)
    assert not (tmp_path / "controller.json").exists()  # no wrong Joy ever reached the role


@pytest.mark.slow  # a group process waiting out its barrier: about 5 s
def test_an_external_role_that_never_appears_on_zenoh_is_named_with_its_topic(
        router: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN))
    report = _teleop(router, wait=4.0).run(timeout=20)  # a wait the group outlives its imports in
    assert not report.ok
    assert "no sign of external roles J, W (a ROS 2 node on rmw_zenoh, ROS_DOMAIN_ID 41)" in report.summary(), \
        report.summary()
    assert "J->C on ROS topic /joy" in report.summary()
