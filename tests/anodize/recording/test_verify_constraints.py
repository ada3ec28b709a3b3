"""``anodize verify`` judges a protocol's time and value constraints on a recording.

The constrained machines are made here by giving transitions their constraints (the
front end that parses them is written in parallel): ``tick`` every 200 ms +- 20 ms with
``abs(v) <= 1.5``, ``pose`` within 100 ms, ``ack`` with ``n == seq`` (``seq`` from the
earlier ``tick`` the receiver of ``tick`` saw). Recordings are written as anodize writes
them: one MCAP channel per label, anodize's metadata, JSON payloads, numbered messages.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from budget import examples
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st
from role_drivers import load_global, machines_of

from anodize import Recording, System
from anodize._recording.encoding import codec_for_sort
from anodize._recording.plan import META, ChannelLabel
from anodize._recording.reader import open_recording
from anodize._recording.tap import channel_metadata
from anodize._recording.verify import VerifyReport, Violation, verify
from sessiontypes import StateMachine
from sessiontypes.constraints import Call, Compare, Expr, Number, Timing
from sessiontypes.constraints import Path as Name
from sessiontypes.location import Location

LOOP = """
global Loop(C, M, O) =
  mu t. C -> M : tick(v: float, seq: int). C -> O : go. O -> M : pose(x: float). M -> C : ack(n: int). t
"""
MS = 1_000_000
BASE = 1_800_000_000 * 10**9  # log times: ns since the epoch
PERIOD = Timing(every=200 * MS, jitter=20 * MS, location=Location("loop.proto", 3, 40))
DEADLINE = Timing(within=100 * MS, location=Location("loop.proto", 3, 80))
SPEED = Compare(("<=",), (Call("abs", (Name(("v",)),)), Number(1.5)), Location("loop.proto", 3, 30))
ECHO = Compare(("==",), (Name(("n",)), Name(("seq",))), Location("loop.proto", 3, 95))


def _constrain(machines: dict[str, StateMachine], label: str, timing: Timing | None = None,
               refinement: Expr | None = None) -> None:
    """Give every transition of ``label`` (sender's and receiver's) these constraints, in place."""
    for machine in machines.values():
        for row in machine.table:
            for key, t in row.items():
                if t.label == label:
                    row[key] = replace(t, timing=timing, refinement=refinement)


def _machines(deadline: Timing = DEADLINE) -> dict[str, StateMachine]:
    machines = machines_of(load_global(LOOP, "Loop"))
    _constrain(machines, "tick", PERIOD, SPEED)
    _constrain(machines, "pose", deadline)
    _constrain(machines, "ack", None, ECHO)
    return machines


Message = tuple[str, str, str, int, object]  # sender, receiver, label, log time, payload


def _rounds(count: int) -> list[Message]:
    """``count`` conforming rounds: tick, go, pose, ack, 200 ms apart."""
    found: list[Message] = []
    for i in range(count):
        at = BASE + i * 200 * MS
        found += [("C", "M", "tick", at, {"v": 0.5, "seq": i}), ("C", "O", "go", at + 1 * MS, None),
                  ("O", "M", "pose", at + 10 * MS, {"x": float(i)}), ("M", "C", "ack", at + 12 * MS, {"n": i})]
    return found


def _retime(messages: list[Message], label: str, index: int, at: int, payload: object = "same") -> None:
    """Move the ``index``-th message of ``label`` to log time ``at`` (and give it ``payload``)."""
    spots = [i for i, m in enumerate(messages) if m[2] == label]
    s, r, lab, _, old = messages[spots[index]]
    messages[spots[index]] = (s, r, lab, at, old if payload == "same" else payload)


def _record(path: Path, messages: list[Message], external: frozenset[str] = frozenset()) -> Path:
    """An MCAP file as anodize records: per label a channel with anodize's metadata, JSON payloads."""
    from mcap.writer import Writer

    codec = codec_for_sort(None)
    groups = {role: role.lower() for role in ("C", "M", "O") if role not in external}
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema(codec.type_name, "ros2msg", codec.ros.message_definition().encode())
        channels: dict[tuple[str, str, str], int] = {}
        numbers: dict[tuple[str, str], int] = {}
        for sender, receiver, label, at, payload in sorted(messages, key=lambda m: m[3]):
            key = (sender, receiver, label)
            if key not in channels:
                metadata = channel_metadata(ChannelLabel(sender, receiver, label, None), codec, "Loop", groups)
                channels[key] = writer.register_channel(f"/anodize/{sender}/{receiver}/{label}", "cdr", schema,
                                                        metadata)
            number = numbers[sender, receiver] = numbers.get((sender, receiver), 0) + 1
            writer.add_message(channels[key], at, codec.encode(payload), at, number)
        writer.add_metadata(META, {"recorded_channels": "C->M C->O O->M M->C"})
        writer.finish()
    return path


def _verify(tmp_path: Path, messages: list[Message], deadline: Timing = DEADLINE,
            external: frozenset[str] = frozenset()) -> VerifyReport:
    with open_recording(_record(tmp_path / "run.mcap", messages, external)) as recording:
        return verify(recording, load_global(LOOP, "Loop"), machines=_machines(deadline))


def _only_violation(report: VerifyReport, channel: str) -> Violation:
    assert not report.conforms
    broken = {name: r.violation for name, r in report.channels.items() if r.violation is not None}
    assert list(broken) == [channel], report.text()
    return broken[channel]


def test_a_recording_that_keeps_every_constraint_conforms(tmp_path: Path) -> None:
    report = _verify(tmp_path, _rounds(5))
    assert report.conforms, report.text()
    assert {name: r.messages for name, r in report.channels.items()} == {
        "C->M": 5, "C->O": 5, "M->C": 5, "O->M": 5}
    assert [line for line in report.text().splitlines() if line.startswith("constraint: ")] == [
        "constraint: C->M tick every 200ms +- 20ms: held on 4 message(s), 200.000 ms to 200.000 ms apart",
        "constraint: C->M tick {abs(v) <= 1.5}: held on 5 message(s)",
        "constraint: M->C ack {n == seq}: held on 5 message(s)",
        "constraint: O->M pose within 100ms: held on 5 message(s), at most 10.000 ms after the previous action"]


def test_a_message_that_reached_its_receiver_late_is_blamed_on_its_sender(tmp_path: Path) -> None:
    messages = _rounds(4)
    _retime(messages, "go", 2, BASE + 400 * MS + 50 * MS)     # O's previous action: 70 ms before its pose
    _retime(messages, "pose", 2, BASE + 400 * MS + 120 * MS)  # M's: the tick, 120 ms before: 20 ms late
    _retime(messages, "ack", 2, BASE + 400 * MS + 125 * MS)
    violation = _only_violation(_verify(tmp_path, messages), "O->M")
    assert (violation.index, violation.blamed, violation.role, violation.kind) == (2, "O", "M", "deadline")
    assert violation.late == 20 * MS and violation.log_time == BASE + 520 * MS
    assert violation.location == "loop.proto:3:80"
    assert violation.reason == ("deadline missed: it reached M 120.000 ms after M's previous action, later than "
                                "within 100.000 ms")


def test_a_message_its_sender_sent_late_is_blamed_on_its_sender_at_the_sender(tmp_path: Path) -> None:
    messages = _rounds(4)
    _retime(messages, "pose", 1, BASE + 200 * MS + 151 * MS)  # 150 ms after O received go
    _retime(messages, "ack", 1, BASE + 200 * MS + 155 * MS)
    violation = _only_violation(_verify(tmp_path, messages), "O->M")
    assert (violation.index, violation.blamed, violation.role, violation.kind) == (1, "O", "O", "deadline")
    assert violation.late == 50 * MS
    assert violation.reason == ("deadline missed: sent 150.000 ms after O's previous action, later than "
                                "within 100.000 ms")


def test_with_else_timeout_a_late_message_is_nobodys_fault(tmp_path: Path) -> None:
    messages = _rounds(4)
    _retime(messages, "pose", 1, BASE + 200 * MS + 151 * MS)
    _retime(messages, "ack", 1, BASE + 200 * MS + 155 * MS)
    report = _verify(tmp_path, messages, deadline=replace(DEADLINE, on_expiry=True))
    assert report.conforms, report.text()
    assert ("constraint: O->M pose within 100ms else timeout: not judged (a late message was a timeout the "
            "recording does not show: nobody's fault)") in report.text().splitlines()


@pytest.mark.parametrize(("shift", "side", "off"), [(-30, "early", 10), (35, "late", 15)])
def test_a_period_broken_early_or_late_is_blamed_on_the_sender(tmp_path: Path, shift: int, side: str,
                                                               off: int) -> None:
    at = BASE + 600 * MS + shift * MS
    messages = [(s, r, label, t + shift * MS if t >= BASE + 600 * MS else t, p)  # rounds 3 and 4 move
                for s, r, label, t, p in _rounds(5)]
    violation = _only_violation(_verify(tmp_path, messages), "C->M")
    assert (violation.index, violation.blamed, violation.role, violation.kind) == (3, "C", "C", "period")
    assert violation.late == off * MS and violation.log_time == at
    assert violation.location == "loop.proto:3:40"
    assert violation.reason == (f"period missed: sent {200 + shift}.000 ms after the interaction's previous send, "
                                f"{off}.000 ms too {side} for every 200ms +- 20ms")


def test_a_period_is_not_judged_on_the_log_times_of_an_external_senders_channel(tmp_path: Path) -> None:
    messages = _rounds(5)
    _retime(messages, "tick", 3, BASE + 570 * MS)  # what the receiver took when: not the sender's pace
    assert _verify(tmp_path, messages, external=frozenset({"C"})).conforms
    assert _only_violation(_verify(tmp_path, messages), "C->M").kind == "period"  # the sender's own log times


def test_a_payload_out_of_range_is_blamed_on_its_sender_with_the_refinement(tmp_path: Path) -> None:
    messages = _rounds(4)
    _retime(messages, "tick", 2, BASE + 400 * MS, {"v": -2.0, "seq": 2})
    violation = _only_violation(_verify(tmp_path, messages), "C->M")
    assert (violation.index, violation.blamed, violation.kind) == (2, "C", "refinement")
    assert violation.location == "loop.proto:3:30"
    assert violation.reason == "refinement {abs(v) <= 1.5} is false for tick {'v': -2.0, 'seq': 2}"


def test_a_name_of_an_earlier_payload_is_its_latest_value_in_log_time_order(tmp_path: Path) -> None:
    messages = _rounds(4)
    _retime(messages, "ack", 1, BASE + 212 * MS, {"n": 0})  # the latest seq M saw is 1
    violation = _only_violation(_verify(tmp_path, messages), "M->C")
    assert (violation.index, violation.blamed, violation.kind) == (1, "M", "refinement")
    assert "refinement {n == seq} is false" in violation.reason


def test_the_report_shows_a_constraint_violation_in_text_and_json(tmp_path: Path) -> None:
    messages = _rounds(3)
    _retime(messages, "tick", 1, BASE + 200 * MS, {"v": 9.0, "seq": 1})
    report = _verify(tmp_path, messages)
    text = report.text()
    assert "violation: channel C->M, message 1 (log time " in text
    assert "refinement {abs(v) <= 1.5} is false" in text and "blamed: C; see loop.proto:3:30" in text
    data = json.loads(json.dumps(report.to_dict()))
    found = data["channels"]["C->M"]["violation"]
    assert (found["index"], found["blamed"], found["kind"], found["location"]) == (1, "C", "refinement",
                                                                                  "loop.proto:3:30")
    held = {(c["channel"], c["constraint"]): c for c in data["constraints"]}
    assert held["C->M", "{abs(v) <= 1.5}"]["judged"] == 1  # up to the violation
    assert (held["C->M", "every 200ms +- 20ms"]["least"], held["C->M", "every 200ms +- 20ms"]["most"]) == (
        None, None)  # the second tick broke the refinement: no period was judged


def test_deadlines_of_a_role_with_a_channel_not_recorded_are_not_judged_and_the_report_says_so(
        tmp_path: Path) -> None:
    messages = [m for m in _rounds(4) if m[2] != "go"]  # C->O not in the recording: O's previous action unknown
    _retime(messages, "pose", 1, BASE + 200 * MS + 60 * MS)
    path = _record(tmp_path / "run.mcap", messages)
    with open_recording(path) as recording:
        recording.info["recorded_channels"] = "C->M O->M M->C"
        report = verify(recording, load_global(LOOP, "Loop"), machines=_machines())
    assert report.channels["O->M"].violation is None
    assert any(note.startswith("deadlines of O not judged: its channel(s) C->O are not in the recording")
               for note in report.notes), report.notes


# ---- against an executable reference of the written semantics ------------------------------

def _reference(messages: list[Message]) -> dict[str, tuple[int, str, str]]:
    """Per channel, its first violation (index, kind, role) by docs/recording.md's reading of
    the constraints, written directly for Loop: every channel recorded, one machine per role."""
    previous: dict[str, int] = {}
    seen_seq: dict[str, object] = {}
    last_tick: int | None = None
    counts: dict[str, int] = {}
    found: dict[str, tuple[int, str, str]] = {}
    for sender, receiver, label, at, payload in sorted(messages, key=lambda m: m[3]):
        channel = f"{sender}->{receiver}"
        index = counts[channel] = counts.get(channel, 0) + 1
        if channel not in found:
            broken: tuple[str, str] | None = None
            if label == "tick":
                assert isinstance(payload, dict)
                if abs(payload["v"]) > 1.5:
                    broken = ("refinement", sender)
                elif last_tick is not None and not 180 * MS <= at - last_tick <= 220 * MS:
                    broken = ("period", sender)
                else:
                    last_tick = at
            elif label == "pose":
                for role in (sender, receiver):  # the sender's deadline first, then the receiver's
                    if role in previous and at - previous[role] > 100 * MS:
                        broken = ("deadline", role)
                        break
            elif label == "ack":
                assert isinstance(payload, dict)
                if "seq" not in seen_seq or payload["n"] != seen_seq["seq"]:
                    broken = ("refinement", sender)
            if broken is not None:
                found[channel] = (index - 1, *broken)
        for role in (sender, receiver):
            previous[role] = at
            if isinstance(payload, dict):
                seen_seq.update({k: v for k, v in payload.items() if k == "seq"} if role == "M" else {})
    return found


@settings(deadline=None, max_examples=examples(25), suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rounds=st.lists(st.tuples(st.integers(150, 250), st.integers(0, 120), st.integers(0, 150),
                                 st.floats(-1.8, 1.8, allow_nan=False), st.integers(-1, 1)),
                       min_size=1, max_size=6))
def test_verify_finds_what_the_written_semantics_find(tmp_path_factory: pytest.TempPathFactory,
                                                      rounds: list[tuple[int, int, int, float, int]]) -> None:
    messages: list[Message] = []
    at = BASE
    for seq, (gap, go, pose, v, off) in enumerate(rounds):
        at += gap * MS if seq else 0
        messages += [("C", "M", "tick", at, {"v": v, "seq": seq}), ("C", "O", "go", at + go * MS + 1, None),
                     ("O", "M", "pose", at + go * MS + pose * MS + 2, {"x": 0.0}),
                     ("M", "C", "ack", at + go * MS + pose * MS + 3, {"n": seq + off})]
        at = max(at, messages[-1][3] - gap * MS + 4)  # the next tick comes after this round's ack
    path = tmp_path_factory.mktemp("rec")
    report = _verify(path, messages)
    found = {name: (r.violation.index, r.violation.kind, r.violation.role)
             for name, r in report.channels.items() if r.violation is not None}
    note(report.text())
    assert found == _reference(messages)


# ---- on a recording of a real run ------------------------------------------------------------

COUNT = """
global Count(A, B) =
  mu t. A -> B : { num(n: int). B -> A : ok. t, stop. end }
"""


def _count_a(ep: Any) -> None:
    for n in range(5):
        ep.send("B", "num", {"n": n})
        ep.recv("B")
    ep.send("B", "stop")


def _count_b(ep: Any) -> None:
    while ep.recv("A").label == "num":
        ep.send("A", "ok")


@pytest.fixture(scope="module")
def counted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recording of Count run by anodize, A and B in groups of their own."""
    path = tmp_path_factory.mktemp("count") / "run.mcap"
    system = System(load_global(COUNT, "Count"))
    system.group("a").role("A", _count_a)
    system.group("b").role("B", _count_b)
    report = system.run(timeout=20, taps=[Recording(path)])
    assert report.ok, report.summary()
    return path


def _verify_count(path: Path, timing: Timing | None = None, refinement: Expr | None = None) -> VerifyReport:
    global_type = load_global(COUNT, "Count")
    machines = machines_of(global_type)
    _constrain(machines, "num", timing, refinement)
    with open_recording(path) as recording:
        return verify(recording, global_type, machines=machines)


def test_a_recorded_run_that_keeps_its_constraints_conforms(counted: Path) -> None:
    report = _verify_count(counted, Timing(within=60 * 10**9), Compare((">=",), (Name(("n",)), Number(0))))
    assert report.conforms, report.text()
    held = {held.constraint: held for held in report.constraints}
    assert (held["within 60s"].judged, held["{n >= 0}"].judged) == (4, 5)  # the first num: no previous action


def test_a_recorded_run_out_of_range_or_too_fast_is_blamed_on_its_sender(counted: Path) -> None:
    violation = _only_violation(_verify_count(counted, refinement=Compare(("<=",), (Name(("n",)), Number(2)))), "A->B")
    assert (violation.index, violation.blamed, violation.kind) == (3, "A", "refinement")
    assert violation.reason == "refinement {n <= 2} is false for num {'n': 3}"
    # Each num follows the previous one's ok at once: far sooner than a period of 60 s +- 1 s allows.
    violation = _only_violation(_verify_count(counted, Timing(every=60 * 10**9, jitter=10**9)), "A->B")
    assert (violation.index, violation.blamed, violation.kind) == (1, "A", "period")
    assert "too early for every 60s +- 1s" in violation.reason
