"""The two ends of a channel between processes, driven directly over one OS pipe.

Every frame is written holding the channel's lock (the compiled writer's, where it was built);
a failure frame written meanwhile from another thread, shortened to one write, must arrive
whole, after messages that arrive whole and in order, and a large frame must not be split by
small ones sent from another thread.
"""

from __future__ import annotations

import contextlib
import gc
import os
import select
import signal
import threading

import pytest

from anodize._session.channel import Corrupt, PeerFailure
from anodize._transport.codec import Codec
from anodize._transport.network import GroupNetwork
from anodize._transport.process import PipeLinks, PipeReceiver, PipeSender


def _ends() -> tuple[PipeSender, PipeReceiver]:
    read, write = os.pipe()
    sending = GroupNetwork(["A"], [("A", "B")], PipeLinks({("A", "B"): write}), {}, lambda pair: Codec())
    receiving = GroupNetwork(["B"], [("A", "B")], PipeLinks({("A", "B"): read}), {}, lambda pair: Codec())
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
    kept, cut = item.cause.split(" [", 1)
    assert cut == "... cut to fit one write]" and cause.startswith(kept)
    assert select.PIPE_BUF // 8 < len(item.cause.encode()) < select.PIPE_BUF
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


def test_small_frames_from_another_thread_never_split_a_large_one() -> None:
    """A frame larger than the pipe takes several writes; small frames sent meanwhile from
    another thread wait for the lock instead of landing inside it."""
    sender, receiver = _ends()
    big = b"B" * (4 * 2**20)  # 4 MiB, over the 1 MiB pipe
    stop = threading.Event()

    def small() -> None:
        number = 0
        while not stop.is_set():
            sender.put(("num", number))
            number += 1

    threads = [threading.Thread(target=sender.put, args=(("blob", big),)), threading.Thread(target=small)]
    for thread in threads:
        thread.start()
    try:
        numbers = []
        while True:
            item = receiver.get(timeout=30)
            assert not isinstance(item, Corrupt), item.reason
            assert type(item) is tuple and item[0] in ("num", "blob"), item
            if item[0] == "blob":
                assert item[1] == big
                break
            numbers.append(item[1])
        assert numbers == list(range(len(numbers)))
    finally:
        stop.set()
        for _ in range(10):  # let the small sender finish a write the pipe may be full for
            with contextlib.suppress(Exception):
                while receiver.get(timeout=0.1):
                    pass
        for thread in threads:
            thread.join(timeout=10)


def test_a_signal_handler_that_raises_ends_a_batch_blocked_on_a_full_pipe() -> None:
    """As os.write lets a signal handler raise, so does a batch written by the compiled writer."""
    class HandlerRaisedError(Exception):
        pass

    def interrupt(signum: int, frame: object) -> None:
        raise HandlerRaisedError

    sender, _receiver = _ends()  # nobody reads: the pipe fills
    sender.put(("num", -1))
    # Earlier tests' garbage is collected now: a finalizer run by the collector during the batch
    # would run the handler inside itself, and Python drops what a finalizer raises.
    gc.collect()
    previous = signal.signal(signal.SIGALRM, interrupt)
    # Every 0.5 s, until one raises out of the batch: a signal that lands while the thread runs
    # Python code the batch does not own is gone, and a single one would leave the write blocked.
    signal.setitimer(signal.ITIMER_REAL, 0.5, 0.5)
    try:
        with pytest.raises(HandlerRaisedError):
            sender.put_many([("num", n) for n in range(200_000)])  # 4 MiB of frames
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
