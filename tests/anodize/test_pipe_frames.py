"""The two ends of a channel between processes, driven directly over one OS pipe.

Small frames are written without the sender's lock (a write of at most PIPE_BUF bytes to a
pipe is never split nor interleaved); a failure frame written meanwhile from another thread
must still arrive whole, after messages that arrive whole and in order.
"""

from __future__ import annotations

import os
import select
import threading

from anodize.session.channel import Corrupt, PeerFailure
from anodize.transport.codec import Codec
from anodize.transport.process import PipeReceiver, PipeSender, ProcessNetwork


def _ends() -> tuple[PipeSender, PipeReceiver]:
    read, write = os.pipe()
    sending = ProcessNetwork(["A"], [("A", "B")], {("A", "B"): write}, {}, lambda pair: Codec())
    receiving = ProcessNetwork(["B"], [("A", "B")], {("A", "B"): read}, {}, lambda pair: Codec())
    sender, receiver = sending.queues[("A", "B")], receiving.queues[("A", "B")]
    assert isinstance(sender, PipeSender) and isinstance(receiver, PipeReceiver)
    return sender, receiver


def test_a_failure_written_from_another_thread_arrives_whole_after_whole_messages() -> None:
    sender, receiver = _ends()
    cause = "x" * (3 * select.PIPE_BUF)  # far longer than one atomic write: it is shortened
    count = 20_000
    failure = threading.Thread(target=sender.put_failure, args=(cause,))

    def send_all() -> None:
        for number in range(count):
            sender.put(("num", number))
            if number == count // 2:
                failure.start()  # while messages are still being written

    writer = threading.Thread(target=send_all)
    writer.start()
    got: list[object] = []
    while True:
        item = receiver.get(timeout=10)
        assert not isinstance(item, Corrupt), item.reason
        if isinstance(item, PeerFailure):
            break
        got.append(item)
    writer.join()
    failure.join()
    assert item.cause == cause[:len(item.cause)] and select.PIPE_BUF // 8 < len(item.cause) < select.PIPE_BUF
    assert got == [("num", n) for n in range(len(got))] and count // 2 < len(got) <= count
    assert [receiver.get(timeout=10) for _ in range(count - len(got))] == [("num", n) for n in range(len(got), count)]


def test_a_frame_larger_than_pipe_buf_arrives_whole_beside_small_ones() -> None:
    sender, receiver = _ends()
    big = "é" * (2 * select.PIPE_BUF)
    items = [("num", 1), ("text", big), ("num", 2)]

    def send_all() -> None:
        for item in items:
            sender.put(item)

    writer = threading.Thread(target=send_all)
    writer.start()
    assert [receiver.get(timeout=10) for _ in items] == items
    writer.join()


def test_a_receiver_told_its_sender_failed_still_takes_all_the_pipe_holds_first() -> None:
    """Messages wait in the pipe, unread, when the supervisor says the sender failed (its write
    end still open, as a forked child of its group may hold it): every one comes out, then the
    failure. The read that finds them must not be followed by a wait for more, which would
    never end here."""
    sender, receiver = _ends()
    count = 1_000  # about 21 KiB of frames: one read takes them all
    for number in range(count):
        sender.put(("num", number))
    receiver.network.note_failed("A", "crashed")
    got: list[object] = []
    taking = threading.Thread(target=lambda: got.extend(receiver.get() for _ in range(count + 1)), daemon=True)
    taking.start()
    taking.join(timeout=30)  # a bound on a hang, not a measure of speed
    assert not taking.is_alive(), f"the receiver waited with {count - len(got)} messages read but not handed out"
    assert got[:count] == [("num", n) for n in range(count)]
    assert isinstance(got[count], PeerFailure) and got[count].cause == "crashed"
