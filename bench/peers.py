#!/usr/bin/env python3
"""anodize against other ways of moving messages, side by side in one run.

Four workloads, every candidate of a workload run in each repetition, interleaved
(repetition 1 of every candidate, then repetition 2, ...), so drift hits all alike. How
each peer is configured, and why that is its best use, is in docs/performance.md.

  stream, two threads      200,000 small ints, ``mu t. P -> C : {data(int). t, stop}``:
                           anodize inproc monitored and unmonitored, and
                           ``queue.SimpleQueue`` (``bench/monitor_overhead.py``'s stream);
                           pyzmq ``inproc://`` PAIR sockets (8-byte ints). Time: from the
                           first send to the last receipt, taken in the threads.
  stream, two processes    the same stream between two groups of ``transport=Processes()``,
                           monitored and unmonitored (``bench/dds.py``'s stream roles), and
                           monitored with ``send_many``/``recv_many``; pyzmq ``ipc://``
                           PUSH/PULL; iceoryx2 publish-subscribe (``c_int64`` samples,
                           lossless); ``multiprocessing.Pipe`` and ``multiprocessing.Queue``
                           (pickled ints); raw Cyclone DDS (``bench/dds.py``'s raw baseline:
                           reliable, keep-all, CDR bytes through ``cyclonedds._clayer``).
                           Time: the producer's clock before its first send to the
                           consumer's after the last receipt (CLOCK_MONOTONIC, one clock for
                           the machine).
  frames, two processes    2,000 frames of 640x480x3 uint8 (900 KiB), from a pool of 8 made
                           before the clock starts, with their index, send time and a row
                           checksum that the receiver checks (``bench/transport.py``'s frames,
                           unmonitored): anodize copying each frame into its shared-memory
                           slot, and anodize filling a slot from ``ep.buffer()`` in place;
                           iceoryx2 writing each frame into a loaned sample in place;
                           pyzmq ``ipc://`` (the header, then the array's buffer, ``copy=False``);
                           ``multiprocessing.Pipe`` (``send_bytes``); and the limit of one
                           ``memcpy`` per frame: ``numpy.copyto`` of a pool frame into one
                           preallocated array, in this process (its destination stays in the
                           CPU's cache), and into the next of 8 in turn, as a ring of 8 slots
                           is filled. Time: from the first frame's
                           send time to the last receipt.
  round trip, two processes  ping-pong, --warmup untimed rounds, then --rounds each timed
                           alone by the client (p50 and p99, us): anodize monitored
                           (``mu t. A -> B : {ping(int). B -> A : pong(int). t, stop}``), and,
                           when ``System.group`` has a ``spin=`` setting, anodize with spin
                           (each group on its own CPU); ``multiprocessing.Pipe`` (tuples); raw
                           ``os.pipe`` (8 bytes); iceoryx2 sleeping on an event, and iceoryx2
                           polling (each process on its own CPU).

Process start-up, discovery and connection are never timed: anodize's roles start together
after its start barrier; each peer proves its connection (pyzmq's and iceoryx2's first
message arrives) and then the peers meet at a ``multiprocessing.Barrier`` (pyzmq's again after
the stream's end, so the sender closes only once everything arrived). Every wait a peer
makes is bounded (``peers_roles.TIMEOUT``, and --timeout for a whole run, after which its
processes are killed); a failed repetition is kept in the JSON with the cause its process
reported. The table has a row per workload and way: the median of --repeat repetitions,
the spread (min-max) and how many failed; then a row per target of issue 31, a ratio of
medians marked met, NOT met, or n/a with the reason.

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
import inspect
import itertools
import json
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
import peers_iceoryx as ice  # noqa: E402
import peers_roles as roles  # noqa: E402
import transport  # noqa: E402
import transport_roles  # noqa: E402
import zmq  # noqa: E402
from runs import LoadWatch, bench_env, print_table, source_state, write_results  # noqa: E402

from anodize import Processes, System  # noqa: E402

DEFAULT_JSON = BENCH / "results" / "peers.json"
THREAD_WAYS = ("monitored", "unmonitored", "zmq_inproc", "simplequeue")
PROCESS_WAYS = ("monitored", "unmonitored", "batched", "zmq_ipc", "iceoryx2", "mp_pipe", "mp_queue", "cyclonedds")
FRAME_WAYS = ("copy", "buffer", "iceoryx2", "zmq_ipc", "mp_pipe", "memcpy", "memcpy_pool")
SPIN = "50us"  # anodize with spin: how long a group may poll before it sleeps (the "spin" change's setting)
ROUND_WAYS = ("anodize", *(("anodize_spin",) if "spin" in inspect.signature(System.group).parameters else ()),
              "mp_pipe", "os_pipe", "iceoryx2_event", "iceoryx2_polling")
NAMES = {"monitored": "anodize monitored", "unmonitored": "anodize unmonitored", "anodize": "anodize monitored",
         "anodize_spin": f"anodize monitored, spin {SPIN}, own CPUs",
         "batched": "anodize monitored, send_many/recv_many",
         "copy": "anodize, copy from a pool", "buffer": "anodize, ep.buffer() in place",
         "zmq_inproc": "pyzmq inproc PAIR", "simplequeue": "queue.SimpleQueue", "zmq_ipc": "pyzmq ipc PUSH/PULL",
         "iceoryx2": "iceoryx2 publish-subscribe, polling", "iceoryx2_event": "iceoryx2, event (sleeps)",
         "iceoryx2_polling": "iceoryx2, polling, own CPUs",
         "mp_pipe": "mp.Pipe", "mp_queue": "mp.Queue", "cyclonedds": "Cyclone DDS", "memcpy": "memcpy limit",
         "memcpy_pool": "memcpy into a pool of 8 (a slot ring's pattern)",
         "os_pipe": "os.pipe"}
SPAWN = multiprocessing.get_context("spawn")
_RUNS = itertools.count()


# ---- one run of one way -----------------------------------------------------------------------
def _rate(n: int, seconds: float, **more: Any) -> dict[str, Any]:
    return {"count": n, "seconds": seconds, "per_second": n / seconds, **more}


def run_peers(targets: list[tuple[Callable[..., None], tuple[Any, ...]]], out: str, timeout: float) -> None:
    """Run peer processes through ``peers_roles.guarded`` (bounded by ``timeout``); if one fails,
    raise with the cause each reported (or "timed out" for one that was killed)."""
    try:
        dds.run_raw([(roles.guarded, (f"{fn.__module__}:{fn.__name__}", *args)) for fn, args in targets], timeout)
    except RuntimeError as error:
        causes = [f"{path.stem[len('error-'):]}: {json.loads(path.read_text(encoding='utf-8'))['error']}"
                  for path in sorted(Path(out).glob("error-*.json"))]
        raise RuntimeError(f"{error}; {'; '.join(causes) or f'no peer reported an error: killed after {timeout:g} s'}")\
            from None


def stream_threads(way: str, n: int) -> dict[str, Any]:
    if way != "zmq_inproc":  # anodize inproc, or the SimpleQueue floor
        return _rate(n, monitor_overhead.measure("stream", "raw" if way == "simplequeue" else way, n))
    context = zmq.Context()
    address = "inproc://peers-stream"
    consumer = roles.zmq_socket(context, zmq.PAIR, address, bind=True)
    producer = roles.zmq_socket(context, zmq.PAIR, address, bind=False)
    got: dict[str, Any] = {}
    errors: list[BaseException] = []

    def run(work: Callable[[], None]) -> None:
        try:
            work()
        except BaseException as error:  # reported below, as a failed repetition
            errors.append(error)

    threads = [threading.Thread(target=run, args=(lambda: got.update(start=roles.zmq_inproc_producer(producer, n)),)),
               threading.Thread(target=run, args=(lambda: got.update(roles.zmq_inproc_consumer(consumer)),))]
    for thread in threads:
        thread.start()
    for thread in threads:  # the sockets' own timeouts end a stuck thread within roles.TIMEOUT
        thread.join(roles.TIMEOUT + 10)
    producer.close(linger=0)
    consumer.close(linger=0)
    context.term()
    if errors or any(thread.is_alive() for thread in threads):
        raise RuntimeError(f"pyzmq inproc: {'; '.join(f'{type(e).__name__}: {e}' for e in errors) or 'a thread hung'}")
    return dds._one_way(lambda name: got, n)


def stream_processes(way: str, n: int, timeout: float) -> dict[str, Any]:
    if way in ("monitored", "unmonitored", "batched"):
        return dds.messages("process", n, timeout, monitors=way != "unmonitored", batched=way == "batched")
    if way == "cyclonedds":
        return dds.messages("raw", n, timeout)
    with bench_env(transport_roles.ENV) as (out, found):
        barrier = SPAWN.Barrier(2)
        if way == "zmq_ipc":
            address = f"ipc://{out}/stream"
            targets = [(roles.zmq_stream_producer, (address, barrier, n)),
                       (roles.zmq_stream_consumer, (address, barrier))]
        elif way == "iceoryx2":
            name = _iceoryx_name("stream")
            targets = [(ice.stream_producer, (name, barrier, n)), (ice.stream_consumer, (name, barrier))]
        else:
            if way == "mp_pipe":
                receiving, sending = SPAWN.Pipe(duplex=False)
                ends = [(sending, "send"), (receiving, "recv")]
            else:
                queue = SPAWN.Queue()
                ends = [(queue, "put"), (queue, "get")]
            targets = [(roles.object_producer, (*ends[0], barrier, n)), (roles.object_consumer, (*ends[1], barrier))]
        run_peers(targets, out, timeout)
        return dds._one_way(found, n)


def _iceoryx_name(kind: str) -> str:
    """A service name no other run (or another engineer's benchmark) shares."""
    return f"anodize-peers/{os.getpid()}/{next(_RUNS)}/{kind}"


def frames(way: str, n: int, timeout: float) -> dict[str, Any]:
    if way in ("copy", "buffer"):
        found = transport.frames_anodize(n, timeout, produce=way == "buffer", monitors=False)
    elif way in ("memcpy", "memcpy_pool"):
        found = {"frames": n, "bad": 0, "seconds": roles.memcpy_frames(n, pool_target=way == "memcpy_pool")}
    else:
        with bench_env(transport_roles.ENV) as (out, result):
            barrier = SPAWN.Barrier(2)
            if way == "zmq_ipc":
                address = f"ipc://{out}/frames"
                targets = [(roles.zmq_frame_source, (address, barrier, n)), (roles.zmq_frame_sink, (address, barrier))]
            elif way == "iceoryx2":
                name = _iceoryx_name("frames")
                targets = [(ice.frame_source, (name, barrier, n)), (ice.frame_sink, (name, barrier))]
            else:
                receiving, sending = SPAWN.Pipe(duplex=False)
                targets = [(roles.pipe_frame_source, (sending, barrier, n)),
                           (roles.pipe_frame_sink, (receiving, barrier))]
            run_peers(targets, out, timeout)
            found = transport._frames_checked(result("frames"), n)
    return _rate(n, found["seconds"], bad=found["bad"])


def spin_setting() -> dict[str, Any] | None:
    """The keyword that turns on spin-then-park for a group, if ``System.group`` has one."""
    return {"spin": SPIN} if "spin" in inspect.signature(System.group).parameters else None


def _own_cpus() -> list[set[int]] | list[None]:
    """Pollers' CPUs: one each when the machine has two (a poller sharing a CPU only burns it)."""
    cpus = sorted(os.sched_getaffinity(0))
    return [{cpus[0]}, {cpus[1]}] if len(cpus) >= 2 else [None, None]


def round_trip(way: str, rounds: int, warmup: int, timeout: float) -> dict[str, Any]:
    with bench_env(transport_roles.ENV, rounds=rounds, warmup=warmup) as (out, found):
        barrier = SPAWN.Barrier(2)
        if way == "anodize":
            transport.run_system("PingPong", {"client": (None, {"A": roles.ping_client}),
                                              "server": (None, {"B": transport_roles.ping_server})}, timeout)
        elif way == "anodize_spin":
            # ---- anodize with spin: the "spin" change's per-group setting (issue 31, item 3) ----
            # Each group polls for up to SPIN before it sleeps, each on its own CPU as the
            # target asks. Listed in ROUND_WAYS only when System.group accepts spin=.
            system = System(transport.GLOBALS["PingPong"], transport=Processes())
            for (group, role, function), cpus in zip((("client", "A", roles.ping_client),
                                                      ("server", "B", transport_roles.ping_server)), _own_cpus(),
                                                     strict=True):
                system.group(group, cpus=cpus, **(spin_setting() or {})).role(role, function)
            report = system.run(timeout=timeout)
            if not report.ok:
                raise RuntimeError(f"anodize run failed:\n{report.summary()}")
        elif way == "mp_pipe":
            client, server = SPAWN.Pipe()
            run_peers([(roles.pipe_client, (client, barrier, warmup, rounds)),
                       (transport_roles.pipe_server, (server, barrier))], out, timeout)
        elif way in ("iceoryx2_event", "iceoryx2_polling"):
            name, event = _iceoryx_name("pingpong"), way == "iceoryx2_event"
            cpus = _own_cpus() if not event else [None, None]
            run_peers([(ice.ping_client, (name, event, barrier, warmup, rounds, cpus[0])),
                       (ice.ping_server, (name, event, barrier, cpus[1]))], out, timeout)
        else:  # the raw descriptors travel to the spawned processes wrapped as Connections
            ends = [Connection(fd) for pair in (os.pipe(), os.pipe()) for fd in pair]  # r1 w1 r2 w2
            try:
                run_peers([(roles.os_pipe_client, (ends[1], ends[2], barrier, warmup, rounds)),
                           (roles.os_pipe_server, (ends[0], ends[3], barrier))], out, timeout)
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
    return {"median": statistics.median(values), "min": min(values), "max": max(values), "runs": len(values)}


def _cell(found: dict[str, Any] | None, repeat: int, scale: float = 1.0, spec: str = ",.0f", suffix: str = "") -> str:
    if found is None:
        return f"failed ({repeat} of {repeat})"
    m, lo, hi = (found[k] / scale for k in ("median", "min", "max"))
    failed = repeat - found["runs"]
    return f"{m:{spec}}{suffix} ({lo:{spec}}-{hi:{spec}})" + (f", {failed} of {repeat} failed" if failed else "")


def _target(name: str, numerator: float | None, denominator: float | None, op: str, bound: float,
            absent: str = "a way failed") -> dict[str, Any]:
    """A target as a ratio of medians; ``absent`` says why there is none when a median is missing."""
    ratio = numerator / denominator if numerator and denominator else None
    met = None if ratio is None else (ratio >= bound if op == ">=" else ratio <= bound if op == "<=" else ratio > bound)
    return {"name": name, "ratio": ratio, "target": f"{op} {bound:g}x", "met": met,
            **({"why_none": absent} if ratio is None else {})}


# A way's label in one workload, where it differs from NAMES.
LABELS = {("frames", "iceoryx2"): "iceoryx2, loaned samples written in place, polling"}
WORKLOADS = (("threads", "stream, two threads, msgs/s", "per_second", THREAD_WAYS, 1e3, ",.0f", "k"),
             ("processes", "stream, two processes, msgs/s", "per_second", PROCESS_WAYS, 1e3, ",.0f", "k"),
             ("frames", "frames 640x480x3, two processes, frames/s", "per_second", FRAME_WAYS, 1.0, ",.0f", ""),
             ("round_trip", "round trip, two processes, p50 us", "p50_us", ROUND_WAYS, 1.0, ".1f", ""),
             ("round_trip", "round trip, two processes, p99 us", "p99_us", ROUND_WAYS, 1.0, ".1f", ""))


def targets_of(results: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """The issue's targets as ratios of medians, each met, NOT met, or n/a (a way failed or is absent)."""
    def med(workload: str, key: str) -> Callable[[str], float | None]:
        def of(way: str) -> float | None:
            found = results[workload]["stats"][key].get(way)
            return found["median"] if found else None
        return of

    th, pr, fr = (med(workload, "per_second") for workload in ("threads", "processes", "frames"))
    p50, p99 = med("round_trip", "p50_us"), med("round_trip", "p99_us")
    return [
        _target("threads: monitored / pyzmq inproc", th("monitored"), th("zmq_inproc"), ">=", 1.2),
        _target("threads: monitored / unmonitored", th("monitored"), th("unmonitored"), ">=", 0.9),
        _target("processes: monitored / pyzmq ipc", pr("monitored"), pr("zmq_ipc"), ">=", 1.5),
        _target("processes: monitored / iceoryx2", pr("monitored"), pr("iceoryx2"), ">=", 1.0),
        _target("processes: monitored / unmonitored", pr("monitored"), pr("unmonitored"), ">=", 0.9),
        _target("processes: send_many / pyzmq ipc", pr("batched"), pr("zmq_ipc"), ">=", 1.2),
        _target("frames: copy / memcpy", fr("copy"), fr("memcpy"), ">=", 0.7),
        _target("frames: copy / memcpy into a pool of 8", fr("copy"), fr("memcpy_pool"), ">=", 0.7),
        _target("frames: ep.buffer() / copy", fr("buffer"), fr("copy"), ">", 1.0),
        _target("frames: ep.buffer() / iceoryx2 loaned", fr("buffer"), fr("iceoryx2"), ">=", 1.0),
        _target("round trip with polling: p50 anodize spin / os.pipe", p50("anodize_spin"), p50("os_pipe"), "<=", 0.3,
                "a way failed" if "anodize_spin" in ROUND_WAYS else "System.group has no spin= setting in this build"),
        _target("round trip without polling: p50 anodize / mp.Pipe", p50("anodize"), p50("mp_pipe"), "<=", 1.0),
        _target("round trip without polling: p99 anodize / mp.Pipe", p99("anodize"), p99("mp_pipe"), "<=", 1.0),
    ]


def summarise(results: dict[str, dict[str, Any]], repeat: int) -> tuple[list[list[str]], list[dict[str, Any]]]:
    """The table (a row per workload and way: median, spread, failures; then a row per target) and
    the targets."""
    rows = [["workload", "way", "median (min-max)", "target"]]
    for workload, label, key, ways, scale, spec, suffix in WORKLOADS:
        stats = results[workload]["stats"][key]
        rows.extend([label, LABELS.get((workload, way), NAMES[way]), _cell(stats.get(way), repeat, scale, spec, suffix),
                     ""] for way in ways)
    targets = targets_of(results)
    mark = {True: "met", False: "NOT met", None: "n/a"}
    for t in targets:
        ratio = "-" if t["ratio"] is None else f"{t['ratio']:.2f}x"
        why = f" ({t['why_none']})" if "why_none" in t else ""
        rows.append(["target", t["name"], ratio, f"{t['target']}: {mark[t['met']]}{why}"])
    return rows, targets


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
                        help="smoke test: 20,000 messages, 200 frames, 2,000 round trips, 1 repetition, 30 s timeout")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON, help=f"default {DEFAULT_JSON}")
    args = parser.parse_args(argv)
    if args.quick:
        args.messages, args.frames = min(args.messages, 20_000), min(args.frames, 200)
        args.rounds, args.warmup, args.repeat = min(args.rounds, 2000), 100, 1
        args.timeout = min(args.timeout, 30.0)

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
    rows, targets = summarise(results, args.repeat)

    versions = {"python": platform.python_version(), "numpy": np.__version__, "pyzmq": zmq.__version__,
                "libzmq": zmq.zmq_version(), "cyclonedds": importlib.metadata.version("cyclonedds"),
                "iceoryx2": importlib.metadata.version("iceoryx2")}
    how = (f"anodize vs peers, {load['cpus']} CPUs, Python {versions['python']}, pyzmq {versions['pyzmq']} "
           f"(libzmq {versions['libzmq']}), cyclonedds {versions['cyclonedds']}, iceoryx2 {versions['iceoryx2']}; "
           f"median (min-max) of {args.repeat}, failed repetitions counted; {args.messages:,} messages, "
           f"{args.frames:,} frames, {args.rounds:,} round trips per run; each peer configured as "
           "docs/performance.md says")
    print(how)
    print(LoadWatch.headline(load))
    if source.get("uncommitted"):
        print(f"measured with uncommitted changes to {', '.join(source['uncommitted'])} (on {source['commit'][:10]})")
    print()
    print_table(rows, (0, 1, 3))

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
        "targets": targets,
        **results,
    }
    write_results(args.json, document, started, title="Against other ways of moving messages", how=how,
                  watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
