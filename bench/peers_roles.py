"""Role functions and peer processes for ``bench/peers.py``.

Module level on purpose: anodize's group processes and the peers' ``multiprocessing``
processes (spawn context) import them by name. Settings and results go as in
``bench/transport_roles.py`` (whose ``config``, ``report``, ``Frame``, ``FrameSink`` and
``frame_pool`` these use): JSON in ``$ANODIZE_BENCH`` names an output folder, and every
measuring function writes what it measured to ``<out>/<name>.json``.

Streams of small ints report ``start.json`` (the producer's clock just before its first
send) and ``end.json`` (the consumer's after the last receipt, with the count and how many
arrived out of order), as ``bench/dds_roles.py`` does, so ``dds._one_way`` reads both.
Clocks: ``time.monotonic()`` is CLOCK_MONOTONIC on Linux, one clock for the machine.

Each peer is written the way its documentation suggests for the job, as directly as it goes
(docs/performance.md says why each is its best use): pyzmq sends 8-byte ints and frames from
the array's buffer (``copy=False``), over ``inproc://`` PAIR between threads and ``ipc://``
PUSH/PULL between processes; ``multiprocessing`` pickles ints (``Connection.send``,
``Queue.put``) and sends frames as bytes (``send_bytes``); ``os.pipe`` writes 8 bytes each
way; iceoryx2 is in ``bench/peers_iceoryx.py``.

Every wait a peer makes on the other is bounded: sockets and barriers by ``TIMEOUT``, the
blocking reads of pipes and queues by the parent, which kills a run that outlives
``--timeout``. The parent starts each peer process through :func:`guarded`, so a failed run
is recorded with its cause.
"""

from __future__ import annotations

import importlib
import os
import struct
import time
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np
import zmq
from transport_roles import CHANNELS, HEIGHT, POOL, WIDTH, Frame, FrameSink, config, frame_pool, report

from anodize import Endpoint

INT = struct.Struct("<q")
STOP = INT.pack(-1)  # os.pipe's last ping
HEADER = struct.Struct("<qdq")  # a frame's index, send time and row checksum, before its pixels
FRAME_BYTES = HEIGHT * WIDTH * CHANNELS


# ---- every peer process -----------------------------------------------------------------------
TIMEOUT = 60.0  # seconds any one wait of a peer may take: a lost message fails the run, never hangs it


def guarded(target: str, *args: Any) -> None:
    """Run ``module:function`` with ``args``; if it raises, report why as ``error-<function>.json``
    (the parent puts it in the failed repetition's record) and exit with an error."""
    module, name = target.split(":")
    try:
        getattr(importlib.import_module(module), name)(*args)
    except BaseException as error:
        report(f"error-{name}", {"error": f"{type(error).__name__}: {error}", "traceback": traceback.format_exc()})
        raise


# ---- streams of small ints --------------------------------------------------------------------
def zmq_socket(context: Any, kind: int, address: str, bind: bool) -> Any:
    """A socket of ``kind`` bound or connected to ``address``, whose every wait is bounded:
    a send or receive that cannot finish in ``TIMEOUT`` s raises ``zmq.Again``, and closing it
    waits at most that long for its queue to drain."""
    sock = context.socket(kind)
    try:
        for option in (zmq.RCVTIMEO, zmq.SNDTIMEO, zmq.LINGER):
            sock.setsockopt(option, int(TIMEOUT * 1000))
        if bind:
            sock.bind(address)
        else:
            sock.connect(address)
    except BaseException:
        sock.close(linger=0)
        raise
    return sock


def zmq_produce(send: Callable[[bytes], Any], n: int) -> float:
    """Send ``n`` ints and an empty end; the clock at the start."""
    pack = INT.pack
    start = time.monotonic()
    for i in range(n):
        send(pack(i))
    send(b"")
    return start


def zmq_consume(recv: Callable[[], bytes]) -> dict[str, Any]:
    """Count until the empty end; the clock after it."""
    unpack = INT.unpack
    count = bad = 0
    while data := recv():
        if unpack(data)[0] != count:
            bad += 1
        count += 1
    return {"end": time.monotonic(), "count": count, "bad": bad}


def zmq_inproc_producer(sock: Any, n: int) -> float:
    """inproc PAIR (the pattern ZeroMQ designs for threads): the consumer's "go", then the stream."""
    sock.recv()
    return zmq_produce(sock.send, n)


def zmq_inproc_consumer(sock: Any) -> dict[str, Any]:
    sock.send(b"go")  # waits (bounded) until the producer's socket is connected
    return zmq_consume(sock.recv)


def zmq_stream_producer(address: str, barrier: Any, n: int) -> None:
    """ipc PUSH: a ``hello`` that proves the connection, the barrier, then the stream; then the
    barrier again, which the consumer reaches once it has the end."""
    # The second barrier keeps the socket open until the consumer has everything. Closing it
    # right after the last send lost the stream's tail (2026-11-27, 10 of 100 streams of 2000):
    # the producer was done in 2-7 ms, the consumer got between 1000 and 1981 of the 2001
    # messages, then nothing until its timeout. LINGER did not prevent it.
    # Leaving the block closes the socket, then ends the context (bounded by LINGER), on an error too.
    with zmq.Context() as context, zmq_socket(context, zmq.PUSH, address, bind=False) as sock:
        sock.send(b"hello")
        barrier.wait(TIMEOUT)
        start = zmq_produce(sock.send, n)
        barrier.wait(TIMEOUT)
        report("start", {"start": start})


def zmq_stream_consumer(address: str, barrier: Any) -> None:
    with zmq.Context() as context, zmq_socket(context, zmq.PULL, address, bind=True) as sock:
        sock.recv()  # the producer's hello: connected
        barrier.wait(TIMEOUT)
        end = zmq_consume(sock.recv)
        barrier.wait(TIMEOUT)  # everything arrived: the producer may close
        report("end", end)


def object_producer(channel: Any, method: str, barrier: Any, n: int) -> None:
    """``n`` pickled ints, then None, through ``channel.<method>`` (Connection.send, Queue.put)."""
    send = getattr(channel, method)
    barrier.wait(TIMEOUT)
    start = time.monotonic()
    for i in range(n):
        send(i)
    send(None)
    report("start", {"start": start})
    if method == "put":  # a Queue: its feeder thread has written everything
        channel.close()
        channel.join_thread()


def object_consumer(channel: Any, method: str, barrier: Any) -> None:
    recv = getattr(channel, method)
    barrier.wait(TIMEOUT)
    count = bad = 0
    while (value := recv()) is not None:
        if value != count:
            bad += 1
        count += 1
    report("end", {"end": time.monotonic(), "count": count, "bad": bad})


# ---- frames -----------------------------------------------------------------------------------
def zmq_frame_source(address: str, barrier: Any, n: int) -> None:
    """ipc PUSH, each frame as two parts: the header, then the array's own buffer (``copy=False``:
    libzmq sends from the array, no copy into a message)."""
    pool = frame_pool()
    with zmq.Context() as context, zmq_socket(context, zmq.PUSH, address, bind=False) as sock:
        sock.send(b"hello")
        barrier.wait(TIMEOUT)
        for i in range(n):
            pixels, check = pool[i % POOL]
            sock.send(HEADER.pack(i, time.monotonic(), check), zmq.SNDMORE)
            sock.send(pixels, copy=False)
        sock.send(b"")
        barrier.wait(TIMEOUT)  # the sink has the end: closing now loses nothing (zmq_stream_producer)


def zmq_frame_sink(address: str, barrier: Any) -> None:
    sink = FrameSink()
    with zmq.Context() as context, zmq_socket(context, zmq.PULL, address, bind=True) as sock:
        sock.recv()
        barrier.wait(TIMEOUT)
        while len(parts := sock.recv_multipart(copy=False)) == 2:
            sink.take(Frame(*HEADER.unpack(parts[0].bytes),
                            np.frombuffer(parts[1].buffer, np.uint8).reshape(HEIGHT, WIDTH, CHANNELS)))
        barrier.wait(TIMEOUT)
    report("frames", sink.result())


def pipe_frame_source(conn: Any, barrier: Any, n: int) -> None:
    """Each frame as two messages: the header, then the pixels (``send_bytes`` of the array)."""
    pool = frame_pool()
    barrier.wait(TIMEOUT)
    for i in range(n):
        pixels, check = pool[i % POOL]
        conn.send_bytes(HEADER.pack(i, time.monotonic(), check))
        conn.send_bytes(pixels.reshape(-1))  # one dimension: send_bytes counts the first one
    conn.send_bytes(b"")


def pipe_frame_sink(conn: Any, barrier: Any) -> None:
    sink = FrameSink()
    barrier.wait(TIMEOUT)
    while header := conn.recv_bytes():
        pixels = np.frombuffer(conn.recv_bytes(), np.uint8).reshape(HEIGHT, WIDTH, CHANNELS)
        sink.take(Frame(*HEADER.unpack(header), pixels))
    report("frames", sink.result())


def memcpy_frames(n: int, pool_target: bool = False) -> float:
    """Seconds for ``n`` copies of a pool frame into one preallocated array, in this process
    (``pool_target``: into the next of ``POOL`` preallocated arrays in turn, as a ring of slots
    is filled, so the destination does not stay in the CPU's cache)."""
    pool = [pixels for pixels, _ in frame_pool()]
    targets = [np.empty_like(pool[0]) for _ in range(POOL if pool_target else 1)]
    for target in targets:
        target.fill(0)  # touched once: no first-touch page faults in the timed loop
    start = time.perf_counter()
    for i in range(n):
        np.copyto(targets[i % len(targets)], pool[i % POOL])
    return time.perf_counter() - start


# ---- round trips ------------------------------------------------------------------------------
def timed_rounds(one_round: Callable[[int], object], warmup: int, rounds: int) -> dict[str, Any]:
    """``warmup`` untimed rounds, then ``rounds`` each timed alone: p50, p99, mean and max in us."""
    for i in range(warmup):
        one_round(i)
    clock = time.perf_counter_ns
    took = [0] * rounds
    for i in range(rounds):
        began = clock()
        one_round(i)
        took[i] = clock() - began
    us = np.array(took, dtype=np.float64) / 1e3
    return {"rounds": rounds, "p50_us": float(np.percentile(us, 50)), "p99_us": float(np.percentile(us, 99)),
            "mean_us": float(us.mean()), "max_us": float(us.max())}


def ping_client(ep: Endpoint) -> None:
    """anodize: ``ping(i)`` to B, its ``pong`` back; then ``stop`` (B is transport_roles.ping_server)."""
    cfg = config()

    def one_round(i: int) -> object:
        ep.send("B", "ping", i)
        return ep.recv("B")

    found = timed_rounds(one_round, cfg["warmup"], cfg["rounds"])
    ep.send("B", "stop")
    report("pingpong", found)


def pipe_client(conn: Any, barrier: Any, warmup: int, rounds: int) -> None:
    """multiprocessing.Pipe: the tuples of transport_roles.pipe_server, ``("ping", i)`` and back."""
    barrier.wait(TIMEOUT)

    def one_round(i: int) -> object:
        conn.send(("ping", i))
        return conn.recv()

    found = timed_rounds(one_round, warmup, rounds)
    conn.send(("stop", None))
    report("pingpong", found)


def os_pipe_client(out_end: Any, in_end: Any, barrier: Any, warmup: int, rounds: int) -> None:
    """os.pipe: 8 bytes written, 8 read back. The ends come as Connections (to cross spawn)."""
    w, r = out_end.fileno(), in_end.fileno()
    barrier.wait(TIMEOUT)
    write, read, pack = os.write, os.read, INT.pack

    def one_round(i: int) -> object:
        write(w, pack(i))
        return read(r, 8)

    found = timed_rounds(one_round, warmup, rounds)
    write(w, STOP)
    report("pingpong", found)


def os_pipe_server(in_end: Any, out_end: Any, barrier: Any) -> None:
    r, w = in_end.fileno(), out_end.fileno()
    barrier.wait(TIMEOUT)
    while (data := os.read(r, 8)) != STOP:
        os.write(w, data)
