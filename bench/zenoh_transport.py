#!/usr/bin/env python3
"""What ``transport="zenoh"`` costs between two groups, against raw Zenoh and against DDS.

(Named ``zenoh_transport.py``, not ``zenoh.py``: ``bench/`` is on the path of every group
process the benchmarks start, where a ``zenoh.py`` would hide the Zenoh library itself.
Its results are ``bench/results/zenoh.json``.)

Every measure is taken by each way in every repetition, interleaved (repetition 1 of every
way, then repetition 2, ...), so drift hits all alike:

  anodize zenoh      two groups, ``anodize.System(..., transport=Zenoh(...))``, monitors on,
                     Zenoh peers on this host, a fresh run id per run.
  raw Zenoh          two spawned processes of ``bench/zenoh_roles.py``: one Zenoh session
                     each, peer to peer over loopback TCP (one listens, the other connects;
                     no scouting), a publisher per direction, reliable with congestion control
                     BLOCK, the subscriber's default bounded FIFO read with ``recv()``; the
                     same payload bytes, no monitors, no codec (its best honest use:
                     ``zenoh_roles``'s docstring and docs/performance.md say why).
  anodize dds        the same anodize system on ``transport=Dds(...)``: ``bench/dds.py``'s
                     runs (its streams, frames and carriers; round trips timed per round).
  through a router   frames only: a Zenoh router in this process on a loopback endpoint,
                     both sides clients of it (client-router-client), anodize
                     (``Zenoh(mode="client", connect=...)``) and raw Zenoh alike.

Measures:

  messages/s  a stream of small ints (``mu t. P -> C : {data(int). t, stop}``, bench/dds.py's
              roles); the consumer counts and checks the order. Time: the producer's clock
              before its first send to the consumer's after the last receipt (CLOCK_MONOTONIC).
  frames/s    640x480x3 uint8 frames one way, from a pool of 8 made before the clock starts,
              each stamped with its number; the receiver checks it and sums every 96th row.
  round trip  ping-pong (``mu t. A -> B : {ping(int). B -> A : pong(int). t, stop}``):
              --warmup untimed rounds, then --rounds each timed alone by the client
              (``peers_roles.timed_rounds``): p50 and p99 in us. Raw Zenoh's publishers are
              ``express`` there (each message sent at once, its best for latency); a row for
              information gives raw Zenoh with ``express`` off, as the transport's publishers are.

Two more rows for information, not targets: raw Zenoh whose subscriber's callback hands
each sample to the reading thread through a bounded ``queue.Queue`` (streams and round
trips: the hand-off the transport's receiver makes to a role's thread), and raw Zenoh
with ``express`` off (round trips). They show how much of a gap such a cost explains.

Targets (issue 32), ratios of medians taken in the same run: anodize zenoh within 1.25x of
raw Zenoh on each measure (>= 0.8x raw's rate, <= 1.25x raw's p50 and p99), and anodize
zenoh through the router >= 30 frames/s. The table gives each way's median and spread
(min-max) of --repeat repetitions and how many failed, then a row per target: met, NOT met,
or n/a with the reason. The machine's load is recorded (``runs.LoadWatch``, a window after
every run); on a busy machine the header says "MACHINE BUSY: do not publish".

Start-up and discovery are never timed: anodize's roles start after its start barrier; the
raw peers wait until Zenoh reports a matching subscriber, then meet at a barrier. Every run
is bounded by --timeout, after which its processes are killed; a failed repetition is kept
in the JSON with its cause (a build without ``anodize.Zenoh`` fails those ways, saying so).

Usage:
  .venv/bin/python bench/zenoh_transport.py [--messages 20000] [--frames 300] [--rounds 2000]
      [--warmup 200] [--repeat 5] [--timeout 120] [--quick] [--json PATH]
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import importlib.metadata
import itertools
import os
import platform
import socket
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

BENCH = Path(__file__).resolve().parent
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

import dds  # noqa: E402  (first: puts bench/ and the repository on sys.path and PYTHONPATH)
import numpy as np  # noqa: E402
import peers  # noqa: E402
import peers_roles  # noqa: E402
import transport_roles  # noqa: E402
import zenoh  # noqa: E402
import zenoh_roles as raw  # noqa: E402
from runs import LoadWatch, bench_env, print_table, source_state, write_results  # noqa: E402

import anodize  # noqa: E402

DEFAULT_JSON = BENCH / "results" / "zenoh.json"
STREAM_WAYS = ("zenoh", "raw_zenoh", "dds", "raw_zenoh_callback")
FRAME_WAYS = ("zenoh", "raw_zenoh", "dds", "zenoh_router", "raw_zenoh_router")
ROUND_WAYS = (*STREAM_WAYS, "raw_zenoh_batched")
NAMES = {"zenoh": "anodize zenoh, peers, monitored", "raw_zenoh": "raw Zenoh, peer to peer",
         "dds": "anodize dds, monitored", "zenoh_router": "anodize zenoh, client-router-client, monitored",
         "raw_zenoh_router": "raw Zenoh, client-router-client",
         "raw_zenoh_batched": "raw Zenoh, peer to peer, express off (information)",
         "raw_zenoh_callback": "raw Zenoh, peer to peer, callback hands each sample to the reader (information)"}
TARGET = 1.25  # within 1.25x of raw Zenoh
MIN_FPS = 30.0  # frames through the router
WAIT = 20.0  # seconds the transport waits for its peers at start (as bench/dds.py's Dds)
_RUNS = itertools.count()
_router: list[str] = []  # the endpoint of the router open now, for the router's carrier


# ---- the ways ---------------------------------------------------------------------------------
def _zenoh(**settings: Any) -> Any:
    """``anodize.Zenoh(**settings)``, or an error saying this build has none."""
    transport = getattr(anodize, "Zenoh", None)
    if transport is None:
        raise RuntimeError("this build of anodize has no Zenoh transport (anodize.Zenoh)")
    return transport(**settings)


def _through_router(run_id: str) -> Any:
    if not _router:
        raise RuntimeError("no router is open")
    return _zenoh(mode="client", connect=(_router[-1],), run_id=run_id, wait=WAIT)


dds.CARRIERS.update({"zenoh": lambda run_id: _zenoh(run_id=run_id, wait=WAIT), "zenoh_router": _through_router})


def _free_endpoint() -> str:
    """A loopback TCP endpoint no one listens on now (the port the kernel picks for a moment)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{probe.getsockname()[1]}"


@contextlib.contextmanager
def router() -> Iterator[str]:
    """A Zenoh router in this process, listening on a fresh loopback endpoint (yielded), closed after."""
    endpoint = _free_endpoint()
    session = zenoh.open(raw.session_config("router", [endpoint], []))
    _router.append(endpoint)
    try:
        yield endpoint
    finally:
        _router.remove(endpoint)
        session.close()  # type: ignore[no-untyped-call]


@contextlib.contextmanager
def raw_sides(via_router: bool, callback: bool = False) -> Iterator[tuple[dict[str, Any], dict[str, Any]]]:
    """Where each raw side's session goes: (listener, connector) peers, or two clients of a router;
    ``callback``: their subscribers hand samples over from a callback (``zenoh_roles.RawEnd``)."""
    if via_router:
        with router() as endpoint:
            client = {"mode": "client", "listen": [], "connect": [endpoint], "callback": callback}
            yield client, client
    else:
        endpoint = _free_endpoint()
        yield ({"mode": "peer", "listen": [endpoint], "connect": [], "callback": callback},
               {"mode": "peer", "listen": [], "connect": [endpoint], "callback": callback})


def _prefix(kind: str) -> str:
    return f"anodize-bench-raw/{os.getpid()}_{next(_RUNS)}/{kind}"


def one_way(kind: str, way: str, n: int, timeout: float) -> dict[str, Any]:
    """A stream (``kind`` "messages") or frames (``kind`` "frames") of ``n``, one way, one run."""
    if not way.startswith("raw_"):
        with router() if way == "zenoh_router" else contextlib.nullcontext():
            return (dds.messages if kind == "messages" else dds.frames)(way, n, timeout)
    with bench_env(transport_roles.ENV) as (out, found), \
            raw_sides(way == "raw_zenoh_router", callback=way == "raw_zenoh_callback") as (first, second):
        barrier = peers.SPAWN.Barrier(2)
        producer, consumer = ((raw.int_producer, raw.int_consumer) if kind == "messages"
                              else (raw.frame_producer, raw.frame_consumer))
        prefix = _prefix(kind)
        peers.run_peers([(producer, (first, prefix, barrier, n)), (consumer, (second, prefix, barrier, n))],
                        out, timeout)
        return dds._one_way(found, n)


def round_trip(way: str, rounds: int, warmup: int, timeout: float) -> dict[str, Any]:
    with bench_env(transport_roles.ENV, rounds=rounds, warmup=warmup) as (out, found):
        if way.startswith("raw_"):
            express = way != "raw_zenoh_batched"  # express off, as the transport's publishers
            with raw_sides(False, callback=way == "raw_zenoh_callback") as (first, second):
                barrier, prefix = peers.SPAWN.Barrier(2), _prefix("pingpong")
                peers.run_peers([(raw.ping_server, (first, prefix, barrier, express)),
                                 (raw.ping_client, (second, prefix, barrier, rounds, warmup, express))], out, timeout)
        else:
            dds.run_anodize(way, "PingPong", {"client": ("A", peers_roles.ping_client),
                                              "server": ("B", transport_roles.ping_server)}, timeout)
        return found("pingpong")


# ---- the table ----------------------------------------------------------------------------------
WORKLOADS = (("messages", "messages/s, small ints", "per_second", STREAM_WAYS, 1e3, ",.1f", "k"),
             ("frames", "frames/s, 640x480x3 uint8", "per_second", FRAME_WAYS, 1.0, ",.1f", ""),
             ("round_trip", "round trip, p50 us", "p50_us", ROUND_WAYS, 1.0, ",.1f", ""),
             ("round_trip", "round trip, p99 us", "p99_us", ROUND_WAYS, 1.0, ",.1f", ""))


def targets_of(results: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Issue 32's targets, each met, NOT met, or n/a (a way failed)."""
    def med(workload: str, key: str, way: str) -> float | None:
        found = results[workload]["stats"][key].get(way)
        return found["median"] if found else None

    fps = med("frames", "per_second", "zenoh_router")
    absolute = {"name": "frames through a router: anodize zenoh, frames/s", "ratio": None,
                "value": fps, "target": f">= {MIN_FPS:g} frames/s", "met": None if fps is None else fps >= MIN_FPS}
    if fps is None:
        absolute["why_none"] = "a way failed"
    return [
        peers._target("messages/s: anodize zenoh / raw Zenoh", med("messages", "per_second", "zenoh"),
                      med("messages", "per_second", "raw_zenoh"), ">=", 1 / TARGET),
        peers._target("frames/s: anodize zenoh / raw Zenoh", med("frames", "per_second", "zenoh"),
                      med("frames", "per_second", "raw_zenoh"), ">=", 1 / TARGET),
        peers._target("frames/s through a router: anodize zenoh / raw Zenoh",
                      med("frames", "per_second", "zenoh_router"), med("frames", "per_second", "raw_zenoh_router"),
                      ">=", 1 / TARGET),
        peers._target("round trip p50: anodize zenoh / raw Zenoh", med("round_trip", "p50_us", "zenoh"),
                      med("round_trip", "p50_us", "raw_zenoh"), "<=", TARGET),
        peers._target("round trip p99: anodize zenoh / raw Zenoh", med("round_trip", "p99_us", "zenoh"),
                      med("round_trip", "p99_us", "raw_zenoh"), "<=", TARGET),
        absolute,
    ]


def summarise(results: dict[str, dict[str, Any]], repeat: int) -> tuple[list[list[str]], list[dict[str, Any]]]:
    """A row per workload and way (median, spread, failures), then a row per target."""
    rows = [["measure", "way", "median (min-max)", "target"]]
    for workload, label, key, ways, scale, spec, suffix in WORKLOADS:
        stats = results[workload]["stats"][key]
        rows.extend([label, NAMES[way], peers._cell(stats.get(way), repeat, scale, spec, suffix), ""] for way in ways)
    targets = targets_of(results)
    mark = {True: "met", False: "NOT met", None: "n/a"}
    for t in targets:
        shown = (f"{t['ratio']:.2f}x" if t["ratio"] is not None
                 else f"{t['value']:,.1f}" if t.get("value") is not None else "-")
        why = f" ({t['why_none']})" if "why_none" in t else ""
        rows.append(["target", t["name"], shown, f"{t['target']}: {mark[t['met']]}{why}"])
    return rows, targets


# ---- the run ------------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--messages", type=int, default=20_000, help="small ints per stream run")
    parser.add_argument("--frames", type=int, default=300, help="frames per frames run")
    parser.add_argument("--rounds", type=int, default=2000, help="timed round trips per run")
    parser.add_argument("--warmup", type=int, default=200, help="untimed round trips first")
    parser.add_argument("--repeat", type=int, default=5, help="repetitions of every way")
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds a single run may take")
    parser.add_argument("--quick", action="store_true",
                        help="smoke test: 2,000 messages, 50 frames, 1,000 round trips, 1 repetition, 60 s timeout")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON, help=f"default {DEFAULT_JSON}")
    args = parser.parse_args(argv)
    if args.quick:
        args.messages, args.frames = min(args.messages, 2000), min(args.frames, 50)
        # Round trips are cheap beside a run's start, and a p99 needs rounds: 1,000 (its 10th worst).
        args.rounds, args.warmup, args.repeat = min(args.rounds, 1000), 100, 1
        args.timeout = min(args.timeout, 60.0)

    started = time.monotonic()
    source = source_state(BENCH.parent, "anodize", "sessiontypes", "bench")  # what was measured
    watch = LoadWatch()
    results = {
        "messages": peers.measure("messages", "per_second", args.repeat,
                                  lambda way: one_way("messages", way, args.messages, args.timeout),
                                  STREAM_WAYS, watch),
        "frames": peers.measure("frames", "per_second", args.repeat,
                                lambda way: one_way("frames", way, args.frames, args.timeout), FRAME_WAYS, watch),
        "round_trip": peers.measure("round trip", "p50_us", args.repeat,
                                    lambda way: round_trip(way, args.rounds, args.warmup, args.timeout),
                                    ROUND_WAYS, watch),
    }
    load = watch.result()
    rows, targets = summarise(results, args.repeat)

    versions = {"python": platform.python_version(), "numpy": np.__version__,
                "eclipse-zenoh": importlib.metadata.version("eclipse-zenoh"),
                "cyclonedds": importlib.metadata.version("cyclonedds")}
    how = (f"anodize transport=\"zenoh\" vs raw Zenoh (eclipse-zenoh {versions['eclipse-zenoh']}) vs "
           f"transport=\"dds\" (cyclonedds {versions['cyclonedds']}), 2 groups or processes on one host over "
           f"loopback, {load['cpus']} CPUs, Python {versions['python']}; median (min-max) of {args.repeat}, failed "
           f"repetitions counted; {args.messages:,} messages, {args.frames:,} frames, {args.rounds:,} round trips "
           f"(after {args.warmup:,}) per run; raw Zenoh configured as docs/performance.md says")
    print(how)
    print(LoadWatch.headline(load))
    if source.get("uncommitted"):
        print(f"measured with uncommitted changes to {', '.join(source['uncommitted'])} (on {source['commit'][:10]})")
    print()
    print_table(rows, (0, 1, 3))

    document = {
        "benchmark": "zenoh",
        "script": "bench/zenoh_transport.py",
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "busy": load["busy"],
        "load": load,
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                    "machine": platform.machine(), **versions},
        "source": source,
        "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "wall_seconds": time.monotonic() - started,
        "table": rows,
        "targets": targets,
        **results,
    }
    write_results(args.json, document, started, title="Groups across machines: Zenoh", how=how, watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
