"""Raw Zenoh peer processes for ``bench/zenoh.py``: the baseline the Zenoh transport is held to.

Module level on purpose: the parent starts them as ``multiprocessing`` processes (spawn
context, through ``peers_roles.guarded``, which reports a failure's cause), which import them
by name. Each writes what it measured as JSON to ``<out>/<name>.json``
(``transport_roles.report``: the folder named in ``$ANODIZE_BENCH``), in the forms the
other benchmarks read: ``start.json`` and ``end.json`` for a stream or frames
(``dds._one_way``), ``pingpong.json`` for round trips (``peers_roles.timed_rounds``: p50,
p99, mean and max in us).

How raw Zenoh is used (its best honest use for a lossless stream between two processes;
docs/performance.md says why):

- One session per process, opened with :func:`session_config`: multicast scouting off, one
  side listening on a loopback TCP endpoint and the other connecting to it (peer to peer),
  or both connecting as clients to a router's endpoint. Endpoints named, not scouted, so no
  other Zenoh process on the machine (another engineer's run) can join.
- Publishers declared once (``declare_publisher``), ``Reliability.RELIABLE`` and
  ``CongestionControl.BLOCK``: nothing is dropped, a full queue stops the sender; with the
  subscriber's bounded FIFO (the default handler) back pressure reaches the sender through
  TCP, so memory stays bounded. ``express`` off for streams and frames (Zenoh batches small
  messages, its strength in a stream), on for round trips (each message sent at once; the
  benchmark shows round trips with it off too, as the transport's publishers have it).
- Subscribers with the default handler (a bounded FIFO channel) read with ``recv()`` in the
  main thread: faster than a Python callback on Zenoh's own thread, measured here.
- For information only (``where["callback"]``): a subscriber whose callback, on Zenoh's own
  thread, hands each payload to the main thread through a ``queue.Queue`` of ``HANDED``, the
  hand-off any receiver pays whose reader is another thread (the transport's is a role's).
- Payloads are the same bytes every way carries: an int as 8 bytes, a frame as its 921,600
  bytes with its number in the first 8 (``dds_roles.stamp``); the receiver checks the number
  and sums every 96th row (``dds_roles.FrameSink``). No monitors, no codec.

Start-up and discovery are never timed: each publisher waits (bounded) until Zenoh reports
a matching subscriber, then both peers meet at a ``multiprocessing.Barrier``; a producer
waits at the barrier again after its last message until the consumer has it, so it never
closes its session with data in flight. The blocking ``recv()`` has no timeout of its own:
the parent kills a run that outlives ``--timeout`` (``runs.run_raw``).
"""

from __future__ import annotations

import json
import queue
import time
from typing import Any

import numpy as np
import zenoh
from dds_roles import CHANNELS, HEIGHT, INT, POOL, STOP, WIDTH, FrameSink, frame_pool, stamp
from peers_roles import timed_rounds
from transport_roles import report

FRAME_BYTES = HEIGHT * WIDTH * CHANNELS
STOP_BYTES = INT.pack(STOP)  # a stream's and a ping-pong's last message
HANDED = 256  # samples the callback way's queue holds (as Zenoh's default FIFO channel)
TIMEOUT = 60.0  # seconds any wait for the other peer may take (matching, barriers)


def session_config(mode: str, listen: list[str], connect: list[str]) -> zenoh.Config:
    """A session's configuration: ``mode`` ("peer" or "client"), its endpoints, no multicast scouting."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", json.dumps(listen))
    config.insert_json5("connect/endpoints", json.dumps(connect))
    return config



class RawEnd:
    """One process's end: a session, a publisher on ``<prefix>/<write>``, a subscriber on ``<prefix>/<read>``."""

    def __init__(self, where: dict[str, Any], prefix: str, write: str | None, read: str | None,
                 express: bool = False) -> None:
        self.session = zenoh.open(session_config(where["mode"], where["listen"], where["connect"]))
        self.publisher = (None if write is None else self.session.declare_publisher(
            f"{prefix}/{write}", reliability=zenoh.Reliability.RELIABLE,
            congestion_control=zenoh.CongestionControl.BLOCK, express=express))
        self.handed: queue.Queue[bytes] | None = None
        self.subscriber: Any  # a FIFO channel's (recv) or a callback's (None)
        if read is None:
            self.subscriber = None
        elif where.get("callback"):  # information: the hand-off a receiver on another thread pays
            handed = self.handed = queue.Queue(HANDED)
            self.subscriber = self.session.declare_subscriber(
                f"{prefix}/{read}", lambda sample: handed.put(sample.payload.to_bytes()))
        else:
            self.subscriber = self.session.declare_subscriber(f"{prefix}/{read}")

    def wait_matched(self, seconds: float | None = None) -> None:
        """Until the publisher has a subscriber (bounded: ``seconds``, else ``TIMEOUT``).

        Raises:
            TimeoutError: no subscriber matched in time.
        """
        seconds = TIMEOUT if seconds is None else seconds
        deadline = time.monotonic() + seconds
        # A MatchingStatus at run time, whatever the binding's stub says (bool).
        while self.publisher is not None and not getattr(self.publisher.matching_status, "matching", False):
            if time.monotonic() > deadline:
                raise TimeoutError(f"raw Zenoh: no subscriber matched within {seconds:g} s")
            time.sleep(0.01)

    def put(self, payload: bytes) -> None:
        assert self.publisher is not None
        self.publisher.put(payload)

    def take(self) -> bytes:
        assert self.subscriber is not None
        if self.handed is not None:
            return self.handed.get()
        data: bytes = self.subscriber.recv().payload.to_bytes()
        return data

    def close(self) -> None:
        self.session.close()  # type: ignore[no-untyped-call]


def _value(payload: bytes) -> int:
    value: int = INT.unpack(payload)[0]
    return value


def int_producer(where: dict[str, Any], prefix: str, barrier: Any, n: int) -> None:
    end = RawEnd(where, prefix, "data", None)
    try:
        end.wait_matched()
        barrier.wait(TIMEOUT)
        report("start", {"start": time.monotonic()})
        put, pack = end.put, INT.pack
        for i in range(n):
            put(pack(i))
        put(STOP_BYTES)
        barrier.wait(TIMEOUT)  # the consumer has everything: closing loses nothing
    finally:
        end.close()


def int_consumer(where: dict[str, Any], prefix: str, barrier: Any, n: int) -> None:
    end = RawEnd(where, prefix, None, "data")
    try:
        barrier.wait(TIMEOUT)
        count = bad = 0
        take = end.take
        while (value := _value(take())) != STOP:
            if value != count:
                bad += 1
            count += 1
        report("end", {"end": time.monotonic(), "count": count, "bad": bad})
        barrier.wait(TIMEOUT)
    finally:
        end.close()


def frame_producer(where: dict[str, Any], prefix: str, barrier: Any, n: int) -> None:
    end = RawEnd(where, prefix, "frames", None)
    try:
        pool = frame_pool()
        end.wait_matched()
        barrier.wait(TIMEOUT)
        report("start", {"start": time.monotonic()})
        for i in range(n):
            end.put(stamp(pool[i % POOL], i).tobytes())  # put takes bytes: one copy, as any sender's encoding
        end.put(STOP_BYTES)
        barrier.wait(TIMEOUT)
    finally:
        end.close()


def frame_consumer(where: dict[str, Any], prefix: str, barrier: Any, n: int) -> None:
    end = RawEnd(where, prefix, None, "frames")
    try:
        barrier.wait(TIMEOUT)
        sink = FrameSink()
        while len(payload := end.take()) == FRAME_BYTES:
            sink.take(np.frombuffer(payload, np.uint8).reshape(HEIGHT, WIDTH, CHANNELS))
        report("end", {"end": time.monotonic(), "count": sink.count, "bad": sink.bad})
        barrier.wait(TIMEOUT)
    finally:
        end.close()


def ping_client(where: dict[str, Any], prefix: str, barrier: Any, rounds: int, warmup: int,
                express: bool = True) -> None:
    end = RawEnd(where, prefix, "ping", "pong", express=express)
    try:
        end.wait_matched()
        barrier.wait(TIMEOUT)
        put, take, pack = end.put, end.take, INT.pack

        def one_round(i: int) -> object:
            put(pack(i))
            return take()

        found = timed_rounds(one_round, warmup, rounds)
        put(STOP_BYTES)
        report("pingpong", found)
        barrier.wait(TIMEOUT)
    finally:
        end.close()


def ping_server(where: dict[str, Any], prefix: str, barrier: Any, express: bool = True) -> None:
    end = RawEnd(where, prefix, "pong", "ping", express=express)
    try:
        end.wait_matched()
        barrier.wait(TIMEOUT)
        put, take = end.put, end.take
        while (payload := take()) != STOP_BYTES:
            put(payload)
        barrier.wait(TIMEOUT)
    finally:
        end.close()

