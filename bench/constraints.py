#!/usr/bin/env python3
"""What time and value constraints cost the monitor, and how soon a missed deadline is seen.

Throughput: ``mu t. A -> B : {data(v: float). t, stop}`` streamed over the inproc transport,
--n messages, four ways in the same process and the same repetition loop (interleaved, so
every ratio compares measurements taken side by side):

  unmonitored  ``System(..., monitors=False)``
  monitored    the protocol as written, no constraint (the baseline of the ratios)
  refined      ``data(v: float{abs(v) <= 1.5})``: a refinement checked on send and on arrival
  timed        the same, and ``within 1s`` on data: the sender reads its clock at each send, the
               receiver waits under a deadline each time (a message already there is taken by
               the compiled core; waiting for one is the Python core's)

Times are taken inside the role functions (first send to last receive); the median of
--repeat repetitions and its spread (min, max) are reported, with the ratios to ``monitored``.

Detection latency: a receiver waits for a message due within --within ms that never comes;
how long after the deadline (the monitor's previous action plus the deadline, on the same
clock) the waiting ``recv`` (and ``recv_any``) raises ``DeadlineMissedError``; --misses times
each, median and p99. On an idle machine the issue's bar is 1 ms.

The constraints are put on the state machines directly (as the tests' timed_machines.py does)
until the front end parses the syntax.

Usage:
  .venv/bin/python bench/constraints.py [--n 50000] [--repeat 5] [--misses 200] [--within 5]
      [--json PATH]
"""

from __future__ import annotations

import argparse
import dataclasses
import platform
import statistics
import sys
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from runs import LoadWatch, write_results  # noqa: E402  (bench/runs.py, beside this script)

import sessiontypes  # noqa: E402
from anodize import DeadlineMissedError, Endpoint, System  # noqa: E402
from anodize._transport.inproc import InprocNetwork  # noqa: E402
from sessiontypes import GlobalType, StateMachine  # noqa: E402
from sessiontypes.constraints import Call, Compare, Expr, Number, Timing  # noqa: E402
from sessiontypes.constraints import Path as Name  # noqa: E402
from sessiontypes.declarations import LocalType  # noqa: E402

DEFAULT_JSON = REPO / "bench" / "results" / "constraints.json"
STREAM = "global Stream(A, B) = mu t. A -> B : {data(v: float). t, stop}"
WAIT = "global Wait(A, B, C) = (A -> B : ping. end || C -> B : ping. end)"
LIMIT: Expr = Compare(("<=",), (Call("abs", (Name(("v",)),)), Number(1.5)))
WAYS = ("unmonitored", "monitored", "refined", "timed")
MS = 1_000_000


class _Primed(LocalType):
    """A projection whose machine is given (the constrained one)."""

    __slots__ = ("machine",)

    def fsm(self) -> StateMachine:
        machine: StateMachine = self.machine  # type: ignore[attr-defined]
        return machine


def constrained(text: str, name: str, label: str, timing: Timing | None, refinement: Expr | None) -> GlobalType:
    """The global ``name`` of ``text`` with ``timing`` and ``refinement`` on every ``label``."""
    gt = sessiontypes.loads(text, f"{name.lower()}.proto").globals[name]
    for role in gt.roles:
        local = gt.project(role)
        machine = local.fsm()
        for m in [machine, *(b for branches in machine.forks.values() for b in branches)]:
            for row in m.table:
                for key, t in list(row.items()):
                    if t.label == label:
                        row[key] = dataclasses.replace(t, timing=timing, refinement=refinement)
        primed = _Primed(local.name, local.role, local.body, local.protocol, local.location)
        object.__setattr__(primed, "machine", machine)
        gt.cached_projections[role] = primed
    return gt


def _system(way: str) -> GlobalType:
    if way == "refined":
        return constrained(STREAM, "Stream", "data", None, LIMIT)
    if way == "timed":
        return constrained(STREAM, "Stream", "data", Timing(within=1000 * MS), LIMIT)
    return sessiontypes.loads(STREAM, "stream.proto").globals["Stream"]


def stream_seconds(way: str, n: int) -> float:
    """Seconds from the first send to the last receive of ``n`` messages."""
    clock: dict[str, float] = {}

    def a(ep: Endpoint) -> None:
        clock["start"] = time.perf_counter()
        for i in range(n):
            ep.send("B", "data", {"v": (i % 100) / 100.0})
        ep.send("B", "stop")

    def b(ep: Endpoint) -> None:
        while ep.recv("A").label == "data":
            pass
        clock["end"] = time.perf_counter()

    system = System(_system(way), monitors=way != "unmonitored")
    system.group("g").role("A", a).role("B", b)
    report = system.run(timeout=120)
    if not report.ok:
        raise RuntimeError(report.summary())
    return clock["end"] - clock["start"]


def throughput(n: int, repeat: int) -> dict[str, Any]:
    stream_seconds("timed", max(1000, n // 20))  # warm-up
    samples: dict[str, list[float]] = {way: [] for way in WAYS}
    for _ in range(repeat):
        for way in WAYS:
            samples[way].append(n / stream_seconds(way, n))
    median = {way: statistics.median(rates) for way, rates in samples.items()}
    return {"n": n, "messages_per_second": samples, "median": median,
            "spread": {way: [min(rates), max(rates)] for way, rates in samples.items()},
            "ratio_to_monitored": {way: median[way] / median["monitored"] for way in WAYS},
            "added_us_per_message": {way: (1 / median[way] - 1 / median["monitored"]) * 1e6 for way in WAYS}}


def miss_latency(kind: str, within_ms: int) -> float:
    """Seconds from a deadline to the waiting receiver's DeadlineMissedError (``recv`` or ``recv_any``)."""
    gt = constrained(WAIT, "Wait", "ping", Timing(within=within_ms * MS), None)
    machine = gt.project("B").fsm()
    network = InprocNetwork([(x, y) for x in gt.roles for y in gt.roles if x != y], doorbell_roles=["B"])
    endpoint = Endpoint("B", "Wait", machine, network)
    caught: list[int] = []
    due: list[int] = []

    def wait() -> None:
        branch = endpoint.fork()[0]
        monitor = branch._monitor
        assert monitor is not None and monitor.previous is not None
        due.append(monitor.previous + within_ms * MS)
        try:
            if kind == "recv":
                branch.recv("A", timeout=10)
            else:
                endpoint.recv_any(timeout=10)
        except DeadlineMissedError:
            caught.append(time.monotonic_ns())

    thread = threading.Thread(target=wait)
    thread.start()
    thread.join(timeout=30)
    if not caught:
        raise RuntimeError(f"{kind}: no DeadlineMissedError")
    return (caught[0] - due[0]) / 1e9


def latencies(misses: int, within_ms: int) -> dict[str, Any]:
    found: dict[str, Any] = {}
    for kind in ("recv", "recv_any"):
        seen = sorted(miss_latency(kind, within_ms) * 1e6 for _ in range(misses))
        found[kind] = {"misses": misses, "median_us": statistics.median(seen),
                       "p99_us": seen[min(len(seen) - 1, round(0.99 * (len(seen) - 1)))], "max_us": seen[-1],
                       "within_1ms": sum(1 for s in seen if s <= 1000) / len(seen)}
    return found


def table(flow: dict[str, Any], late: dict[str, Any]) -> list[list[str]]:
    rows = [["measure", "value", "vs monitored", "spread (min .. max)"]]
    for way in WAYS:
        low, high = flow["spread"][way]
        rows.append([f"stream, {way}", f"{flow['median'][way] / 1e3:,.0f} k msg/s",
                     f"{flow['ratio_to_monitored'][way]:.2f}x", f"{low / 1e3:,.0f} .. {high / 1e3:,.0f} k msg/s"])
    for kind, entry in late.items():
        rows.append([f"deadline miss seen by {kind}",
                     f"median {entry['median_us']:.0f} us, p99 {entry['p99_us']:.0f} us",
                     "", f"max {entry['max_us']:.0f} us; {entry['within_1ms']:.0%} within 1 ms"])
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--n", type=int, default=50_000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--misses", type=int, default=200)
    parser.add_argument("--within", type=int, default=5, help="the deadline of the latency runs, in ms")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    args = parser.parse_args(argv)
    if args.repeat < 1 or args.n < 1 or args.misses < 1 or args.within < 1:
        parser.error("--n, --repeat, --misses and --within must be at least 1")
    started = time.monotonic()
    watch = LoadWatch()
    flow = throughput(args.n, args.repeat)
    watch.sample()
    late = latencies(args.misses, args.within)
    rows = table(flow, late)
    for row in rows:
        print(" | ".join(row))
    how = (f"inproc transport, two threads; {args.n:,} streamed messages, median of {args.repeat}; "
           f"{args.misses} missed deadlines of {args.within} ms per receive; Python {platform.python_version()}")
    write_results(args.json, {"benchmark": "constraints", "python": platform.python_version(),
                              "machine": platform.machine(), "repeat": args.repeat, "throughput": flow,
                              "miss_latency": late, "table": rows}, started,
                  title="What time and value constraints cost", how=how, watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
