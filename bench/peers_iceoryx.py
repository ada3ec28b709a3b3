"""iceoryx2's peer processes for ``bench/peers.py``: a stream, frames and round trips.

Module level on purpose: the spawned processes import these functions by name. Settings
and results go as in ``bench/peers_roles.py`` (``report`` into ``$ANODIZE_BENCH``'s folder).

iceoryx2 is configured for each job the way its authors' examples and defaults suggest, and
for a lossless comparison with anodize (which never drops a message):

- **No loss.** Every service is made with ``enable_safe_overflow(False)`` (iceoryx2's default
  overwrites the oldest sample in a full subscriber buffer) and every publisher with
  ``BackpressureStrategy.RetryUntilDelivered``: a publisher whose subscriber's buffer is full
  waits, as anodize's sender does.
- **Start.** A publisher delivers only to subscribers it has connected to, and a subscriber
  that has not yet opened its side of the connection is not waited for: in trials, samples
  sent right after both ports existed were dropped once the subscriber's buffer filled.
  So each side proves the connection before the clock starts: the publisher sends a ``HELLO``
  sample until ``send`` says a subscriber took it, the subscriber reads until it has it, and
  then both meet at a ``multiprocessing.Barrier``.
- **Payloads.** Fixed-size ``ctypes`` types (``c_int64``; a frame as one ``Structure``), the
  binding's zero-copy path: ``loan_uninit()``, write through ``payload_ptr``, ``assume_init()``,
  ``send()``; the receiver reads through ``Sample.payload_ptr`` without a copy.
- **Waiting.** Streams and frames poll ``receive()`` (iceoryx2's own benchmarks poll; both
  sides are busy anyway). Round trips are measured both ways: polling, and sleeping on an
  event service (``Notifier.notify`` after each send, ``Listener.timed_wait`` when empty; a
  wake with no event is possible and is not a timeout: ``receive`` again, until the deadline).

Every wait is bounded (``TIMEOUT`` s): a peer that stops answering makes the other raise.
"""

from __future__ import annotations

import ctypes
import os
import time
from collections.abc import Callable
from typing import Any

import iceoryx2 as iox2
import numpy as np
from peers_roles import timed_rounds
from transport_roles import CHANNELS, HEIGHT, POOL, WIDTH, Frame, FrameSink, frame_pool, report

HELLO, STOP = -2, -1
TIMEOUT = 60.0  # seconds any one wait may take
STREAM_BUFFER = 1024  # the subscriber's buffer: the producer runs ahead by at most this many
FRAME_BUFFER = 4  # frames in flight, as anodize's frame slots
FRAME_BYTES = HEIGHT * WIDTH * CHANNELS
_Pixels = ctypes.c_uint8 * FRAME_BYTES


class FrameSample(ctypes.Structure):
    """A frame as one fixed-size payload: its index, send time, row checksum and pixels."""

    _fields_ = [("index", ctypes.c_int64), ("sent_at", ctypes.c_double), ("check", ctypes.c_int64),
                ("pixels", _Pixels)]

    @staticmethod
    def type_name() -> str:
        return "peers::FrameSample"


_PIXELS_AT = FrameSample.pixels.offset
_Int = ctypes.c_int64


def _node() -> Any:
    iox2.set_log_level(iox2.LogLevel.Error)  # "no config file was loaded" is expected, not news
    return iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)


def _service(node: Any, name: str, payload: Any, buffer: int) -> Any:
    return (node.service_builder(iox2.ServiceName.new(name)).publish_subscribe(payload)
            .enable_safe_overflow(False).history_size(0).subscriber_max_buffer_size(buffer)
            .subscriber_max_borrowed_samples(2).max_publishers(1).max_subscribers(1).open_or_create())


def _publisher(service: Any) -> Any:
    return (service.publisher_builder().backpressure_strategy(iox2.BackpressureStrategy.RetryUntilDelivered)
            .max_loaned_samples(2).create())


def _deadline_check(what: str) -> Callable[[], None]:
    deadline = time.monotonic() + TIMEOUT

    def check() -> None:
        if time.monotonic() > deadline:
            raise TimeoutError(f"iceoryx2: {what} for {TIMEOUT:.0f} s")
    return check


def _send_int(publisher: Any, value: int) -> int:
    sample = publisher.loan_uninit()
    _Int.from_address(sample.payload_ptr).value = value
    return int(sample.assume_init().send())


def _hello(publisher: Any) -> None:
    """Send ``HELLO`` until a subscriber has taken it: the connection exists from here on."""
    check = _deadline_check("no subscriber connected")
    while _send_int(publisher, HELLO) < 1:
        check()
        time.sleep(0.001)
        publisher.update_connections()


def _wait_hello(subscriber: Any) -> None:
    check = _deadline_check("no HELLO from the publisher")
    while True:
        sample = subscriber.receive()
        if sample is None:
            check()
            time.sleep(0.0001)
        elif _Int.from_address(sample.payload_ptr).value == HELLO:
            return


def _receive(subscriber: Any, what: str) -> Callable[[], Any]:
    """``receive`` that polls until a sample comes, checking the deadline now and then."""
    receive = subscriber.receive

    def take() -> Any:
        sample = receive()
        if sample is not None:
            return sample
        check = _deadline_check(what)
        spins = 0
        while (sample := receive()) is None:
            spins += 1
            if not spins & 0x3FFF:
                check()
        return sample
    return take


# ---- a stream of small ints -------------------------------------------------------------------
def stream_producer(name: str, barrier: Any, n: int) -> None:
    node = _node()
    publisher = _publisher(_service(node, name, ctypes.c_int64, STREAM_BUFFER))
    _hello(publisher)
    barrier.wait(TIMEOUT)
    loan, at = publisher.loan_uninit, _Int.from_address
    start = time.monotonic()
    for i in range(n):
        sample = loan()
        at(sample.payload_ptr).value = i
        sample.assume_init().send()
    _send_int(publisher, STOP)
    report("start", {"start": start})


def stream_consumer(name: str, barrier: Any) -> None:
    node = _node()
    subscriber = _service(node, name, ctypes.c_int64, STREAM_BUFFER).subscriber_builder().buffer_size(
        STREAM_BUFFER).create()
    _wait_hello(subscriber)
    barrier.wait(TIMEOUT)
    take, at = _receive(subscriber, "the stream stopped"), _Int.from_address
    count = bad = 0
    while True:
        sample = take()  # held while it is read: once dropped, the publisher may reuse its memory
        if (value := at(sample.payload_ptr).value) == STOP:
            break
        if value != count:
            bad += 1
        count += 1
    report("end", {"end": time.monotonic(), "count": count, "bad": bad})


# ---- frames -----------------------------------------------------------------------------------
def frame_source(name: str, barrier: Any, n: int) -> None:
    """Each frame written in place into a loaned sample (header fields, then one copy of the pixels)."""
    node = _node()
    service = _service(node, name, FrameSample, FRAME_BUFFER)
    publisher = _publisher(service)
    pool = frame_pool()
    # The HELLO is a frame with index HELLO (the service has one payload type).
    check = _deadline_check("no subscriber connected")
    while True:
        sample = publisher.loan_uninit()
        FrameSample.from_address(sample.payload_ptr).index = HELLO
        if sample.assume_init().send() >= 1:
            break
        check()
        time.sleep(0.001)
        publisher.update_connections()
    barrier.wait(TIMEOUT)
    for i in range(n):
        pixels, row_check = pool[i % POOL]
        sample = publisher.loan_uninit()
        frame = FrameSample.from_address(sample.payload_ptr)
        frame.index, frame.sent_at, frame.check = i, time.monotonic(), row_check
        np.copyto(np.frombuffer(_Pixels.from_address(sample.payload_ptr + _PIXELS_AT), np.uint8), pixels.reshape(-1))
        sample.assume_init().send()
    sample = publisher.loan_uninit()
    FrameSample.from_address(sample.payload_ptr).index = STOP
    sample.assume_init().send()


def frame_sink(name: str, barrier: Any) -> None:
    """Check each frame's rows in the sample itself (no copy), as the other receivers do."""
    node = _node()
    subscriber = _service(node, name, FrameSample, FRAME_BUFFER).subscriber_builder().buffer_size(
        FRAME_BUFFER).create()
    check = _deadline_check("no HELLO from the publisher")
    while (sample := subscriber.receive()) is None or FrameSample.from_address(sample.payload_ptr).index != HELLO:
        check()
        time.sleep(0.0001)
    del sample
    barrier.wait(TIMEOUT)
    take, sink = _receive(subscriber, "the frames stopped"), FrameSink()
    while True:
        sample = take()
        frame = FrameSample.from_address(sample.payload_ptr)
        if frame.index == STOP:
            break
        pixels = np.frombuffer(_Pixels.from_address(sample.payload_ptr + _PIXELS_AT), np.uint8)
        sink.take(Frame(frame.index, frame.sent_at, frame.check, pixels.reshape(HEIGHT, WIDTH, CHANNELS)))
        del frame, pixels, sample  # the sample goes back to the publisher
    report("frames", sink.result())


# ---- round trips ------------------------------------------------------------------------------
class _Side:
    """One end of a ping-pong: a publisher out, a subscriber in, and (``event``) a notifier and
    a listener so a receiver with nothing to read sleeps until the other side sends."""

    def __init__(self, name: str, out: str, into: str, event: bool) -> None:
        self.node = _node()
        self.publisher = _publisher(_service(self.node, f"{name}/{out}", ctypes.c_int64, 2))
        self.subscriber = _service(self.node, f"{name}/{into}", ctypes.c_int64, 2).subscriber_builder().buffer_size(
            2).create()
        self.notifier = self.listener = None
        if event:
            builder = self.node.service_builder
            self.notifier = builder(iox2.ServiceName.new(f"{name}/{out}/event")).event().open_or_create() \
                .notifier_builder().create()
            self.listener = builder(iox2.ServiceName.new(f"{name}/{into}/event")).event().open_or_create() \
                .listener_builder().create()

    def connect(self, barrier: Any) -> None:
        """Both directions proven (each side's HELLO taken by the other), then the barrier."""
        _hello(self.publisher)
        _wait_hello(self.subscriber)
        barrier.wait(TIMEOUT)

    def send(self, value: int) -> None:
        _send_int(self.publisher, value)
        if self.notifier is not None:
            self.notifier.notify()

    def recv_function(self) -> Callable[[], int]:
        at = _Int.from_address
        if self.listener is None:
            take = _receive(self.subscriber, "no answer")

            def poll() -> int:
                sample = take()  # held while it is read
                return int(at(sample.payload_ptr).value)
            return poll
        receive, wait = self.subscriber.receive, self.listener.timed_wait

        def recv() -> int:
            if (sample := receive()) is None:
                # An empty ``timed_wait`` is not a timeout: iceoryx2's listener can wake with no
                # event (a notifier's wake-up datagram may arrive after this listener already
                # took that notification's event id; twice in ~160,000 waits in trials), so
                # only the deadline ends the wait, and every wake is followed by a ``receive``.
                deadline = time.monotonic() + TIMEOUT
                while (sample := receive()) is None:
                    if (left := deadline - time.monotonic()) <= 0:
                        raise TimeoutError(f"iceoryx2: no answer for {TIMEOUT:.0f} s")
                    wait(iox2.Duration.from_secs_f64(left))
            return int(at(sample.payload_ptr).value)
        return recv


def _pin(cpus: set[int] | None) -> None:
    if cpus:  # a poller on its own CPU: sharing one, the two pollers would take turns
        os.sched_setaffinity(0, cpus)


def ping_client(name: str, event: bool, barrier: Any, warmup: int, rounds: int, cpus: set[int] | None) -> None:
    _pin(cpus)
    side = _Side(name, "ping", "pong", event)
    side.connect(barrier)
    send, recv = side.send, side.recv_function()

    def one_round(i: int) -> object:
        send(i)
        return recv()

    found = timed_rounds(one_round, warmup, rounds)
    send(STOP)
    report("pingpong", found)


def ping_server(name: str, event: bool, barrier: Any, cpus: set[int] | None) -> None:
    _pin(cpus)
    side = _Side(name, "pong", "ping", event)
    side.connect(barrier)
    send, recv = side.send, side.recv_function()
    while (value := recv()) != STOP:
        send(value)
