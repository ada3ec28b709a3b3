"""Spin then park: a round trip between two processes, each on its own CPU, with and without
spinning, against ``os.pipe`` measured in the same run.

Ways (interleaved, ``--repeat`` times each; medians of the runs):

  os.pipe                 two processes, 8 bytes each way, blocking reads (the floor of a
                          sleeping receiver: two wake-ups per round trip)
  os.pipe, polling        the same with non-blocking reads in a loop (the floor of polling)
  anodize                 ``Processes()``, groups pinned with ``cpus``, monitored, no spin
  anodize, spin           the same with ``spin`` on both groups (``--spin``, default 200us)

Each client times every round trip alone (p50, p99 in us); the CPU a round trip costs is the
client's and the server's thread CPU time over the round trips (us per round trip: 2 x the
round trip's time when both spin all the time). Ratios are against ``os.pipe``'s p50 of the same
run. The machine's load is recorded (bench/runs.py's LoadWatch): a busy run is marked so.

  .venv/bin/python bench/spin.py [--rounds 5000] [--warmup 500] [--repeat 3] [--spin 200us]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import statistics
import sys
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import spin_roles as roles
import transport_roles
from runs import LoadWatch, bench_env, print_table, run_raw, source_state, write_results

import sessiontypes
from anodize import Processes, System

REPO = Path(__file__).resolve().parent.parent
RESULTS = REPO / "bench" / "results" / "spin.json"
WAYS = ("os_pipe", "os_pipe_poll", "anodize", "anodize_spin")
NAMES = {"os_pipe": "os.pipe", "os_pipe_poll": "os.pipe, polling", "anodize": "anodize",
         "anodize_spin": "anodize, spin"}
TARGET = 0.3  # anodize with spinning: p50 <= 0.3x os.pipe's (issue 31)
SPAWN = multiprocessing.get_context("spawn")
GLOBAL = sessiontypes.loads(roles.PROTOCOL, "spin_bench.proto").globals["PingPong"]


def cpus() -> tuple[int, int]:
    available = sorted(os.sched_getaffinity(0))
    if len(available) < 2:
        raise SystemExit("bench/spin.py needs two CPUs: each role on its own")
    return available[0], available[1]


def one_run(way: str, rounds: int, warmup: int, spin: str, timeout: float) -> dict[str, Any]:
    first, second = cpus()
    with bench_env(transport_roles.ENV, rounds=rounds, warmup=warmup) as (_, found):
        if way.startswith("anodize"):
            system = System(GLOBAL, transport=Processes())
            asked = spin if way == "anodize_spin" else None
            system.group("client", cpus={first}, spin=asked).role("A", roles.client)
            system.group("server", cpus={second}, spin=asked).role("B", roles.server)
            report = system.run(timeout=timeout)
            if not report.ok:
                raise RuntimeError(f"anodize run failed:\n{report.summary()}")
        else:
            _pipes(way == "os_pipe_poll", first, second, timeout)
        client, server = found("client"), found("server")
    times = sorted(client["times_ns"])
    return {"p50_us": statistics.median(times) / 1e3, "p99_us": times[int(0.99 * (len(times) - 1))] / 1e3,
            "cpu_us_per_round_trip": (client["cpu_s"] / rounds + server["cpu_s"] / max(1, server["rounds"])) * 1e6}


def _pipes(poll: bool, first: int, second: int, timeout: float) -> None:
    to_server, to_client = os.pipe(), os.pipe()
    ends = [Connection(fd) for fd in (*to_server, *to_client)]  # r w r w
    barrier = SPAWN.Barrier(2)
    try:
        run_raw([(roles.pipe_client, (ends[2], ends[1], first, barrier, poll)),
                 (roles.pipe_server, (ends[0], ends[3], second, barrier, poll))], timeout, "os.pipe processes")
    finally:
        for end in ends:
            end.close()


def median_of(samples: list[dict[str, Any]], key: str) -> float | None:
    good = [s[key] for s in samples if "error" not in s]
    return statistics.median(good) if good else None


def table(samples: dict[str, list[dict[str, Any]]], spin: str) -> tuple[list[list[str]], dict[str, Any]]:
    floor = median_of(samples["os_pipe"], "p50_us")
    rows = [["round trip, each role on its own CPU", "p50 us", "p99 us", "CPU us per round trip",
             "p50 / os.pipe p50"]]
    medians: dict[str, Any] = {}
    for way in WAYS:
        p50, p99 = median_of(samples[way], "p50_us"), median_of(samples[way], "p99_us")
        cpu = median_of(samples[way], "cpu_us_per_round_trip")
        ratio = p50 / floor if p50 is not None and floor else None
        medians[way] = {"p50_us": p50, "p99_us": p99, "cpu_us_per_round_trip": cpu, "ratio_to_os_pipe": ratio}
        name = NAMES[way] + (f" {spin}" if way == "anodize_spin" else "")
        rows.append([name, _cell(p50), _cell(p99), _cell(cpu), "-" if ratio is None else f"{ratio:.2f}x"])
    return rows, medians


def _cell(value: float | None) -> str:
    return "failed" if value is None else f"{value:.1f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=5000, help="timed round trips per run")
    parser.add_argument("--warmup", type=int, default=500, help="untimed round trips first")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each way, interleaved")
    parser.add_argument("--spin", default="200us", help="the groups' spin setting for 'anodize, spin'")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds one run may take")
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    started = time.monotonic()
    watch = LoadWatch()
    samples: dict[str, list[dict[str, Any]]] = {way: [] for way in WAYS}
    for r in range(args.repeat):
        for way in WAYS:
            print(f"spin: {way}, run {r + 1}/{args.repeat}", file=sys.stderr, flush=True)
            try:
                samples[way].append(one_run(way, args.rounds, args.warmup, args.spin, args.timeout))
            except RuntimeError as error:
                samples[way].append({"error": str(error)})
            watch.sample()
    rows, medians = table(samples, args.spin)
    print_table(rows, text_columns=(0,))
    spin_ratio = medians["anodize_spin"]["ratio_to_os_pipe"]
    document = {
        "table": rows, "medians": medians, "samples": samples, "target": {
            "anodize, spin p50 / os.pipe p50": TARGET, "ratio": spin_ratio,
            "met": None if spin_ratio is None else spin_ratio <= TARGET},
        "settings": {"rounds": args.rounds, "warmup": args.warmup, "repeat": args.repeat, "spin": args.spin,
                     "cpus": list(cpus())},
        "source": source_state(REPO, "anodize", "bench"),
    }
    write_results(args.output, document, started, title="Spin then park: round trips below the pipe's floor",
                  how=(f"{args.rounds:,} timed round trips (after {args.warmup:,}) per run, {args.repeat} runs of "
                       f"each way interleaved, medians; each role pinned to its own CPU; spin {args.spin}"),
                  watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
