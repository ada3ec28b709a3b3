"""Role functions and raw Cyclone DDS processes for ``bench/dds.py``.

Module level on purpose: anodize's group processes and the raw baseline's
``multiprocessing`` processes (spawn context) import them by name. The anodize
roles take their settings from the JSON in the environment variable
``ANODIZE_BENCH_DDS`` (set by the parent before a run; spawned interpreters
inherit it); every measuring function writes what it measured as JSON to
``<out>/<name>.json``, where the parent reads it after the run.

Clocks: ``time.monotonic()`` is CLOCK_MONOTONIC on Linux, one clock for the whole
machine, so a start taken in the producer and an end taken in the consumer can be
subtracted. Round trips are timed by the client alone (``time.perf_counter``).

The raw baseline (:class:`RawPeer`) uses what ``anodize._transport.dds`` uses: the
topic type ``anodize::Frame``, samples written as CDR bytes with
``cyclonedds._clayer.ddspy_write`` (retrying in short sleeps while the reader is
full), taken as raw CDR with ``ddspy_take`` after a ``WaitSet`` wait, and the same
QoS (reliable, keep-all, reader resource limits ``READER_SAMPLES``, automatic liveliness 1 s) and
participant configuration (discovery lease 1 s). No monitors, no codec, no
identity checks: a payload is 8 bytes of int, or the frame's bytes.
"""

from __future__ import annotations

import json
import os
import struct
import time
from pathlib import Path
from typing import Any

import numpy as np
from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.core import InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from anodize import Endpoint
from anodize._transport.dds import READER_SAMPLES, Frame, cdr_sample, participant_config

ENV = "ANODIZE_BENCH_DDS"
HEIGHT, WIDTH, CHANNELS = 480, 640, 3
POOL = 8  # distinct frames the sender cycles through (made before the clock starts)
LEASE = 1.0  # seconds: liveliness and discovery lease, as the transport's default
WRITE_BLOCK = duration(milliseconds=2)
TAKE = 32
TIMEOUT_RET = -10  # DDS_RETCODE_TIMEOUT
ANY = SampleState.Any | ViewState.Any | InstanceState.Any
INT = struct.Struct("<q")
STOP = -1  # the raw streams' and ping-pong's last message


def config() -> dict[str, Any]:
    return json.loads(os.environ[ENV])  # type: ignore[no-any-return]


def report(name: str, data: dict[str, Any], out: str | None = None) -> None:
    """Write ``data`` where the parent will look for it (atomically: write, then rename)."""
    folder = Path(out if out is not None else config()["out"])
    tmp = folder / f".{name}.json"
    tmp.write_text(json.dumps(data), encoding="utf-8")
    tmp.rename(folder / f"{name}.json")


# ---- frames, shared by every way -----------------------------------------------------------
def frame_pool() -> list[np.ndarray]:
    rng = np.random.default_rng(2024)
    return [rng.integers(0, 256, size=(HEIGHT, WIDTH, CHANNELS), dtype=np.uint8) for _ in range(POOL)]


def stamp(pixels: np.ndarray, index: int) -> np.ndarray:
    """Number the frame in its first 8 bytes (the receiver checks order with it)."""
    pixels.reshape(-1)[:8] = np.frombuffer(index.to_bytes(8, "little"), np.uint8)
    return pixels


class FrameSink:
    """What every receiver does with a frame: check its number, sum every 96th row, count."""

    def __init__(self) -> None:
        self.count = 0
        self.bad = 0
        self.touched = 0

    def take(self, pixels: np.ndarray) -> None:
        if pixels.shape != (HEIGHT, WIDTH, CHANNELS) or int.from_bytes(pixels.reshape(-1)[:8].tobytes(),
                                                                       "little") != self.count:
            self.bad += 1
        self.touched += int(pixels[::96].sum(dtype=np.uint64))
        self.count += 1


# ---- anodize roles -------------------------------------------------------------------------
def int_producer(ep: Endpoint) -> None:
    n = config()["messages"]
    report("start", {"start": time.monotonic()})
    for i in range(n):
        ep.send("C", "data", i)
    ep.send("C", "stop")


def int_batch_producer(ep: Endpoint) -> None:
    """As int_producer, in batches of 1,000 (``Endpoint.send_many``)."""
    n = config()["messages"]
    report("start", {"start": time.monotonic()})
    for first in range(0, n, 1000):
        ep.send_many("C", "data", range(first, min(n, first + 1000)))
    ep.send("C", "stop")


def int_consumer(ep: Endpoint) -> None:
    count = bad = 0
    while (message := ep.recv("P")).label == "data":
        if message.payload != count:
            bad += 1
        count += 1
    report("end", {"end": time.monotonic(), "count": count, "bad": bad})


def int_batch_consumer(ep: Endpoint) -> None:
    """As int_consumer, taking what has arrived in batches (``Endpoint.recv_many``)."""
    count = bad = 0
    while True:
        for message in ep.recv_many("P", 1024):
            if message.label != "data":
                report("end", {"end": time.monotonic(), "count": count, "bad": bad})
                return
            if message.payload != count:
                bad += 1
            count += 1


def frame_producer(ep: Endpoint) -> None:
    n = config()["frames"]
    pool = frame_pool()
    report("start", {"start": time.monotonic()})
    for i in range(n):
        ep.send("C", "frame", stamp(pool[i % POOL], i))
    ep.send("C", "stop")


def frame_consumer(ep: Endpoint) -> None:
    sink = FrameSink()
    while (message := ep.recv("P")).label == "frame":
        sink.take(message.payload)
    report("end", {"end": time.monotonic(), "count": sink.count, "bad": sink.bad})


def ping_client(ep: Endpoint) -> None:
    cfg = config()
    for i in range(cfg["warmup"]):
        ep.send("B", "ping", i)
        ep.recv("B")
    n = cfg["rounds"]
    start = time.perf_counter()
    for i in range(n):
        ep.send("B", "ping", i)
        ep.recv("B")
    seconds = time.perf_counter() - start
    ep.send("B", "stop")
    report("pingpong", {"rounds": n, "seconds": seconds})


def ping_server(ep: Endpoint) -> None:
    while (message := ep.recv("A")).label == "ping":
        ep.send("A", "pong", message.payload)


# ---- raw Cyclone DDS -----------------------------------------------------------------------
class RawPeer:
    """One process's end of the raw baseline: a participant, a writer and/or a reader.

    Topics are ``<prefix>/<name>`` of type ``anodize::Frame``, with the transport's QoS.
    """

    def __init__(self, domain: int, prefix: str, write: str | None, read: str | None, bounded: bool = True) -> None:
        previous = os.environ.get("CYCLONEDDS_URI", "")
        os.environ["CYCLONEDDS_URI"] = ",".join(p for p in (previous, participant_config(LEASE)) if p)
        self.participant = DomainParticipant(domain)
        lease = duration(seconds=LEASE)
        self.writer: DataWriter[Frame] | None = None
        self.reader: DataReader[Frame] | None = None
        if write is not None:
            qos = Qos(Policy.Reliability.Reliable(WRITE_BLOCK), Policy.History.KeepAll,
                      Policy.Liveliness.Automatic(lease))
            self.writer = DataWriter(self.participant, Topic(self.participant, f"{prefix}/{write}", Frame), qos=qos)
            self._wref = self.writer._ref
        if read is not None:
            # Unbounded: Cyclone's own default, a reader that holds whatever arrives (no back pressure).
            limits = [Policy.ResourceLimits(max_samples=READER_SAMPLES)] if bounded else []
            qos = Qos(Policy.Reliability.Reliable(WRITE_BLOCK), Policy.History.KeepAll, *limits,
                      Policy.Liveliness.Automatic(lease))
            self.reader = DataReader(self.participant, Topic(self.participant, f"{prefix}/{read}", Frame), qos=qos)
            self._rref = self.reader._ref
            self.waitset = WaitSet(self.participant)
            self.waitset.attach(ReadCondition(self.reader, ANY))
        self.pending: list[bytes] = []

    def wait_matched(self, seconds: float) -> None:
        """Until the writer has a reader and the reader a writer (bounded).

        Raises:
            TimeoutError: the other end did not appear within ``seconds``.
        """
        deadline = time.monotonic() + seconds
        while True:
            ok = (self.writer is None or self.writer.get_publication_matched_status().current_count > 0) and (
                self.reader is None or self.reader.get_subscription_matched_status().current_count > 0)
            if ok:
                return
            if time.monotonic() > deadline:
                raise TimeoutError(f"raw DDS peer did not match within {seconds:g} s")
            time.sleep(0.01)

    def write(self, sample: bytes, give_up: float) -> None:
        """Write CDR bytes; while the reader is full, retry in short sleeps (as the transport).

        Raises:
            RuntimeError: the write failed, or found no room before ``give_up`` (monotonic).
        """
        pause = 0.0002
        while True:
            ret = ddspy_write(self._wref, sample)
            if ret == 0:
                return
            if ret != TIMEOUT_RET:
                raise RuntimeError(f"ddspy_write failed: {ret}")
            if time.monotonic() > give_up:
                raise RuntimeError("ddspy_write: no room until the deadline")
            time.sleep(pause)
            pause = min(pause * 2, 0.005)

    def take(self, give_up: float) -> bytes:
        """The next sample's CDR bytes (waiting on the WaitSet).

        Raises:
            RuntimeError: the take failed, or nothing came before ``give_up`` (monotonic).
        """
        while not self.pending:
            taken = ddspy_take(self._rref, ANY, TAKE)
            if type(taken) is int:
                raise RuntimeError(f"ddspy_take failed: {taken}")
            self.pending = [data for data, info in taken if info.valid_data][::-1]
            if self.pending:
                break
            left = give_up - time.monotonic()
            if left <= 0:
                raise RuntimeError("ddspy_take: nothing arrived until the deadline")
            self.waitset.wait(duration(seconds=min(left, 0.05)))
        return self.pending.pop()

    def flush(self, seconds: float = 5.0) -> None:
        """Wait (bounded) until the reader has acknowledged everything written."""
        if self.writer is not None:
            self.writer.wait_for_acks(duration(seconds=seconds))


def _int_of(sample: bytes) -> int:
    value: int = INT.unpack_from(sample, 8)[0]  # 4 bytes encapsulation, 4 bytes sequence length
    return value


def raw_int_producer(domain: int, prefix: str, barrier: Any, n: int, out: str, timeout: float,
                     bounded: bool = True) -> None:
    peer = RawPeer(domain, prefix, "data", None, bounded)
    peer.wait_matched(timeout)
    barrier.wait(timeout)
    give_up = time.monotonic() + timeout
    report("start", {"start": time.monotonic()}, out)
    for i in range(n):
        peer.write(cdr_sample(INT.pack(i)), give_up)
    peer.write(cdr_sample(INT.pack(STOP)), give_up)
    peer.flush()


def raw_int_consumer(domain: int, prefix: str, barrier: Any, n: int, out: str, timeout: float,
                     bounded: bool = True) -> None:
    peer = RawPeer(domain, prefix, None, "data", bounded)
    peer.wait_matched(timeout)
    barrier.wait(timeout)
    give_up = time.monotonic() + timeout
    count = bad = 0
    while (value := _int_of(peer.take(give_up))) != STOP:
        if value != count:
            bad += 1
        count += 1
    report("end", {"end": time.monotonic(), "count": count, "bad": bad}, out)


def raw_frame_producer(domain: int, prefix: str, barrier: Any, n: int, out: str, timeout: float,
                       bounded: bool = True) -> None:
    peer = RawPeer(domain, prefix, "frames", None, bounded)
    pool = frame_pool()
    peer.wait_matched(timeout)
    barrier.wait(timeout)
    give_up = time.monotonic() + timeout
    report("start", {"start": time.monotonic()}, out)
    for i in range(n):
        peer.write(cdr_sample(stamp(pool[i % POOL], i).reshape(-1).data), give_up)  # type: ignore[arg-type]
    peer.write(cdr_sample(INT.pack(STOP)), give_up)
    peer.flush()


def raw_frame_consumer(domain: int, prefix: str, barrier: Any, n: int, out: str, timeout: float,
                       bounded: bool = True) -> None:
    peer = RawPeer(domain, prefix, None, "frames", bounded)
    peer.wait_matched(timeout)
    barrier.wait(timeout)
    give_up = time.monotonic() + timeout
    sink = FrameSink()
    size = HEIGHT * WIDTH * CHANNELS
    while len(sample := peer.take(give_up)) >= 8 + size:
        sink.take(np.frombuffer(sample, np.uint8, count=size, offset=8).reshape(HEIGHT, WIDTH, CHANNELS))
    report("end", {"end": time.monotonic(), "count": sink.count, "bad": sink.bad}, out)


def raw_ping_client(domain: int, prefix: str, barrier: Any, rounds: int, warmup: int, out: str,
                    timeout: float) -> None:
    peer = RawPeer(domain, prefix, "ping", "pong")
    peer.wait_matched(timeout)
    barrier.wait(timeout)
    give_up = time.monotonic() + timeout
    for i in range(warmup):
        peer.write(cdr_sample(INT.pack(i)), give_up)
        peer.take(give_up)
    start = time.perf_counter()
    for i in range(rounds):
        peer.write(cdr_sample(INT.pack(i)), give_up)
        peer.take(give_up)
    seconds = time.perf_counter() - start
    peer.write(cdr_sample(INT.pack(STOP)), give_up)
    peer.flush()
    report("pingpong", {"rounds": rounds, "seconds": seconds}, out)


def raw_ping_server(domain: int, prefix: str, barrier: Any, out: str, timeout: float) -> None:
    peer = RawPeer(domain, prefix, "pong", "ping")
    peer.wait_matched(timeout)
    barrier.wait(timeout)
    give_up = time.monotonic() + timeout
    while (value := _int_of(peer.take(give_up))) != STOP:
        peer.write(cdr_sample(INT.pack(value)), give_up)
    peer.flush()
