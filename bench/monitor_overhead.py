#!/usr/bin/env python3
"""What run-time monitoring costs on the inproc transport.

Three workloads, each run three ways in the same process and the same
repetition loop (so every ratio compares measurements taken side by side):

  raw          plain threads and ``queue.SimpleQueue`` (one per channel), the same
               workload written inline: ``q.put(("data", i))``, ``q.get()``, messages
               as ``(label, payload)`` tuples: the floor for any inproc transport
  unmonitored  anodize ``System(..., monitors=False)``: endpoints, channels, no checks
  monitored    anodize ``System(...)`` as shipped

Workloads:

  stream     ``mu t. A -> B : {data(int). t, stop}``; A sends --stream-n messages
             as fast as it can, B receives them; result: messages per second
  pingpong   ``mu t. A -> B : {ping(int). B -> A : pong(int). t, stop}``;
             --rounds round trips; result: microseconds per round trip
  ring       ``mu t. A -> B : {token(int). B -> C : token(int). C -> A : token(int). t,
             stop. B -> C : stop}``; --rounds rounds; result: microseconds per round

Times are taken inside the role functions (from the first send to the last
receive), so thread start-up and ``System.run`` set-up are not counted; the
median of --repeat repetitions is reported. Role code is written the way a
user would write it (``ep.send("B", "data", i)``, ``msg = ep.recv("A")``).

Then the monitored stream is taken apart:

  per-call   the sender sends everything while the receiver waits, then the
             receiver takes everything: the cost of one send and of one receive
             without the two threads competing for the GIL
  profile    cProfile of the sender's and the receiver's loop (monitored), top
             functions by own time

Usage:
  .venv/bin/python bench/monitor_overhead.py [--stream-n 200000] [--rounds 20000]
      [--repeat 5] [--json PATH] [--no-profile] [--top 12]
"""

from __future__ import annotations

import argparse
import cProfile
import datetime
import io
import platform
import pstats
import statistics
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from queue import SimpleQueue
from typing import Any

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from runs import LoadWatch, write_results  # noqa: E402  (bench/runs.py, beside this script)

import sessiontypes  # noqa: E402
from anodize import Endpoint, System  # noqa: E402

DEFAULT_JSON = REPO / "bench" / "results" / "monitor_overhead.json"

PROTOCOLS = """
global Stream(A, B) = mu t. A -> B : {data(int). t, stop}
global PingPong(A, B) = mu t. A -> B : {ping(int). B -> A : pong(int). t, stop}
global Ring3(A, B, C) =
  mu t. A -> B : {token(int). B -> C : token(int). C -> A : token(int). t,
                  stop. B -> C : stop}
"""
GLOBALS = sessiontypes.loads(PROTOCOLS, "monitor_overhead.proto").globals

Clock = dict[str, float]
Roles = dict[str, Callable[[Any], None]]   # role functions taking an endpoint
RawRoles = dict[str, Callable[[], None]]  # thread bodies of the raw baseline


# ---- the workloads, as role functions over an endpoint-like object ------------------------------

def stream_roles(n: int, clock: Clock) -> Roles:
    def a(ep: Endpoint) -> None:
        clock["start"] = time.perf_counter()
        for i in range(n):
            ep.send("B", "data", i)
        ep.send("B", "stop")

    def b(ep: Endpoint) -> None:
        while ep.recv("A").label == "data":
            pass
        clock["end"] = time.perf_counter()

    return {"A": a, "B": b}


def pingpong_roles(n: int, clock: Clock) -> Roles:
    def a(ep: Endpoint) -> None:
        clock["start"] = time.perf_counter()
        for i in range(n):
            ep.send("B", "ping", i)
            ep.recv("B")
        clock["end"] = time.perf_counter()
        ep.send("B", "stop")

    def b(ep: Endpoint) -> None:
        while (message := ep.recv("A")).label == "ping":
            ep.send("A", "pong", message.payload)

    return {"A": a, "B": b}


def ring_roles(n: int, clock: Clock) -> Roles:
    def a(ep: Endpoint) -> None:
        clock["start"] = time.perf_counter()
        for i in range(n):
            ep.send("B", "token", i)
            ep.recv("C")
        clock["end"] = time.perf_counter()
        ep.send("B", "stop")

    def relay(frm: str, to: str) -> Callable[[Endpoint], None]:
        def role(ep: Endpoint) -> None:
            while (message := ep.recv(frm)).label == "token":
                ep.send(to, "token", message.payload)
            if to != "A":
                ep.send(to, "stop")
        return role

    return {"A": a, "B": relay("A", "C"), "C": relay("B", "A")}


WORKLOADS: dict[str, tuple[str, Callable[[int, Clock], Roles]]] = {
    "stream": ("Stream", stream_roles),
    "pingpong": ("PingPong", pingpong_roles),
    "ring": ("Ring3", ring_roles),
}


# ---- the raw baseline: the same workloads written straight onto SimpleQueues -------------------

def raw_stream(n: int, clock: Clock) -> RawRoles:
    ab: SimpleQueue[tuple[str, object]] = SimpleQueue()

    def a() -> None:
        clock["start"] = time.perf_counter()
        for i in range(n):
            ab.put(("data", i))
        ab.put(("stop", None))

    def b() -> None:
        while ab.get()[0] == "data":
            pass
        clock["end"] = time.perf_counter()

    return {"A": a, "B": b}


def raw_pingpong(n: int, clock: Clock) -> RawRoles:
    ab: SimpleQueue[tuple[str, object]] = SimpleQueue()
    ba: SimpleQueue[tuple[str, object]] = SimpleQueue()

    def a() -> None:
        clock["start"] = time.perf_counter()
        for i in range(n):
            ab.put(("ping", i))
            ba.get()
        clock["end"] = time.perf_counter()
        ab.put(("stop", None))

    def b() -> None:
        while (message := ab.get())[0] == "ping":
            ba.put(("pong", message[1]))

    return {"A": a, "B": b}


def raw_ring(n: int, clock: Clock) -> RawRoles:
    ab: SimpleQueue[tuple[str, object]] = SimpleQueue()
    bc: SimpleQueue[tuple[str, object]] = SimpleQueue()
    ca: SimpleQueue[tuple[str, object]] = SimpleQueue()

    def a() -> None:
        clock["start"] = time.perf_counter()
        for i in range(n):
            ab.put(("token", i))
            ca.get()
        clock["end"] = time.perf_counter()
        ab.put(("stop", None))

    def relay(inbox: SimpleQueue[tuple[str, object]], outbox: SimpleQueue[tuple[str, object]],
              forward_stop: bool) -> Callable[[], None]:
        def role() -> None:
            while (message := inbox.get())[0] == "token":
                outbox.put(("token", message[1]))
            if forward_stop:
                outbox.put(("stop", None))
        return role

    return {"A": a, "B": relay(ab, bc, True), "C": relay(bc, ca, False)}


RAW: dict[str, Callable[[int, Clock], RawRoles]] = {
    "stream": raw_stream, "pingpong": raw_pingpong, "ring": raw_ring}


def run_raw(roles: RawRoles) -> None:
    threads = [threading.Thread(target=fn) for fn in roles.values()]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()


def run_anodize(protocol: str, roles: Roles, monitored: bool) -> None:
    system = System(GLOBALS[protocol], monitors=monitored)
    group = system.group("g")
    for name, fn in roles.items():
        group.role(name, fn)
    report = system.run(timeout=600)
    if not report.ok:
        raise RuntimeError(report.summary())


def measure(workload: str, way: str, n: int) -> float:
    """Seconds from the first send to the last receive."""
    protocol, make_roles = WORKLOADS[workload]
    clock: Clock = {}
    if way == "raw":
        run_raw(RAW[workload](n, clock))
    else:
        run_anodize(protocol, make_roles(n, clock), monitored=(way == "monitored"))
    return clock["end"] - clock["start"]


WAYS = ("raw", "unmonitored", "monitored")


def run_workloads(stream_n: int, rounds: int, repeat: int) -> dict[str, Any]:
    sizes = {"stream": stream_n, "pingpong": rounds, "ring": rounds}
    samples: dict[str, dict[str, list[float]]] = {w: {way: [] for way in WAYS} for w in WORKLOADS}
    for workload in WORKLOADS:
        measure(workload, "monitored", max(1000, sizes[workload] // 20))  # warm-up
        for _ in range(repeat):
            for way in WAYS:  # interleaved, so drift hits all three alike
                samples[workload][way].append(measure(workload, way, sizes[workload]))
    results: dict[str, Any] = {}
    for workload, by_way in samples.items():
        n = sizes[workload]
        median = {way: statistics.median(times) for way, times in by_way.items()}
        entry: dict[str, Any] = {"n": n, "seconds": by_way, "median_seconds": median}
        if workload == "stream":
            rate = {way: n / t for way, t in median.items()}
            entry["messages_per_second"] = rate
            entry["ratio_monitored_to_raw"] = rate["monitored"] / rate["raw"]
            entry["ratio_monitored_to_unmonitored"] = rate["monitored"] / rate["unmonitored"]
            entry["ratio_unmonitored_to_raw"] = rate["unmonitored"] / rate["raw"]
            entry["target"] = "monitored >= 0.75 x raw throughput"
            entry["meets_target"] = entry["ratio_monitored_to_raw"] >= 0.75
        else:
            per_round = {way: t / n * 1e6 for way, t in median.items()}
            entry["microseconds_per_round"] = per_round
            entry["ratio_monitored_to_raw"] = per_round["monitored"] / per_round["raw"]
            entry["ratio_monitored_to_unmonitored"] = per_round["monitored"] / per_round["unmonitored"]
            entry["ratio_unmonitored_to_raw"] = per_round["unmonitored"] / per_round["raw"]
            if workload == "pingpong":
                entry["target"] = "monitored round trip <= 1.05 x raw"
                entry["meets_target"] = entry["ratio_monitored_to_raw"] <= 1.05
        results[workload] = entry
    return results


# ---- taking the monitored stream apart -----------------------------------------------------------

def split_stream(way: str, n: int, profile: bool = False) -> dict[str, Any]:
    """The sender sends all n while the receiver waits; then the receiver takes all n."""
    sent = threading.Event()
    out: dict[str, Any] = {}

    def timed(name: str, body: Callable[[], None]) -> None:
        profiler = cProfile.Profile() if profile else None
        start = time.perf_counter()
        if profiler:
            profiler.enable()
        body()
        if profiler:
            profiler.disable()
        out[name] = time.perf_counter() - start
        if profiler:
            out[f"{name}_profile"] = profiler

    def a(ep: Endpoint) -> None:
        def loop() -> None:
            for i in range(n):
                ep.send("B", "data", i)
        timed("send", loop)
        ep.send("B", "stop")
        sent.set()

    def b(ep: Endpoint) -> None:
        sent.wait()

        def loop() -> None:
            for _ in range(n):
                ep.recv("A")
        timed("recv", loop)
        ep.recv("A")

    if way == "raw":
        ab: SimpleQueue[tuple[str, object]] = SimpleQueue()

        def raw_a() -> None:
            def loop() -> None:
                for i in range(n):
                    ab.put(("data", i))
            timed("send", loop)
            sent.set()

        def raw_b() -> None:
            sent.wait()

            def loop() -> None:
                for _ in range(n):
                    ab.get()
            timed("recv", loop)

        run_raw({"A": raw_a, "B": raw_b})
    else:
        run_anodize("Stream", {"A": a, "B": b}, monitored=(way == "monitored"))
    return out


def per_call(n: int, repeat: int) -> dict[str, dict[str, float]]:
    """Median microseconds per send and per receive, uncontended."""
    samples: dict[str, dict[str, list[float]]] = {way: {"send": [], "recv": []} for way in WAYS}
    for _ in range(repeat):
        for way in WAYS:
            times = split_stream(way, n)
            for kind in ("send", "recv"):
                samples[way][kind].append(times[kind] / n * 1e6)
    return {way: {kind: statistics.median(v) for kind, v in kinds.items()}
            for way, kinds in samples.items()}


def profile_stream(n: int, top: int) -> dict[str, list[dict[str, Any]]]:
    found = split_stream("monitored", n, profile=True)
    report = {}
    for kind in ("send", "recv"):
        stats = pstats.Stats(found[f"{kind}_profile"], stream=io.StringIO())
        rows = []
        for (file, line, function), (_, nc, tt, ct, _) in stats.stats.items():  # type: ignore[attr-defined]
            where = f"{Path(file).name}:{line}" if line else file
            rows.append({"function": function, "where": where, "calls": nc,
                         "own_us_per_message": tt / n * 1e6, "cumulative_us_per_message": ct / n * 1e6})
        rows.sort(key=lambda r: -r["own_us_per_message"])
        report[kind] = rows[:top]
    return report


# ---- output --------------------------------------------------------------------------------------

def print_tables(results: dict[str, Any], calls: dict[str, dict[str, float]],
                 profiles: dict[str, list[dict[str, Any]]] | None, repeat: int) -> None:
    print(f"monitor overhead, inproc transport, median of {repeat} (Python {platform.python_version()})")
    print()
    header = (f"{'workload':<10} {'n':>8} {'raw':>12} {'unmonitored':>12} {'monitored':>12}"
              f" {'mon/raw':>8} {'mon/unmon':>9} {'unmon/raw':>9}  target")
    print(header)
    print("-" * len(header))
    for workload, entry in results.items():
        if workload == "stream":
            values = entry["messages_per_second"]
            cells = [f"{values[w] / 1e3:>8.0f} k/s" for w in WAYS]
        else:
            values = entry["microseconds_per_round"]
            cells = [f"{values[w]:>9.1f} us" for w in WAYS]
        target = entry.get("target", "")
        if target:
            target += " (met)" if entry["meets_target"] else " (NOT met)"
        print(f"{workload:<10} {entry['n']:>8} {cells[0]:>12} {cells[1]:>12} {cells[2]:>12}"
              f" {entry['ratio_monitored_to_raw']:>8.2f} {entry['ratio_monitored_to_unmonitored']:>9.2f}"
              f" {entry['ratio_unmonitored_to_raw']:>9.2f}  {target}")
    print("(stream: messages per second, higher is better; pingpong, ring: microseconds per round)")
    print()
    print("per call, uncontended (sender runs alone, then receiver): microseconds")
    print(f"{'':<12} {'send':>8} {'recv':>8}")
    for way in WAYS:
        print(f"{way:<12} {calls[way]['send']:>8.3f} {calls[way]['recv']:>8.3f}")
    if profiles:
        for kind, rows in profiles.items():
            print()
            print(f"profile of the monitored {kind} loop (microseconds per message; cProfile's own"
                  " cost inflates these: compare shares)")
            for row in rows:
                print(f"  {row['own_us_per_message']:>7.3f} own {row['cumulative_us_per_message']:>7.3f} cum"
                      f" {row['calls']:>8}  {row['function']} ({row['where']})")


def table_rows(results: dict[str, Any]) -> list[list[str]]:
    """The workloads as table rows (the first the header), as the performance page prints them."""
    rows = [["workload", "raw", "unmonitored", "monitored", "monitored / raw", "monitored / unmonitored", "target"]]
    for workload, entry in results.items():
        if workload == "stream":
            cells = [f"{entry['messages_per_second'][w] / 1e3:,.0f} k msg/s" for w in WAYS]
        else:
            cells = [f"{entry['microseconds_per_round'][w]:.1f} us/round" for w in WAYS]
        target = entry.get("target", "")
        if target:
            target += ": met" if entry["meets_target"] else ": NOT met"
        rows.append([f"{workload} ({entry['n']:,})", *cells, f"{entry['ratio_monitored_to_raw']:.2f}x",
                     f"{entry['ratio_monitored_to_unmonitored']:.2f}x", target])
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--stream-n", type=int, default=200_000)
    parser.add_argument("--rounds", type=int, default=20_000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    parser.add_argument("--no-profile", action="store_true")
    parser.add_argument("--top", type=int, default=12)
    args = parser.parse_args(argv)
    if args.repeat < 1:
        parser.error("--repeat must be at least 1")

    started = time.monotonic()
    watch = LoadWatch()
    results = run_workloads(args.stream_n, args.rounds, args.repeat)
    calls = per_call(args.stream_n, args.repeat)
    profiles = None if args.no_profile else profile_stream(min(args.stream_n, 100_000), args.top)
    print_tables(results, calls, profiles, args.repeat)

    document = {
        "benchmark": "monitor_overhead",
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "implementation": platform.python_implementation(),
        "machine": platform.machine(),
        "platform": platform.platform(),
        "repeat": args.repeat,
        "workloads": results,
        "per_call_microseconds": calls,
        "profile": profiles,
    }
    how = (f"inproc transport, two threads; median of {args.repeat}; {args.stream_n:,} streamed messages, "
           f"{args.rounds:,} rounds; Python {platform.python_version()}")
    write_results(args.json, {**document, "table": table_rows(results)}, started, title="What monitoring costs",
                  how=how, watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
