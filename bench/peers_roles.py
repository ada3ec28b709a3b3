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

Each peer is written the way its documentation suggests for the job, as directly as it goes:
pyzmq sends 8-byte ints and frames from the array's buffer (``copy=False``);
``multiprocessing`` pickles ints (``Connection.send``, ``Queue.put``) and sends frames as
bytes (``send_bytes``); ``os.pipe`` writes 8 bytes each way.
"""

from __future__ import annotations

import os
import struct
import time
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


# ---- streams of small ints --------------------------------------------------------------------
def zmq_pair(address: str, bind: bool, context: Any = None) -> tuple[Any, Any]:
    """A context (``context``, or a new one) and a PAIR socket bound or connected to ``address``."""
    context = context or zmq.Context()
    sock = context.socket(zmq.PAIR)
    if bind:
        sock.bind(address)
    else:
        sock.connect(address)
    return context, sock


def zmq_produce(sock: Any, n: int) -> float:
    """Wait for the consumer's go, then send ``n`` ints and an empty end; the clock at the start."""
    sock.recv()
    send, pack = sock.send, INT.pack
    start = time.monotonic()
    for i in range(n):
        send(pack(i))
    send(b"")
    return start


def zmq_consume(sock: Any) -> dict[str, Any]:
    """Say go (the send waits for the producer to connect), then count until the empty end."""
    sock.send(b"go")
    recv, unpack = sock.recv, INT.unpack
    count = bad = 0
    while data := recv():
        if unpack(data)[0] != count:
            bad += 1
        count += 1
    return {"end": time.monotonic(), "count": count, "bad": bad}


def zmq_stream_producer(address: str, n: int) -> None:
    context, sock = zmq_pair(address, bind=False)
    report("start", {"start": zmq_produce(sock, n)})
    sock.close(linger=-1)  # everything delivered before the context ends
    context.term()


def zmq_stream_consumer(address: str) -> None:
    context, sock = zmq_pair(address, bind=True)
    report("end", zmq_consume(sock))
    sock.close()
    context.term()


def object_producer(channel: Any, method: str, barrier: Any, n: int) -> None:
    """``n`` pickled ints, then None, through ``channel.<method>`` (Connection.send, Queue.put)."""
    send = getattr(channel, method)
    barrier.wait()
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
    barrier.wait()
    count = bad = 0
    while (value := recv()) is not None:
        if value != count:
            bad += 1
        count += 1
    report("end", {"end": time.monotonic(), "count": count, "bad": bad})


# ---- frames -----------------------------------------------------------------------------------
def zmq_frame_source(address: str, n: int) -> None:
    """Each frame as two parts: the header, then the array's own buffer (no copy into a message)."""
    context, sock = zmq_pair(address, bind=False)
    pool = frame_pool()
    sock.recv()
    for i in range(n):
        pixels, check = pool[i % POOL]
        sock.send(HEADER.pack(i, time.monotonic(), check), zmq.SNDMORE)
        sock.send(pixels, copy=False)
    sock.send(b"")
    sock.close(linger=-1)
    context.term()


def zmq_frame_sink(address: str) -> None:
    context, sock = zmq_pair(address, bind=True)
    sink = FrameSink()
    sock.send(b"go")
    while len(parts := sock.recv_multipart(copy=False)) == 2:
        sink.take(Frame(*HEADER.unpack(parts[0].bytes),
                        np.frombuffer(parts[1].buffer, np.uint8).reshape(HEIGHT, WIDTH, CHANNELS)))
    report("frames", sink.result())
    sock.close()
    context.term()


def pipe_frame_source(conn: Any, barrier: Any, n: int) -> None:
    """Each frame as two messages: the header, then the pixels (``send_bytes`` of the array)."""
    pool = frame_pool()
    barrier.wait()
    for i in range(n):
        pixels, check = pool[i % POOL]
        conn.send_bytes(HEADER.pack(i, time.monotonic(), check))
        conn.send_bytes(pixels.reshape(-1))  # one dimension: send_bytes counts the first one
    conn.send_bytes(b"")


def pipe_frame_sink(conn: Any, barrier: Any) -> None:
    sink = FrameSink()
    barrier.wait()
    while header := conn.recv_bytes():
        pixels = np.frombuffer(conn.recv_bytes(), np.uint8).reshape(HEIGHT, WIDTH, CHANNELS)
        sink.take(Frame(*HEADER.unpack(header), pixels))
    report("frames", sink.result())


def memcpy_frames(n: int) -> float:
    """Seconds for ``n`` copies of a pool frame into one preallocated array, in this process."""
    pool = [pixels for pixels, _ in frame_pool()]
    target = np.empty_like(pool[0])
    start = time.perf_counter()
    for i in range(n):
        np.copyto(target, pool[i % POOL])
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
    barrier.wait()

    def one_round(i: int) -> object:
        conn.send(("ping", i))
        return conn.recv()

    found = timed_rounds(one_round, warmup, rounds)
    conn.send(("stop", None))
    report("pingpong", found)


def os_pipe_client(out_end: Any, in_end: Any, barrier: Any, warmup: int, rounds: int) -> None:
    """os.pipe: 8 bytes written, 8 read back. The ends come as Connections (to cross spawn)."""
    w, r = out_end.fileno(), in_end.fileno()
    barrier.wait()
    write, read, pack = os.write, os.read, INT.pack

    def one_round(i: int) -> object:
        write(w, pack(i))
        return read(r, 8)

    found = timed_rounds(one_round, warmup, rounds)
    write(w, STOP)
    report("pingpong", found)


def os_pipe_server(in_end: Any, out_end: Any, barrier: Any) -> None:
    r, w = in_end.fileno(), out_end.fileno()
    barrier.wait()
    while (data := os.read(r, 8)) != STOP:
        os.write(w, data)
