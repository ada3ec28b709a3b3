"""A group's ROS topics on a Zenoh session (``anodize._transport.zenoh.ros_topics``), seen by raw Zenoh.

The "ROS node" is a plain Zenoh session on loopback that reads what rmw_zenoh would read: the
samples on the rmw_zenoh key of ``/cmd_vel`` (CDR decoded with rosbags, the attachment's sequence
numbers 1, 2, 3, ... and the GID of the publisher's token), and the graph's liveliness tokens under
``@ros2_lv``. One pair of sessions serves the whole module.
"""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as Twist
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Vector3 as Vector3

from anodize._ros import ros_type
from anodize._ros.rmw_zenoh import (
    Attachment,
    Entity,
    TopicInfo,
    encode_attachment,
    entity_gid,
    entity_key,
    parse_attachment,
    parse_entity_key,
    topic_key,
)
from anodize._transport.qos_profiles import QosProfile
from anodize._transport.ros_lanes import RosSettings, RosTopic
from anodize._transport.zenoh.ros_topics import RosInbox, RosTopicsNode

zenoh = pytest.importorskip("zenoh")

DOMAIN = 7
TWIST = ros_type("geometry_msgs/msg/Twist")
JOY = ros_type("sensor_msgs/msg/Joy")
CMD_VEL = topic_key(DOMAIN, "/cmd_vel", TWIST.dds_name, TWIST.type_hash)
JOY_KEY = topic_key(DOMAIN, "/joy", JOY.dds_name, JOY.type_hash)
SETTINGS = RosSettings(DOMAIN, "", {("Control", "Wheels", "Twist"): RosTopic("/cmd_vel", "geometry_msgs/msg/Twist"),
                                    ("J", "Control", "Joy"): RosTopic("/joy", "sensor_msgs/msg/Joy")},
                       external=frozenset({"J", "Wheels"}),
                       qos={"/joy": QosProfile("best_effort", "keep_last", 5, "volatile", "sensor_data")})
STORE = get_typestore(Stores.ROS2_JAZZY)
WAIT = 10.0  # seconds any one thing may take on a busy machine


def _config(listen: str | None, connect: str | None) -> Any:
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("peer"))
    config.insert_json5("scouting/multicast/enabled", "false")  # only each other, on loopback
    config.insert_json5("listen/endpoints", json.dumps([listen] if listen else []))
    config.insert_json5("connect/endpoints", json.dumps([connect] if connect else []))
    return config


@pytest.fixture(scope="module")
def sessions() -> Iterator[tuple[Any, Any]]:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    endpoint = f"tcp/127.0.0.1:{port}"
    ours = zenoh.open(_config(endpoint, None))
    theirs = zenoh.open(_config(None, endpoint))
    try:
        yield ours, theirs
    finally:
        theirs.close()
        ours.close()


def _until(predicate: Any, what: str) -> None:
    deadline = time.monotonic() + WAIT
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"no {what} within {WAIT} s")
        time.sleep(0.02)


def _tokens(session: Any) -> set[str]:
    return {str(reply.ok.key_expr) for reply in session.liveliness().get("@ros2_lv/**", timeout=2.0)
            if reply.ok is not None}


@pytest.fixture(scope="module")
def node(sessions: tuple[Any, Any]) -> Iterator[RosTopicsNode]:
    ours, _ = sessions
    made = RosTopicsNode(ours, SETTINGS, "control-group", roles={"Control"})
    try:
        yield made
    finally:
        made.close()


def test_the_node_and_its_entities_are_on_the_graph(sessions: tuple[Any, Any], node: RosTopicsNode) -> None:
    _, theirs = sessions
    zid = str(sessions[0].zid())
    expected = {
        f"@ros2_lv/{DOMAIN}/{zid}/0/0/NN/%/%/control_group",
        f"@ros2_lv/{DOMAIN}/{zid}/0/1/MP/%/%/control_group/%cmd_vel/{TWIST.dds_name}/{TWIST.type_hash}/::2,:,:,:,,",
        f"@ros2_lv/{DOMAIN}/{zid}/0/2/MS/%/%/control_group/%joy/{JOY.dds_name}/{JOY.type_hash}/2::,5:,:,:,,",
    }
    seen: set[str] = set()

    def all_there() -> bool:  # the set that had them all is the one checked (a later query may answer late)
        seen.clear()
        seen.update(_tokens(theirs))
        return expected <= seen
    _until(all_there, "liveliness tokens of the node, its publisher and its subscription")
    ours = {entity_key(parse_entity_key(key)) for key in seen if f"/{zid}/" in key}
    assert ours == expected  # each parses, and formats back to itself


def test_cmd_vel_reaches_a_raw_subscriber_as_rmw_zenoh_puts_it(sessions: tuple[Any, Any],
                                                               node: RosTopicsNode) -> None:
    _, theirs = sessions
    got: list[tuple[bytes, bytes | None]] = []
    lock = threading.Lock()

    def take(sample: Any) -> None:
        with lock:
            got.append((sample.payload.to_bytes(),
                        sample.attachment.to_bytes() if sample.attachment is not None else None))

    subscriber = theirs.declare_subscriber(CMD_VEL, take)
    try:
        _until(lambda: _matched(node), "match between the publisher and the raw subscriber")
        before = time.time_ns()
        for step in range(5):
            assert node.publish("Control", "Wheels", "Twist",
                                TWIST.serialize(Twist(Vector3(float(step), 0.0, 0.0), Vector3(0.0, 0.0, 0.5))))
        _until(lambda: len(got) >= 5, "five Twists on the rmw_zenoh key")
    finally:
        subscriber.undeclare()
    publisher = node.publishers[("Control", "Wheels", "Twist")]
    attachments = []
    for step, (payload, raw) in enumerate(got):
        twist = STORE.deserialize_cdr(payload, TWIST.name)  # rosbags' own decoder
        assert isinstance(twist, Twist)
        assert (twist.linear.x, twist.angular.z) == (float(step), 0.5)
        assert raw is not None
        attachments.append(parse_attachment(raw))
    assert [a.sequence for a in attachments] == [1, 2, 3, 4, 5]
    assert all(a.gid == entity_gid(publisher.token_key) for a in attachments)
    stamps = [a.timestamp for a in attachments]
    assert stamps == sorted(stamps) and stamps[0] >= before


def _matched(node: RosTopicsNode) -> bool:
    return node.publishers[("Control", "Wheels", "Twist")].matched()


def test_an_external_nodes_joy_is_taken_and_a_stranger_is_named(sessions: tuple[Any, Any],
                                                                node: RosTopicsNode) -> None:
    _, theirs = sessions
    inbox = node.inbox("J", "Control", "Joy")
    assert inbox is not None and inbox.key == JOY_KEY
    gid = bytes(range(16))
    message = JOY.serialize(JOY.cls(ros_type("std_msgs/msg/Header").cls(
        ros_type("builtin_interfaces/msg/Time").cls(1, 2), "pad"), [0.5], [1]))
    wrong = topic_key(DOMAIN, "/joy", JOY.dds_name, "RIHS01_" + "0" * 64)
    _until(lambda: _has_subscriber(theirs, JOY_KEY), "the inbox's subscriber seen from the node's side")
    theirs.put(JOY_KEY, message, attachment=encode_attachment(Attachment(1, 5, gid)))
    theirs.put(wrong, message, attachment=encode_attachment(Attachment(2, 6, gid)))
    theirs.put(JOY_KEY, message, attachment=b"\x01\x02")
    theirs.put(JOY_KEY, message)
    samples = [inbox.take(WAIT) for _ in range(4)]
    assert all(sample is not None for sample in samples)
    first, stranger, garbled, bare = samples
    assert first is not None and first.problem is None and first.attachment == Attachment(1, 5, gid)
    assert first.payload == message
    assert stranger is not None and stranger.problem is not None and "type hash" in stranger.problem
    assert garbled is not None and garbled.attachment is None and "2 bytes" in (garbled.problem or "")
    assert bare is not None and "no rmw_zenoh attachment" in (bare.problem or "")
    assert inbox.take(0.05) is None


def _has_subscriber(session: Any, key: str) -> bool:
    publisher = session.declare_publisher(key)
    try:
        return bool(publisher.matching_status.matching)
    finally:
        publisher.undeclare()


def test_closing_takes_the_node_off_the_graph(sessions: tuple[Any, Any]) -> None:
    ours, theirs = sessions
    other = RosTopicsNode(ours, SETTINGS, "second", roles={"Control"}, namespace="/robot1")
    zid = str(ours.zid())
    node_token = f"@ros2_lv/{DOMAIN}/{zid}/0/0/NN/%/%robot1/second"
    _until(lambda: node_token in _tokens(theirs), "the second node's token")
    other.close()
    _until(lambda: not any("/second" in token for token in _tokens(theirs)), "the second node leaving the graph")



def test_a_keep_last_inbox_keeps_the_newest_as_a_keep_last_reader_does(sessions: tuple[Any, Any],
                                                                        node: RosTopicsNode) -> None:
    """/joy is sensor_data (keep last 5): eight Joys not taken leave the last five, three dropped."""
    _, theirs = sessions
    inbox = node.inbox("J", "Control", "Joy")
    assert inbox is not None and inbox.keep_last == 5
    message = JOY.serialize(JOY.cls(ros_type("std_msgs/msg/Header").cls(
        ros_type("builtin_interfaces/msg/Time").cls(1, 2), "pad"), [0.5], [1]))
    before = inbox.dropped
    for number in range(1, 9):
        theirs.put(JOY_KEY, message, attachment=encode_attachment(Attachment(number, 5, bytes(16))))
    _until(lambda: inbox.dropped - before == 3, "three Joys overwritten")
    taken = [inbox.take(WAIT) for _ in range(5)]
    assert [sample.attachment.sequence for sample in taken if sample is not None and sample.attachment] == \
        [4, 5, 6, 7, 8]
    assert inbox.take(0.05) is None


def test_a_transient_local_topic_keeps_its_last_samples_for_a_late_subscriber(sessions: tuple[Any, Any]) -> None:
    """As rmw_zenoh's transient-local publisher (an advanced publisher with a cache of depth samples):
    a subscriber that joins after three puts, querying history as rmw_zenoh's does, gets the last two."""
    ours, theirs = sessions
    ext = pytest.importorskip("zenoh.ext")
    text = ros_type("std_msgs/msg/String")
    latched = RosSettings(DOMAIN, "", {("Control", "Map", "String"): RosTopic("/map", "std_msgs/msg/String")},
                          qos={"/map": QosProfile("reliable", "keep_last", 2, "transient_local")})
    node = RosTopicsNode(ours, latched, "mapper", roles={"Control"})
    got: list[bytes] = []
    try:
        for word in ("a", "b", "c"):
            node.publish("Control", "Map", "String", text.serialize(text.cls(word)))
        late = ext.declare_advanced_subscriber(
            theirs, topic_key(DOMAIN, "/map", text.dds_name, text.type_hash),
            lambda sample: got.append(sample.attachment.to_bytes()),
            history=ext.HistoryConfig(detect_late_publishers=True))
        try:
            _until(lambda: len(got) >= 2, "the cached samples")
        finally:
            late.undeclare()
    finally:
        node.close()
    assert [parse_attachment(raw).sequence for raw in got] == [2, 3]


def test_a_keep_all_inbox_that_overruns_ends_with_its_reason_and_holds_no_more(sessions: tuple[Any, Any]) -> None:
    """A node that runs further ahead than the inbox holds is not dropped silently, nor does it hold
    up Zenoh: the inbox ends with a sample that says so (the receiver blames the node's role)."""
    ours, theirs = sessions
    entity = Entity(DOMAIN, str(ours.zid()), "0", "9", "MS", "/", "/", "overrun",
                    TopicInfo("/joy2", JOY.dds_name, JOY.type_hash))
    inbox = RosInbox(ours, entity, RosTopic("/joy2", "sensor_msgs/msg/Joy"), JOY, DOMAIN, capacity=3)
    key = topic_key(DOMAIN, "/joy2", JOY.dds_name, JOY.type_hash)
    try:
        _until(lambda: _has_subscriber(theirs, key), "the inbox's subscriber")
        for number in range(1, 7):
            theirs.put(key, b"\x00\x01\x00\x00", attachment=encode_attachment(Attachment(number, 5, bytes(16))))
        _until(lambda: inbox.dropped == 3, "the samples past the overrun dropped")
        taken = [inbox.take(WAIT) for _ in range(4)]
        assert [s.attachment.sequence for s in taken[:3] if s is not None and s.attachment] == [1, 2, 3]
        last = taken[3]
        assert last is not None and last.problem is not None and "ran 3 messages" in last.problem
        assert inbox.take(0.05) is None
    finally:
        inbox.close()
