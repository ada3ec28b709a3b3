"""Roles for the DDS transport tests (imported by name in the groups' processes)."""

from __future__ import annotations

import os
import threading
import time
import zlib

import numpy as np

from anodize import Endpoint, RoleStopped

STREAM = ('type Image = "numpy:ndarray"\n'
          "global Stream(P, C) = mu t. P -> C : {data(int). t, frame(Image). t, stop}")


def _count() -> int:
    return int(os.environ.get("DDS_TEST_COUNT", "1000"))


def producer(ep: Endpoint) -> None:
    """Send the numbers 0..n-1 (each message's payload is its place in the stream)."""
    for i in range(_count()):
        ep.send("C", "data", i)
    ep.send("C", "stop")


def consumer(ep: Endpoint) -> None:
    """Check that every number arrives once and in order."""
    expected = 0
    while True:
        label, value = ep.recv("P")
        if label == "stop":
            break
        if value != expected:
            raise AssertionError(f"expected message {expected}, got {value}: lost, duplicated or reordered")
        expected += 1
    if expected != _count():
        raise AssertionError(f"{expected} messages arrived, {_count()} were sent")


def frame_producer(ep: Endpoint) -> None:
    """Send frames whose first 8 bytes number them and whose last 4 are a CRC of the rest."""
    rng = np.random.default_rng(1)
    for i in range(_count()):
        frame = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
        flat = frame.reshape(-1)
        flat[:8] = np.frombuffer(i.to_bytes(8, "little"), np.uint8)
        flat[-4:] = np.frombuffer(zlib.crc32(flat[:-4].tobytes()).to_bytes(4, "little"), np.uint8)
        ep.send("C", "frame", frame)
    ep.send("C", "stop")


def frame_consumer(ep: Endpoint) -> None:
    expected = 0
    while True:
        label, frame = ep.recv("P")
        if label == "stop":
            break
        flat = frame.reshape(-1)
        number = int.from_bytes(flat[:8].tobytes(), "little")
        if number != expected:
            raise AssertionError(f"expected frame {expected}, got {number}")
        if zlib.crc32(flat[:-4].tobytes()) != int.from_bytes(flat[-4:].tobytes(), "little"):
            raise AssertionError(f"frame {number} arrived damaged")
        expected += 1
    if expected != _count():
        raise AssertionError(f"{expected} frames arrived, {_count()} were sent")


def slow_producer(ep: Endpoint) -> None:
    """Stream for ever, slowly: the test kills this group, freezes it or cuts it off. Once the
    first message is out (the start barrier has passed), the file $DDS_TEST_FLOWING is made."""
    i = 0
    while True:
        ep.send("C", "data", i)
        if i == 0 and os.environ.get("DDS_TEST_FLOWING"):
            with open(os.environ["DDS_TEST_FLOWING"], "w", encoding="utf-8"):
                pass
        i += 1
        ep.sleep(0.01)


def slow_producer_of_count(ep: Endpoint) -> None:
    """Send 0..n-1 a little apart (so that samples of a forger arrive in between); then stop."""
    for i in range(_count()):
        ep.send("C", "data", i)
        ep.sleep(0.005)
    ep.send("C", "stop")


STREAM_AND_TICKS = ("global Both(P, C, Q, R) = (mu t. P -> C : {data(int). t, stop} "
                    "|| mu u. Q -> R : {tick(int). u, done})")


def failing_producer(ep: Endpoint) -> None:
    """Send a few numbers, then fail."""
    for i in range(5):
        ep.send("C", "data", i)
        ep.sleep(0.05)
    raise RuntimeError("the producer gives up")


def failing_once_producer(ep: Endpoint) -> None:
    """Fail after a few numbers the first time ($DDS_TEST_MARKER does not exist yet); then be
    :func:`producer`."""
    marker = os.environ["DDS_TEST_MARKER"]
    if not os.path.exists(marker):
        with open(marker, "w", encoding="utf-8"):
            pass
        for i in range(5):
            ep.send("C", "data", i)
        raise RuntimeError("the first incarnation fails")
    producer(ep)


def ticker(ep: Endpoint) -> None:
    """Tick for ever (until stopped)."""
    i = 0
    while True:
        ep.send("R", "tick", i)
        i += 1
        ep.sleep(0.01)


def tick_counter(ep: Endpoint) -> None:
    while ep.recv("Q")[0] == "tick":
        pass


def _progress() -> str:
    return os.environ["DDS_TEST_PROGRESS"]


def eager_producer(ep: Endpoint) -> None:
    """Send as fast as sends return (numbers, or 640x480x3 frames if $DDS_TEST_FRAMES is set);
    after each, check how far ahead of the consumer we are (the consumer writes its count to
    $DDS_TEST_PROGRESS) and remember the most."""
    ahead = 0
    frame = np.zeros((480, 640, 3), np.uint8) if os.environ.get("DDS_TEST_FRAMES") else None
    for i in range(_count()):
        if frame is None:
            ep.send("C", "data", i)
        else:
            ep.send("C", "frame", frame)
        with open(_progress(), encoding="utf-8") as progress:
            consumed = int(progress.read() or 0)
        ahead = max(ahead, i + 1 - consumed)
    ep.send("C", "stop")
    with open(_progress() + ".ahead", "w", encoding="utf-8") as out:
        out.write(str(ahead))


def slow_consumer(ep: Endpoint) -> None:
    """:func:`consumer`, taking 2 ms over each message and saying how many it has had."""
    expected = 0
    while ep.recv("P")[0] != "stop":
        expected += 1
        with open(_progress() + ".tmp", "w", encoding="utf-8") as progress:
            progress.write(str(expected))
        os.replace(_progress() + ".tmp", _progress())
        ep.sleep(0.002)
    if expected != _count():
        raise AssertionError(f"{expected} messages arrived, {_count()} were sent")


# A role whose own thread is receiving when the role fails (as TinMan's Move takes poses in a thread).
HELD = "global Held(P, C, K) = P -> C : data(int). C -> K : done(int)"
_OUTCOME_WITHIN = 30.0  # seconds P and K wait for the thread's outcome before going on anyway


def _outcome_file() -> str:
    return os.environ["DDS_TEST_OUTCOME"]


def _wait_for_outcome() -> None:
    deadline = time.monotonic() + _OUTCOME_WITHIN
    while not os.path.exists(_outcome_file()) and time.monotonic() < deadline:
        time.sleep(0.05)


def held_producer(ep: Endpoint) -> None:
    """Send only once C's thread has said how its receive ended (so it was waiting, not reading)."""
    _wait_for_outcome()
    ep.send("C", "data", 1)


def failing_with_a_receiving_thread(ep: Endpoint) -> None:
    """Start a thread that receives from P, then fail while it waits; the thread writes what its
    receive raised to DDS_TEST_OUTCOME."""
    waiting = threading.Event()

    def receive() -> None:
        waiting.set()
        try:
            ep.recv("P")
            outcome = "received"
        except RoleStopped:
            outcome = "RoleStopped"
        except Exception as error:  # what the test must not see: the sender blamed
            outcome = f"{type(error).__name__}: {error}"
        with open(_outcome_file() + ".part", "w", encoding="utf-8") as out:
            out.write(outcome)
        os.replace(_outcome_file() + ".part", _outcome_file())

    threading.Thread(target=receive, name="C-receiving", daemon=True).start()
    waiting.wait(10)
    time.sleep(0.3)  # in its receive's wait by now (a late start would only find the reader gone sooner)
    raise RuntimeError("C fails on purpose")


def keeping_the_group_alive(ep: Endpoint) -> None:
    """Keep C's group running until C's thread has an outcome, then take C's part (which failed)."""
    _wait_for_outcome()
    ep.recv("C")
