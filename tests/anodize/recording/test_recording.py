"""Recordings: ``System.run(taps=[Recording(path)])`` / ``anodize run --record``, and ``anodize verify``.

- a recording holds every message between groups, as sent, in order: checked against
  what the role drivers themselves saw sent (an independent account), and read back
  identically by ``mcap`` and by ``rosbags``;
- ``verify`` accepts the recordings of conforming runs of generated protocols, and for a
  recording mutated at a random point (a label changed, a message dropped, two swapped,
  a payload of the wrong sort) names the channel, the index and who is to blame;
- ``verify`` checks a bag written by a plain ROS writer through a topic map.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest
from budget import examples
from hypothesis import HealthCheck, assume, given, note, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parents[1]))
sys.path.insert(0, str(Path(__file__).parents[2] / "sessiontypes"))

from mcap_rewrite import rewrite
from role_drivers import BOGUS_LABEL, build_system, can_always_end, load_global, machines_of
from strategies import GeneratedGlobal, global_protocols

import sessiontypes
from anodize import Processes, Recording, System
from anodize._recording.encoding import codec_for_sort, from_json, to_json
from anodize._recording.reader import open_recording
from anodize._recording.verify import RECORDING_FAULT, verify
from anodize._tools.cli import main
from anodize._tools.recordings import topic_map

ROOT = Path(__file__).parents[3]
TINMAN = ROOT / "tinman" / "src" / "tinman"  # the tinman package of the checkout
SETTINGS = settings(deadline=None, max_examples=examples(25),
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                           HealthCheck.filter_too_much])
seeds = st.integers(0, 2**32 - 1)

BUYERS = """
global Buy(B, S) =
  mu t. B -> S : { title(str). S -> B : quote(int). t,
                   done }
"""


def _recorded_run(global_type: sessiontypes.GlobalType, seed: int, path: Path) -> Any:
    system, drivers_saw, _ = build_system(global_type, seed)
    report = system.run(timeout=20.0, taps=[Recording(path)])
    assert report.ok, report.summary()
    return drivers_saw


def _by_channel(path: Path) -> dict[tuple[str, str], list[tuple[str, object]]]:
    """Per channel, (label, payload) in recorded order, decoded with the channel's sort."""
    found: dict[tuple[str, str], list[tuple[str, object]]] = {}
    with open_recording(path) as recording:
        for message in recording.messages():
            meta = message.topic.metadata
            if "anodize.label" not in meta:  # the hash chain's link records
                continue
            label = meta["anodize.label"]
            codec = codec_for_sort(None)  # builtin sorts: JSON in a String
            payload = codec.decode(message.data)
            found.setdefault((meta["anodize.sender"], meta["anodize.receiver"]), []).append((label, payload))
    return found


# ---- what a recording holds ----------------------------------------------------------------

@SETTINGS
@given(generated=global_protocols(), seed=seeds)
def test_a_recording_holds_every_message_as_sent_and_verify_accepts_it(
        tmp_path_factory: pytest.TempPathFactory, generated: GeneratedGlobal, seed: int) -> None:
    note(generated.text)
    global_type = load_global(generated.text)
    assume(all(can_always_end(m) for m in machines_of(global_type).values()))
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    drivers_saw = _recorded_run(global_type, seed, path)
    assert _by_channel(path) == drivers_saw.nonempty(drivers_saw.sent)  # every role is its own group
    with open_recording(path) as recording:
        report = verify(recording, global_type)
    note(report.text())
    assert report.conforms
    assert not report.missing or all(not drivers_saw.sent[tuple(c.split("->"))] for c in report.missing)


def test_mcap_and_rosbags_read_the_same_messages(tmp_path: Path) -> None:
    global_type = load_global(BUYERS, "Buy")
    _recorded_run(global_type, 7, tmp_path / "run.mcap")
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader

    with (tmp_path / "run.mcap").open("rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        by_mcap = [(c.topic, s.name, s.encoding, c.message_encoding, bytes(m.data))
                   for s, c, m in reader.iter_messages(log_time_order=True)]
    with Reader(tmp_path / "run.mcap") as bag:
        by_rosbags = [(c.topic, c.msgtype, "ros2msg", "cdr", bytes(data)) for c, _, data in bag.messages()]
    assert by_mcap == by_rosbags
    assert by_mcap  # the run sent something
    assert {topic for topic, *_ in by_mcap} <= {"/anodize/B/S/title", "/anodize/B/S/done", "/anodize/S/B/quote",
                                                "/anodize/recording/chain"}


def test_a_folder_recording_is_a_rosbag2_bag_with_its_metadata(tmp_path: Path) -> None:
    global_type = load_global(BUYERS, "Buy")
    _recorded_run(global_type, 3, tmp_path / "bag")
    from rosbags.rosbag2 import Reader

    with Reader(tmp_path / "bag") as bag:
        counts = {c.topic: c.msgcount for c in bag.connections}
        assert sum(counts.values()) == bag.message_count > 0
        qos = {c.topic: c.ext.offered_qos_profiles for c in bag.connections}
    assert all(profile and profile[0].reliability.name == "RELIABLE" for profile in qos.values())
    assert (tmp_path / "bag" / "bag_0.mcap").is_file()
    assert main(["verify", str(tmp_path / "bag")]) == 0


def test_the_json_of_other_sorts_reads_back_what_was_written() -> None:
    import numpy as np

    value = {"a": (1, 2.5, float("inf")), 3: [b"\x00\xff", None, True, "é"], "m": np.arange(6).reshape(2, 3)}
    back = from_json(json.loads(json.dumps(to_json(value))))
    assert isinstance(back, dict)
    assert back["a"] == (1, 2.5, float("inf"))
    assert back[3] == [b"\x00\xff", None, True, "é"]
    assert np.array_equal(back["m"], value["m"])


# ---- mutated recordings ----------------------------------------------------------------------


def _positions(messages: list[Any], channel: tuple[str, str]) -> list[int]:
    return [i for i, m in enumerate(messages)
            if (dict(m[0][2]).get("anodize.sender"), dict(m[0][2]).get("anodize.receiver")) == channel]


def _with(key: Any, **changes: str) -> Any:
    metadata = dict(key[2])
    metadata.update({f"anodize.{k}": v for k, v in changes.items()})
    return (key[0] + "x", key[1], tuple(sorted(metadata.items())))


@SETTINGS
@given(generated=global_protocols(), seed=seeds, mutation=st.sampled_from(["label", "drop", "swap", "sort"]),
       data=st.data())
def test_verify_names_the_channel_index_and_blame_of_a_mutation(
        tmp_path_factory: pytest.TempPathFactory, generated: GeneratedGlobal, seed: int, mutation: str,
        data: st.DataObject) -> None:
    note(generated.text)
    global_type = load_global(generated.text)
    assume(all(can_always_end(m) for m in machines_of(global_type).values()))
    folder = tmp_path_factory.mktemp("rec")
    drivers_saw = _recorded_run(global_type, seed, folder / "run.mcap")
    sent = drivers_saw.nonempty(drivers_saw.sent)
    needed = 2 if mutation in ("drop", "swap") else 1  # a last message dropped cannot be missed
    candidates = sorted(pair for pair, items in sent.items() if len(items) >= needed)
    assume(candidates)
    channel = data.draw(st.sampled_from(candidates), label="channel")
    index = data.draw(st.integers(0, len(sent[channel]) - needed), label="index")
    sender = channel[0]

    def change(messages: list[Any]) -> None:
        at = _positions(messages, channel)
        spot = messages[at[index]]
        if mutation == "label":
            spot[0] = _with(spot[0], label=BOGUS_LABEL)
        elif mutation == "drop":
            del messages[at[index]]
        elif mutation == "swap":
            first, second = messages[at[index]], messages[at[index + 1]]
            first[1], second[1] = second[1], first[1]  # the log times follow the messages
            messages[at[index]], messages[at[index + 1]] = second, first
        else:  # a payload of no sort a label may carry (one label may carry several sorts on a channel)
            string = codec_for_sort(None).ros
            spot[3] = string.serialize(string.cls(data='{"$object": "nowhere:Nothing", "repr": "?"}'))

    rewrite(folder / "run.mcap", folder / "mutated.mcap", change)
    with open_recording(folder / "mutated.mcap") as recording:
        report = verify(recording, global_type)
    note(report.text())
    assert not report.conforms
    name = f"{channel[0]}->{channel[1]}"
    violation = report.channels[name].violation
    assert violation is not None
    assert [n for n, r in report.channels.items() if r.violation is not None] == [name]
    assert violation.index == index
    assert violation.blamed == (RECORDING_FAULT if mutation in ("drop", "swap") else sender)
    if mutation == "sort":
        assert "wrong sort" in violation.reason
    if mutation == "label":
        assert f"({BOGUS_LABEL})" in violation.actual


def test_the_cli_reports_a_violation_with_state_expectation_and_location(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    global_type = load_global(BUYERS, "Buy")
    _recorded_run(global_type, 1, tmp_path / "run.mcap")

    def b_sends_a_quote(messages: list[Any]) -> None:
        messages[0][0] = _with(messages[0][0], label="quote")  # only S sends quotes
    rewrite(tmp_path / "run.mcap", tmp_path / "bad.mcap", b_sends_a_quote)
    capsys.readouterr()
    assert main(["verify", str(tmp_path / "bad.mcap"), "--json", str(tmp_path / "v.json")]) == 1
    out = capsys.readouterr().out
    assert "does NOT conform to Buy" in out
    result = json.loads((tmp_path / "v.json").read_text())
    assert result["conforms"] is False
    violation = result["channels"]["B->S"]["violation"]
    assert violation["index"] == 0 and violation["blamed"] == "B", out
    assert violation["expected"] == ["!S(done)", "!S(title(str))"]
    assert violation["location"].startswith("generated.proto:3:"), violation
    assert "blamed: B; see generated.proto:3:" in out


# ---- recordings made by others -----------------------------------------------------------------

def _ros_bag(path: Path, twists: list[float], joy_type: str = "sensor_msgs/msg/Joy") -> None:
    """A bag as a ROS 2 recorder would write it: TinMan's /joy and /teleop/cmd_vel, no anodize metadata."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    joy_class, twist_class, vector = (store.types[n] for n in (joy_type, "geometry_msgs/msg/Twist",
                                                                 "geometry_msgs/msg/Vector3"))
    header, time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    import numpy as np

    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        joy = bag.add_connection("/joy", joy_type, typestore=store)
        cmd = bag.add_connection("/teleop/cmd_vel", "geometry_msgs/msg/Twist", typestore=store)
        for i, speed in enumerate(twists):
            stamp = 10**9 + i * 20_000_000
            if joy_type == "sensor_msgs/msg/Joy":
                message = joy_class(header=header(stamp=time(sec=1, nanosec=i), frame_id="joy"),
                              axes=np.array([speed, 0.0], dtype=np.float32), buttons=np.array([], dtype=np.int32))
            else:
                message = joy_class(data=f"joy {i}")
            bag.write(joy, stamp, store.serialize_cdr(message, joy_type))
            twist = twist_class(linear=vector(x=speed, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.0))
            bag.write(cmd, stamp + 1_000_000, store.serialize_cdr(twist, "geometry_msgs/msg/Twist"))


def test_verify_checks_a_plain_ros_bag_through_a_topic_map(tmp_path: Path) -> None:
    _ros_bag(tmp_path / "good", [0.1, 0.2, 0.3])
    args = ["verify", str(tmp_path / "good"), "--protocol", str(TINMAN / "tinman.proto"),
            "--global", "TinManParallel", "--topics", str(TINMAN / "tinman.toml")]
    assert main(args) == 0
    gt = sessiontypes.load(TINMAN / "tinman.proto").globals["TinManParallel"]
    with open_recording(tmp_path / "good") as recording:
        report = verify(recording, gt, topic_map(str(TINMAN / "tinman.toml"), gt))
    assert {name: r.messages for name, r in report.channels.items()} == {"Joy->Control": 3, "Control->Move": 3}
    assert "Camera->VisOdom" in report.missing


def test_a_topic_of_the_wrong_type_in_a_ros_bag_is_the_senders_violation(tmp_path: Path) -> None:
    _ros_bag(tmp_path / "bad", [0.1, 0.2], joy_type="std_msgs/msg/String")
    gt = sessiontypes.load(TINMAN / "tinman.proto").globals["TinManParallel"]
    with open_recording(tmp_path / "bad") as recording:
        report = verify(recording, gt, topic_map(str(TINMAN / "tinman.toml"), gt))
    violation = report.channels["Joy->Control"].violation
    assert violation is not None and violation.index == 0 and violation.blamed == "Joy"
    assert "std_msgs/msg/String" in violation.reason and "sensor_msgs/msg/Joy" in violation.reason
    assert report.channels["Control->Move"].violation is None


def test_verify_without_a_protocol_on_a_foreign_bag_says_what_to_give(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _ros_bag(tmp_path / "bag", [0.1])
    assert main(["verify", str(tmp_path / "bag")]) == 1
    assert "--protocol FILE.proto" in capsys.readouterr().err


def test_verify_of_something_that_is_not_a_recording_is_an_error_not_a_traceback(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "junk.mcap").write_bytes(b"\x89MCAP0\r\n not really")
    assert main(["verify", str(tmp_path / "junk.mcap")]) == 1
    err = capsys.readouterr().err
    assert "junk.mcap" in err and "Traceback" not in err
    assert main(["verify", str(tmp_path / "absent.mcap")]) == 1


# ---- a ROS-typed system across processes -------------------------------------------------------

@pytest.mark.slow
def test_tinman_records_and_its_recording_verifies(tmp_path: Path, tinman_recorded: Any) -> None:
    """On the session's recorded ``anodize run tinman --record`` (tests/conftest.py)."""
    out: Path = tinman_recorded.out
    assert "recorded" in tinman_recorded.printed, tinman_recorded.printed
    assert main(["verify", str(out / "run.mcap")]) == 0
    assert main(["verify", str(out / "run.mcap"), "--key", str(tinman_recorded.key)]) == 0  # signed: `run tinman`
    assert ", signed (HMAC-SHA256)" in tinman_recorded.printed
    with open_recording(out / "run.mcap") as recording:
        types = {t.topic: t.type_name for t in recording.topics}
    assert types["/cmd_vel"] == "geometry_msgs/msg/Twist"
    assert types["/gazebo/camera/color/image_raw"] == "sensor_msgs/msg/Image"

    def cut_the_tenth_twist(messages: list[Any]) -> None:
        twists = [m for m in messages if m[0][0] == "/cmd_vel"]
        twists[10][3] = twists[10][3][:20]  # a Twist is 52 bytes of CDR
    rewrite(out / "run.mcap", tmp_path / "cut.mcap", cut_the_tenth_twist)
    with open_recording(tmp_path / "cut.mcap") as recording:
        report = verify(recording, sessiontypes.load(TINMAN / "tinman.proto").globals["TinManParallel"])
    violation = report.channels["Move->Gazebo"].violation
    assert violation is not None and violation.index == 10 and violation.blamed == "Move", report.text()
    assert "does not decode" in violation.reason
    assert [n for n, r in report.channels.items() if r.violation] == ["Move->Gazebo"]


def test_a_run_recorded_between_groups_only_leaves_the_channels_inside_a_group_out(tmp_path: Path) -> None:
    global_type = load_global(BUYERS, "Buy")

    def buyer(ep: Any) -> None:
        ep.send("S", "done")

    def seller(ep: Any) -> None:
        ep.recv("B")

    system = System(global_type)
    system.group("all").role("B", buyer).role("S", seller)
    report = system.run(timeout=10, taps=[Recording(tmp_path / "r.mcap", inside=False)])
    assert report.ok
    assert any("recorded 0 messages" in n for n in report.notes), report.notes
    with open_recording(tmp_path / "r.mcap") as recording:
        result = verify(recording, global_type)
    assert result.conforms and result.inside == ["B->S", "S->B"] and not result.missing


def test_a_recorded_channel_the_protocol_does_not_have_fails_verify(tmp_path: Path) -> None:
    global_type = load_global(BUYERS, "Buy")
    _recorded_run(global_type, 5, tmp_path / "run.mcap")

    def to_a_stranger(messages: list[Any]) -> None:
        messages[0][0] = _with(messages[0][0], receiver="Eve")
    rewrite(tmp_path / "run.mcap", tmp_path / "odd.mcap", to_a_stranger)
    with open_recording(tmp_path / "odd.mcap") as recording:
        report = verify(recording, global_type)
    assert not report.conforms
    assert len(report.unknown) == 1 and report.unknown[0].startswith("B->Eve")


STREAM = """
global Stream(Talker, Listener) = mu t. Talker -> Listener : { number(int). t, stop }
"""


def test_a_killed_group_keeps_what_it_recorded_and_the_report_says_its_part_ended_early(tmp_path: Path) -> None:
    import recording_roles

    system = System(load_global(STREAM, "Stream"), transport=Processes())
    system.group("talk").role("Talker", "recording_roles:talker_killed_midway")
    system.group("listen").role("Listener", "recording_roles:listener")
    report = system.run(timeout=20, taps=[Recording(tmp_path / "r.mcap")])
    assert report.failed
    assert any("part talk-0.mcap ends early" in n for n in report.notes), report.notes
    with open_recording(tmp_path / "r.mcap") as recording:
        result = verify(recording, load_global(STREAM, "Stream"))
    assert result.conforms, result.text()
    assert result.channels["Talker->Listener"].messages == recording_roles.SENT_BEFORE_DYING


# ---- the JSON of other sorts, and hostile recordings ---------------------------------------------

_hashables = st.recursive(st.none() | st.booleans() | st.integers() | st.text(max_size=5) | st.binary(max_size=5),
                          lambda inner: st.tuples(inner, inner) | st.frozensets(inner, max_size=3), max_leaves=6)
_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8) | st.binary(max_size=8)
    | st.binary(max_size=8).map(bytearray) | st.complex_numbers(),
    lambda inner: (st.lists(inner, max_size=3) | st.tuples(inner, inner) | st.sets(_hashables, max_size=3)
                   | st.frozensets(_hashables, max_size=3) | st.dictionaries(_hashables, inner, max_size=3)),
    max_leaves=12)


def _same(a: object, b: object) -> bool:
    """Equal, with the same types all the way down (nan equal to nan)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return a == b or (a != a and b != b)
    if isinstance(a, complex):
        return _same(a.real, b.real) and _same(a.imag, b.imag)  # type: ignore[attr-defined]
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))  # type: ignore[arg-type]
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)  # type: ignore[attr-defined,index]
    return a == b


@settings(max_examples=examples(300), deadline=None)
@given(value=_values)
def test_every_builtin_value_reads_back_with_its_types(value: object) -> None:
    assert _same(from_json(json.loads(json.dumps(to_json(value), allow_nan=False))), value)


def test_a_recording_never_makes_a_module_be_imported(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "side_effect_module.py").write_text(
        f"open({str(tmp_path / 'imported')!r}, 'w').close()\nclass Thing: pass\n", encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    value = from_json({"$dataclass": "side_effect_module:Thing", "fields": {}})
    assert type(value).__name__ == "UnknownObject"
    assert not (tmp_path / "imported").exists()


def test_verify_of_a_recording_with_hostile_json_reports_it_without_a_traceback(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    global_type = load_global(BUYERS, "Buy")
    _recorded_run(global_type, 7, tmp_path / "run.mcap")

    def poison(messages: list[Any]) -> None:
        messages[0][3] = codec_for_sort(None).ros.serialize(codec_for_sort(None).ros.cls(data="[" * 100_000))
    rewrite(tmp_path / "run.mcap", tmp_path / "deep.mcap", poison)
    capsys.readouterr()
    assert main(["verify", str(tmp_path / "deep.mcap")]) == 1
    captured = capsys.readouterr()
    assert "does not decode" in captured.out and "internal error" not in captured.err


def test_sequence_numbers_that_wrap_after_32_bits_are_not_a_gap() -> None:
    from anodize._recording.tap import SEQUENCE_WRAP
    from anodize._recording.verify import _ChannelCheck

    check = _ChannelCheck("Talker", "Listener", machines_of(load_global(STREAM, "Stream")))
    check.sequence = SEQUENCE_WRAP - 2  # as after that many messages
    assert [check._numbering(n) for n in (SEQUENCE_WRAP - 1, SEQUENCE_WRAP, 1, 2)] == ["", "", "", ""]
    assert "missing" in check._numbering(4)


def test_a_recorder_whose_writer_fails_never_blocks_its_senders(tmp_path: Path) -> None:
    import threading

    from anodize._recording.plan import record_plan
    from anodize._recording.tap import Recorder

    global_type = load_global(STREAM, "Stream")
    machines = machines_of(global_type)
    plan = record_plan(str(tmp_path / "parts"), machines, {"Talker": "t", "Listener": "l"}, {})
    recorder = Recorder(plan, "t", 0, "Stream", {"Talker": machines["Talker"]})

    def fail(*args: object) -> None:
        raise OSError(28, "No space left on device")

    recorder._writer.add_message = fail  # type: ignore[method-assign]
    done = threading.Event()

    def send_a_lot() -> None:
        for i in range(2000):
            encoded = recorder.encode(("Talker", "Listener"), "number", i)
            assert encoded is not None
            recorder.queue(("Talker", "Listener"), encoded)
        done.set()

    threading.Thread(target=send_a_lot, daemon=True).start()
    assert done.wait(10), "a sender waited for a writer that had died"
    recorder.close()
    assert "No space left on device" in recorder.broken
    assert recorder.unrecorded
