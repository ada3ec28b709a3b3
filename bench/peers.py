#!/usr/bin/env python3
"""anodize against other ways of moving messages, side by side in one run.

Four workloads, every candidate of a workload run in each repetition, interleaved
(repetition 1 of every candidate, then repetition 2, ...), so drift hits all alike:

  stream, two threads      200,000 small ints, ``mu t. P -> C : {data(int). t, stop}``:
                           anodize inproc monitored and unmonitored, and
                           ``queue.SimpleQueue`` (``bench/monitor_overhead.py``'s stream);
                           pyzmq ``inproc://`` PAIR sockets (8-byte ints). Time: from the
                           first send to the last receipt, taken in the threads.
  stream, two processes    the same stream between two groups of ``transport=Processes()``,
                           monitored and unmonitored (``bench/dds.py``'s stream roles);
                           pyzmq ``ipc://`` PAIR; ``multiprocessing.Pipe`` and
                           ``multiprocessing.Queue`` (pickled ints); raw Cyclone DDS
                           (``bench/dds.py``'s raw baseline: reliable, keep-all, CDR bytes
                           through ``cyclonedds._clayer``). Time: the producer's clock before
                           its first send to the consumer's after the last receipt
                           (CLOCK_MONOTONIC, one clock for the machine).
  frames, two processes    2,000 frames of 640x480x3 uint8 (900 KiB), from a pool of 8 made
                           before the clock starts, with their index, send time and a row
                           checksum that the receiver checks (``bench/transport.py``'s frames,
                           unmonitored): anodize copying each frame into its shared-memory
                           slot, and anodize filling a slot from ``ep.buffer()`` in place;
                           pyzmq ``ipc://`` (the header, then the array's buffer, ``copy=False``);
                           ``multiprocessing.Pipe`` (``send_bytes``); and the limit of one
                           ``memcpy`` per frame: ``numpy.copyto`` of a pool frame into one
                           preallocated array, in this process. Time: from the first frame's
                           send time to the last receipt.
  round trip, two processes  ping-pong, --warmup untimed rounds, then --rounds each timed
                           alone by the client (p50 and p99, us): anodize monitored
                           (``mu t. A -> B : {ping(int). B -> A : pong(int). t, stop}``);
                           ``multiprocessing.Pipe`` (tuples); raw ``os.pipe`` (8 bytes).

Process start-up, discovery and connection are never timed: anodize's roles start together
after its start barrier; the peers meet at a ``multiprocessing.Barrier`` or, for pyzmq, the
consumer's "go". The table shows medians of --repeat repetitions with the spread (min-max),
and the targets as ratios, each marked met or NOT met. A way that fails shows "failed"
(its error is kept in the JSON).

Load: the 1-minute load and the CPU count at the start and the end, and the CPU time other
processes used during the run (``runs.LoadWatch``). When the machine was busy the table's
header says "MACHINE BUSY: do not publish" and the JSON has ``"busy": true``; the run goes on.

Usage:
  .venv/bin/python bench/peers.py [--messages 200000] [--frames 2000] [--rounds 20000]
      [--warmup 500] [--repeat 5] [--timeout 120] [--quick] [--json PATH]
"""

from __future__ import annotations

import argparse
import datetime
import importlib.metadata
import multiprocessing
import os
import platform
import statistics
import sys
import threading
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

BENCH = Path(__file__).resolve().parent
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

import dds  # noqa: E402  (first: puts bench/ and the repository on sys.path and PYTHONPATH)
import monitor_overhead  # noqa: E402
import numpy as np  # noqa: E402
import peers_roles as roles  # noqa: E402
import transport  # noqa: E402
import transport_roles  # noqa: E402
import zmq  # noqa: E402
from runs import LoadWatch, bench_env, print_table, source_state, write_results  # noqa: E402

DEFAULT_JSON = BENCH / "results" / "peers.json"
THREAD_WAYS = ("monitored", "unmonitored", "zmq_inproc", "simplequeue")
PROCESS_WAYS = ("monitored", "unmonitored", "batched", "zmq_ipc", "mp_pipe", "mp_queue", "cyclonedds")
FRAME_WAYS = ("copy", "buffer", "zmq_ipc", "mp_pipe", "memcpy")
ROUND_WAYS = ("anodize", "mp_pipe", "os_pipe")
NAMES = {"monitored": "anodize monitored", "unmonitored": "anodize unmonitored", "anodize": "anodize monitored",
         "batched": "anodize monitored, send_many/recv_many",
         "copy": "anodize, copy from a pool", "buffer": "anodize, ep.buffer() in place",
         "zmq_inproc": "pyzmq inproc PAIR", "simplequeue": "queue.SimpleQueue", "zmq_ipc": "pyzmq ipc PAIR",
         "mp_pipe": "mp.Pipe", "mp_queue": "mp.Queue", "cyclonedds": "Cyclone DDS", "memcpy": "memcpy limit",
         "os_pipe": "os.pipe"}
SPAWN = multiprocessing.get_context("spawn")


# ---- one run of one way -----------------------------------------------------------------------
def _rate(n: int, seconds: float, **more: Any) -> dict[str, Any]:
    return {"count": n, "seconds": seconds, "per_second": n / seconds, **more}


def stream_threads(way: str, n: int) -> dict[str, Any]:
    if way != "zmq_inproc":  # anodize inproc, or the SimpleQueue floor
        return _rate(n, monitor_overhead.measure("stream", "raw" if way == "simplequeue" else way, n))
    context = zmq.Context()
    address = "inproc://peers-stream"
    _, consumer = roles.zmq_pair(address, True, context)
    _, producer = roles.zmq_pair(address, False, context)
    got: dict[str, Any] = {}
    threads = [threading.Thread(target=lambda: got.update(start=roles.zmq_produce(producer, n))),
               threading.Thread(target=lambda: got.update(roles.zmq_consume(consumer)))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    producer.close()
    consumer.close()
    context.term()
    return dds._one_way(lambda name: got, n)


def stream_processes(way: str, n: int, timeout: float) -> dict[str, Any]:
    if way in ("monitored", "unmonitored", "batched"):
        return dds.messages("process", n, timeout, monitors=way != "unmonitored", batched=way == "batched")
    if way == "cyclonedds":
        return dds.messages("raw", n, timeout)
    with bench_env(transport_roles.ENV) as (out, found):
        if way == "zmq_ipc":
            address = f"ipc://{out}/stream"
            targets = [(roles.zmq_stream_producer, (address, n)), (roles.zmq_stream_consumer, (address,))]
        else:
            barrier = SPAWN.Barrier(2)
            if way == "mp_pipe":
                receiving, sending = SPAWN.Pipe(duplex=False)
                ends = [(sending, "send"), (receiving, "recv")]
            else:
                queue = SPAWN.Queue()
                ends = [(queue, "put"), (queue, "get")]
            targets = [(roles.object_producer, (*ends[0], barrier, n)), (roles.object_consumer, (*ends[1], barrier))]
        dds.run_raw(targets, timeout)
        return dds._one_way(found, n)


def frames(way: str, n: int, timeout: float) -> dict[str, Any]:
    if way in ("copy", "buffer"):
        found = transport.frames_anodize(n, timeout, produce=way == "buffer", monitors=False)
    elif way == "memcpy":
        found = {"frames": n, "bad": 0, "seconds": roles.memcpy_frames(n)}
    else:
        with bench_env(transport_roles.ENV) as (out, result):
            if way == "zmq_ipc":
                address = f"ipc://{out}/frames"
                dds.run_raw([(roles.zmq_frame_source, (address, n)), (roles.zmq_frame_sink, (address,))], timeout)
            else:
                receiving, sending = SPAWN.Pipe(duplex=False)
                barrier = SPAWN.Barrier(2)
                dds.run_raw([(roles.pipe_frame_source, (sending, barrier, n)),
                             (roles.pipe_frame_sink, (receiving, barrier))], timeout)
            found = transport._frames_checked(result("frames"), n)
    return _rate(n, found["seconds"], bad=found["bad"])


def round_trip(way: str, rounds: int, warmup: int, timeout: float) -> dict[str, Any]:
    with bench_env(transport_roles.ENV, rounds=rounds, warmup=warmup) as (_, found):
        barrier = SPAWN.Barrier(2)
        if way == "anodize":
            transport.run_system("PingPong", {"client": (None, {"A": roles.ping_client}),
                                              "server": (None, {"B": transport_roles.ping_server})}, timeout)
        elif way == "mp_pipe":
            client, server = SPAWN.Pipe()
            dds.run_raw([(roles.pipe_client, (client, barrier, warmup, rounds)),
                         (transport_roles.pipe_server, (server, barrier))], timeout)
        else:  # the raw descriptors travel to the spawned processes wrapped as Connections
            ends = [Connection(fd) for pair in (os.pipe(), os.pipe()) for fd in pair]  # r1 w1 r2 w2
            try:
                dds.run_raw([(roles.os_pipe_client, (ends[1], ends[2], barrier, warmup, rounds)),
                             (roles.os_pipe_server, (ends[0], ends[3], barrier))], timeout)
            finally:
                for end in ends:
                    end.close()
        return found("pingpong")


# ---- repetitions and summaries ----------------------------------------------------------------
def measure(name: str, key: str, repeat: int, run: Callable[[str], dict[str, Any]], ways: tuple[str, ...],
            watch: LoadWatch) -> dict[str, Any]:
    """``dds.measure`` (interleaved repetitions), a load window after every run, and the spread."""
    def sampled(way: str) -> dict[str, Any]:
        try:
            return run(way)
        finally:
            watch.sample()

    found = dds.measure(name, key, repeat, sampled, ways)
    keys = (key, "p99_us") if key == "p50_us" else (key,)
    found["stats"] = {k: {way: _stats([s[k] for s in got if "error" not in s]) for way, got in found["samples"].items()}
                      for k in keys}
    return found


def _stats(values: list[float]) -> dict[str, float] | None:
    if not values:
        return None
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def _cell(found: dict[str, Any] | None, scale: float = 1.0, spec: str = ",.0f", suffix: str = "") -> str:
    if found is None:
        return "failed"
    m, lo, hi = (found[k] / scale for k in ("median", "min", "max"))
    return f"{m:{spec}}{suffix} ({lo:{spec}}-{hi:{spec}})"


def _target(name: str, numerator: float | None, denominator: float | None, op: str, bound: float) -> dict[str, Any]:
    ratio = numerator / denominator if numerator and denominator else None
    met = None if ratio is None else (ratio >= bound if op == ">=" else ratio <= bound if op == "<=" else ratio > bound)
    return {"name": name, "ratio": ratio, "target": f"{op} {bound:g}x", "met": met}


def _ratios(targets: list[dict[str, Any]]) -> str:
    mark = {True: "met", False: "NOT met", None: "n/a"}
    return "; ".join(f"{t['name']} {'-' if t['ratio'] is None else format(t['ratio'], '.2f')}x "
                     f"({t['target']}: {mark[t['met']]})" for t in targets)


def summarise(results: dict[str, dict[str, Any]]) -> tuple[list[list[str]], list[list[str]], list[dict[str, Any]]]:
    """The table, the detail (every way: median, min, max) and the targets."""
    th, pr, fr, rt = (results[k]["stats"] for k in ("threads", "processes", "frames", "round_trip"))
    med = {k: {way: (s["median"] if s else None) for way, s in v[key].items()}
           for k, v, key in (("th", th, "per_second"), ("pr", pr, "per_second"), ("fr", fr, "per_second"),
                             ("p50", rt, "p50_us"), ("p99", rt, "p99_us"))}
    targets = {
        "threads": [_target("monitored/pyzmq", med["th"]["monitored"], med["th"]["zmq_inproc"], ">=", 1.2),
                    _target("monitored/unmonitored", med["th"]["monitored"], med["th"]["unmonitored"], ">=", 0.9)],
        "processes": [_target("monitored/pyzmq", med["pr"]["monitored"], med["pr"]["zmq_ipc"], ">=", 1.2),
                      _target("monitored/unmonitored", med["pr"]["monitored"], med["pr"]["unmonitored"], ">=", 0.9),
                      _target("batched/pyzmq", med["pr"]["batched"], med["pr"]["zmq_ipc"], ">=", 1.2)],
        "frames": [_target("copy/memcpy", med["fr"]["copy"], med["fr"]["memcpy"], ">=", 0.7),
                   _target("buffer/memcpy", med["fr"]["buffer"], med["fr"]["memcpy"], ">=", 0.7),
                   _target("buffer/copy", med["fr"]["buffer"], med["fr"]["copy"], ">", 1.0)],
        "round_trip": [_target(f"{p} anodize/{NAMES[peer]}", med[p]["anodize"], med[p][peer], "<=", bound)
                       for peer, bound in (("mp_pipe", 1.0), ("os_pipe", 3.0)) for p in ("p50", "p99")],
    }

    def rate(stats: dict[str, Any], ways: tuple[str, ...], scale: float, suffix: str) -> str:
        return "; ".join(f"{NAMES[w]} {_cell(stats[w], scale, suffix=suffix)}" for w in ways)

    def trip(way: str) -> str:
        return f"{_cell(rt['p50_us'][way], spec='.1f')} / {_cell(rt['p99_us'][way], spec='.1f')}"

    rows = [["workload", "anodize (monitored)", "anodize unmonitored", "peers", "ratios (target: met?)"],
            ["stream, two threads, msgs/s", _cell(th["per_second"]["monitored"], 1e3, suffix="k"),
             _cell(th["per_second"]["unmonitored"], 1e3, suffix="k"),
             rate(th["per_second"], THREAD_WAYS[2:], 1e3, "k"), _ratios(targets["threads"])],
            ["stream, two processes, msgs/s", _cell(pr["per_second"]["monitored"], 1e3, suffix="k"),
             _cell(pr["per_second"]["unmonitored"], 1e3, suffix="k"),
             rate(pr["per_second"], PROCESS_WAYS[2:], 1e3, "k"), _ratios(targets["processes"])],
            ["frames 640x480x3, two processes, frames/s", "-",
             "; ".join(f"{w} {_cell(fr['per_second'][w])}" for w in FRAME_WAYS[:2]),
             rate(fr["per_second"], FRAME_WAYS[2:], 1, ""), _ratios(targets["frames"])],
            ["round trip, two processes, us p50 / p99", trip("anodize"), "-",
             "; ".join(f"{NAMES[w]} {trip(w)}" for w in ROUND_WAYS[1:]), _ratios(targets["round_trip"])]]
    detail = [["workload", "way", "median", "min", "max"]]
    for label, stats, ways, spec in (("stream, threads, msgs/s", th["per_second"], THREAD_WAYS, ",.0f"),
                                     ("stream, processes, msgs/s", pr["per_second"], PROCESS_WAYS, ",.0f"),
                                     ("frames/s", fr["per_second"], FRAME_WAYS, ",.0f"),
                                     ("round trip p50, us", rt["p50_us"], ROUND_WAYS, ".1f"),
                                     ("round trip p99, us", rt["p99_us"], ROUND_WAYS, ".1f")):
        for way in ways:
            s = stats[way]
            detail.append([label, NAMES[way],
                           *(["failed"] * 3 if s is None else [format(s[k], spec) for k in ("median", "min", "max")])])
    return rows, detail, [t for group in targets.values() for t in group]


# ---- the run ----------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--messages", type=int, default=200_000, help="small ints per stream run")
    parser.add_argument("--frames", type=int, default=2000, help="frames per frames run")
    parser.add_argument("--rounds", type=int, default=20_000, help="timed round trips per run")
    parser.add_argument("--warmup", type=int, default=500, help="untimed round trips first")
    parser.add_argument("--repeat", type=int, default=5, help="repetitions of every way")
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds a single run may take")
    parser.add_argument("--quick", action="store_true",
                        help="smoke test: 20,000 messages, 200 frames, 2,000 round trips, 1 repetition")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON, help=f"default {DEFAULT_JSON}")
    args = parser.parse_args(argv)
    if args.quick:
        args.messages, args.frames = min(args.messages, 20_000), min(args.frames, 200)
        args.rounds, args.warmup, args.repeat = min(args.rounds, 2000), 100, 1

    started = time.monotonic()
    source = source_state(BENCH.parent, "anodize", "sessiontypes")  # what was measured
    watch = LoadWatch()
    for way in THREAD_WAYS:  # untimed: the first inproc run pays for caches the others find warm
        stream_threads(way, max(1000, args.messages // 20))
    results = {
        "threads": measure("stream, threads", "per_second", args.repeat,
                           lambda way: stream_threads(way, args.messages), THREAD_WAYS, watch),
        "processes": measure("stream, processes", "per_second", args.repeat,
                             lambda way: stream_processes(way, args.messages, args.timeout), PROCESS_WAYS, watch),
        "frames": measure("frames", "per_second", args.repeat,
                          lambda way: frames(way, args.frames, args.timeout), FRAME_WAYS, watch),
        "round_trip": measure("round trip", "p50_us", args.repeat,
                              lambda way: round_trip(way, args.rounds, args.warmup, args.timeout), ROUND_WAYS, watch),
    }
    load = watch.result()
    rows, detail, targets = summarise(results)

    versions = {"python": platform.python_version(), "numpy": np.__version__, "pyzmq": zmq.__version__,
                "libzmq": zmq.zmq_version(), "cyclonedds": importlib.metadata.version("cyclonedds")}
    how = (f"anodize vs peers, {load['cpus']} CPUs, Python {versions['python']}, pyzmq {versions['pyzmq']} "
          f"(libzmq {versions['libzmq']}), cyclonedds {versions['cyclonedds']}; median (min-max) of {args.repeat}; "
          f"{args.messages:,} messages, {args.frames:,} frames, {args.rounds:,} round trips per run")
    print(how)
    print(LoadWatch.headline(load))
    if source.get("uncommitted"):
        print(f"measured with uncommitted changes to {', '.join(source['uncommitted'])} (on {source['commit'][:10]})")
    print()
    print_table(rows, (0, 1, 2, 3, 4))
    print()
    print_table(detail, (0, 1))

    document = {
        "benchmark": "peers",
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "busy": load["busy"],
        "load": load,
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(), "machine": platform.machine(),
                    **versions},
        "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "source": source,
        "wall_seconds": time.monotonic() - started,
        "table": rows,
        "detail": detail,
        "targets": targets,
        **results,
    }
    write_results(args.json, document, started, title="Against other ways of moving messages", how=how,
                  watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
