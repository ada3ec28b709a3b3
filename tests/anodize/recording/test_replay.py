"""``anodize replay``: one role's code run against a recording.

- every role of a recorded two-buyer run (process transport, through the CLI) replays
  with its own function (``--function``: the recording's names are never imported) and matches;
- a function that sends another value diverges, naming the channel and the index; one
  that breaks the protocol gets the monitor's ``ProtocolViolationError``; one that stops
  sending early, or crashes, fails the replay;
- time: ``Endpoint.sleep`` does not wait; ``Endpoint.sleep(math.inf)`` ends the replay;
- the ends of a replay: the recording's end (receiving or sending beyond it), a channel
  inside a group (not recorded), a role that never ends (the replay's timeout);
- how payloads are compared (JSON by value, numpy arrays by dtype, shape and content,
  ROS messages by their CDR bytes);
- property: for generated protocols, replaying any role of a recorded run with the same
  driver matches.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from budget import examples
from hypothesis import HealthCheck, assume, given, note, settings
from hypothesis import strategies as st

HERE = Path(__file__).resolve().parents[1]
for _folder in (HERE, HERE.parent / "sessiontypes"):  # helper modules, no packages
    if str(_folder) not in sys.path:
        sys.path.insert(0, str(_folder))

import replay_roles  # noqa: E402
from role_drivers import Recorder, RoleDriver, build_system, can_always_end, load_global, machines_of  # noqa: E402
from strategies import GeneratedGlobal, global_protocols  # noqa: E402

import sessiontypes  # noqa: E402
from anodize import Endpoint, ProtocolViolationError, Recording, System  # noqa: E402
from anodize._recording.compare import payload_difference, same_value  # noqa: E402
from anodize._recording.encoding import codec_for_sort  # noqa: E402
from anodize._recording.reader import open_recording  # noqa: E402
from anodize._recording.replay import ReplayReport, replay  # noqa: E402
from anodize._tools.cli import main  # noqa: E402

ROOT = HERE.parents[1]
TWO_BUYER = sessiontypes.load(ROOT / "protocols" / "two_buyer.proto").globals["TwoBuyer"]
LOOP = load_global("""
global Buy(B, S) =
  mu t. B -> S : { title(str). S -> B : quote(int). t,
                   done }
""", "Buy")


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    status = main(list(argv))
    out, err = capsys.readouterr()
    assert err == ""
    return status, out


def _replay(path: Path, role: str, function: Callable[..., Any], global_type: sessiontypes.GlobalType = TWO_BUYER,
            timeout: float = 20.0) -> ReplayReport:
    with open_recording(path) as recording:
        report = replay(recording, global_type, role, function, timeout=timeout)
    print(report.text())  # shown when a test fails
    return report


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A two-buyer run on the process transport, every role in a group of its own, recorded."""
    folder = tmp_path_factory.mktemp("replay")
    system = folder / "system.toml"
    system.write_text(f'protocol = "{ROOT / "protocols" / "two_buyer.proto"}"\nglobal = "TwoBuyer"\n'
                      f'transport = "process"\npythonpath = ["{HERE}"]\n'
                      '[groups.b1]\nroles = { B1 = "replay_roles:buyer1" }\n'
                      '[groups.b2]\nroles = { B2 = "replay_roles:buyer2" }\n'
                      '[groups.s]\nroles = { S = "replay_roles:seller" }\n', encoding="utf-8")
    path = folder / "run.mcap"
    assert main(["run", str(system), "--record", str(path), "--quiet"]) == 0
    return path


# ---- the same code matches; other code does not -------------------------------------------

@pytest.mark.parametrize("role", ["B1", "B2", "S"])
def test_each_role_replays_with_the_function_it_ran_and_matches(
        capsys: pytest.CaptureFixture[str], recorded: Path, role: str) -> None:
    capsys.readouterr()
    function = {"B1": "buyer1", "B2": "buyer2", "S": "seller"}[role]
    status, out = _cli(capsys, "replay", str(recorded), "--role", role, "--function", f"replay_roles:{function}",
                       "--pythonpath", str(HERE))
    assert out.splitlines()[0] == (f"replay of role {role} (replay_roles:{function}) from {recorded}, global TwoBuyer: "
                                   "matches the recording and follows the protocol")
    assert out.splitlines()[1] == f"  ended: {role} returned at the end of its local type"
    assert status == 0


def test_the_seller_s_lines_count_every_recorded_message(capsys: pytest.CaptureFixture[str], recorded: Path) -> None:
    capsys.readouterr()
    status, out = _cli(capsys, "replay", str(recorded), "--role", "S", "--function", "replay_roles:seller",
                       "--pythonpath", str(HERE))
    assert (status, out.splitlines()[2:]) == (0, [
        "  received on B1->S: 1 delivered of 1 recorded",
        "  received on B2->S: 1 delivered of 1 recorded",
        "  sent on S->B1: 1 compared of 1 recorded",
        "  sent on S->B2: 2 compared of 2 recorded"])


def test_another_value_is_a_divergence_naming_channel_and_index(
        capsys: pytest.CaptureFixture[str], recorded: Path) -> None:
    capsys.readouterr()
    status, out = _cli(capsys, "replay", str(recorded), "--role", "S", "--function", "replay_roles:seller_on_sale")
    assert status == 1
    assert out.splitlines()[0].endswith("global TwoBuyer: DIVERGES from the recording")
    assert re.search(r"^divergence: role S diverges from the recording on S->B2, message 0 \(recorded at "
                     r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d{6} UTC\): expected quote\(140\), got quote\(126\): "
                     r"the payload differs$", out, re.M), out
    report = _replay(recorded, "S", replay_roles.seller_on_sale)
    divergence = report.divergence
    assert divergence is not None
    assert (divergence.role, divergence.channel, divergence.index, divergence.expected, divergence.actual) == (
        "S", "S->B2", 0, "quote(140)", "quote(126)")
    assert report.compared["S->B1"] == (1, 1)  # the quote to B1 was right


def test_a_role_that_breaks_the_protocol_gets_the_monitor_s_violation(
        capsys: pytest.CaptureFixture[str], recorded: Path) -> None:
    report = _replay(recorded, "S", replay_roles.seller_skipping_buyer2)
    assert not report.ok
    error = report.error
    assert isinstance(error, ProtocolViolationError)
    assert (error.role, error.blame, str(error.actual)) == ("S", "S", "?B2(*)")
    capsys.readouterr()
    status, out = _cli(capsys, "replay", str(recorded), "--role", "S", "--function",
                       "replay_roles:seller_skipping_buyer2")
    assert status == 1
    assert out.splitlines()[0].endswith("global TwoBuyer: VIOLATES the protocol")
    assert f"violation: ProtocolViolationError: {error}" in out.splitlines()


def test_a_role_that_returns_early_violates_and_does_not_pass(recorded: Path) -> None:
    report = _replay(recorded, "S", replay_roles.seller_done_early)
    assert isinstance(report.error, ProtocolViolationError)
    assert str(report.error.actual) == "end (the role's function returned)"
    assert report.compared == {"S->B1": (1, 1), "S->B2": (0, 2)}


def test_a_crash_on_recorded_input_is_reproduced_with_its_traceback(recorded: Path) -> None:
    report = _replay(recorded, "B1", replay_roles.crashing_buyer1)
    assert (report.ok, report.outcome) == (False, "failed")
    assert isinstance(report.error, ValueError)
    assert str(report.error) == "quote 140 is out of range"
    assert "replay_roles.py" in report.traceback and "in crashing_buyer1" in report.traceback
    assert report.text().splitlines()[0].endswith(": FAILED")


# ---- time -----------------------------------------------------------------------------------

def test_endpoint_sleep_does_not_wait_in_a_replay(recorded: Path) -> None:
    # Two hours of sleeps; a replay that waited for them would hit its timeout and fail.
    report = _replay(recorded, "B1", replay_roles.patient_buyer1, timeout=10.0)
    assert (report.ok, report.outcome, report.slept) == (True, "finished", 7200.0)
    assert "  Endpoint.sleep: 7200 s of sleeping skipped" in report.text().splitlines()


def test_sleeping_for_ever_ends_the_replay_once_the_role_has_done_its_part(recorded: Path) -> None:
    report = _replay(recorded, "B1", replay_roles.idle_buyer1)
    assert (report.ok, report.outcome, report.detail) == (
        True, "sleeps for ever", "B1 sleeps until the run stops (Endpoint.sleep(math.inf))")


def test_sleeping_for_ever_before_a_recorded_send_is_a_divergence(recorded: Path) -> None:
    report = _replay(recorded, "B1", replay_roles.sleepy_buyer1)
    assert report.divergence is not None
    assert str(report.divergence).endswith(
        "expected share(70), got nothing more (B1 sleeps until the run stops (Endpoint.sleep(math.inf))): "
        "the recording has 1 more message(s) there")
    assert (report.divergence.channel, report.divergence.index) == ("B1->B2", 0)


def test_a_role_that_never_ends_is_stopped_at_the_replay_s_timeout(recorded: Path) -> None:
    def busy(ep: Endpoint) -> None:
        while True:  # computes, looking at its endpoint now and then
            ep.sleep(0.0)

    report = _replay(recorded, "B1", busy, timeout=0.2)
    assert (report.ok, report.outcome) == (False, "timed out")
    assert report.detail.startswith("B1 did not end within 0.2 s")


# ---- the recording's end, and channels it does not have ---------------------------------

@pytest.fixture(scope="module")
def cut_short(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run stopped at its timeout: B asked for one title, got the quote, then slept."""

    def buyer(ep: Endpoint) -> None:
        ep.send("S", "title", "Ulysses")
        ep.recv("S")
        ep.sleep(math.inf)

    def seller(ep: Endpoint) -> None:
        while ep.recv("B").label == "title":
            ep.send("B", "quote", 140)

    system = System(LOOP)
    system.group("b").role("B", buyer)
    system.group("s").role("S", seller)
    path = tmp_path_factory.mktemp("cut") / "run.mcap"
    report = system.run(timeout=0.5, taps=[Recording(path)])
    assert not report.ok and report.roles["B"].status == "stopped"
    return path


def test_receiving_beyond_the_recording_ends_the_replay_cleanly(cut_short: Path) -> None:
    def seller(ep: Endpoint) -> None:
        while ep.recv("B").label == "title":
            ep.send("B", "quote", 140)

    report = _replay(cut_short, "S", seller, LOOP)
    assert (report.ok, report.outcome) == (True, "recording ends")
    assert report.detail == ("the recording ends here: S in state 0 (&B{title(str).!B(quote(int)).t, done}) "
                             "waits for a message from B, and all 1 recorded on B->S have been delivered")


def test_sending_beyond_the_recording_ends_the_replay_cleanly(cut_short: Path) -> None:
    def buyer(ep: Endpoint) -> None:
        for title in ("Ulysses", "Dubliners"):
            ep.send("S", "title", title)
            ep.recv("S")
        ep.send("S", "done")

    report = _replay(cut_short, "B", buyer, LOOP)
    assert (report.ok, report.outcome) == (True, "recording ends")
    assert report.detail == ("the recording ends here: B sends title('Dubliners') on B->S, but the recording has "
                             "only the 1 message(s) before it there")


def _three_titles_seller(ep: Endpoint) -> None:
    while ep.recv("B").label == "title":
        ep.send("B", "quote", 140)


def test_a_gap_in_the_role_s_input_ends_the_replay_there_without_calling_it_a_divergence(tmp_path: Path) -> None:
    """The recorder lost a message into the role (its writer fell behind: a gap): the role is fed up
    to the gap, and what it sent in the run after it is not what the replay can ask of it."""
    from mcap_rewrite import rewrite

    def buyer(ep: Endpoint) -> None:
        for title in ("Ulysses", "Dubliners", "Emma"):
            ep.send("S", "title", title)
            ep.recv("S")
        ep.send("S", "done")

    system = System(LOOP)
    system.group("b").role("B", buyer)
    system.group("s").role("S", _three_titles_seller)
    path = tmp_path / "run.mcap"
    assert system.run(timeout=20.0, taps=[Recording(path)]).ok

    def lose_the_second_title(messages: list[list[Any]]) -> None:
        titles = [m for m in messages if m[0][0].endswith("/B/S/title")]
        messages.remove(titles[1])

    gapped = tmp_path / "gapped.mcap"
    rewrite(path, gapped, lose_the_second_title)
    report = _replay(gapped, "S", _three_titles_seller, LOOP)
    assert (report.ok, report.outcome, report.divergence) == (True, "recording ends", None), report.text()
    assert report.compared == {"S->B": (1, 3)}
    assert "B->S: replayed up to message 0; the next one is numbered 3 (messages are missing)" in report.notes
    assert ("the recorded messages S sent after the break on B->S are not compared: it did not get the input "
            "that made it send them") in report.notes


def test_a_channel_inside_a_group_recorded_between_groups_only_is_counted_not_compared_and_cannot_be_fed(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    system = System(TWO_BUYER)
    system.group("shop").role("B1", replay_roles.buyer1).role("S", replay_roles.seller)
    system.group("b2").role("B2", replay_roles.buyer2)
    path = tmp_path / "run.mcap"
    assert system.run(timeout=20.0, taps=[Recording(path, inside=False)]).ok
    report = _replay(path, "B1", replay_roles.buyer1)
    # B1 stopped before its first send on a recorded channel: nothing was compared, which is no pass.
    assert (report.ok, report.outcome, report.messages_compared) == (False, "not recorded", 0)
    assert report.text().splitlines()[0].endswith(
        "COMPARED NOTHING: the role sent no message on a recorded channel, so the replay shows nothing (not a pass)")
    status, out = _cli(capsys, "replay", str(path), "--role", "B1", "--function", "replay_roles:buyer1",
                       "--pythonpath", str(HERE))
    assert status == 1 and "COMPARED NOTHING" in out.splitlines()[0], out
    assert report.detail == (
        "B1 in state 1 (?S(quote(int)).!B2(share(int))) receives from S on S->B1, which the recording does not "
        "have (S and B1 are both in group shop, and only channels between groups are recorded): B1 cannot be "
        "replayed alone from here")
    assert report.uncompared == {"B1->S": 1}
    assert report.compared == {"B1->B2": (0, 1)}
    assert _replay(path, "B2", replay_roles.buyer2).outcome == "finished"  # all its channels leave its group


def test_usage_errors(capsys: pytest.CaptureFixture[str], recorded: Path) -> None:
    capsys.readouterr()
    assert main(["replay", str(recorded), "--role", "X"]) == 2
    assert capsys.readouterr().err == "anodize replay: error: no role X in global TwoBuyer; expected one of B1, B2, S\n"
    assert main(["replay", str(recorded), "--role", "S"]) == 1  # the recording's own name is only a hint
    assert capsys.readouterr().err == ("error: replaying role S needs --function module:function (code of your own: "
                                       "what a recording names is never imported); the recording says role S ran "
                                       "`replay_roles:seller`: pass --function replay_roles:seller to replay it\n")
    assert main(["replay", str(recorded), "--role", "S", "--function", "replay_roles:nothing"]) == 1
    assert capsys.readouterr().err == ("error: role function 'replay_roles:nothing': module replay_roles has no "
                                       "nothing\n")


# ---- how payloads are compared ------------------------------------------------------------

def test_json_payloads_compare_by_value() -> None:
    import numpy as np

    codec = codec_for_sort(None)
    array = np.arange(6, dtype=np.int16).reshape(2, 3)
    recorded = codec.encode({"a": (1, 2.5), "b": [float("nan")], "c": array})
    same = {"b": [float("nan")], "c": array.copy(), "a": (1, 2.5)}  # another order: a dict's does not matter
    assert payload_difference(codec, recorded, same) == ""
    for other in ({"a": [1, 2.5], "b": [float("nan")], "c": array},                      # a list, not a tuple
                  {"a": (1, 2.5), "b": [float("nan")], "c": array.astype(np.int32)},     # another dtype
                  {"a": (1, 2.5), "b": [float("nan")], "c": array.reshape(3, 2)},        # another shape
                  {"a": (1, 2.5), "b": [0.0], "c": array}):
        assert payload_difference(codec, recorded, other) == "the payload differs"
    assert not same_value(1, True)


def test_ros_payloads_compare_by_their_cdr_bytes() -> None:
    sort = sessiontypes.loads('type V = "ros:geometry_msgs/msg/Vector3"\nglobal G(A, B) = A -> B : v(V)',
                              "v.proto").globals["G"].project("A").fsm().expected(0)[0].sort
    codec = codec_for_sort(sort)
    vector = codec.ros.cls
    recorded = codec.encode(vector(x=1.0, y=float("nan"), z=0.0))
    assert payload_difference(codec, recorded, vector(x=1.0, y=float("nan"), z=0.0)) == ""
    assert payload_difference(codec, recorded, vector(x=1.0, y=float("nan"), z=-0.0)) == (
        "its CDR bytes differ from the recorded ones from byte 27 on (28 bytes sent, 28 recorded)")


# ---- property --------------------------------------------------------------------------------

@settings(deadline=None, max_examples=examples(20),
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                 HealthCheck.filter_too_much])
@given(generated=global_protocols(), seed=st.integers(0, 2**32 - 1), data=st.data())
def test_any_role_of_a_recorded_run_replays_with_the_same_driver_and_matches(
        tmp_path_factory: pytest.TempPathFactory, generated: GeneratedGlobal, seed: int, data: st.DataObject) -> None:
    note(generated.text)
    global_type = load_global(generated.text)
    machines = machines_of(global_type)
    assume(all(can_always_end(m) for m in machines.values()))
    system, _, _ = build_system(global_type, seed)
    path = tmp_path_factory.mktemp("prop") / "run.mcap"
    run = system.run(timeout=20.0, taps=[Recording(path)])
    assert run.ok, run.summary()
    role = data.draw(st.sampled_from(global_type.roles), label="role")
    driver = RoleDriver(role, machines[role], Recorder(global_type.roles), seed)
    report = _replay(path, role, driver, global_type)
    if report.messages_compared == 0:  # a role that sent nothing between groups: its replay shows nothing
        assert (report.ok, report.outcome) == (False, "finished"), report.text()
        assert "COMPARED NOTHING" in report.text().splitlines()[0]
    else:
        assert (report.ok, report.outcome) == (True, "finished"), report.text()
    assert all(done == total for done, total in report.compared.values())
