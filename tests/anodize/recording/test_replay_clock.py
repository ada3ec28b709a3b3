"""The role's clock (``Endpoint.now()``, ``Endpoint.wall()``): the machine's live, recorded in a
recorded run, the recording's in a replay; and a run recorded inside its groups.

- live, ``now`` is ``time.monotonic()`` and ``wall`` is ``time.time()`` (bracketed by them);
- a role whose messages carry what it read from its clock replays equal: the replay gives
  back each endpoint's readings, in order (a parallel branch's apart from the role's);
- beyond the recorded readings, a role reads message time: the recorded time of the message
  it received last, advanced by its ``Endpoint.sleep`` arguments;
- a role that reads its clock otherwise than in the run is told so;
- the clock's channels are no channels of the protocol: ``anodize verify`` passes;
- ``Recording(inside=True)``: a role that talks to a role of its own group replays equal;
- a forked role's threads replay in their recorded order (and are let go, saying so, when
  its code no longer acts as in the run);
- a generated typed state reads the clock without being used;
- `anodize run --record PATH --record-inside` (and `--record-inside` alone is a usage error).
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

HERE = Path(__file__).resolve().parents[1]
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import replay_roles  # noqa: E402
from role_drivers import load_global  # noqa: E402

import sessiontypes  # noqa: E402
from anodize import Endpoint, Recording, State, System  # noqa: E402
from anodize._recording import turnstile  # noqa: E402
from anodize._recording.reader import open_recording  # noqa: E402
from anodize._recording.replay import ReplayReport, replay  # noqa: E402
from anodize._recording.verify import verify  # noqa: E402
from anodize._tools.cli import main  # noqa: E402

ROOT = HERE.parents[1]
TWO_BUYER = sessiontypes.load(ROOT / "protocols" / "two_buyer.proto").globals["TwoBuyer"]
TALK = load_global("""
global Talk(B, S) =
  mu t. B -> S : { title(str). S -> B : quote(str). t,
                   done }
""", "Talk")
FORKED = load_global("""
global Forked(A, B, C) =
  ( mu x. A -> B : { tick(str). x, done } || mu y. A -> C : { tock(str). y, done } )
""", "Forked")
ROUNDS = 5


def _replay(path: Path, global_type: sessiontypes.GlobalType, role: str, function: Callable[..., Any]) -> ReplayReport:
    with open_recording(path) as recording:
        report = replay(recording, global_type, role, function, timeout=20.0)
    print(report.text())  # shown when a test fails
    return report


def _clocked_buyer(ep: Endpoint) -> None:
    """Sends what it reads from its clock, sleeping a little between rounds."""
    for _ in range(ROUNDS):
        ep.send("S", "title", f"{ep.now()!r} {ep.wall()!r}")
        ep.recv("S")
        ep.sleep(0.01)
    ep.send("S", "done")


def _clocked_seller(ep: Endpoint) -> None:
    """Answers each title with the time it took since the last one, by its own clock."""
    last = ep.now()
    while ep.recv("B").label == "title":
        now = ep.now()
        ep.send("B", "quote", repr(now - last))
        last = now


@pytest.fixture(scope="module")
def talked(tmp_path_factory: pytest.TempPathFactory) -> Path:
    system = System(TALK)
    system.group("b").role("B", _clocked_buyer)
    system.group("s").role("S", _clocked_seller)
    path = tmp_path_factory.mktemp("clock") / "run.mcap"
    report = system.run(timeout=20.0, taps=[Recording(path)])
    assert report.ok
    # B read now() and wall() and ended a sleep each round; S read now() once, then once a title.
    note = next(note for note in report.notes if note.startswith("recorded "))
    assert note.startswith("recorded 11 messages (") and note.endswith(
        f" on 2 channels (3 topics) between and inside groups, and {3 * ROUNDS + ROUNDS + 1} readings of the roles' "
        "clocks, "
        f"to {path}"), note
    return path


def test_the_live_clock_is_the_machine_s() -> None:
    seen: list[float] = []

    def buyer(ep: Endpoint) -> None:
        seen.extend((time.monotonic(), ep.now(), time.monotonic(), time.time(), ep.wall(), time.time()))
        ep.send("S", "done")

    def seller(ep: Endpoint) -> None:
        ep.recv("B")

    system = System(TALK)
    system.group("b").role("B", buyer)
    system.group("s").role("S", seller)
    assert system.run(timeout=20.0).ok
    before, now, after, wall_before, wall, wall_after = seen
    assert before <= now <= after and wall_before <= wall <= wall_after


@pytest.mark.parametrize("role", ["B", "S"])
def test_a_role_that_sends_its_clock_readings_replays_equal(talked: Path, role: str) -> None:
    report = _replay(talked, TALK, role, {"B": _clocked_buyer, "S": _clocked_seller}[role])
    assert report.ok and report.divergence is None
    readings = {"B": 3 * ROUNDS, "S": ROUNDS + 1}[role]  # B: now(), wall(), and each sleep's end
    assert report.clock == (readings, readings, 0)
    assert f"  clock: {readings} of {readings} recorded readings given back" in report.text().splitlines()


def test_beyond_the_recorded_readings_now_goes_on_as_message_time_does(talked: Path) -> None:
    """Past its recorded readings, now() goes on from the last one, advanced as message time
    advanced since (a received message, a sleep): the monotonic clock's origin is kept, so a
    role (or a period's monitor) that compares two readings sees the time that passed."""
    seen: list[float] = []

    def seller(ep: Endpoint) -> None:  # reads its clock more often than the seller did in the run
        seen.extend(ep.now() for _ in range(ROUNDS + 1))
        ep.recv("B")
        seen.append(ep.now())
        ep.sleep(2.0)
        seen.append(ep.now())
        ep.send("B", "quote", "0.0")

    report = _replay(talked, TALK, "S", seller)
    assert report.clock == (ROUNDS + 1, ROUNDS + 1, 3)  # the sleep's end is a reading too
    last_recorded = seen[ROUNDS]
    assert last_recorded < 1e8  # a monotonic reading (seconds since boot), not time since the epoch
    assert seen[ROUNDS + 1] - last_recorded >= 0  # the message came after: time went on, from there
    assert seen[ROUNDS + 1] - last_recorded < 60  # by the recording's own time, not by the epoch's
    assert seen[ROUNDS + 2] == pytest.approx(seen[ROUNDS + 1] + 2.0)  # the sleep, skipped, counted


def test_a_role_that_reads_its_clock_otherwise_is_told_so(talked: Path) -> None:
    def seller(ep: Endpoint) -> None:
        ep.wall()  # the run's seller read now() first
        ep.recv("B")

    report = _replay(talked, TALK, "S", seller)
    assert ("note: clock: endpoint (the role) read wall() where the run read now() (its reading 1): the role "
            "reads its clock otherwise than in the run; from there on it reads message time") in report.text()


def test_a_send_made_past_the_recorded_readings_ends_the_replay_without_a_divergence(
        talked: Path, tmp_path: Path) -> None:
    """A recorder loses the readings it could not write before its group ended: the seller's last
    reading is not in this copy of the recording, so its last quote is made of a time the replay
    does not know. That is not a divergence: the replay ends there and says what it left."""
    from mcap_rewrite import rewrite

    def drop_last_reading(messages: list[list[Any]]) -> None:
        last = max(i for i, message in enumerate(messages) if message[0][0] == "/anodize/clock/S")
        del messages[last]

    cut = tmp_path / "cut.mcap"
    rewrite(talked, cut, drop_last_reading)
    report = _replay(cut, TALK, "S", _clocked_seller)
    assert report.divergence is None and report.ok, report.text()
    assert report.outcome == "recording ends" and "past the readings the recording holds" in report.detail
    assert report.compared == {"S->B": (ROUNDS - 1, ROUNDS)}
    assert any(note.startswith("the last 1 recorded message(s) S sent are not compared") for note in report.notes)


FUSED = load_global("""
global Fused(G, C, V, M) =
  ( mu x. G -> V : { odo(int). x, done } || mu y. C -> V : { frame(int). V -> M : pose(int). y, done. V -> M : done } )
""", "Fused")
EARLY_ODOS = 3  # odometry readings V takes before its first pose; two more come long after its last


def _odometer(ep: Endpoint) -> None:
    for n in range(EARLY_ODOS):
        ep.send("V", "odo", n)
    _POSES_DONE.wait(10.0)  # the last two come after V's last pose (a run stopped then never had V take them)
    for n in range(EARLY_ODOS, EARLY_ODOS + 2):
        ep.send("V", "odo", n)
    ep.send("V", "done")


def _camera(ep: Endpoint) -> None:
    for n in range(2):
        ep.sleep(0.05)
        ep.send("V", "frame", n)
    ep.send("V", "done")


def _fuser(ep: Endpoint) -> None:
    """TinMan's VisOdom in small: one thread takes odometry (reading its clock as it does), the
    other sends, for each frame, the count of odometry readings taken by then."""
    branches = ep.fork()
    wheels = next(branch for branch in branches if "G" in branch.received)
    frames = next(branch for branch in branches if "C" in branch.received)
    taken = [0]

    def take_odometry() -> None:
        while wheels.recv("G").label == "odo":
            wheels.now()
            taken[0] += 1

    thread = threading.Thread(target=take_odometry, name="V-wheels")
    thread.start()
    while frames.recv("C").label == "frame":
        frames.now()
        time.sleep(0.1)  # the frame's work: meanwhile the odometry thread goes on, as far as it did in the run
        frames.send("M", "pose", taken[0])
    frames.send("M", "done")
    thread.join()


def _pose_receiver(ep: Endpoint) -> None:
    while ep.recv("V").label != "done":
        pass
    _POSES_DONE.set()


_POSES_DONE = threading.Event()  # M has V's last pose and its done: the odometer sends its last two (inproc)


@pytest.fixture(scope="module")
def fused(tmp_path_factory: pytest.TempPathFactory) -> Path:
    _POSES_DONE.clear()
    system = System(FUSED)
    system.group("g").role("G", _odometer)
    system.group("c").role("C", _camera)
    system.group("v").role("V", _fuser)
    system.group("m").role("M", _pose_receiver)
    path = tmp_path_factory.mktemp("fused") / "run.mcap"
    assert system.run(timeout=20.0, taps=[Recording(path)]).ok
    return path


def test_readings_the_recording_lacks_come_after_every_recorded_event_of_the_role(fused: Path, tmp_path: Path) -> None:
    """A group's recorder writes its roles' sends and clock readings in the order they happened,
    so a reading the recording lacks (the run stopped before it, or the group ended) came after
    every recorded one. Here the run stopped after V's last pose, before V's odometry thread read
    its clock for the last two readings: the replay delivers them (they were sent), and the thread
    that takes them waits until V's recorded poses have gone out, as in the run. (It ran ahead
    before, and the last poses, counting odometry V had not taken in the run, ended the replay.)"""
    from mcap_rewrite import rewrite

    dropped: list[int] = []

    def stop_after_the_last_pose(messages: list[list[Any]]) -> None:
        last_pose = max(log_time for key, log_time, *_ in messages if key[0] == "/anodize/V/M/done")
        dropped.extend(i for i, (key, log_time, *_) in enumerate(messages)
                       if key[0] == "/anodize/clock/V" and log_time > last_pose)
        for i in reversed(dropped):
            del messages[i]

    cut = tmp_path / "stopped.mcap"
    rewrite(fused, cut, stop_after_the_last_pose)
    assert len(dropped) == 2  # the odometry thread's last two readings
    report = _replay(cut, FUSED, "V", _fuser)
    assert report.divergence is None and report.ok, report.text()
    assert report.compared == {"V->M": (3, 3)}, report.text()
    assert (report.outcome, report.clock) == ("finished", (2 + EARLY_ODOS, 2 + EARLY_ODOS, 2)), report.text()
    assert not any(note.startswith(("threads:", "clock:")) for note in report.notes), report.notes


def test_an_input_the_recorder_lost_ends_the_replay_after_what_the_role_did_before_it_was_sent(
        fused: Path, tmp_path: Path) -> None:
    """A recorder that fell behind loses messages, and says so with a gap record; when the last
    messages of a channel are lost, none follows to show the break. The thread that waits for
    a lost input cannot go on, and V's threads wait for its recorded readings after it: the
    replay lets the other threads do what they did before the input was sent (V's poses), then
    ends ("recording ends"), at once (it waited ten seconds for a turn before, and let the threads
    interleave as they would)."""
    import json

    from mcap_rewrite import rewrite

    from anodize._recording.encoding import codec_for_sort
    from anodize._recording.plan import GAP_KEY, GAP_TOPIC

    def lose_the_late_odometry(messages: list[list[Any]]) -> None:
        late = [i for i, (key, _, sequence, _) in enumerate(messages)
                if key[0].startswith("/anodize/G/V/") and sequence > EARLY_ODOS]
        clock = next(key for key, *_ in messages if key[0] == "/anodize/clock/V")
        codec = codec_for_sort(None)
        gap = codec.ros.serialize(codec.ros.cls(data=json.dumps(
            {"channel": "G->V", "first": EARLY_ODOS + 1, "count": len(late)})))
        first = messages[late[0]][1]
        for i in reversed(late):
            del messages[i]
        messages.append([(GAP_TOPIC, clock[1], ((GAP_KEY, "1"),)), first, 0, gap])
        messages.sort(key=lambda message: message[1])

    cut = tmp_path / "lost.mcap"
    rewrite(fused, cut, lose_the_late_odometry)
    report = _replay(cut, FUSED, "V", _fuser)
    assert report.divergence is None and report.ok, report.text()
    assert report.compared == {"V->M": (3, 3)}, report.text()
    assert report.received["G->V"] == (EARLY_ODOS, EARLY_ODOS)
    assert report.outcome == "recording ends", report.text()
    assert "waits for message 3 on G->V, where the recording cuts the channel short" in report.detail
    assert (f"G->V: replayed up to message {EARLY_ODOS - 1}; the recording lost 3 message(s) from number "
            f"{EARLY_ODOS + 1} on (its recorder fell behind)") in report.notes
    assert not any(note.startswith("threads:") for note in report.notes), report.notes


def _two_threads(ep: Endpoint) -> None:
    """One thread counts, the other sends the count now and then: what the second sends depends
    on how the two interleaved, each reading its own branch's clock."""
    ticks, tocks = ep.fork()
    count = [0]

    def tock() -> None:
        for _ in range(ROUNDS):
            tocks.sleep(0.004)
            tocks.send("C", "tock", f"{count[0]} at {tocks.now()!r}")
        tocks.send("C", "done")

    thread = threading.Thread(target=tock, name="A-tocks")
    thread.start()
    for number in range(4 * ROUNDS):
        count[0] += 1
        ticks.send("B", "tick", str(number))
        ticks.sleep(0.001)
    ticks.send("B", "done")
    thread.join()


def _receiver(ep: Endpoint) -> None:
    while ep.recv("A").label != "done":
        pass


@pytest.fixture(scope="module")
def forked(tmp_path_factory: pytest.TempPathFactory) -> Path:
    system = System(FORKED)
    system.group("a").role("A", _two_threads)
    system.group("b").role("B", _receiver)
    system.group("c").role("C", _receiver)
    path = tmp_path_factory.mktemp("forked") / "run.mcap"
    assert system.run(timeout=20.0, taps=[Recording(path)]).ok
    return path


def test_a_role_s_threads_replay_in_their_recorded_order(forked: Path) -> None:
    # Each thread reads its own branch's readings, and the tock thread sends the count the tick
    # thread had reached in the run: the replay keeps the threads' recorded order.
    report = _replay(forked, FORKED, "A", _two_threads)
    assert report.ok and report.divergence is None
    assert report.clock == (4 * ROUNDS + 2 * ROUNDS, 4 * ROUNDS + 2 * ROUNDS, 0)
    assert not any(note.startswith("threads:") for note in report.notes)


def test_threads_that_no_longer_act_as_in_the_run_are_let_go_and_told_so(
        forked: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(turnstile, "PATIENCE", 0.5)  # a second of a test, not ten
    def one_thread(ep: Endpoint) -> None:  # all tocks before any tick: the tocks' turns never come
        ticks, tocks = ep.fork()
        tocks.send("C", "tock", "0")
        ticks.send("B", "tick", "0")

    report = _replay(forked, FORKED, "A", one_thread)
    assert any(note.startswith("threads: a thread of A (replay:A) waited 0.5 s for its recorded turn")
               for note in report.notes), report.notes


def test_the_clock_s_readings_are_no_channel_of_the_protocol(talked: Path) -> None:
    with open_recording(talked) as recording:
        topics = sorted(topic.topic for topic in recording.topics)
        report = verify(recording, TALK)
    assert "/anodize/clock/B" in topics and "/anodize/clock/S" in topics
    assert report.conforms and report.unmapped == [], report.text()


def test_a_run_recorded_inside_its_groups_replays_a_role_that_talks_inside_its_group(tmp_path: Path) -> None:
    system = System(TWO_BUYER)
    system.group("shop").role("B1", replay_roles.buyer1).role("S", replay_roles.seller)
    system.group("b2").role("B2", replay_roles.buyer2)
    path = tmp_path / "run.mcap"
    run = system.run(timeout=20.0, taps=[Recording(path, inside=True)])
    assert run.ok
    assert any("between and inside groups" in note for note in run.notes), run.notes
    report = _replay(path, TWO_BUYER, "B1", replay_roles.buyer1)
    assert (report.ok, report.outcome) == (True, "finished")
    assert report.compared == {"B1->S": (1, 1), "B1->B2": (1, 1)}


def test_a_typed_state_reads_the_clock_without_being_used() -> None:
    class Clocked:
        def now(self) -> float:
            return 1.5

        def wall(self) -> float:
            return 1.7e9

    state = State(Clocked())  # type: ignore[arg-type]  # only the clock is read
    assert (state.now(), state.wall()) == (1.5, 1.7e9)
    state._use()  # still unused: reading the clock is no action of the protocol


def test_record_inside_needs_record(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    system = tmp_path / "system.toml"
    system.write_text(f'protocol = "{ROOT / "protocols" / "two_buyer.proto"}"\nglobal = "TwoBuyer"\n'
                      f'pythonpath = ["{HERE}"]\n[groups.all]\n'
                      'roles = { B1 = "replay_roles:buyer1", B2 = "replay_roles:buyer2", S = "replay_roles:seller" }\n',
                      encoding="utf-8")
    capsys.readouterr()
    assert main(["run", str(system), "--record-inside", "--quiet"]) == 2
    assert capsys.readouterr().err.endswith("--record-inside needs --record PATH\n")
    path = tmp_path / "run.mcap"
    assert main(["run", str(system), "--record", str(path), "--record-inside", "--quiet"]) == 0
    assert "on 5 channels (6 topics) between and inside groups" in capsys.readouterr().out


def test_a_thread_s_patience_counts_from_when_it_starts_to_wait(monkeypatch: pytest.MonkeyPatch) -> None:
    """A role that computes for longer than the patience before its first wait (or between two
    turns) has not lost its order: the wait starts counting when it starts."""
    monkeypatch.setattr(turnstile, "PATIENCE", 5.0)  # far below the minute since the last turn
    gate = turnstile.Turnstile({"first": [1], "second": [2]}, active=True)
    gate._last_event -= 60.0  # the last turn was a minute ago: the role computed meanwhile
    taken: list[bool] = []  # whether the first's turn had come when the second took its own

    def second() -> None:
        gate.take("second", "A")
        taken.append(not gate._streams.get("first"))

    waiter = threading.Thread(target=second)
    waiter.start()
    time.sleep(0.1)  # the second's thread waits for the first's turn (well within its patience)
    gate.take("first", "A")
    waiter.join(timeout=10)
    assert not waiter.is_alive()
    assert gate.out_of_order == "" and taken == [True]


@pytest.mark.parametrize("value", ["NaN", "Infinity", "-Infinity", "1"])
def test_a_recorded_reading_that_no_clock_reads_is_not_given_back(value: str) -> None:
    """A recording is untrusted: JSON may say NaN or Infinity (or an integer), which no clock reads."""
    from anodize._recording.encoding import codec_for_sort
    from anodize._recording.reader import RecordedMessage, RecordedTopic
    from anodize._recording.replay import _reading

    codec = codec_for_sort(None)
    data = codec.ros.serialize(codec.ros.cls(data='{"branch": "", "now": ' + value + "}"))
    message = RecordedMessage(RecordedTopic("/anodize/clock/A", "std_msgs/msg/String"), 1, 1, data)
    readings: dict[str, list[tuple[str, float, int]]] = {}
    notes: list[str] = []
    assert _reading(message, 0, readings, notes) == -1
    assert notes and notes[0].startswith("clock: reading 1 on /anodize/clock/A does not decode (not a reading: ")
