"""Role functions and baseline processes for ``bench/transport.py``.

Module level on purpose: anodize's group processes and the baselines'
``multiprocessing`` processes (spawn context) import them by name. Every
function takes its settings from the JSON in the environment variable
``ANODIZE_BENCH`` (set by the parent before it starts a run; spawned
interpreters inherit the environment) and writes what it measured as JSON to
``<out>/<name>.json``, where the parent reads it after the run.

Clocks: ``time.monotonic()`` is CLOCK_MONOTONIC on Linux, one clock for the
whole machine, so a time taken in one process can be subtracted from a time
taken in another.
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from anodize import Endpoint

ENV = "ANODIZE_BENCH"
HEIGHT, WIDTH, CHANNELS = 480, 640, 3
POOL = 8  # distinct frames the sender cycles through (made before the clock starts)


def config() -> dict[str, Any]:
    return json.loads(os.environ[ENV])  # type: ignore[no-any-return]


def report(name: str, data: dict[str, Any]) -> None:
    """Write ``data`` where the parent will look for it (atomically: write, then rename)."""
    out = Path(config()["out"])
    tmp = out / f".{name}.json"
    tmp.write_text(json.dumps(data), encoding="utf-8")
    tmp.rename(out / f"{name}.json")


# ---- frames ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Frame:
    """One camera frame: its number, when it was sent, a checksum of a few rows, the pixels.

    A dataclass sort (``type Frame = "transport_roles:Frame"``): anodize encodes it
    field by field and the pixels travel through a shared-memory ring. The
    multiprocessing baseline pickles the same object.
    """

    index: int
    sent_at: float
    check: int
    pixels: np.ndarray


def rows_checksum(pixels: np.ndarray) -> int:
    """The receiver's touch of the data: the sum of every 96th row (5 rows, 9,600 bytes)."""
    return int(pixels[::96].sum(dtype=np.uint64))


def frame_pool() -> list[tuple[np.ndarray, int]]:
    rng = np.random.default_rng(2024)
    pool = []
    for _ in range(POOL):
        pixels = rng.integers(0, 256, size=(HEIGHT, WIDTH, CHANNELS), dtype=np.uint8)
        pool.append((pixels, rows_checksum(pixels)))
    return pool


class FrameSink:
    """What both receivers do with each frame: check the rows, count, note the first send."""

    def __init__(self) -> None:
        self.count = 0
        self.first_sent: float | None = None
        self.bad = 0

    def take(self, frame: Frame) -> None:
        if self.first_sent is None:
            self.first_sent = frame.sent_at
        if frame.index != self.count or rows_checksum(frame.pixels) != frame.check:
            self.bad += 1
        self.count += 1

    def result(self) -> dict[str, Any]:
        end = time.monotonic()
        assert self.first_sent is not None
        return {"frames": self.count, "bad": self.bad, "seconds": end - self.first_sent}


def frame_source(ep: Endpoint) -> None:
    """Sends pre-made frames, or (``produce``) fills each frame in a slot from ``ep.buffer``."""
    cfg = config()
    n, produce = cfg["frames"], cfg.get("produce", False)
    pool = frame_pool()
    for i in range(n):
        pixels, check = pool[i % POOL]
        if produce:  # the producer writes the frame where it will travel: no copy after this
            made = ep.buffer("B", pixels.shape, pixels.dtype)
            np.copyto(made, pixels)
            pixels = made
        ep.send("B", "frame", Frame(i, time.monotonic(), check, pixels))
    ep.send("B", "fin")


def frame_sink(ep: Endpoint) -> None:
    sink = FrameSink()
    while (message := ep.recv("A")).label == "frame":
        sink.take(message.payload)
    report("frames", sink.result())


def queue_frame_source(queue: Any, barrier: Any, n: int) -> None:
    pool = frame_pool()
    produce = config().get("produce", False)
    barrier.wait()
    for i in range(n):
        pixels, check = pool[i % POOL]
        if produce:  # a fresh frame each time (Queue.put pickles later, in its feeder thread)
            pixels = pixels.copy()
        queue.put(("frame", Frame(i, time.monotonic(), check, pixels)))
    queue.put(("fin", None))
    queue.close()
    queue.join_thread()  # the feeder thread has written everything


def queue_frame_sink(queue: Any, barrier: Any, n: int) -> None:
    sink = FrameSink()
    barrier.wait()
    while (message := queue.get())[0] == "frame":
        sink.take(message[1])
    report("frames", sink.result())


# ---- round trips ----------------------------------------------------------------------------
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


def pipe_client(conn: Any, barrier: Any, warmup: int, n: int) -> None:
    barrier.wait()
    for i in range(warmup):
        conn.send(("ping", i))
        conn.recv()
    start = time.perf_counter()
    for i in range(n):
        conn.send(("ping", i))
        conn.recv()
    seconds = time.perf_counter() - start
    conn.send(("stop", None))
    report("pingpong", {"rounds": n, "seconds": seconds})


def pipe_server(conn: Any, barrier: Any) -> None:
    barrier.wait()
    while (message := conn.recv())[0] == "ping":
        conn.send(("pong", message[1]))


# ---- jitter ---------------------------------------------------------------------------------
PERIOD = 0.01  # 100 Hz


def control_loop(ep: Endpoint) -> None:
    """Wake up every 10 ms on an absolute schedule; record how late each wake-up was (ms)."""
    cfg = config()
    ticks = round(cfg["jitter_seconds"] / PERIOD)
    lateness = []
    monotonic, sleep = time.monotonic, time.sleep
    start = monotonic()
    for i in range(1, ticks + 1):
        scheduled = start + i * PERIOD
        now = monotonic()
        if scheduled > now:
            sleep(scheduled - now)
        lateness.append((monotonic() - scheduled) * 1e3)
    for burner in cfg["burners"]:
        ep.send(burner, "stop")
    report("control", {"lateness_ms": lateness, "period_s": PERIOD,
                       "policy": _policy_of_this_thread()})


def burner(ep: Endpoint) -> None:
    """Keep one CPU busy (when told to burn) until the control loop says stop.

    The spinning runs in a plain thread this role starts (it inherits the group's
    scheduling); the role's own thread waits in ``recv``, then sets the event. The
    spinning hashes a 1 MiB buffer: hashlib releases the GIL for large inputs, so the
    burners of one group really run on one CPU each instead of taking turns at the GIL.
    Between hashes it calls ``sched_yield``: at SCHED_FIFO a thread is never preempted by
    one of its own priority, so without it the role thread, woken by the stop message,
    could not run on a CPU the spinner holds (the CPU stays just as busy: the spinner is
    picked again at once when nothing else of its priority is waiting).
    """
    cfg = config()
    stop = threading.Event()
    loops = [0]

    def spin() -> None:
        data = bytes(2**20)
        count = 0
        while not stop.is_set():
            hashlib.sha256(data)  # about 3 ms of C code without the GIL
            os.sched_yield()  # lets this role's own thread (same priority) take the stop
            count += 1
        loops[0] = count

    wall, cpu = time.monotonic(), time.process_time()
    thread = threading.Thread(target=spin, name=f"burn:{ep.role}", daemon=True)
    if cfg["burn"]:
        thread.start()
    ep.recv("C")
    stop.set()
    if cfg["burn"]:
        thread.join()
    report(f"burner-{ep.role}", {"wall_s": time.monotonic() - wall,
                                 "process_cpu_s": time.process_time() - cpu, "loops": loops[0],
                                 "burned": bool(cfg["burn"])})


def _policy_of_this_thread() -> str:
    policy = os.sched_getscheduler(0)
    names = {os.SCHED_OTHER: "SCHED_OTHER", os.SCHED_FIFO: "SCHED_FIFO", os.SCHED_RR: "SCHED_RR"}
    priority, nice = os.sched_getparam(0).sched_priority, os.getpriority(os.PRIO_PROCESS, 0)
    return f"{names.get(policy, policy)} {priority} nice {nice}"
