#!/usr/bin/env python3
"""What crossing a process boundary costs with ``transport=Processes()``, against multiprocessing.

(``transport=Dds()`` is measured by ``bench/dds.py``, side by side with this transport and
with raw Cyclone DDS, its own baseline, in one run: the same three workloads, small
messages, round trip and frames.)

Three measurements, each against a baseline measured in the same run (the
anodize and the baseline repetitions are interleaved, so drift hits both):

  frames      640x480x3 uint8 frames (900 KiB each) from a role in one group to a role
              in another: ``mu t. A -> B : {frame(Frame). t, fin}``, where ``Frame`` is
              a dataclass sort (index, send time, row checksum, pixels) so the pixels go
              through anodize's shared-memory ring and arrive as a zero-copy view.
              (Not ``type Image = "numpy:ndarray"``: that resolves, but the codec then
              treats ndarray as a named class and pickles it inline, and the receiver's
              restricted unpickler refuses numpy's reconstructor: a DecodeError.)
              Baseline: the same ``Frame`` objects through a ``multiprocessing.Queue``
              (spawn context) between two processes, i.e. pickled and piped.
              Two ways of sending: "sent from a pool", the sender cycles through 8
              pre-made frames (anodize copies each into a slot; the Queue pickles it);
              "made in place", each frame is produced anew (a 900 KiB fill, the same
              work on both sides): anodize's producer fills a slot it got from
              ``ep.buffer()`` (then nothing is copied), the baseline fills a fresh array
              (then the Queue pickles it). The receiver touches every
              frame identically in both cases (sums every 96th row and compares with the
              sender's checksum, and checks the index). Time: from the first frame's
              send (its timestamp, CLOCK_MONOTONIC, shared by all processes) to the last
              frame's receipt, taken in the receiving process. Result: frames per second.
              Target: anodize >= 20x the Queue.
  round trip  ``mu t. A -> B : {ping(int). B -> A : pong(int). t, stop}`` across two
              groups, monitored at both ends. Baseline: a duplex ``multiprocessing.Pipe()``
              between two spawned processes exchanging the same ``("ping", i)`` /
              ``("pong", i)`` tuples. --warmup untimed rounds, then --rounds timed by the
              client. Result: microseconds per round trip. Target: anodize / raw <= 1.05.
  jitter      a 100 Hz control loop in a group at ``priority=90`` (time.sleep to each next
              period on an absolute schedule; lateness = actual - scheduled wake-up, ms)
              for --jitter-seconds, once alone and once while a group at ``priority=10``
              keeps every CPU busy (one burner role per CPU, each spinning in a thread it
              starts itself, hashing a 1 MiB buffer: hashlib drops the GIL, so the burners
              really occupy one CPU each). The "alone" run is the same system with burners
              that do not burn. The control role stops the burners with a protocol message
              (``C -> B0 : stop. C -> B1 : stop ...``). Result: p50 and p99 lateness;
              ratio p99 with burner / p99 alone. Target: <= 1.2.
              anodize's watchdog demotes a SCHED_FIFO group that keeps a CPU busy for 2 s,
              so the burner runs at SCHED_FIFO 10 for about 2 s and then at SCHED_OTHER;
              the report's scheduling strings and notes are printed and kept in the JSON.
              --no-rt sets ANODIZE_NO_RT=1: nice values instead of SCHED_FIFO.

Process start-up is never timed: the anodize roles start together when the
supervisor says go; the baseline processes meet at a ``multiprocessing.Barrier``
before the first send. Each measuring role writes its numbers as JSON to a
temporary directory named in the environment (see ``bench/transport_roles.py``).
Medians over --repeat repetitions for frames and round trips; jitter runs once
per configuration (--jitter-repeat to change that; then the median of p50s and p99s).

Usage:
  .venv/bin/python bench/transport.py [--frames 2000] [--rounds 20000] [--warmup 500]
      [--repeat 3] [--jitter-seconds 5] [--jitter-repeat 1] [--no-rt] [--quick]
      [--json PATH]
"""

from __future__ import annotations

import argparse
import datetime
import multiprocessing
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

BENCH = Path(__file__).resolve().parent
REPO = BENCH.parent
for path in (str(REPO), str(BENCH)):  # bench/ too: group processes import transport_roles
    if path not in sys.path:
        sys.path.insert(0, path)

import numpy as np  # noqa: E402
import transport_roles as roles  # noqa: E402
from runs import LoadWatch, bench_env, write_results  # noqa: E402

import sessiontypes  # noqa: E402
from anodize import Processes, RunReport, System  # noqa: E402

DEFAULT_JSON = BENCH / "results" / "transport.json"
CPUS = os.cpu_count() or 1
BURNERS = [f"B{i}" for i in range(CPUS)]


def _protocols() -> dict[str, Any]:
    stops = ". ".join(f"C -> {b} : stop" for b in BURNERS)
    text = f"""
type Frame = "transport_roles:Frame"
global Frames(A, B) = mu t. A -> B : {{frame(Frame). t, fin}}
global PingPong(A, B) = mu t. A -> B : {{ping(int). B -> A : pong(int). t, stop}}
global Jitter(C, {", ".join(BURNERS)}) = {stops}
"""
    return sessiontypes.loads(text, "transport.proto").globals


GLOBALS = _protocols()


# ---- running one measurement ----------------------------------------------------------------


def run_system(global_name: str, groups: dict[str, tuple[int | None, dict[str, Callable[..., None]]]],
               timeout: float, monitors: bool = True) -> RunReport:
    system = System(GLOBALS[global_name], transport=Processes(), monitors=monitors)
    for name, (priority, placed) in groups.items():
        group = system.group(name, priority=priority)
        for role, function in placed.items():
            group.role(role, function)
    report = system.run(timeout=timeout)
    if not report.ok:
        raise RuntimeError(f"anodize run failed:\n{report.summary()}")
    return report


def run_processes(targets: list[tuple[Callable[..., None], tuple[Any, ...]]], timeout: float) -> None:
    ctx = multiprocessing.get_context("spawn")
    processes = [ctx.Process(target=fn, args=args, daemon=True) for fn, args in targets]
    for process in processes:
        process.start()
    deadline = time.monotonic() + timeout
    for process in processes:
        process.join(max(0.0, deadline - time.monotonic()))
    failed = [p for p in processes if p.exitcode != 0]
    for process in processes:
        if process.is_alive():
            process.kill()
            process.join()
    if failed:
        raise RuntimeError(f"baseline process(es) failed or timed out: {[p.exitcode for p in failed]}")


def frames_anodize(n: int, timeout: float, produce: bool = False, monitors: bool = True) -> dict[str, Any]:
    with bench_env(roles.ENV, frames=n, produce=produce) as (_, result):
        run_system("Frames", {"camera": (None, {"A": roles.frame_source}),
                              "viewer": (None, {"B": roles.frame_sink})}, timeout, monitors)
        return _frames_checked(result("frames"), n)


def frames_queue(n: int, timeout: float, produce: bool = False) -> dict[str, Any]:
    ctx = multiprocessing.get_context("spawn")
    queue, barrier = ctx.Queue(), ctx.Barrier(2)
    with bench_env(roles.ENV, produce=produce) as (_, result):
        run_processes([(roles.queue_frame_source, (queue, barrier, n)),
                       (roles.queue_frame_sink, (queue, barrier, n))], timeout)
        return _frames_checked(result("frames"), n)


def _frames_checked(found: dict[str, Any], n: int) -> dict[str, Any]:
    if found["frames"] != n or found["bad"]:
        raise RuntimeError(f"frames: {found['frames']} of {n} arrived, {found['bad']} wrong")
    return found


def pingpong_anodize(rounds: int, warmup: int, timeout: float) -> dict[str, Any]:
    with bench_env(roles.ENV, rounds=rounds, warmup=warmup) as (_, result):
        run_system("PingPong", {"client": (None, {"A": roles.ping_client}),
                                "server": (None, {"B": roles.ping_server})}, timeout)
        return result("pingpong")


def pingpong_pipe(rounds: int, warmup: int, timeout: float) -> dict[str, Any]:
    ctx = multiprocessing.get_context("spawn")
    client_end, server_end = ctx.Pipe()
    barrier = ctx.Barrier(2)
    with bench_env(roles.ENV) as (_, result):
        run_processes([(roles.pipe_client, (client_end, barrier, warmup, rounds)),
                       (roles.pipe_server, (server_end, barrier))], timeout)
        return result("pingpong")


def jitter_run(seconds: float, burn: bool) -> dict[str, Any]:
    """One control loop run; the burner group burns or idles. Bounded by run(timeout=...)."""
    with bench_env(roles.ENV, jitter_seconds=seconds, burners=BURNERS, burn=burn) as (_, result):
        report = run_system("Jitter", {"control": (90, {"C": roles.control_loop}),
                                       "burner": (10, dict.fromkeys(BURNERS, roles.burner))},
                            timeout=seconds + 30)
        control = result("control")
        burners = {b: result(f"burner-{b}") for b in BURNERS}
    lateness = np.array(control["lateness_ms"])
    burner = report.groups["burner"]
    first = burners[BURNERS[0]]  # process-wide CPU time: the same for every burner role
    return {
        "burn": burn,
        "ticks": len(lateness),
        "p50_ms": float(np.percentile(lateness, 50)),
        "p99_ms": float(np.percentile(lateness, 99)),
        "max_ms": float(lateness.max()),
        "mean_ms": float(lateness.mean()),
        "late_ticks": [[round((i + 1) * roles.PERIOD, 2), round(float(x), 3)]
                       for i, x in enumerate(lateness) if x > 1.0],  # [s into the loop, ms]
        "lateness_ms": control["lateness_ms"],
        "control_thread_policy": control["policy"],
        "scheduling": {name: g.scheduling for name, g in report.groups.items()},
        "burner_note": burner.memory_note,
        "notes": list(report.notes),
        "burner_cpus_busy": first["process_cpu_s"] / first["wall_s"] if first["wall_s"] else 0.0,
        "burners": burners,
        "report": report.to_dict(),
    }


# ---- the measurements, repeated -------------------------------------------------------------
def measure_frames(n: int, repeat: int, produce: bool = False) -> dict[str, Any]:
    samples: dict[str, list[dict[str, Any]]] = {"anodize": [], "queue": []}
    for _ in range(repeat):
        samples["anodize"].append(frames_anodize(n, timeout=120, produce=produce))
        samples["queue"].append(frames_queue(n, timeout=300, produce=produce))
    rate = {way: statistics.median(n / s["seconds"] for s in runs) for way, runs in samples.items()}
    ratio = rate["anodize"] / rate["queue"]
    return {"frames": n, "shape": [roles.HEIGHT, roles.WIDTH, roles.CHANNELS], "dtype": "uint8",
            "produce": produce, "samples": samples, "frames_per_second": rate,
            "megabytes_per_second": {w: r * roles.HEIGHT * roles.WIDTH * roles.CHANNELS / 1e6
                                     for w, r in rate.items()},
            "ratio": ratio, "target": "anodize >= 20 x multiprocessing.Queue",
            "met": ratio >= 20}


def measure_pingpong(rounds: int, warmup: int, repeat: int) -> dict[str, Any]:
    samples: dict[str, list[dict[str, Any]]] = {"anodize": [], "pipe": []}
    for _ in range(repeat):
        samples["anodize"].append(pingpong_anodize(rounds, warmup, timeout=120))
        samples["pipe"].append(pingpong_pipe(rounds, warmup, timeout=120))
    per_round = {way: statistics.median(s["seconds"] / s["rounds"] * 1e6 for s in runs)
                 for way, runs in samples.items()}
    ratio = per_round["anodize"] / per_round["pipe"]
    return {"rounds": rounds, "warmup": warmup, "samples": samples,
            "microseconds_per_round_trip": per_round, "ratio": ratio,
            "target": "anodize <= 1.05 x multiprocessing.Pipe", "met": ratio <= 1.05}


def measure_jitter(seconds: float, repeat: int) -> dict[str, Any]:
    runs: dict[str, list[dict[str, Any]]] = {"alone": [], "burner": []}
    for _ in range(repeat):
        runs["alone"].append(jitter_run(seconds, burn=False))
        runs["burner"].append(jitter_run(seconds, burn=True))
    summary = {key: {stat: statistics.median(r[stat] for r in found) for stat in ("p50_ms", "p99_ms", "max_ms")}
               for key, found in runs.items()}
    ratio = summary["burner"]["p99_ms"] / summary["alone"]["p99_ms"]
    return {"seconds": seconds, "period_s": roles.PERIOD, "burners": len(BURNERS),
            "runs": runs, "summary": summary, "ratio_p99": ratio,
            "ratio_p50": summary["burner"]["p50_ms"] / summary["alone"]["p50_ms"],
            "target": "p99 with burner <= 1.2 x p99 alone", "met": ratio <= 1.2,
            "no_rt": bool(os.environ.get("ANODIZE_NO_RT"))}


# ---- output ---------------------------------------------------------------------------------
def table(frames: dict[str, Any], pingpong: dict[str, Any], jitter: dict[str, Any],
          produced: dict[str, Any]) -> list[list[str]]:
    fps, rt, js = frames["frames_per_second"], pingpong["microseconds_per_round_trip"], jitter["summary"]
    made = produced["frames_per_second"]
    yes = {True: "yes", False: "NO"}
    return [
        ["measure", "anodize", "baseline", "ratio", "target", "met?"],
        ["frames/s, 640x480x3 uint8, made in place (vs mp.Queue)", f"{made['anodize']:,.0f}",
         f"{made['queue']:,.0f}", f"{produced['ratio']:.1f}x", ">= 20x", yes[produced["met"]]],
        ["frames/s, 640x480x3 uint8, sent from a pool (vs mp.Queue)", f"{fps['anodize']:,.0f}",
         f"{fps['queue']:,.0f}", f"{frames['ratio']:.1f}x", ">= 20x", yes[frames["met"]]],
        ["round trip, us (vs mp.Pipe)", f"{rt['anodize']:.1f}", f"{rt['pipe']:.1f}",
         f"{pingpong['ratio']:.2f}x", "<= 1.05x", yes[pingpong["met"]]],
        ["jitter p50 lateness, ms (burner vs alone)", f"{js['burner']['p50_ms']:.3f}",
         f"{js['alone']['p50_ms']:.3f}", f"{jitter['ratio_p50']:.2f}x", "", ""],
        ["jitter p99 lateness, ms (burner vs alone)", f"{js['burner']['p99_ms']:.3f}",
         f"{js['alone']['p99_ms']:.3f}", f"{jitter['ratio_p99']:.2f}x", "<= 1.2x", yes[jitter["met"]]],
    ]


def print_results(rows: list[list[str]], frames: dict[str, Any], pingpong: dict[str, Any],
                  jitter: dict[str, Any], args: argparse.Namespace) -> None:
    print(f"process transport vs multiprocessing, {CPUS} CPUs, Python {platform.python_version()}, "
          f"median of {args.repeat} (frames, round trips), jitter {args.jitter_seconds:g} s x "
          f"{args.jitter_repeat}{', ANODIZE_NO_RT=1' if args.no_rt else ''}")
    print()
    for name, runs in jitter["runs"].items():
        last = runs[-1]
        print(f"jitter, {name}: " + "; ".join(f"group {g}: {s}" for g, s in last["scheduling"].items()))
        print(f"  control thread: {last['control_thread_policy']}; burner process busy "
              f"{last['burner_cpus_busy']:.2f} CPUs; max lateness {last['max_ms']:.3f} ms")
        late = last["late_ticks"]
        if late:
            shown = ", ".join(f"{ms:.1f} ms at {t:.2f} s" for t, ms in late[:8])
            print(f"  {len(late)} wake-ups later than 1 ms: {shown}{' ...' if len(late) > 8 else ''}")
        if last["burner_note"]:
            print(f"  burner note: {last['burner_note']}")
    notes = jitter["runs"]["burner"][-1]["notes"]
    for note in notes:
        print(f"  note: {note}")
    print()
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    for k, row in enumerate(rows):
        cells = [cell.ljust(w) if i == 0 else cell.rjust(w) if i < 4 else cell.ljust(w)
                 for i, (cell, w) in enumerate(zip(row, widths, strict=True))]
        print(" | ".join(cells).rstrip())
        if k == 0:
            print("-+-".join("-" * w for w in widths))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=2000, help="frames per frames run")
    parser.add_argument("--rounds", type=int, default=20000, help="timed round trips per run")
    parser.add_argument("--warmup", type=int, default=500, help="untimed round trips first")
    parser.add_argument("--repeat", type=int, default=3, help="repetitions of frames and round trips")
    parser.add_argument("--jitter-seconds", type=float, default=5.0)
    parser.add_argument("--jitter-repeat", type=int, default=1, help="runs per jitter configuration")
    parser.add_argument("--no-rt", action="store_true", help="ANODIZE_NO_RT=1: nice values, no SCHED_FIFO")
    parser.add_argument("--quick", action="store_true",
                        help="smoke test: 200 frames, 2,000 rounds, 1 repetition, 1 s of jitter")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON, help=f"default {DEFAULT_JSON}")
    args = parser.parse_args(argv)
    if args.quick:
        args.frames, args.rounds, args.warmup = min(args.frames, 200), min(args.rounds, 2000), 200
        args.repeat, args.jitter_seconds, args.jitter_repeat = 1, 1.0, 1
    if args.no_rt:
        os.environ["ANODIZE_NO_RT"] = "1"  # inherited by every group process

    started = time.monotonic()
    watch = LoadWatch()
    frames = measure_frames(args.frames, args.repeat)
    produced = measure_frames(args.frames, args.repeat, produce=True)
    pingpong = measure_pingpong(args.rounds, args.warmup, args.repeat)
    jitter = measure_jitter(args.jitter_seconds, args.jitter_repeat)
    rows = table(frames, pingpong, jitter, produced)
    print_results(rows, frames, pingpong, jitter, args)

    document = {
        "benchmark": "transport",
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                    "machine": platform.machine(), "processor": platform.processor(),
                    "python": platform.python_version(),
                    "implementation": platform.python_implementation(), "numpy": np.__version__},
        "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "wall_seconds": time.monotonic() - started,
        "table": rows,
        "frames": frames,
        "frames_made_in_place": produced,
        "round_trip": pingpong,
        "jitter": jitter,
    }
    how = (f"anodize process transport vs multiprocessing, {os.cpu_count()} CPUs, Python {platform.python_version()}; "
           f"median of {args.repeat}; {args.frames:,} frames, {args.rounds:,} round trips per run, "
           f"{args.jitter_seconds:g} s of jitter loop per configuration")
    write_results(args.json, document, started, title="Across processes", how=how, watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
