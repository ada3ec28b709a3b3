"""``Endpoint.send_many``: a batch of sends, checked one by one, handed on at once."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).parent))

import send_many_roles

import sessiontypes
from anodize import ProtocolViolationError, System
from anodize.recording.reader import open_recording
from anodize.recording.verify import verify

STREAM = sessiontypes.loads("global S(A, B) = mu t. A -> B : { num(int). t, fin }", "s.proto").globals["S"]
TWO = sessiontypes.loads("global T(A, B) = A -> B : num(int). A -> B : num(int)", "t.proto").globals["T"]


@pytest.mark.parametrize("transport", ["inproc", "process"])
def test_a_batch_arrives_whole_and_in_order_and_is_recorded(
        transport: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SEND_MANY_OUT", str(tmp_path / "got.json"))
    system = System(STREAM, transport=transport)
    system.group("a").role("A", "send_many_roles:batch_sender")
    system.group("b").role("B", "send_many_roles:counting_receiver")
    report = system.run(timeout=60, record=tmp_path / "r.mcap")
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
