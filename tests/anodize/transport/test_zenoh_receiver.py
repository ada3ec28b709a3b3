"""A Zenoh receiver's handling of what the network sends it, without processes: one session of its own
(peer mode, scouting off, nothing to connect to), samples handed to it as Zenoh's thread would."""

from __future__ import annotations

import ast
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from queue import Empty

import pytest

from anodize._session.channel import STOP, PeerFailure
from anodize._transport.codec import Codec
from anodize._transport.zenoh import ZenohSettings
from anodize._transport.zenoh.flow import WINDOW
from anodize._transport.zenoh.identity import HEADER, Claim, attachment, claim_of, parse_attachment

pytest.importorskip("zenoh", reason="the zenoh extra is not installed")

from anodize._transport.zenoh.receiver import ZenohReceiver
from anodize._transport.zenoh.session import GroupSession

ROOT = Path(__file__).resolve().parents[3]
WRITER = b"\x07" * 8


@dataclass
class Bytes:
    data: bytes

    def to_bytes(self) -> bytes:
        return self.data


@dataclass
class Sample:
    """What the receiver reads of a Zenoh sample: its payload and attachment."""

    payload: Bytes
    attachment: Bytes | None


@dataclass
class Network:
    failed: dict[str, str] = field(default_factory=dict)
    stopping: bool = False
    capacities: dict[tuple[str, str], int] = field(default_factory=dict)

    def note_failed(self, role: str, cause: str) -> None:
        self.failed.setdefault(role, cause)

    def wait_for_cause(self, role: str, default: str) -> str | None:
        return self.failed.get(role, default)


@pytest.fixture(scope="module")
def group() -> Iterator[GroupSession]:
    settings = ZenohSettings(mode="peer", run_id="unit", host="here", group_of={"P": "p", "C": "c"},
                             host_of={"p": "here", "c": "here"}, scouting=False, token="unit_token")
    session = GroupSession(settings, "c", 0)
    yield session
    session.close()


@pytest.fixture
def receiver(group: GroupSession) -> Iterator[ZenohReceiver]:
    lines: list[str] = []
    group.report = lines.append
    channel = ZenohReceiver(group, Codec(), Network(), "P", "C")
    channel.writer_id = WRITER  # as the start barrier chooses it
    channel.lines = lines  # type: ignore[attr-defined]
    yield channel
    channel.close()


def sample(number: int, frame: bytes, writer: bytes = WRITER, claim: bytes = b"anodize1;x") -> Sample:
    return Sample(Bytes(frame), Bytes(HEADER.pack(number, writer) + claim))


def test_samples_are_handed_on_in_order_once_whatever_order_they_arrive_in(receiver: ZenohReceiver) -> None:
    frames = [Codec().message_frame("data", i) for i in range(5)]
    for number in (0, 2, 1, 0, 1, 2, 3, 4, 4):  # a gap, duplicates
        receiver._on_sample(sample(number, frames[number]))
    got = [receiver.get(timeout=1) for _ in range(receiver.qsize())]
    # The first 2 came before 1: a gap, dropped (the sender sends it again); duplicates dropped.
    assert got == [("data", 0), ("data", 1), ("data", 2), ("data", 3), ("data", 4)]
    assert (receiver.duplicates, receiver.gaps) == (3, 1)


def test_what_the_network_makes_up_is_dropped_counted_and_named_never_queued(receiver: ZenohReceiver) -> None:
    frame = Codec().message_frame("data", 1)
    for forged in (Sample(Bytes(frame), None), Sample(Bytes(frame), Bytes(b"short")),
                   sample(0, frame, writer=b"\x01" * 8, claim=b"anodize1;intruder"),
                   sample(2**64 - 1, frame), *(sample(0, frame, writer=bytes([100 + i]) * 8) for i in range(20))):
        receiver._on_sample(forged)
    assert receiver.qsize() == 0 and receiver.received == 0
    assert sum(receiver.rejected.values()) == 23 and len(receiver.rejected) <= 9  # bounded, whatever comes
    lines = receiver.lines  # type: ignore[attr-defined]
    assert any("from Zenoh writer 0101010101010101 (it claims 'anodize1;intruder'); only 0707070707070707" in line
               for line in lines), lines
    assert len(lines) == 8


def test_a_writer_that_overruns_its_window_cannot_grow_the_queue(receiver: ZenohReceiver) -> None:
    frame = Codec().message_frame("data", 1)
    for number in range(WINDOW * 4):
        receiver._on_sample(sample(number, frame))
    assert receiver.qsize() <= WINDOW + 1  # the rest dropped as gaps, to be sent again once credited


@pytest.mark.parametrize("frame", [b"", b"\x00\x00", b"\xff\xff\xff\x7f" + b"x" * 10])
def test_a_malformed_frame_is_corrupt_not_a_crash(receiver: ZenohReceiver, frame: bytes) -> None:
    receiver._on_sample(sample(0, frame))
    item = receiver.get(timeout=1)
    assert type(item).__name__ == "Corrupt", item


def test_a_failure_frame_ends_the_channel_with_its_cause(receiver: ZenohReceiver) -> None:
    receiver._on_sample(sample(0, Codec.failure_frame("the producer gives up")))
    item = receiver.get(timeout=1)
    assert isinstance(item, PeerFailure) and "the producer gives up" in str(item.cause)


def test_only_the_binding_imports_zenoh() -> None:
    importers = []
    for path in (ROOT / "anodize").rglob("*.py"):
        text = path.read_text()
        if "zenoh" not in text:
            continue  # parse only the files that name it
        for node in ast.walk(ast.parse(text)):
            names = ([alias.name for alias in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else [])
            if any(name == "zenoh" or name.startswith("zenoh.") for name in names):
                importers.append(str(path.relative_to(ROOT)))
    assert sorted(set(importers)) == ["anodize/_transport/zenoh/binding.py"]


# ---- the hot path (issue 32's benchmark targets): short attachments, samples pulled, credits on the tick ----
def test_only_a_writers_first_sample_carries_its_claim_every_other_its_number_and_id_alone() -> None:
    claim = Claim("run;digest", "producing", 0, "vm", WRITER)
    assert attachment(5, claim) == HEADER.pack(5, WRITER) and len(attachment(5, claim)) == 16
    assert attachment(0, claim) == HEADER.pack(0, WRITER) + claim.encoded
    assert parse_attachment(attachment(0, claim)) == (0, WRITER) and claim_of(attachment(0, claim)) == claim.text


def test_a_forged_short_id_is_dropped_counted_and_named_without_a_claim(receiver: ZenohReceiver) -> None:
    frame = Codec().message_frame("data", 1)
    for number in range(3):  # a forger's samples past its first: the header alone
        receiver._on_sample(Sample(Bytes(frame), Bytes(HEADER.pack(number + 1, b"\x02" * 8))))
    assert receiver.qsize() == 0 and receiver.rejected == {b"\x02" * 8: 3}
    assert any("from Zenoh writer 0202020202020202 (it claims 'nothing')" in line
               for line in receiver.lines), receiver.lines  # type: ignore[attr-defined]


def test_samples_wait_in_the_ring_until_the_flow_thread_pulls_and_acknowledges_them(
        receiver: ZenohReceiver, group: GroupSession) -> None:
    """A role busy elsewhere still has what arrived acknowledged (the sender need not send it again)."""
    from anodize._transport.zenoh.binding import publisher, undeclare

    writer = publisher(group.session, group.settings.channel_key("P", "C"))
    frames = [Codec().message_frame("data", i) for i in range(3)]
    for number, frame in enumerate(frames):
        writer.put(frame, attachment=HEADER.pack(number, WRITER))
    deadline = time.monotonic() + 30  # generous: a busy machine
    while receiver.received < 3 and time.monotonic() < deadline:
        receiver.tick()
        time.sleep(0.01)
    undeclare(writer)
    assert (receiver.received, receiver.taken, receiver.credited) == (3, 0, (0, 3))
    assert [receiver.get(timeout=1) for _ in range(3)] == [("data", i) for i in range(3)]


def test_an_idle_reader_leaves_its_credit_to_the_flow_tick(receiver: ZenohReceiver) -> None:
    """Not one credit put back per message of a ping-pong: the flow thread's tick says it."""
    receiver._on_sample(sample(0, Codec().message_frame("data", 0)))
    assert receiver.get(timeout=1) == ("data", 0)
    with pytest.raises(Empty):
        receiver.get(timeout=0.01)  # idle
    assert receiver.credited == (0, 0)
    receiver.tick()
    assert receiver.credited == (1, 1)


def test_a_reader_waiting_in_the_ring_is_woken_when_the_run_stops(receiver: ZenohReceiver) -> None:
    receiver.ticked = True  # as the links set it: the reader waits in recv(), unbounded
    got: list[object] = []
    reader = threading.Thread(target=lambda: got.append(receiver.get()), daemon=True)
    reader.start()
    deadline = time.monotonic() + 30  # generous: a busy machine
    while not receiver._waiting and time.monotonic() < deadline:
        time.sleep(0.001)
    receiver.network.stopping = True  # type: ignore[attr-defined]
    receiver.wake()
    reader.join(30)
    assert got == [STOP]


def test_a_timed_read_waiting_in_the_ring_is_woken_by_the_flow_tick_before_its_deadline(
        receiver: ZenohReceiver) -> None:
    receiver.ticked = True
    outcome: list[object] = []

    def read() -> None:
        try:
            outcome.append(receiver.get(timeout=0.3))
        except Empty:
            outcome.append(Empty)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    waited = False
    for _ in range(400):  # the flow thread's ticks, bounded (a tick about every 10 ms here)
        waited = waited or receiver._waiting
        receiver.tick()
        reader.join(0.01)
        if not reader.is_alive():
            break
    assert outcome == [Empty] and waited  # it waited in recv(), and the tick woke it for its deadline


def test_closing_a_channel_whose_reader_waits_in_the_ring_wakes_it_first(receiver: ZenohReceiver) -> None:
    """(PyO3 refuses to undeclare a subscriber another thread waits in: close() wakes it first.)"""
    receiver.ticked = True
    got: list[object] = []
    reader = threading.Thread(target=lambda: got.append(receiver.get()), daemon=True)
    reader.start()
    deadline = time.monotonic() + 30  # generous: a busy machine
    while not receiver._waiting and time.monotonic() < deadline:
        time.sleep(0.001)
    receiver.close()  # raises nothing
    assert not receiver._waiting
    receiver.network.stopping = True  # type: ignore[attr-defined]
    reader.join(30)
    assert got == [STOP]
