"""ROS topic maps: which label goes on which topic, what cannot be a ROS topic, and the lane plan
that tells a receiver which topic its next message comes on."""

from __future__ import annotations

import random
import sys
from pathlib import Path

import pytest
from budget import examples
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

import sessiontypes
from anodize._transport.ros_lanes import check_topic_name, dds_topic_of, lane_plan, ros_settings
from anodize.errors import ConfigurationError
from sessiontypes.graph import communication_graph

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "sessiontypes"))
from strategies import global_protocols

CAMERA = sessiontypes.loads("""
type Image = "ros:sensor_msgs/msg/Image"
type Twist = "ros:geometry_msgs/msg/Twist"
global Camera(C, V, M, R) = (
  mu t. C -> V : {frame(int). C -> V : color(Image). C -> V : depth(Image). V -> M : n(int). t,
                  stop. V -> M : done}
                            || mu u. M -> R : Twist. u )
global Either(C, V) = mu t. C -> V : {color(Image). t, depth(Image). t}
""", "camera.proto").globals


def settings_of(name: str, topics: dict[str, str], external: tuple[str, ...] = (),
                domain: int | None = None) -> object:
    gt = CAMERA[name]
    machines = {role: gt.project(role).fsm() for role in gt.roles}
    return ros_settings(machines, tuple(communication_graph(gt).edges), topics, external, domain=domain)


def test_labels_of_one_channel_on_two_topics_are_read_in_the_protocols_order() -> None:
    ros = settings_of("Camera", {"C->V:color": "/camera/color/image_raw", "C->V:depth": "/camera/depth/image_raw",
                                 "M->R": "/cmd_vel"}, external=("R",))
    plan = ros.plans[("C", "V")]  # type: ignore[attr-defined]
    state = plan.initial
    seen = []
    for label in ["frame", "color", "depth", "frame", "color", "depth", "stop"]:
        seen.append(plan.lanes[state])
        state = plan.after(state, label)
    assert seen == [None, "/camera/color/image_raw", "/camera/depth/image_raw"] * 2 + [None]
    assert ("M", "R") not in ros.plans  # type: ignore[attr-defined]  # nobody reads into an external role here
    assert ros.topics[("M", "R", "Twist")].type_name == "geometry_msgs/msg/Twist"  # type: ignore[attr-defined]


@pytest.mark.parametrize(("topics", "external", "message"), [
    ({"C->V": "/x"}, (),
     'carries the labels color, depth, frame, stop; a ROS topic carries one: map each, e.g. "C->V:color"'),
    ({"C->V:nope": "/x"}, (), "channel C->V has no label nope; expected one of color, depth, frame, stop"),
    ({"V->M:done": "/x"}, (),
     'label done does not carry a ROS message (its sort must be declared as "ros:pkg/msg/Name")'),
    ({"V->C": "/x"}, (), "the protocol has no channel V->C"),
    ({"C->V:color": "/a", "C->V:depth": "/a"}, (), "ros topic /a is given to both C->V:color and C->V:depth"),
    ({"C->V:color": "camera"}, (), "expected an absolute ROS topic name"),
    ({"C->V:color": "/a__b"}, (), "may not contain '__'"),
    ({"C->V->X": "/a"}, (), 'expected "Sender->Receiver" or "Sender->Receiver:label"'),
    ({"C->V:color": "/a"}, ("C",), "external role C: label depth of channel C->V is on no ROS topic"),
    ({}, ("Nobody",), "external role Nobody: the protocol has no such role"),
])
def test_a_topic_map_that_cannot_be_is_refused_naming_the_entry(topics: dict[str, str], external: tuple[str, ...],
                                                                 message: str) -> None:
    with pytest.raises(ConfigurationError) as caught:
        settings_of("Camera", topics, external)
    assert message in str(caught.value)


def test_labels_on_different_topics_that_may_come_in_either_order_are_refused() -> None:
    with pytest.raises(ConfigurationError) as caught:
        settings_of("Either", {"C->V:color": "/a", "C->V:depth": "/b"})
    assert "the next message may be any of color (/a), depth (/b)" in str(caught.value)
    # One label on a topic and the other on the channel's own: the same ambiguity.
    with pytest.raises(ConfigurationError, match=r"any of color \(/a\), depth \(not a ROS topic\)"):
        settings_of("Either", {"C->V:color": "/a"})


def test_the_ros_domain_is_the_environments_then_the_files_then_0(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    assert settings_of("Camera", {"M->R": "/cmd_vel"}).domain == 0  # type: ignore[attr-defined]
    assert settings_of("Camera", {"M->R": "/cmd_vel"}, domain=7).domain == 7  # type: ignore[attr-defined]
    monkeypatch.setenv("ROS_DOMAIN_ID", "12")
    assert settings_of("Camera", {"M->R": "/cmd_vel"}, domain=7).domain == 12  # type: ignore[attr-defined]
    monkeypatch.setenv("ROS_DOMAIN_ID", "twelve")
    with pytest.raises(ConfigurationError, match="ROS_DOMAIN_ID='twelve'"):
        settings_of("Camera", {"M->R": "/cmd_vel"})


def test_topic_names() -> None:
    assert dds_topic_of("/cmd_vel") == "rt/cmd_vel"
    assert check_topic_name("/camera/color/image_raw") is None
    for bad in ("cmd_vel", "/", "/cmd vel", "/1abc", "/a//b", "/a/", "~/x", "/a_/b"):
        assert check_topic_name(bad) is not None, bad


@settings(max_examples=examples(100), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(global_protocols(), st.integers(0, 2**32 - 1))
def test_the_lane_plan_always_names_the_topic_of_the_label_that_comes(generated: object, seed: int) -> None:
    """For random protocols and random maps of labels to topics: whenever the plan is accepted,
    every receive of a random run of the receiver comes on the lane the plan chose."""
    rng = random.Random(seed)
    gt = sessiontypes.loads(generated.text, "g.proto").globals["G"]  # type: ignore[attr-defined]
    edges = sorted(communication_graph(gt).edges)
    assume(edges)
    sender, receiver = rng.choice(edges)
    machine = gt.project(receiver).fsm()
    assume(not machine.forks)
    offers = [{k[2] for k in t if k[0] == "recv" and k[1] == sender} for t in machine.table]
    labels = sorted(set().union(*offers))
    # A label offered beside another cannot have a topic of its own (the plan refuses that; see
    # above): map mostly labels that always come alone, and now and then any, to test refusals.
    alone = {label for label in labels if all(offer == {label} for offer in offers if label in offer)}
    topic_of = {label: f"/t{i}" for i, label in enumerate(labels)
                if rng.random() < (0.8 if label in alone else 0.1)}
    try:
        plan = lane_plan(machine, sender, topic_of, f"{sender}->{receiver}")
    except ConfigurationError:
        return
    event(f"lanes: {len(set(plan.lanes))}")
    state, lane = machine.initial, plan.initial
    for _ in range(60):
        moves = list(machine.table[state].items())
        if not moves:
            break
        (action, peer, label), transition = rng.choice(moves)
        if action == "recv" and peer == sender:
            assert plan.lanes[lane] == topic_of.get(label), (generated.text, topic_of)  # type: ignore[attr-defined]
            lane = plan.after(lane, label)
        state = transition.target
