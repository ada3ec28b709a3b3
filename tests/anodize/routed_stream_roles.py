"""Roles of the three-namespace Zenoh tests (test_zenoh_routed.py), for dds_roles.STREAM: producers
that pace themselves and say how far they got, so a test can break the network mid-run.

$ROUTED_TEST_COUNT is how many numbers a producer sends; $ROUTED_TEST_FLOWING, a file the producer
makes once it has sent $ROUTED_TEST_AFTER numbers (the test acts then); $ROUTED_TEST_MARKER, a file
whose absence makes the first incarnation fail (see :func:`failing_once_paced_producer`);
$ROUTED_TEST_RECEIVED, a file where :func:`counting_consumer` says how many numbers it has had;
$ROUTED_TEST_HELD and $ROUTED_TEST_REPLAYED, the replayer's files (routed.py's ``replay_old_writer``).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

from anodize import Endpoint, PeerFailedError


def _count() -> int:
    return int(os.environ.get("ROUTED_TEST_COUNT", "1000"))


def _flowing(sent: int) -> None:
    if sent == int(os.environ.get("ROUTED_TEST_AFTER", "1")) and os.environ.get("ROUTED_TEST_FLOWING"):
        Path(os.environ["ROUTED_TEST_FLOWING"]).touch()


def paced_producer(ep: Endpoint) -> None:
    """Send the numbers 0..n-1, 2 ms apart (the consumer checks each, in order), then stop."""
    _paced(ep)


def _paced(ep: Endpoint, before_stop: Path | None = None) -> None:
    """:func:`paced_producer`; with ``before_stop``, the stop waits (bounded) until that file exists."""
    for i in range(_count()):
        ep.send("C", "data", i)
        _flowing(i + 1)
        ep.sleep(0.002)
    _wait_until(ep, lambda: before_stop is None or before_stop.exists())
    ep.send("C", "stop")


def _wait_until(ep: Endpoint, condition: Callable[[], bool], seconds: float = 60) -> None:
    """Until ``condition()`` holds, or ``seconds`` have passed (then the test's own checks fail)."""
    deadline = time.monotonic() + seconds
    while not condition() and time.monotonic() < deadline:
        ep.sleep(0.05)


def _count_in(path: Path) -> int:
    """The count written to ``path`` (0 while there is none)."""
    try:
        return int(path.read_text() or 0)
    except FileNotFoundError:
        return 0


def failing_once_paced_producer(ep: Endpoint) -> None:
    """The first incarnation ($ROUTED_TEST_MARKER does not exist yet) sends 0..4, waits (bounded) until
    the consumer has them all (they crossed the router: $ROUTED_TEST_RECEIVED, see
    :func:`counting_consumer`) and the replayer holds them ($ROUTED_TEST_HELD: how many numbers of this
    writer it recorded), removes $ROUTED_TEST_RECEIVED (so that file says, when it comes again, that the
    next consumer accepted the next writer) and fails. The next is :func:`paced_producer`, whose stop waits
    (bounded) until the replay is past the router ($ROUTED_TEST_REPLAYED): the consumer is still there to
    reject it."""
    marker = Path(os.environ["ROUTED_TEST_MARKER"])
    received, held = Path(os.environ["ROUTED_TEST_RECEIVED"]), Path(os.environ["ROUTED_TEST_HELD"])
    if not marker.exists():
        marker.touch()
        for i in range(5):
            ep.send("C", "data", i)
        _wait_until(ep, lambda: _count_in(received) >= 5 and _count_in(held) >= 5)
        received.unlink(missing_ok=True)  # the consumer of this incarnation writes no more: it has all five
        raise RuntimeError("the first incarnation fails")
    _paced(ep, Path(os.environ["ROUTED_TEST_REPLAYED"]))


def counting_consumer(ep: Endpoint) -> None:
    """Check that 0..n-1 arrive once and in order ($ROUTED_TEST_COUNT), writing how many have come so far
    to $ROUTED_TEST_RECEIVED."""
    received = Path(os.environ["ROUTED_TEST_RECEIVED"])
    expected = 0
    while True:
        label, value = ep.recv("P")
        if label == "stop":
            break
        if value != expected:
            raise AssertionError(f"expected message {expected}, got {value}: lost, duplicated or reordered")
        expected += 1
        received.with_suffix(".tmp").write_text(str(expected))
        received.with_suffix(".tmp").replace(received)
    if expected != _count():
        raise AssertionError(f"{expected} messages arrived, {_count()} were sent")


def timed_consumer(ep: Endpoint) -> None:
    """Receive for ever; when told the producer failed, write the time (CLOCK_MONOTONIC, one clock for
    every process of the machine) to $ROUTED_TEST_TOLD, then fail as told."""
    try:
        while ep.recv("P")[0] != "stop":
            pass
    except PeerFailedError:
        Path(os.environ["ROUTED_TEST_TOLD"]).write_text(repr(time.monotonic()))
        raise
