"""Against an implementation we did not write: the Fast DDS ROS 2 peer (``ros_peer``, built from
``tests/anodize/ros_peer/main.cpp`` during the tests) plays external roles of a protocol whose
channels are ROS 2 topics. It reads the Twists anodize publishes on ``/cmd_vel`` and publishes the
Joys anodize's monitors check, as a ROS 2 node on Fast DDS (ROS 2's default middleware) would."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import ros_topic_roles as roles
from ros_peer import finish_peer, ros_peer_binary, start_peer

import anodize
import sessiontypes
from anodize import ProtocolViolationError
from anodize._ros import ros_type

pytestmark = pytest.mark.slow
TELEOP = sessiontypes.loads(roles.JOY, "teleop.proto").globals["Teleop"]


@pytest.fixture
def ros_domain(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> int:
    from dds_hosts import domain

    ros_peer_binary()  # built (or skipped, saying why) before any system starts
    number = domain()
    monkeypatch.setenv("ROS_DOMAIN_ID", str(number))
    monkeypatch.setenv("ROS_TEST_OUT", str(tmp_path))
    return number


def teleop() -> anodize.System:
    system = anodize.System(TELEOP, transport=anodize.Dds(run_id="interop", wait=30),
                            ros=anodize.RosBridge(topics=roles.JOY_TOPICS, external=frozenset({"J", "W"})))
    system.group("control").role("C", roles.controller)
    return system


def test_fast_dds_drives_the_controller_and_reads_its_twists(ros_domain: int, tmp_path: Path) -> None:
    wheels = start_peer("listen-twist", topic="rt/cmd_vel", domain=ros_domain, count=40, timeout=60)
    joystick = start_peer("publish-joy", topic="rt/joy", domain=ros_domain, count=40, period_ms=30, wait_match=30,
                          typehash=ros_type("sensor_msgs/msg/Joy").type_hash)
    report = teleop().run(timeout=60)
    joy_code, joy_out, joy_err = finish_peer(joystick, 30)
    # It waits for 40 Twists, but only as many come as Joys reached the controller (a volatile topic
    # loses the first few): once the run is over, every Twist is sent, so a short grace delivers them.
    _, twist_out, _ = finish_peer(wheels, 10)
    assert joy_code == 0, joy_out + joy_err
    # The joystick node published its 40 and left: the controller hears that no node publishes
    # /joy any more, rather than waiting for ever.
    error = report.roles["C"].error
    assert isinstance(error, anodize.PeerFailedError), report.summary()
    assert "no ROS 2 node publishes /joy any more" in str(error)
    # A volatile ROS topic: what the node published before Cyclone had discovered its writer is not
    # delivered (any ROS 2 subscriber loses it too; Fast DDS sees our reader first). From then on,
    # every Joy, in order, none twice.
    received = json.loads((tmp_path / "controller.json").read_text())
    first = received[0]["sec"]
    assert [r["sec"] for r in received] == list(range(first, 40)) and len(received) >= 20, received
    assert received[-1] == {"sec": 39, "axes": [pytest.approx(3.9), -0.5, 1.0], "buttons": [1, 1, 0]}
    twists = [json.loads(line) for line in twist_out.splitlines() if line.startswith("{")]
    assert [t["linear"][0] for t in twists] == [pytest.approx(0.1 * i) for i in range(1, len(received) + 1)]
    assert [t["angular"][2] for t in twists] == [pytest.approx(-0.5 * i) for i in range(1, len(received) + 1)]


def test_a_fast_dds_joy_of_another_type_hash_is_rejected_and_the_external_role_blamed(
        ros_domain: int, tmp_path: Path) -> None:
    wheels = start_peer("listen-twist", topic="rt/cmd_vel", domain=ros_domain, count=1, timeout=15)
    joystick = start_peer("publish-joy", topic="rt/joy", domain=ros_domain, count=40, period_ms=30, wait_match=30,
                          typehash="RIHS01_" + "ab" * 32)
    report = teleop().run(timeout=30)
    finish_peer(joystick, 30)
    _, twist_out, _ = finish_peer(wheels, 3)  # the run is over: a Twist it sent would have arrived
    error = report.roles["C"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert error.blame == "J" and error.role == "C"
    assert f"advertises type hash RIHS01_{'ab' * 32}" in str(error), str(error)
    assert not (tmp_path / "controller.json").exists()  # the wrong Joy never reached the role
    assert not [line for line in twist_out.splitlines() if line.startswith("{")]  # so no Twist went out


@pytest.fixture
def sequence(tinman_sequence: Path) -> Path:
    """The session's 6 s synthetic TinMan sequence (tests/conftest.py), shared with TinMan's system tests."""
    return tinman_sequence


def run_tinman(monkeypatch: pytest.MonkeyPatch, out: Path, sequence: Path, *options: str) -> dict[str, object]:
    from anodize._tools import cli
    from tinman.settings import ENVIRONMENT_VARIABLE

    monkeypatch.setenv(ENVIRONMENT_VARIABLE, "")
    cli.main(["run", "tinman", "--quiet", "--dataset", str(sequence), "--out", str(out), "--transport", "dds",
              *options])
    report: dict[str, object] = json.loads((out / "report.json").read_text())
    return report


def test_fast_dds_sees_tinmans_cmd_vel_during_the_run(ros_domain: int, monkeypatch: pytest.MonkeyPatch,
                                                       tmp_path: Path, sequence: Path) -> None:
    """TinMan on DDS, its channels ROS topics in a ROS domain of the test's own (never 0, where real
    ROS nodes may be): the whole system runs (every channel carried messages) and a Fast DDS node
    reads its /cmd_vel."""
    wheels = start_peer("listen-twist", topic="rt/cmd_vel", domain=ros_domain, count=50, timeout=90)
    report = run_tinman(monkeypatch, tmp_path, sequence, "--duration", "4")
    code, out, err = finish_peer(wheels, 60)
    assert report["ok"] and report["violations"] == 0, report["problems"]
    assert report["transport"] == "dds" and report["frames_processed"] > 10  # type: ignore[operator]
    messages = report["messages"]
    assert isinstance(messages, dict)
    for channel in ("Joy->Control", "Control->Move", "Move->Gazebo", "Camera->VisOdom",
                    "VisOdom->Visualizer", "VisOdom->Planner", "Planner->Move"):
        assert messages[channel] > 0, channel
    twists = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert code == 0 and len(twists) == 50, out + err  # a 50 Hz loop: the first second of it
    assert all(len(t["linear"]) == 3 and len(t["angular"]) == 3 for t in twists)
    assert any(t["linear"][0] > 0 for t in twists)  # the robot was driven forward


def test_a_fast_dds_joystick_node_drives_tinman(ros_domain: int, monkeypatch: pytest.MonkeyPatch,
                                                 tmp_path: Path, sequence: Path) -> None:
    joystick = start_peer("publish-joy", topic="rt/joy", domain=ros_domain, count=400, period_ms=20, wait_match=60,
                          typehash=ros_type("sensor_msgs/msg/Joy").type_hash)
    report = run_tinman(monkeypatch, tmp_path, sequence, "--duration", "4", "--external", "Joy")
    joystick.kill()
    finish_peer(joystick, 10)
    # The node's stick is pushed hard (axes 0.1 i, -0.5, 1.0): it may well steer the robot into
    # a wall, which the report counts against the run; nothing else may go wrong.
    problems = report["problems"]
    assert isinstance(problems, list) and all(p.startswith("the robot bumped") for p in problems), problems
    assert report["violations"] == 0
    messages = report["messages"]
    # Counts are of what anodize's roles sent: a Twist to Move for every Joy the node published.
    assert isinstance(messages, dict) and "Joy->Control" not in messages and messages["Control->Move"] > 20
    assert "Joy" not in report["roles"]  # type: ignore[operator]  # played by the Fast DDS node, not by TinMan
