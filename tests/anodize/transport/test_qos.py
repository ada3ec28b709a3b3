"""QoS per ROS topic: the named profiles, the tables, and which topics a protocol lets lose messages
(refused elsewhere with the interaction that forbids it, before anything runs)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import qos_roles

import sessiontypes
from anodize import RosBridge
from anodize._tools.cli import main
from anodize._tools.config import ConfigError, build_system, load_config
from anodize._transport.qos_profiles import PROFILES, RELIABLE_KEEP_ALL, QosError, QosProfile, qos_profile
from anodize.errors import ConfigurationError
from sessiontypes.graph import communication_graph

REPO = Path(__file__).resolve().parents[3]
TINMAN = sessiontypes.load(str(REPO / "tinman/src/tinman/tinman.proto")).globals["TinManParallel"]
TINMAN_TOPICS = {"Gazebo->Move": "/scan", "Gazebo->VisOdom:Odometry": "/odom", "Joy->Control": "/joy",
                 "Gazebo->Camera:color": "/gazebo/camera/color/image_raw"}


def tinman_settings(qos: dict[str, object]) -> object:
    machines = {role: TINMAN.project(role).fsm() for role in TINMAN.roles}
    bridge = RosBridge(topics=TINMAN_TOPICS, qos=qos)  # type: ignore[arg-type]
    return bridge.settings(machines, tuple(communication_graph(TINMAN).edges))


def test_the_named_profiles_are_rmws() -> None:
    # rmw/include/rmw/qos_profiles.h (ros2/rmw): history, depth, reliability, durability.
    assert {name: (p.history, p.depth, p.reliability, p.durability) for name, p in PROFILES.items()} == {
        "sensor_data": ("keep_last", 5, "best_effort", "volatile"),
        "default": ("keep_last", 10, "reliable", "volatile"),
        "services_default": ("keep_last", 10, "reliable", "volatile"),
        "parameters": ("keep_last", 1000, "reliable", "volatile"),
        "parameter_events": ("keep_last", 1000, "reliable", "volatile"),
        "system_default": ("keep_last", 1, "best_effort", "volatile"),
    }
    assert not RELIABLE_KEEP_ALL.lossy and PROFILES["sensor_data"].lossy and PROFILES["default"].lossy


def test_a_table_gives_each_policy() -> None:
    assert qos_profile({"reliability": "best_effort", "history": "keep_last", "depth": 5}, "k") == QosProfile(
        "best_effort", "keep_last", 5, "volatile")
    latched = qos_profile({"history": "keep_last", "depth": 1, "durability": "transient_local"}, "k")
    assert (latched.reliability, latched.depth, latched.durability) == ("reliable", 1, "transient_local")
    assert qos_profile({}, "k") == RELIABLE_KEEP_ALL


@pytest.mark.parametrize(("value", "key", "problem"), [
    ("sensors", "k", "expected a ROS 2 profile ('sensor_data'"),
    ({"reliablity": "reliable"}, "k.reliablity", "unknown key; expected one of reliability, history"),
    ({"reliability": "lossy"}, "k.reliability", "expected 'reliable' or 'best_effort', got 'lossy'"),
    ({"history": "keep_last", "depth": 0}, "k.depth", "expected a whole number of samples 1..100000, got 0"),
    ({"depth": 5}, "k.depth", "a keep_all history has no depth"),
    ({"durability": "transient_local"}, "k.durability", "with keep_all that is every message of the run"),
    (5, "k", "expected a profile name such as \"sensor_data\" or a table, got a int"),
])
def test_a_profile_that_cannot_be_is_refused_naming_its_key(value: object, key: str, problem: str) -> None:
    with pytest.raises(QosError) as caught:
        qos_profile(value, "k")
    assert caught.value.key == key and problem in caught.value.problem


def test_a_stream_whose_receiver_loops_on_it_may_be_lossy() -> None:
    # TinMan's scanner: mu s. Gazebo -> Move : LaserScan within 250ms else timeout. s
    settings = tinman_settings({"/scan": "sensor_data"})
    assert settings.qos_of("/scan").name == "sensor_data"  # type: ignore[attr-defined]
    assert settings.qos_of("/odom") == RELIABLE_KEEP_ALL  # type: ignore[attr-defined]


@pytest.mark.parametrize(("entry", "topic", "why"), [
    # Odometry then LaserScan in one loop: a lost Odometry leaves VisOdom waiting for it.
    ("/odom", "/odom", "Gazebo -> VisOdom : Odometry (at "),
    # Control answers each Joy with a Twist: losing one changes what Control does next.
    ("Joy->Control", "/joy", "Joy -> Control : Joy (at "),
    # The camera's deadline has 'else timeout', but colour is followed by depth: not a self-loop.
    ("Gazebo->Camera:color", "/gazebo/camera/color/image_raw", "Gazebo -> Camera : color (at "),
])
def test_a_lossy_topic_whose_loss_would_change_a_state_is_refused_naming_the_interaction(
        entry: str, topic: str, why: str) -> None:
    with pytest.raises(QosError) as caught:
        tinman_settings({entry: "sensor_data"})
    key = f'ros.qos."{entry}"' if entry.startswith("/") else f'channels."{entry}".qos'
    assert caught.value.key == key
    assert f"{topic} is sensor_data (best_effort, keep_last 5, volatile) and may lose messages" in str(caught.value)
    assert why in caught.value.problem and "tinman.proto:" in caught.value.problem
    assert "moves" in caught.value.problem and "on to its next step" in caught.value.problem


def test_a_reliable_keep_all_qos_is_never_refused() -> None:
    settings = tinman_settings({"/odom": {"reliability": "reliable"}})
    assert not settings.qos_of("/odom").lossy  # type: ignore[attr-defined]


def test_a_lossy_receive_with_a_deadline_and_no_else_timeout_is_refused() -> None:
    text = ('type Scan = "ros:sensor_msgs/msg/LaserScan"\n'
            "global G(S, R) = mu s. S -> R : Scan within 100ms. s\n")
    g = sessiontypes.loads(text, "g.proto").globals["G"]
    machines = {role: g.project(role).fsm() for role in g.roles}
    with pytest.raises(QosError, match="has a deadline \\(within\\) with no 'else timeout'"):
        RosBridge(topics={"S->R": "/scan"}, qos={"/scan": "sensor_data"}).settings(machines, [("S", "R")])


@pytest.mark.parametrize(("entry", "problem"), [
    ("/nowhere", "no label of the protocol is on ROS topic /nowhere"),
    ("Planner->Move", "channel Planner->Move is on no ROS topic"),
])
def test_a_qos_for_no_ros_topic_is_refused(entry: str, problem: str) -> None:
    with pytest.raises(ConfigurationError, match=problem):
        tinman_settings({entry: "default"})


SYSTEM = """\
protocol = "sense.proto"
global = "Sense"
pythonpath = ["{here}"]

[transport]
kind = "dds"

[groups.all]
roles = {{ S = "qos_roles:sensor", R = "qos_roles:scans", C = "qos_roles:counter" }}

[ros.topics]
"S->R" = "/scan"
"S->C" = "/count"

{qos}
"""
SENSE = qos_roles.SENSE.replace("count(int)", "count(Count)").replace(
    'type Scan', 'type Count = "ros:std_msgs/msg/Int64"\ntype Scan')


def write_system(tmp_path: Path, qos: str) -> Path:
    (tmp_path / "sense.proto").write_text(SENSE)
    path = tmp_path / "sense.toml"
    path.write_text(SYSTEM.format(here=Path(qos_roles.__file__).parent, qos=qos))
    return path


def test_the_system_file_gives_qos_per_topic_and_per_channel(tmp_path: Path) -> None:
    path = write_system(tmp_path, '[ros.qos]\n"/scan" = "sensor_data"\n\n'
                                  '[channels."S->C"]\nqos = { reliability = "reliable" }\n')
    config = load_config(path)
    assert config.ros is not None and config.ros.qos == {"S->C": RELIABLE_KEEP_ALL, "/scan": PROFILES["sensor_data"]}
    settings = build_system(config).ros_settings()
    assert settings is not None and settings.qos_of("/scan") == PROFILES["sensor_data"]


@pytest.mark.parametrize("kind", ["dds", "process"])  # the file is the same with --transport dds
def test_a_lossy_channel_the_protocol_cannot_lose_is_refused_by_run_with_its_key_and_interaction(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str) -> None:
    path = write_system(tmp_path, '[channels."S->C"]\nqos = "sensor_data"\n')
    path.write_text(path.read_text().replace('kind = "dds"', f'kind = "{kind}"'))
    # Make the count a request the sensor waits on: a lost count would leave C waiting forever.
    (tmp_path / "sense.proto").write_text(SENSE.replace("mu c. S -> C : count(Count). c",
                                                        "mu c. S -> C : count(Count). C -> S : ack. c"))
    status = main(["run", str(path)])
    out, err = capsys.readouterr()
    assert status != 0 and "protocol Sense" not in out + err  # refused before anything ran
    assert f'{path}: channels."S->C".qos: /count is sensor_data (best_effort, keep_last 5, volatile)' in err
    assert f"S -> C : count (at {tmp_path / 'sense.proto'}:4:" in err
    assert "Traceback" not in err


def test_a_bad_table_is_refused_at_load_with_its_key(tmp_path: Path) -> None:
    path = write_system(tmp_path, '[ros.qos]\n"/scan" = { history = "keep_last", depth = -1 }\n')
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert str(caught.value) == (f'{path}: ros.qos."/scan".depth: expected a whole number of samples 1..100000, '
                                 "got -1")


def test_a_channel_qos_without_ros_topics_is_refused(tmp_path: Path) -> None:
    path = write_system(tmp_path, "")
    path.write_text(path.read_text().split("[ros.topics]")[0] + '[channels."S->C"]\nqos = "sensor_data"\n')
    with pytest.raises(ConfigError, match=re.escape('channels."S->C".qos: a QoS is a ROS topic\'s, and this system')):
        load_config(path)


@pytest.mark.parametrize("namespace", ["", '[ros]\nnamespace = "/r1"\n'])
def test_a_relative_qos_key_follows_its_topic_and_one_on_no_topic_is_refused_as_written(
        tmp_path: Path, namespace: str) -> None:
    # A relative key names the topic written so (under any namespace); one on no topic is refused
    # by the key the file has, not by a name the namespace made of it.
    path = write_system(tmp_path, f'{namespace}[ros.qos]\n"scan" = "sensor_data"\n')
    path.write_text(path.read_text().replace('"S->R" = "/scan"', '"S->R" = "scan"'))
    settings = build_system(load_config(path)).ros_settings()
    scan = "/r1/scan" if namespace else "/scan"
    assert settings is not None and settings.qos_of(scan) == PROFILES["sensor_data"]
    path.write_text(path.read_text().replace('"scan" = "sensor_data"', '"nosuch" = "sensor_data"'))
    with pytest.raises(ConfigError, match=re.escape(f'{path}: ros.qos."nosuch": no label of the protocol is on '
                                                    "ROS topic nosuch")):
        build_system(load_config(path))
