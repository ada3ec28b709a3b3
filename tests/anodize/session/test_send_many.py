"""``Endpoint.send_many``: a batch of sends, checked one by one, handed on at once."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).parents[1]))

import send_many_roles

import sessiontypes
from anodize import Inproc, Processes, ProtocolViolationError, Recording, System
from anodize._recording.reader import open_recording
from anodize._recording.verify import verify

STREAM = sessiontypes.loads("global S(A, B) = mu t. A -> B : { num(int). t, fin }", "s.proto").globals["S"]
TWO = sessiontypes.loads("global T(A, B) = A -> B : num(int). A -> B : num(int)", "t.proto").globals["T"]


@pytest.mark.parametrize("transport", [Inproc(), Processes()], ids=["inproc", "process"])
def test_a_batch_arrives_whole_and_in_order_and_is_recorded(
        transport: Inproc | Processes, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SEND_MANY_OUT", str(tmp_path / "got.json"))
    system = System(STREAM, transport=transport)
    system.group("a").role("A", "send_many_roles:batch_sender")
    system.group("b").role("B", "send_many_roles:counting_receiver")
    report = system.run(timeout=60, taps=[Recording(tmp_path / "r.mcap")])
    assert report.ok, report.summary()
    assert json.loads((tmp_path / "got.json").read_text()) == list(range(send_many_roles.COUNT))
    assert report.messages["A->B"] == send_many_roles.COUNT + 1
    with open_recording(tmp_path / "r.mcap") as recording:
        result = verify(recording, STREAM)
    assert result.conforms and result.channels["A->B"].messages == send_many_roles.COUNT + 1


def _run_inproc(sender: Any, global_type: sessiontypes.GlobalType) -> tuple[Any, list[object]]:
    got: list[object] = []

    def receiver(ep: Any) -> None:
        while True:
            got.append(ep.recv("A").payload)

    system = System(global_type)
    system.group("a").role("A", sender)
    system.group("b").role("B", receiver)
    return system.run(timeout=5), got


def test_what_the_local_type_allows_is_sent_then_the_refused_send_is_the_senders_violation() -> None:
    def sender(ep: Any) -> None:
        ep.send_many("B", "num", [1, 2, 3])  # the type allows two

    report, got = _run_inproc(sender, TWO)
    assert got == [1, 2]
    error = report.roles["A"].error
    assert isinstance(error, ProtocolViolationError) and error.blame == "A"


def test_a_payload_of_the_wrong_sort_in_a_batch_stops_it_there() -> None:
    def sender(ep: Any) -> None:
        ep.send_many("B", "num", [1, "two", 3])

    report, got = _run_inproc(sender, TWO)
    assert got == [1]
    error = report.roles["A"].error
    assert isinstance(error, ProtocolViolationError) and error.blame == "A" and "int" in str(error)


FLOATS = sessiontypes.loads("global F(A, B) = mu t. A -> B : { num(float). t, fin }", "f.proto").globals["F"]


@pytest.mark.parametrize(("global_type", "sender"), [(STREAM, "batch_sender"), (FLOATS, "mixed_sender")])
def test_recv_many_takes_what_has_arrived_in_order_and_leaves_what_needs_a_full_check(
        global_type: sessiontypes.GlobalType, sender: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SEND_MANY_OUT", str(tmp_path / "got.json"))
    system = System(global_type, transport=Processes())
    system.group("a").role("A", f"send_many_roles:{sender}")
    system.group("b").role("B", "send_many_roles:batch_receiver")
    report = system.run(timeout=60)
    assert report.ok, report.summary()
    result = json.loads((tmp_path / "got.json").read_text())
    expected = [float(i) if i % 3 and sender == "mixed_sender" else i for i in range(send_many_roles.COUNT)]
    assert result["got"] == expected
    assert [type(v).__name__ for v in result["got"][:3]] == [type(v).__name__ for v in expected[:3]]
    assert result["batches"] < send_many_roles.COUNT  # some batches held several messages
    assert report.received["A->B"] == send_many_roles.COUNT + 1


def test_recv_many_refuses_a_limit_below_one() -> None:
    def sender(ep: Any) -> None:
        ep.send("B", "num", 1)

    def receiver(ep: Any) -> None:
        ep.recv_many("A", limit=0)

    system = System(TWO)
    system.group("a").role("A", sender)
    system.group("b").role("B", receiver)
    report = system.run(timeout=5)
    assert isinstance(report.roles["B"].error, ValueError)


FRAMES = sessiontypes.loads('type Array = "numpy:ndarray"\nglobal F(A, B) = mu t. A -> B : { frame(Array). t, fin }',
                            "f.proto").globals["F"]
STRINGS = sessiontypes.loads("global S(A, B) = mu t. A -> B : { s(str). t, fin }", "s.proto").globals["S"]


def test_a_batch_of_more_arrays_than_the_ring_has_slots_goes_through(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SEND_MANY_OUT", str(tmp_path / "got.json"))
    system = System(FRAMES, transport=Processes())
    system.group("a").role("A", "send_many_roles:array_batch_sender")
    system.group("b").role("B", "send_many_roles:array_receiver")
    report = system.run(timeout=60)
    assert report.ok, report.summary()
    assert json.loads((tmp_path / "got.json").read_text()) == [float(i) for i in range(send_many_roles.ARRAYS)]


def test_what_a_failed_batch_did_send_is_counted_and_recorded(tmp_path: Path) -> None:
    system = System(STRINGS, transport=Processes())
    system.group("a").role("A", "send_many_roles:too_big_in_the_middle")
    system.group("b").role("B", "send_many_roles:string_receiver")
    report = system.run(timeout=60, taps=[Recording(tmp_path / "r.mcap")])
    assert report.roles["A"].status == "failed" and "cannot send s to B" in str(report.roles["A"].error)
    assert report.messages["A->B"] == 2
    with open_recording(tmp_path / "r.mcap") as recording:
        assert verify(recording, STRINGS).channels["A->B"].messages == 2


def test_a_batch_that_reaches_a_parallel_composition_goes_on_in_its_branch() -> None:
    forked = sessiontypes.loads("global G(A, B, C) = A -> B : n(int). (A -> B : n(int) || A -> C : m(int))",
                                "g.proto").globals["G"]
    got: list[object] = []

    def a(ep: Any) -> None:
        assert ep.send_many("B", "n", [1, 2]) == 2
        ep.send("C", "m", 3)

    def b(ep: Any) -> None:
        got.extend(ep.recv("A").payload for _ in range(2))

    def c(ep: Any) -> None:
        got.append(ep.recv("A").payload)

    system = System(forked)
    system.group("a").role("A", a)
    system.group("b").role("B", b).role("C", c)
    report = system.run(timeout=10)
    assert report.ok, report.summary()
    assert sorted(got) == [1, 2, 3]
