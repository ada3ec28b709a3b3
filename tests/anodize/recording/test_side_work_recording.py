"""Recording on a slow disk: the senders never wait for it, and what it cannot write is a gap.

The disk is a file whose every write sleeps (through :func:`anodize._recording.tap.open_part`,
the seam for it): the recorder's queue fills, the senders go on, the messages it could not
take keep their numbers and are marked on the gap channel, ``anodize verify`` reports the
gap as the recording's (the recording still conforms), and the run's report counts what
was lost. Every wait is bounded; nothing here asserts a duration.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path
from typing import IO, Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from role_drivers import load_global, machines_of

from anodize import Recording, System
from anodize._isolation.sched import SIDE_WORK_BELOW
from anodize._recording import tap as recording_tap
from anodize._recording.merge import merge_parts
from anodize._recording.plan import record_plan
from anodize._recording.reader import open_recording
from anodize._recording.verify import _after_any, _ChannelCheck, verify

TEXTS = """
global Texts(Talker, Listener) = mu t. Talker -> Listener : { text(str). t, stop }
"""
PAIR = ("Talker", "Listener")
TEXT = "x" * 10_000  # 10 kB a message: a 1 MiB backlog holds about a hundred


class SlowFile:
    """A part file on a disk that takes ``delay`` seconds for every write."""

    def __init__(self, path: Path, delay: float) -> None:
        self._file = path.open("wb")
        self._delay = delay

    def write(self, data: Any) -> int:
        time.sleep(self._delay)
        return self._file.write(data)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._file, name)


def _slow(delay: float) -> Any:
    def opener(path: Path) -> IO[bytes]:
        return SlowFile(path, delay)  # type: ignore[return-value]
    return opener


def test_a_recorder_on_a_slow_disk_never_blocks_its_sender_and_marks_the_gap(tmp_path: Path) -> None:
    global_type = load_global(TEXTS, "Texts")
    machines = machines_of(global_type)
    plan = record_plan(str(tmp_path / "parts"), machines, {"Talker": "t", "Listener": "l"}, {})
    # A memory bound of 8 MiB gives a backlog of 1 MiB (an eighth, at least 1 MiB).
    recorder = recording_tap.Recorder(plan, "t", 0, "Texts", {"Talker": machines["Talker"]}, memory=8 * 2**20,
                                      opener=_slow(0.002))
    sent = 3000
    done = threading.Event()

    def send_a_lot() -> None:
        for _ in range(sent):
            encoded = recorder.encode(PAIR, "text", TEXT)
            assert encoded is not None
            recorder.queue(PAIR, encoded)
        encoded = recorder.encode(PAIR, "stop", None)
        assert encoded is not None
        recorder.queue(PAIR, encoded)
        done.set()

    threading.Thread(target=send_a_lot, daemon=True).start()
    assert done.wait(30), "a sender waited for the recording's slow disk"
    assert recorder._pending_bytes <= recorder.backlog  # bounded memory
    recorder.close(within=1.0)
    lost = recorder.lost[PAIR]
    assert 0 < lost <= sent + 1
    base = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())  # this thread's: the writer's creator
    assert recorder.priority == f"nice {min(19, base + SIDE_WORK_BELOW)}"  # not real time: just below its group

    result = merge_parts(tmp_path / "parts", tmp_path / "r.mcap", {"global": "Texts"})
    assert any("a gap on /anodize/recording/gaps" in note and note.startswith(f"Talker->Listener: {lost} ")
               for note in result.notes), result.notes
    with open_recording(tmp_path / "r.mcap") as recording:
        report = verify(recording, global_type)
    assert report.conforms, report.text()  # a gap is the recording's, not a role's violation
    assert sum(gap.count for gap in report.gaps) == lost
    assert {gap.channel for gap in report.gaps} == {"Talker->Listener"}
    assert report.channels["Talker->Listener"].messages == sent + 1 - lost
    assert "gap: channel Talker->Listener: " in report.text()


def test_a_skip_no_gap_record_explains_is_still_the_recordings_fault() -> None:
    check = _ChannelCheck("Talker", "Listener", machines_of(load_global(TEXTS, "Texts")))
    assert check._numbering(1) == ""
    check.gaps[2] = 3  # numbers 2, 3, 4 marked as not recorded
    assert check._numbering(5) == ""
    assert "missing" in check._numbering(7)  # 6 is missing and no gap says so


def test_after_a_gap_the_check_goes_on_from_where_the_missing_messages_could_lead() -> None:
    machines = machines_of(load_global("global G(A, B) = A -> B : one. A -> B : two. A -> B : three", "G"))
    check = _ChannelCheck("A", "B", machines)
    view = check.views[0]
    after_two = _after_any(view, view.start, 2)
    assert [t.label for t in view.allowed(after_two)] == ["three"]
    assert _after_any(view, view.start, 5) == frozenset()  # past the end: nothing may follow
    loop = machines_of(load_global(TEXTS, "Texts"))
    looped = _ChannelCheck("Talker", "Listener", loop).views[0]
    assert {t.label for t in looped.allowed(_after_any(looped, looped.start, 10**9))} == {"stop", "text"}


def test_a_run_recording_to_a_slow_disk_ends_and_its_report_counts_the_gap(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(recording_tap, "open_part", _slow(0.002))
    global_type = load_global(TEXTS, "Texts")
    sent = 2000

    def talker(ep: Any) -> None:
        for _ in range(sent):
            ep.send("Listener", "text", TEXT)
        ep.send("Listener", "stop")

    def listener(ep: Any) -> None:
        while ep.recv("Talker")[0] != "stop":
            pass

    system = System(global_type)
    system.group("talk", memory=8 * 2**20).role("Talker", talker)
    system.group("listen").role("Listener", listener)
    report = system.run(timeout=60, taps=[Recording(tmp_path / "r.mcap")])
    assert report.ok, report.summary()
    lost = [n for n in report.notes if "Talker->Listener: " in n and "a gap on /anodize/recording/gaps" in n]
    assert lost, report.notes
    below = min(19, os.getpriority(os.PRIO_PROCESS, 0) + SIDE_WORK_BELOW)  # the groups have this process's nice
    assert f"recording: the groups' writers ran at nice {below} (listen-0, talk-0)" in report.notes  # reported
    with open_recording(tmp_path / "r.mcap") as recording:
        result = verify(recording, global_type)
    assert result.conforms, result.text()
    assert result.gaps and result.channels["Talker->Listener"].messages + sum(g.count for g in result.gaps) == sent + 1


def test_side_work_runs_just_below_its_group_and_side_work_it_starts_no_lower() -> None:
    from anodize._isolation.sched import apply_thread_scheduling, side_work_priority, start_side_work_thread

    seen: dict[str, tuple[str, str, int, int, int]] = {}

    def observe(name: str) -> None:
        described = side_work_priority()
        assert side_work_priority() == described  # a second call changes nothing
        seen[name] = ("", described, os.sched_getscheduler(0), os.sched_getparam(0).sched_priority,
                      os.getpriority(os.PRIO_PROCESS, threading.get_native_id()))

    def helper(name: str, group_priority: int | None, nice: int | None = None) -> None:
        group = apply_thread_scheduling(group_priority, nice=nice)  # as a group's process does
        observe(name)
        seen[name] = (group, *seen[name][1:])
        started = start_side_work_thread(observe, "side work's", (f"{name}, started by its side work",))
        started.join(10)  # it inherits the side work's scheduling, and keeps it

    base = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    cases: list[tuple[str, int | None, int | None]] = [("plain", None, None), ("real-time", 80, None),
                                                        ("nice 17", None, 17)]
    if base > -10 and os.geteuid() == 0:  # a nice below 0 needs the privilege to raise priorities
        cases.append(("nice -10", None, -10))
    for name, priority, nice in cases:
        thread = threading.Thread(target=helper, args=(name, priority, nice))
        thread.start()
        thread.join(10)
    for name, group_nice in (("plain", base), ("nice 17", 17), ("nice -10", -10)):
        if name not in seen:
            continue
        below = min(19, group_nice + SIDE_WORK_BELOW)  # 5 steps below its group, at most the weakest
        for who in (name, f"{name}, started by its side work"):
            _, described, policy, _, nice = seen[who]
            assert (described, policy, nice) == (f"nice {below}", os.SCHED_OTHER, below), who
    group, described, policy, rt, nice = seen["real-time"]
    if group == "SCHED_FIFO 80":  # permitted here: the lowest real-time priority, below the group
        assert (described, policy, rt) == ("SCHED_FIFO 1", os.SCHED_FIFO, 1)
        assert seen["real-time, started by its side work"][1:4] == ("SCHED_FIFO 1", os.SCHED_FIFO, 1)
    else:  # the group got a nice value instead: its side work goes just below that
        assert policy == os.SCHED_OTHER and described == f"nice {nice}", seen["real-time"]


def test_clock_readings_the_writer_could_not_take_are_said_in_the_runs_notes(tmp_path: Path) -> None:
    """A role's clock readings share the writer's backlog with its messages: those it could not take
    leave the replay on message time from the first, and the run's notes say so."""
    global_type = load_global(TEXTS, "Texts")
    machines = machines_of(global_type)
    plan = record_plan(str(tmp_path / "parts"), machines, {"Talker": "t", "Listener": "l"}, {})
    recorder = recording_tap.Recorder(plan, "t", 0, "Texts", {"Talker": machines["Talker"]}, memory=8 * 2**20)
    recorder.reading("Talker", "", "now", 1.0)
    recorder._pending_bytes = recorder.backlog  # the backlog is full (images, say): no room for a reading
    for _ in range(3):
        recorder.reading("Talker", "", "now", 2.0)
    recorder._pending_bytes = 0
    recorder.close(within=5.0)
    assert recorder.clock_lost == {"Talker": 3}
    result = merge_parts(tmp_path / "parts", tmp_path / "r.mcap", {"global": "Texts"})
    assert ("clock of Talker: 3 clock readings not recorded (the writer was behind): a replay of Talker follows "
            "message time from the first") in result.notes, result.notes
