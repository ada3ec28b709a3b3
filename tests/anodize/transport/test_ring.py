"""The shared-memory byte ring of a channel between processes (anodize/_transport/ring.py).

The compiled ring (``_frames.c``) against its pure-Python reference on random writes and reads
(wraparound, a full ring); a forged peer's impossible indices and lengths (the receiver reports
the sender's stream corrupt, reads nothing unbounded, and does not crash); a sender killed
mid-write (its death is seen, never a partial frame); a failure after messages, in order; back
pressure (a full ring holds its sender); and no system call per message to an awake receiver.

AddressSanitizer: on 2026-11-27 ``_frames.c`` was built with ``CFLAGS=-fsanitize=address`` and
this file run with ``LD_PRELOAD=$(gcc -print-file-name=libasan.so)`` and
``ASAN_OPTIONS=detect_leaks=0``: all tests passed, no report.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from typing import Any

import pytest
from budget import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from anodize._session.channel import Corrupt, PeerFailure
from anodize._transport import process as process_module
from anodize._transport import ring as ring_module
from anodize._transport.codec import Codec
from anodize._transport.network import GroupNetwork
from anodize._transport.process import PipeLinks, PipeReceiver, PipeSender, Ring, map_ring
from anodize._transport.ring import (
    HEADER_SIZE,
    SLEEPING,
    WAITING,
    create_ring_memory,
    ring_capacity,
    ring_read_python,
    ring_write_python,
    take_flag_python,
)
from anodize.errors import PeerFailedError

try:
    from anodize._transport._frames import ring_read as compiled_read
    from anodize._transport._frames import ring_take_flag as compiled_take
    from anodize._transport._frames import ring_write as compiled_write
except ImportError:
    compiled_read = compiled_write = compiled_take = None

needs_compiled = pytest.mark.skipif(compiled_read is None, reason="anodize was installed without a C compiler "
                                    "(the reference is then the only ring)")

_QUADS = "Q"


def _memory(capacity: int) -> memoryview:
    fd = create_ring_memory(capacity)
    try:
        return map_ring(fd)
    finally:
        os.close(fd)


def _set_index(memory: memoryview, offset: int, value: int) -> None:
    memory[:HEADER_SIZE].cast(_QUADS)[offset // 8] = value % (1 << 64)


def _ends(capacity: int = 1 << 20) -> tuple[PipeSender, PipeReceiver, Ring, int]:
    """A channel A->B over a ring in this process: (sender, receiver, the receiver's ring, pipe write end)."""
    read, write = os.pipe()
    fd = create_ring_memory(capacity)
    room = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
    sending_ring, receiving_ring = Ring(map_ring(fd), room), Ring(map_ring(fd), room)
    os.close(fd)
    sending = GroupNetwork(["A"], [("A", "B")], PipeLinks({("A", "B"): write}, {("A", "B"): sending_ring}), {},
                           lambda pair: Codec())
    receiving = GroupNetwork(["B"], [("A", "B")], PipeLinks({("A", "B"): read}, {("A", "B"): receiving_ring}), {},
                             lambda pair: Codec())
    sender, receiver = sending.queues[("A", "B")], receiving.queues[("A", "B")]
    assert isinstance(sender, PipeSender) and isinstance(receiver, PipeReceiver)
    return sender, receiver, receiving_ring, write


# ---- the compiled ring against the reference -------------------------------------------------
_operations = st.lists(st.one_of(
    st.tuples(st.just("write"), st.integers(0, 300)),
    st.tuples(st.just("read"), st.integers(0, 300)),
    st.tuples(st.just("flag"), st.sampled_from([SLEEPING, WAITING]))), max_size=60)


@needs_compiled
@settings(max_examples=examples(300), deadline=None)
@given(_operations, st.integers(0, 1 << 64 - 1))
def test_the_compiled_ring_does_what_the_reference_does(operations: list[tuple[str, int]], start: int) -> None:
    """Same bytes written and read, same indices, same flags: wraparound and a full ring included
    (a 256-byte ring, writes up to 300 bytes, indices starting anywhere, even near 2**64)."""
    rings = [_memory(256), _memory(256)]
    for memory in rings:
        _set_index(memory, 0, start)
        _set_index(memory, 64, start)
    room = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
    implementations: list[tuple[Any, Any, Any]] = [
        (compiled_write, compiled_read, compiled_take), (ring_write_python, ring_read_python, take_flag_python)]
    outs = [bytearray(), bytearray()]
    counter = 0
    try:
        for kind, value in operations:
            results = []
            for memory, (write, read, take), out in zip(rings, implementations, outs, strict=True):
                if kind == "write":
                    data = bytes((counter + i) % 251 for i in range(value))
                    results.append(write(memory, data))
                elif kind == "read":
                    results.append(read(memory, out, value, room))
                else:
                    memory[:HEADER_SIZE].cast("I")[value // 4] = 1
                    results.append(take(memory, value))
            counter += 1
            assert results[0] == results[1], (kind, value)
            assert bytes(rings[0][:HEADER_SIZE]) == bytes(rings[1][:HEADER_SIZE])
        assert outs[0] == outs[1]
    finally:
        os.close(room)


@pytest.mark.parametrize("implementation", ["python", pytest.param("compiled", marks=needs_compiled)])
def test_a_write_publishes_only_what_fits_and_a_read_rings_a_waiting_sender(implementation: str) -> None:
    write, read = ((ring_write_python, ring_read_python) if implementation == "python"
                   else (compiled_write, compiled_read))
    memory = _memory(64)
    room = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
    try:
        assert write(memory, b"x" * 100) == 64 and write(memory, b"y") == 0  # full: nothing more
        memory[:HEADER_SIZE].cast("I")[WAITING // 4] = 1  # the sender waits for room
        out = bytearray()
        assert read(memory, out, 10, room) == 10 and out == b"x" * 10
        assert os.eventfd_read(room) == 1 and memory[:HEADER_SIZE].cast("I")[WAITING // 4] == 0
        assert write(memory, b"0123456789AB") == 10  # wraps around the end
        out.clear()
        assert read(memory, out, 1000, room) == 64 and out == b"x" * 54 + b"0123456789"
    finally:
        os.close(room)


# ---- hostile indices and lengths ---------------------------------------------------------------
@pytest.mark.parametrize("implementation", ["python", pytest.param("compiled", marks=needs_compiled)])
@pytest.mark.parametrize(("tail", "head"), [(-1, 0), (4097, 0), (1 << 63, 5), (10, 11), ((1 << 64) - 1, 1 << 40)])
def test_impossible_indices_are_refused_by_both_sides(implementation: str, tail: int, head: int) -> None:
    write, read = ((ring_write_python, ring_read_python) if implementation == "python"
                   else (compiled_write, compiled_read))
    memory = _memory(4096)
    _set_index(memory, 0, tail)
    _set_index(memory, 64, head)
    out = bytearray()
    with pytest.raises(ValueError, match="impossible"):
        read(memory, out, 1 << 30, -1)
    with pytest.raises(ValueError, match="impossible"):
        write(memory, b"data")
    assert out == b""  # not one byte was taken


@pytest.mark.parametrize("tail", [-7, 5 << 20, 1 << 63])
def test_a_forged_tail_is_the_senders_corrupt_stream_and_nothing_is_read_past_it(tail: int) -> None:
    sender, receiver, ring, write_end = _ends(1 << 16)
    sender.put(("num", 1))
    assert receiver.get(timeout=5) == ("num", 1)
    _set_index(ring.memory, 0, tail)  # the sender's process writes what no sender would
    item = receiver.get(timeout=5)
    assert isinstance(item, Corrupt) and "ring from A" in item.reason and "impossible" in item.reason
    assert len(receiver._buffer) < 1 << 16
    os.close(write_end)  # the sender's process ends: the receiver still notices
    receiver.network.stop()
    assert receiver.get(timeout=5) is not None


def test_a_forged_length_in_the_ring_is_a_corrupt_frame_not_a_huge_read() -> None:
    sender, receiver, _, _ = _ends(1 << 16)
    sender._write((2**31).to_bytes(4, "little") + b"M" * 1000)
    item = receiver.get(timeout=5)
    assert isinstance(item, Corrupt) and "over the" in item.reason
    assert len(receiver._buffer) <= 1004


# ---- a sender that dies --------------------------------------------------------------------------
def test_bytes_copied_but_never_published_are_not_read_when_the_sender_dies() -> None:
    """A sender killed between its copy and its store of the tail: the receiver sees the death."""
    sender, receiver, ring, write_end = _ends(1 << 16)
    sender.put(("num", 7))
    frame = Codec().message_frame("num", 8)
    ring.memory[HEADER_SIZE + 64:HEADER_SIZE + 64 + len(frame)] = frame  # copied, tail not moved
    ring.memory[HEADER_SIZE + 64 + len(frame):HEADER_SIZE + 200] = b"\xff" * (136 - len(frame))
    os.close(write_end)  # its process is gone: end-of-file on the pipe
    assert receiver.get(timeout=5) == ("num", 7)
    item = receiver.get(timeout=10)
    assert isinstance(item, PeerFailure) and item.peer == "A"


def test_a_sender_killed_while_streaming_leaves_a_whole_prefix_then_its_death() -> None:
    sender, receiver, _, write_end = _ends(1 << 12)  # small: the child often waits for room too
    child = os.fork()
    if child == 0:  # pragma: no cover - the child streams until it is killed
        try:
            number = 0
            while True:
                sender.put(("num", number))
                sender._write(Codec().message_frame("text", "t" * (number % 300)))
                number += 1
        finally:
            os._exit(0)
    os.close(write_end)  # only the child holds the write end: its death is end-of-file
    got: list[object] = []
    try:
        while len(got) < 4000:
            got.append(receiver.get(timeout=10))
    finally:
        os.kill(child, signal.SIGKILL)
        os.waitpid(child, 0)
    while not isinstance(got[-1], PeerFailure):
        got.append(receiver.get(timeout=10))
        assert len(got) < 10_000_000
    messages = got[:-1]
    assert all(not isinstance(item, Corrupt) for item in messages)
    numbers = [payload for label, payload in messages if label == "num"]  # type: ignore[misc]
    assert numbers == list(range(len(numbers)))


# ---- order, back pressure, wake-ups ----------------------------------------------------------
def test_a_failure_put_after_messages_arrives_after_them() -> None:
    sender, receiver, _, _ = _ends()
    for number in range(1000):
        sender.put(("num", number))
    sender.put_failure("it broke")
    got = [receiver.get(timeout=5) for _ in range(1001)]
    assert got[:1000] == [("num", n) for n in range(1000)]
    assert isinstance(got[1000], PeerFailure) and got[1000].cause == "it broke"


def test_a_full_ring_holds_its_sender_until_the_receiver_reads() -> None:
    sender, receiver, ring, _ = _ends(1 << 12)
    count = 3000  # about 17 bytes a frame: ten times the ring
    done = threading.Event()

    def send_all() -> None:
        for number in range(count):
            sender.put(("num", number))
        done.set()

    thread = threading.Thread(target=send_all, daemon=True)
    thread.start()
    deadline = time.monotonic() + 10
    while not ring.memory[:HEADER_SIZE].cast("I")[WAITING // 4] and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not done.is_set() and ring.memory[:HEADER_SIZE].cast("I")[WAITING // 4] == 1  # bounded: it waits
    quads = ring.memory[:HEADER_SIZE].cast("Q")
    assert quads[0] - quads[8] <= 1 << 12
    assert [receiver.get(timeout=5) for _ in range(count)] == [("num", n) for n in range(count)]
    assert done.wait(5)
    thread.join(5)


def test_a_silenced_receiver_fails_a_sender_waiting_for_room() -> None:
    sender, receiver, _, _ = _ends(1 << 12)
    errors: list[BaseException] = []

    def send_all() -> None:
        try:
            for number in range(3000):
                sender.put(("num", number))
        except BaseException as error:
            errors.append(error)

    thread = threading.Thread(target=send_all, daemon=True)
    thread.start()
    time.sleep(0.2)
    receiver.network.links.silence(("A", "B"))  # type: ignore[attr-defined]
    sender.network.note_failed("B", "it failed")  # what the supervisor tells the sender's group
    thread.join(10)
    assert not thread.is_alive() and errors and "it failed" in str(errors[0])


def test_an_awake_receiver_costs_its_sender_no_system_call() -> None:
    """No doorbell while the receiver is not asleep: the pipe stays empty; one when it sleeps."""
    sender, receiver, ring, _ = _ends()
    for number in range(100):
        sender.put(("num", number))
    sender.put_many([("num", n) for n in range(100)])
    os.set_blocking(receiver.fd, False)
    with pytest.raises(BlockingIOError):  # not one doorbell byte in the pipe
        os.read(receiver.fd, 1)
    os.set_blocking(receiver.fd, True)
    assert [receiver.get(timeout=5) for _ in range(200)] == [("num", n % 100) for n in range(200)]
    woken: list[object] = []
    thread = threading.Thread(target=lambda: woken.append(receiver.get(timeout=10)))
    thread.start()
    deadline = time.monotonic() + 10
    while not ring.memory[:HEADER_SIZE].cast("I")[SLEEPING // 4] and time.monotonic() < deadline:
        time.sleep(0.01)
    sender.put(("num", 5))  # the receiver sleeps in poll(): this one rings
    thread.join(10)
    assert woken == [("num", 5)]


def test_a_spin_policy_is_asked_before_the_receiver_sleeps() -> None:
    sender, receiver, ring, _ = _ends()
    asked: list[bool] = []

    class Spin:
        def wait(self, ready: Any, limit: float | None = None) -> bool:
            asked.append(ready())
            sender.put(("num", 1))  # arrives while it spins
            asked.append(ready())
            return True

    receiver.spin = Spin()
    assert receiver.get(timeout=5) == ("num", 1)
    assert asked == [False, True] and ring.memory[:HEADER_SIZE].cast("I")[SLEEPING // 4] == 0


def test_the_reference_is_chosen_by_anodize_pure_python() -> None:
    pure = os.environ.get("ANODIZE_PURE_PYTHON", "") not in ("", "0")
    assert (compiled_read is not None and not pure) == ring_module.COMPILED


def test_a_rings_memory_is_sealed_against_shrinking() -> None:
    """A peer that shrank the memfd would kill the other side's reads with SIGBUS."""
    fd = create_ring_memory(4096)
    try:
        with pytest.raises(PermissionError):
            os.ftruncate(fd, 0)
    finally:
        os.close(fd)


@pytest.mark.parametrize("compiled_writer", [True, False])
def test_a_send_after_the_receiver_was_silenced_fails_at_once(compiled_writer: bool) -> None:
    """As EPIPE did on the pipe: the receiver's role failed, the next send says so (C and Python paths)."""
    sender, receiver, _, _ = _ends()
    if not compiled_writer:
        sender.put = sender.put_python  # type: ignore[method-assign]
    sender.put(("num", 1))
    receiver.network.links.silence(("A", "B"))  # type: ignore[attr-defined]
    sender.network.note_failed("B", "it failed")
    with pytest.raises(PeerFailedError, match="it failed"):
        sender.put(("num", 2))


def test_a_batch_larger_than_a_small_ring_arrives_whole_and_in_order() -> None:
    """put_many sizes its compiled batches to the ring's room and waits in Python when it is full."""
    sender, receiver, _, _ = _ends(1 << 12)
    items = [("num", n) for n in range(20_000)]
    thread = threading.Thread(target=sender.put_many, args=(items,), daemon=True)
    thread.start()
    assert [receiver.get(timeout=10) for _ in items] == items
    thread.join(10)
    assert not thread.is_alive()


@pytest.mark.parametrize("reference", [False, True], ids=["compiled", "reference"])
def test_a_room_eventfd_the_sender_filled_neither_fails_the_receiver_nor_its_silencing(
        reference: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """The room eventfd is shared with the sender's process, which may fill it: the receiver's
    read and the silencing of its failed role ring it as best they can, never raise."""
    import anodize._transport.process as process

    if reference:
        monkeypatch.setattr(process, "ring_read", ring_read_python)
    elif compiled_read is None:
        pytest.skip("anodize was installed without a C compiler (the reference is then the only ring)")
    sender, receiver, ring, _ = _ends(1 << 12)
    sender.put(("num", 1))
    os.eventfd_write(ring.room_fd, 0xFFFFFFFFFFFFFFFE)  # the largest count an eventfd holds
    ring.memory[:HEADER_SIZE].cast("I")[WAITING // 4] = 1  # and the sender says it waits for room
    assert receiver.get(timeout=5) == ("num", 1)
    receiver.network.links.silence(("A", "B"))  # type: ignore[attr-defined]


def test_a_full_ring_is_decoded_about_a_batch_at_a_time_not_all_it_holds() -> None:
    """A receiver behind a full ring turns at most 16 KiB of frames into messages ahead of the
    reader (about one recv_many batch of 1,024): 64 KiB (3,000 messages of this stream) built
    objects the cache had evicted again before a batch reached them."""
    sender, receiver, ring, _ = _ends()
    frame_size = len(Codec().message_frame("num", 0))
    items = [("num", n) for n in range(ring_capacity(ring.memory) // frame_size)]
    sender.put_many(items)  # the ring is full: all of it is there to take
    taken = [receiver.get(timeout=0)]
    ahead = receiver.take_ready(len(items))  # what the first read decoded, without reading more
    assert 0 < len(ahead) * frame_size <= 16 * 1024
    taken += ahead
    while len(taken) < len(items):
        taken.append(receiver.get(timeout=0))
    assert taken == items


def test_the_rest_of_a_large_frame_is_read_in_64_kib_pieces(monkeypatch: pytest.MonkeyPatch) -> None:
    """Small frames are taken 16 KiB at a time, but a frame larger than that is completed 64 KiB
    at a time: fewer reads, and fewer wake-ups of a sender waiting for room."""
    sender, receiver, _, _ = _ends()
    reads: list[int] = []
    real_read = process_module.ring_read

    def counting_read(memory: memoryview, into: bytearray, limit: int, room_fd: int) -> int:
        reads.append(limit)
        return real_read(memory, into, limit, room_fd)

    monkeypatch.setattr(process_module, "ring_read", counting_read)
    payload = bytes(range(256)) * 2400  # 600 KiB, in the ring whole
    sender.put(("blob", payload))
    assert receiver.get(timeout=0) == ("blob", payload)
    assert reads[0] == 16 * 1024 and set(reads[1:]) == {64 * 1024}
    assert len(reads) <= 2 + len(payload) // (64 * 1024)
