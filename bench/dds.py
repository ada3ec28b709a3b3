#!/usr/bin/env python3
"""What ``transport="dds"`` costs between two groups on one host, against raw Cyclone DDS.

Each measure is taken three ways, interleaved in every repetition (so drift hits all):

  anodize dds      two groups, ``anodize.System(..., transport=Dds(...))`` on a DDS domain
                   derived from this process's pid, a fresh run id per run.
  raw Cyclone      two spawned processes, a writer/reader pair per direction on topics
                   of type ``anodize._transport.dds.Frame``, written with
                   ``cyclonedds._clayer.ddspy_write`` as CDR bytes built as the transport
                   builds them (``cdr_sample``), taken with ``ddspy_take`` after a WaitSet wait;
                   the transport's QoS (reliable, keep-all, reader resource limits ``READER_SAMPLES``,
                   automatic liveliness 1 s) and discovery lease; no monitors, no codec.
  anodize process  the same anodize system with ``transport=Processes()`` (pipes, and
                   shared memory for large arrays).
  raw, unbounded   (streams only) raw Cyclone with its default reader, which holds whatever
                   arrives: no back pressure, memory grows with the backlog. Shown for
                   information, as what Cyclone does when nothing bounds the receiver.

Measures:

  messages/s  a stream of small ints (``mu t. P -> C : {data(int). t, stop}``); the
              consumer counts and checks the order. Time: from the producer's clock
              just before its first send to the consumer's after the last receipt
              (CLOCK_MONOTONIC, one clock for the machine). Target: raw/dds <= 1.25x.
  round trip  ping-pong (``mu t. A -> B : {ping(int). B -> A : pong(int). t, stop}``):
              --warmup untimed rounds, then --rounds timed by the client
              (``time.perf_counter``). Microseconds per round. Target: dds/raw <= 1.25x.
  frames/s    640x480x3 uint8 frames one way, from a pool of 8 made before the clock
              starts (each stamped with its number); the receiver checks the number and
              sums every 96th row. Targets: raw/dds <= 1.25x, and dds >= 30 frames/s.

Process start-up and discovery are never timed: anodize's roles start after its start
barrier; the raw processes wait until their endpoints have matched, then meet at a
``multiprocessing.Barrier``. Every wait is bounded; a way that fails or times out
shows as "failed" in the table and its error is kept in the JSON. Medians over
--repeat repetitions.

Usage:
  .venv/bin/python bench/dds.py [--messages 20000] [--rounds 2000] [--warmup 200]
      [--frames 300] [--repeat 3] [--quick] [--json PATH]
"""

from __future__ import annotations

import argparse
import datetime
import importlib.metadata
import itertools
import multiprocessing
import os
import platform
import statistics
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

BENCH = Path(__file__).resolve().parent
REPO = BENCH.parent
for _path in (str(REPO), str(BENCH)):  # bench/ too: group processes import dds_roles
    if _path not in sys.path:
        sys.path.insert(0, _path)
os.environ["PYTHONPATH"] = os.pathsep.join(
    p for p in (str(BENCH), str(REPO), os.environ.get("PYTHONPATH", "")) if p)

import dds_roles as roles  # noqa: E402
import numpy as np  # noqa: E402
from runs import LoadWatch, bench_env, print_table, run_raw, write_results  # noqa: E402

import sessiontypes  # noqa: E402
from anodize import Dds, Inproc, Processes, System  # noqa: E402

DEFAULT_JSON = BENCH / "results" / "dds.json"
DOMAIN = 1 + os.getpid() % 232  # DDS domain ids are 0..232; 0 is everyone's default
WAYS = ("dds", "raw", "process")
# Streams only: Cyclone's own default reader, which holds whatever arrives. It has no back
# pressure (memory grows with the backlog), so it is shown for information, not as the target.
STREAM_WAYS = (*WAYS, "raw_unbounded")
TARGET = 1.25
MIN_FPS = 30.0
GLOBALS = sessiontypes.loads("""
type Image = "numpy:ndarray"
global Stream(P, C) = mu t. P -> C : {data(int). t, stop}
global Frames(P, C) = mu t. P -> C : {frame(Image). t, stop}
global PingPong(A, B) = mu t. A -> B : {ping(int). B -> A : pong(int). t, stop}
""", "dds_bench.proto").globals
_runs = itertools.count()
# A way's name -> its transport, given a fresh run id; bench/zenoh.py adds the Zenoh transport's
# ways, and measures them with this module's streams and frames.
CARRIERS: dict[str, Callable[[str], Any]] = {"dds": lambda run_id: Dds(domain=DOMAIN, run_id=run_id, wait=20),
                                             "process": lambda _: Processes()}


# ---- running one measurement ----------------------------------------------------------------
def run_anodize(transport: str, global_name: str, groups: dict[str, tuple[str, Callable[..., None]]],
                timeout: float, monitors: bool = True) -> None:
    """Run a two-group system; raise if it did not end well."""
    run_id = f"bench{os.getpid()}_{next(_runs)}"
    system = System(GLOBALS[global_name], transport=CARRIERS.get(transport, lambda _: Inproc())(run_id),
                    monitors=monitors)
    for name, (role, function) in groups.items():
        system.group(name).role(role, function)
    report = system.run(timeout=timeout)
    if not report.ok:
        raise RuntimeError(f"anodize ({transport}) run failed:\n{report.summary()}")


def _prefix(kind: str) -> str:
    return f"rawbench/{os.getpid()}_{next(_runs)}/{kind}"


def _one_way(found: Callable[[str], dict[str, Any]], n: int) -> dict[str, Any]:
    start, end = found("start")["start"], found("end")
    if end["count"] != n or end["bad"]:
        raise RuntimeError(f"{end['count']} of {n} arrived, {end['bad']} wrong or out of order")
    seconds = end["end"] - start
    return {"count": n, "seconds": seconds, "per_second": n / seconds}


def messages(way: str, n: int, timeout: float, monitors: bool = True, batched: bool = False) -> dict[str, Any]:
    with bench_env(roles.ENV, messages=n) as (out, found):
        if way in ("raw", "raw_unbounded"):
            barrier = multiprocessing.get_context("spawn").Barrier(2)
            args = (DOMAIN, _prefix("messages"), barrier, n, out, timeout, way == "raw")
            run_raw([(roles.raw_int_producer, args), (roles.raw_int_consumer, args)], timeout + 30)
        else:
            producer = roles.int_batch_producer if batched else roles.int_producer
            consumer = roles.int_batch_consumer if batched else roles.int_consumer
            run_anodize(way, "Stream", {"producing": ("P", producer),
                                        "consuming": ("C", consumer)}, timeout, monitors)
        return _one_way(found, n)


def frames(way: str, n: int, timeout: float) -> dict[str, Any]:
    with bench_env(roles.ENV, frames=n) as (out, found):
        if way in ("raw", "raw_unbounded"):
            barrier = multiprocessing.get_context("spawn").Barrier(2)
            args = (DOMAIN, _prefix("frames"), barrier, n, out, timeout, way == "raw")
            run_raw([(roles.raw_frame_producer, args), (roles.raw_frame_consumer, args)], timeout + 30)
        else:
            run_anodize(way, "Frames", {"camera": ("P", roles.frame_producer),
                                        "viewer": ("C", roles.frame_consumer)}, timeout)
        return _one_way(found, n)


def round_trip(way: str, rounds: int, warmup: int, timeout: float) -> dict[str, Any]:
    with bench_env(roles.ENV, rounds=rounds, warmup=warmup) as (out, found):
        if way == "raw":
            barrier = multiprocessing.get_context("spawn").Barrier(2)
            prefix = _prefix("pingpong")
            run_raw([(roles.raw_ping_client, (DOMAIN, prefix, barrier, rounds, warmup, out, timeout)),
                     (roles.raw_ping_server, (DOMAIN, prefix, barrier, out, timeout))], timeout + 30)
        else:
            run_anodize(way, "PingPong", {"client": ("A", roles.ping_client),
                                          "server": ("B", roles.ping_server)}, timeout)
        result = found("pingpong")
        return {**result, "microseconds": result["seconds"] / result["rounds"] * 1e6}


def attempt(measure: Callable[[], dict[str, Any]]) -> dict[str, Any]:
    """One sample, or the error it raised (printed in the table, kept in the JSON)."""
    try:
        return measure()
    except Exception as error:  # a failed way must not end the benchmark
        print(f"  failed: {error}", file=sys.stderr)
        return {"error": f"{type(error).__name__}: {error}", "traceback": traceback.format_exc()}


def measure(name: str, key: str, repeat: int, run: Callable[[str], dict[str, Any]],
            ways: tuple[str, ...] = WAYS) -> dict[str, Any]:
    """``repeat`` interleaved samples of every way; the median of ``key`` over the good ones."""
    samples: dict[str, list[dict[str, Any]]] = {way: [] for way in ways}
    for r in range(repeat):
        for way in ways:
            print(f"{name}: {way}, repetition {r + 1}/{repeat}", file=sys.stderr, flush=True)
            samples[way].append(attempt(lambda way=way: run(way)))  # type: ignore[misc]
    median = {way: (statistics.median(s[key] for s in got if "error" not in s)
                    if any("error" not in s for s in got) else None) for way, got in samples.items()}
    return {"samples": samples, "median": median}


# ---- output ---------------------------------------------------------------------------------
def _fmt(value: float | None, spec: str) -> str:
    return "failed" if value is None else format(value, spec)


def table(results: dict[str, dict[str, Any]]) -> list[list[str]]:
    yes = {True: "yes", False: "NO", None: "n/a"}
    rows = [["measure", "anodize dds", "raw Cyclone", "ratio dds/raw", "anodize process", "target", "met?"]]

    def rate_row(label: str, found: dict[str, Any], spec: str) -> None:
        med = found["median"]
        ratio = med["raw"] / med["dds"] if med["raw"] and med["dds"] else None
        found["ratio"], found["met"] = ratio, (None if ratio is None else ratio <= TARGET)
        rows.append([label, _fmt(med["dds"], spec), _fmt(med["raw"], spec),
                     _fmt(ratio, ".2f") + ("x (raw/dds)" if ratio is not None else ""),
                     _fmt(med["process"], spec), f"raw/dds <= {TARGET}x", yes[found["met"]]])
        unbounded = med.get("raw_unbounded")
        if unbounded is not None or "raw_unbounded" in med:
            ratio = unbounded / med["dds"] if unbounded and med["dds"] else None
            found["ratio_unbounded"] = ratio
            rows.append([f"{label}, raw reader unbounded", _fmt(med["dds"], spec), _fmt(unbounded, spec),
                         _fmt(ratio, ".2f") + ("x (raw/dds)" if ratio is not None else ""), "",
                         "information: no back pressure", ""])

    rate_row("messages/s, small ints", results["messages"], ",.0f")
    rt = results["round_trip"]
    med = rt["median"]
    ratio = med["dds"] / med["raw"] if med["dds"] and med["raw"] else None
    rt["ratio"], rt["met"] = ratio, (None if ratio is None else ratio <= TARGET)
    rows.append(["round trip, us (median of runs)", _fmt(med["dds"], ".1f"), _fmt(med["raw"], ".1f"),
                 _fmt(ratio, ".2f") + ("x (dds/raw)" if ratio is not None else ""), _fmt(med["process"], ".1f"),
                 f"dds/raw <= {TARGET}x", yes[rt["met"]]])
    fr = results["frames"]
    rate_row("frames/s, 640x480x3 uint8", fr, ",.1f")
    fps = fr["median"]["dds"]
    fr["met_min_fps"] = None if fps is None else fps >= MIN_FPS
    rows.append(["frames/s, 640x480x3 uint8 (absolute)", _fmt(fps, ",.1f"), "", "", "",
                 f"dds >= {MIN_FPS:g} frames/s", yes[fr["met_min_fps"]]])
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--messages", type=int, default=20000, help="small ints per throughput run")
    parser.add_argument("--rounds", type=int, default=2000, help="timed round trips per run")
    parser.add_argument("--warmup", type=int, default=200, help="untimed round trips first")
    parser.add_argument("--frames", type=int, default=300, help="frames per frames run")
    parser.add_argument("--repeat", type=int, default=3, help="repetitions of every measure")
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds a single run may take")
    parser.add_argument("--quick", action="store_true",
                        help="smoke test: 2,000 messages, 300 rounds, 50 frames, 1 repetition")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON, help=f"default {DEFAULT_JSON}")
    args = parser.parse_args(argv)
    if args.quick:
        args.messages, args.rounds, args.warmup = min(args.messages, 2000), min(args.rounds, 300), 50
        args.frames, args.repeat = min(args.frames, 50), 1

    started = time.monotonic()
    watch = LoadWatch()
    results = {
        "messages": measure("messages", "per_second", args.repeat,
                            lambda way: messages(way, args.messages, args.timeout), STREAM_WAYS),
        "round_trip": measure("round trip", "microseconds", args.repeat,
                              lambda way: round_trip(way, args.rounds, args.warmup, args.timeout)),
        "frames": measure("frames", "per_second", args.repeat,
                          lambda way: frames(way, args.frames, args.timeout), STREAM_WAYS),
    }
    rows = table(results)
    cyclone = importlib.metadata.version("cyclonedds")
    how = (f"anodize transport=\"dds\" vs raw Cyclone DDS {cyclone} vs transport=\"process\", "
          f"2 groups on one host, {os.cpu_count()} CPUs, Python {platform.python_version()}, DDS domain {DOMAIN}, "
          f"median of {args.repeat}; {args.messages:,} messages, {args.rounds:,} round trips "
          f"(after {args.warmup:,}), {args.frames:,} frames per run")
    print(how)
    print()
    print_table(rows, (0, 5, 6))

    document = {
        "benchmark": "dds",
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                    "machine": platform.machine(), "python": platform.python_version(),
                    "numpy": np.__version__, "cyclonedds": cyclone},
        "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "domain": DOMAIN,
        "wall_seconds": time.monotonic() - started,
        "table": rows,
        **results,
    }
    write_results(args.json, document, started, title="Groups across machines: DDS", how=how, watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
