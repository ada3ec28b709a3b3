"""What priority inheritance costs: the receive fast path (a message already waiting) with and
without the inheritance hook, and one boost episode (lend, then take back: two scheduling
calls on the target thread and the table's locks). Imported by bench/inversion.py."""

from __future__ import annotations

import os
import threading
import time
from typing import Any

import sessiontypes
from anodize._isolation.inherit import BoostTable, RoleSeat
from anodize._session.endpoint import Endpoint
from anodize._transport.inproc import InprocNetwork

_ASK = sessiontypes.loads("global Ask(H, L) = mu t. H -> L : {ask. L -> H : answer. t, stop}",
                          "cost.proto").globals["Ask"]


def _receive_ns(table: BoostTable | None, count: int) -> float:
    """Nanoseconds per ``recv`` of a message already waiting (no monitor: the channel path alone)."""
    network = InprocNetwork([("H", "L"), ("L", "H")])
    network.inheritance = table
    endpoint = Endpoint("H", "Ask", _ASK.project("H").fsm(), network, monitored=False)
    channel = network.queues[("L", "H")]
    best = float("inf")
    for _ in range(5):
        for _ in range(count):
            channel.put(("answer", None))
        start = time.perf_counter_ns()
        for _ in range(count):
            endpoint.recv("L")
        best = min(best, (time.perf_counter_ns() - start) / count)
    return best


def _episode_ns(table: BoostTable, count: int) -> float:
    """Nanoseconds per boost episode (lend to a real thread, take back), as a blocking wait pays it."""
    ready, done = threading.Event(), threading.Event()

    def target() -> None:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))  # below the waiter: a boost to lend
        table.enter("L")
        ready.set()
        done.wait(60)  # blocks: nothing spins
        table.leave("L")

    thread = threading.Thread(target=target)
    thread.start()
    ready.wait(10)
    try:
        start = time.perf_counter_ns()
        for _ in range(count):
            with table.waiting("H", "L"):
                pass
        return (time.perf_counter_ns() - start) / count
    finally:
        done.set()
        thread.join(10)


def measure(count: int = 20_000) -> dict[str, Any]:
    """The receive fast path with and without the hook, and a boost episode, in nanoseconds."""
    seats = [RoleSeat("H", 90, True), RoleSeat("L", 10, True)]
    table = BoostTable.create(seats)
    before = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(90))  # the waiter must be under FIFO to lend
        table.enter("H")
        _receive_ns(table, count // 10)  # untimed: the first endpoint built pays for what the others find warm
        plain = min(_receive_ns(None, count), _receive_ns(None, count))
        hooked = min(_receive_ns(table, count), _receive_ns(table, count))
        episode = _episode_ns(table, max(1, count // 10))
        lent = table.boosts().get(("H", "L"))
    finally:
        table.leave("H")
        os.sched_setscheduler(0, before[0], before[1])
        table.close()
    return {"recv_plain_ns": plain, "recv_hooked_ns": hooked, "episode_ns": episode,
            "episodes_counted": 0 if lent is None else lent.episodes}
