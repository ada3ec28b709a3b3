"""Role functions and baseline processes for ``bench/spin.py`` (module level: anodize's group
processes and the baselines' spawned processes import them by name).

Each client times every round trip alone (``perf_counter_ns``) and measures the CPU its thread
used (``thread_time``); each server measures its own thread's CPU. Settings come from the JSON in
``ANODIZE_BENCH`` (bench/runs.py's ``bench_env``); results go to ``<out>/<name>.json``.
"""

from __future__ import annotations

import os
import time
from typing import Any

from transport_roles import config, report

from anodize import Endpoint

PROTOCOL = "global PingPong(A, B) = mu t. A -> B : {ping(nat). B -> A : pong(nat). t, stop}"


def _timed(rounds: int, warmup: int, one: Any) -> tuple[list[int], float]:
    for i in range(warmup):
        one(i)
    times = []
    clock = time.perf_counter_ns
    cpu = time.thread_time()
    for i in range(rounds):
        start = clock()
        one(i)
        times.append(clock() - start)
    return times, time.thread_time() - cpu


def client(ep: Endpoint) -> None:
    cfg = config()

    def one(i: int) -> None:
        ep.send("B", "ping", i)
        ep.recv("B")

    times, cpu = _timed(cfg["rounds"], cfg["warmup"], one)
    ep.send("B", "stop")
    report("client", {"times_ns": times, "cpu_s": cpu})


def server(ep: Endpoint) -> None:
    cpu = time.thread_time()
    count = 0
    while (message := ep.recv("A")).label == "ping":
        ep.send("A", "pong", message.payload)
        count += 1
    report("server", {"cpu_s": time.thread_time() - cpu, "rounds": count})


def pipe_client(read_end: Any, write_end: Any, cpu: int, barrier: Any, poll: bool) -> None:
    """``os.pipe``: 8 bytes each way; ``poll``: the reads spin on a non-blocking descriptor."""
    cfg = config()
    os.sched_setaffinity(0, {cpu})
    rfd, wfd = read_end.fileno(), write_end.fileno()
    os.set_blocking(rfd, not poll)
    read = _poll_read if poll else os.read
    barrier.wait()

    def one(i: int) -> None:
        os.write(wfd, i.to_bytes(8, "little"))
        read(rfd, 8)

    times, used = _timed(cfg["rounds"], cfg["warmup"], one)
    report("client", {"times_ns": times, "cpu_s": used})


def pipe_server(read_end: Any, write_end: Any, cpu: int, barrier: Any, poll: bool) -> None:
    os.sched_setaffinity(0, {cpu})
    rfd, wfd = read_end.fileno(), write_end.fileno()
    os.set_blocking(rfd, not poll)
    read = _poll_read if poll else os.read
    barrier.wait()
    used = time.thread_time()
    count = 0
    total = config()["rounds"] + config()["warmup"]
    while count < total:
        data = read(rfd, 8)
        os.write(wfd, data)
        count += 1
    report("server", {"cpu_s": time.thread_time() - used, "rounds": count})


def _poll_read(fd: int, size: int) -> bytes:
    while True:
        try:
            return os.read(fd, size)
        except BlockingIOError:
            continue
