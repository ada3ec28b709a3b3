#!/usr/bin/env python3
"""TinMan's visual odometry and simulated camera in both worlds, side by side: accuracy and speed on one core.

Each world's sequence is ``tinman.sequences.default_sequence(look=WORLD)``: the
robot's 30 s patrol of the default room (planner, pure pursuit, scripted joystick,
drive model), rendered at 30 fps and written in the TUM RGB-D layout (generated
once, then cached). ``easy`` is the room painted for ORB; ``realistic`` the room
of photographs, plain paint and repeated patterns, with flickering lamps and
motion blur (``tinman.worlds``). Both have Kinect-like depth noise and dropouts.
``tinman.vo.run_sequence`` runs the odometry over every frame, starting from the
ground truth's first pose and using nothing else from it.

  accuracy  ATE RMSE after Horn alignment, exactly as the TUM benchmark's
            evaluate_ate.py (``tinman.ate``), over the trajectory's length.
            Target: <= 1.0 % of the length. Drift: the final position error,
            unaligned (in the frame the odometry starts in), per metre travelled.
            The odometry is deterministic (OpenCV's RANSAC seeds itself), so
            every repetition gives the same ATE; the bench checks that.
  speed     VO: frames per second of tracking time, reading and decoding the
            PNGs not counted; median over --repeat runs. Target: >= 15 fps (aim:
            30, as the odometry shares two cores with the rest of the system).
            Rendering: frames per second of the ray caster alone, and of the
            whole simulated camera (``LiveCamera.capture``: the renderer that
            world's camera uses, lamps, motion blur, noise, messages), on
            --render-frames poses of the patrol at the robot's velocity there.
  ablation  the easy world's run with the depth refinement switched off
            (reprojection errors only, ``cv2.solvePnPRefineLM``), and the realistic
            world's without the low-contrast FAST fallback (threshold 20 only), to
            show what each buys.

--patrol measures the whole robot instead: N runs of ``anodize run tinman --patrol``
(every waypoint, then back to the dock, or the time limit) quiet and N with two CPU hogs at
normal priority, interleaved: patrol completed, time to complete, bumps, safety stops,
recoveries, VO and fused ATE, control period p99 (``bench/patrol_runs.py``); medians and
spread, into bench/results/tinman_patrol.json. A run takes up to the time limit (180 s).

The process is pinned to one CPU (``os.sched_setaffinity``) and OpenCV to one
thread once the sequences exist. The machine's load average is recorded with the
results: on a shared machine other work slows everything down, so read fps with
the load in mind.

Usage:
  .venv/bin/python bench/tinman.py [--repeat 3] [--cpu N] [--max-frames N] [--worlds easy,realistic]
      [--render-frames 150] [--no-ablation] [--quick] [--json PATH]
  .venv/bin/python bench/tinman.py --patrol [--runs 10] [--limit 180] [--world realistic]
      [--loads quiet,hogs] [--keep DIR] [--json PATH]
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

BENCH = Path(__file__).resolve().parent
REPO = BENCH.parent
# This file is called tinman.py: with bench/ on the path, 'import tinman' would import it.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != BENCH]
sys.path[:0] = [str(REPO), str(REPO / "tinman" / "src")]  # the checkout's anodize and TinMan
sys.path.append(str(BENCH))  # last: bench's shared helpers (runs.py), after the real tinman package

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from runs import LoadWatch, source_state, write_results  # noqa: E402

from tinman.ate import evaluate_ate  # noqa: E402
from tinman.cameras import LiveCamera  # noqa: E402
from tinman.dataset import TumSequence  # noqa: E402
from tinman.geometry import FR1, robot_pose  # noqa: E402
from tinman.render import RoomRenderer  # noqa: E402
from tinman.vo import VoRun, run_sequence  # noqa: E402
from tinman.world import DEFAULT_WORLD  # noqa: E402
from tinman.worlds import WORLDS, world_look  # noqa: E402

DEFAULT_JSON = BENCH / "results" / "tinman.json"
DEFAULT_PATROL_JSON = BENCH / "results" / "tinman_patrol.json"
ATE_TARGET_PERCENT = 1.0
FPS_TARGET = 15.0
FPS_AIM = 30.0


def sequence_directory(world: str) -> Path:
    """The world's default sequence (generated on first use), or SystemExit with what to do instead."""
    try:
        from tinman.sequences import default_sequence
    except ImportError as error:
        raise SystemExit(f"bench/tinman.py: tinman.sequences.default_sequence is not available ({error}); "
                         "write a sequence with 'tinman generate DIR' and pass --sequence DIR") from None
    return default_sequence(log=lambda line: print(line, flush=True), look=world)


def pin_to_one_cpu(cpu: int | None) -> int:
    """Pin this process to one CPU (the last one unless told) and OpenCV to one thread; return the CPU."""
    allowed = sorted(os.sched_getaffinity(0))
    chosen = allowed[-1] if cpu is None else cpu
    if chosen not in allowed:
        raise SystemExit(f"bench/tinman.py: CPU {chosen} is not available to this process (allowed: {allowed})")
    os.sched_setaffinity(0, {chosen})
    cv2.setNumThreads(1)
    return chosen


def summarise(run: VoRun, sequence: TumSequence) -> dict[str, Any]:
    """ATE, drift, speed and tracking counts of one run."""
    truth = sequence.groundtruth
    if truth is None:
        raise SystemExit(f"bench/tinman.py: {sequence.directory} has no groundtruth.txt")
    result = evaluate_ate(truth[0], truth[1][:, :3, 3], run.stamps, run.poses[:, :3, 3])
    nearest = int(np.argmin(np.abs(truth[0] - run.stamps[-1])))
    final = float(np.linalg.norm(run.poses[-1][:3, 3] - truth[1][nearest][:3, 3]))
    ms = np.array([s.ms for s in run.stats])
    return {
        "frames": len(run.stats), "failed": run.failures, "keyframes": run.keyframes,
        "ate_rmse_m": result.rmse, "ate_max_m": result.max, "ate_median_m": result.median,
        "length_m": result.length, "percent": result.percent, "pairs": result.pairs,
        "final_error_m": final, "drift_per_m": final / result.length if result.length > 0 else float("nan"),
        "fps": run.fps, "ms_median": float(np.median(ms)), "ms_p95": float(np.percentile(ms, 95)),
        "ms_max": float(ms.max()),
        "median_inliers": float(np.median([s.inliers for s in run.stats[1:]])) if len(run.stats) > 1 else 0.0,
        "median_features": float(np.median([s.features for s in run.stats])),
        "longest_failure_run": _longest_run([s.failed for s in run.stats]),
    }


def _longest_run(flags: list[bool]) -> int:
    longest = current = 0
    for flag in flags:
        current = current + 1 if flag else 0
        longest = max(longest, current)
    return longest


def render_speed(world: str, sequence: TumSequence, frames: int) -> dict[str, Any]:
    """Milliseconds per frame of the ray caster, and of the world's whole simulated camera, over
    ``frames`` poses spread along the sequence's ground truth (the robot's velocity from it)."""
    truth = sequence.groundtruth
    assert truth is not None
    stamps, poses = truth
    picks = np.linspace(1, len(stamps) - 2, frames).astype(int)
    robots = [robot_pose(poses[i]) for i in picks]
    velocities = []
    for i in picks:
        (x0, y0, a0), (x1, y1, a1) = robot_pose(poses[i - 1]), robot_pose(poses[i + 1])
        dt = float(stamps[i + 1] - stamps[i - 1])
        turn = (a1 - a0 + np.pi) % (2 * np.pi) - np.pi
        velocities.append((float(np.hypot(x1 - x0, y1 - y0) / dt), float(turn / dt)))
    ray = RoomRenderer(DEFAULT_WORLD, FR1, seed=0, paint=world_look(world).paint)
    camera = LiveCamera(DEFAULT_WORLD, FR1, seed=0, look=world)
    ray_ms, camera_ms = [], []
    for k, (robot, velocity) in enumerate(zip(robots, velocities, strict=True)):
        pose = poses[picks[k]]
        began = time.perf_counter()
        ray.render(pose)
        ray_ms.append((time.perf_counter() - began) * 1000.0)
        began = time.perf_counter()
        camera.capture(robot, float(stamps[picks[k]]), velocity=velocity)
        camera_ms.append((time.perf_counter() - began) * 1000.0)
    return {"frames": frames, "camera_renderer": type(camera.renderer).__name__,
            "ray_ms_median": float(np.median(ray_ms)), "ray_fps": 1000.0 / float(np.median(ray_ms)),
            "camera_ms_median": float(np.median(camera_ms)), "camera_ms_p95": float(np.percentile(camera_ms, 95)),
            "camera_fps": 1000.0 / float(np.median(camera_ms))}


def table(results: dict[str, dict[str, Any]], ablations: dict[str, tuple[str, dict[str, Any]]]) -> list[list[str]]:
    """Measures down, worlds across, then the target and whether every world met it."""
    worlds = list(results)
    yes = {True: "yes", False: "NO"}

    def row(measure: str, cell: Any, target: str = "", met: Any = None) -> list[str]:
        cells = [cell(results[w]) for w in worlds]
        verdict = "" if met is None else "/".join(yes[bool(met(results[w]))] for w in worlds)
        return [measure, *cells, target, verdict]

    def first(r: dict[str, Any]) -> dict[str, Any]:
        return r["runs"][0]  # type: ignore[no-any-return]

    def fps(r: dict[str, Any]) -> float:
        return statistics.median(x["fps"] for x in r["runs"])

    repeats = len(results[worlds[0]]["runs"])
    rows = [
        ["measure", *worlds, "target", "met?"],
        row("ATE RMSE, m", lambda r: f"{first(r)['ate_rmse_m']:.4f}"),
        row("trajectory length, m", lambda r: f"{first(r)['length_m']:.2f}"),
        row("ATE / length", lambda r: f"{first(r)['percent']:.3f} %", f"<= {ATE_TARGET_PERCENT:g} %",
            lambda r: first(r)["percent"] <= ATE_TARGET_PERCENT),
        row("drift: final error / length, m/m", lambda r: f"{first(r)['drift_per_m']:.4f}"),
        row("frames failed (longest run), keyframes",
            lambda r: f"{first(r)['failed']} ({first(r)['longest_failure_run']}), {first(r)['keyframes']}"),
        row("ORB features, PnP inliers (medians)",
            lambda r: f"{first(r)['median_features']:.0f}, {first(r)['median_inliers']:.0f}"),
        row(f"VO on one core, fps (median of {repeats})", lambda r: f"{fps(r):.1f}",
            f">= {FPS_TARGET:g} (aim {FPS_AIM:g})", lambda r: fps(r) >= FPS_TARGET),
        row("VO per frame, ms (median, p95)",
            lambda r: f"{statistics.median(x['ms_median'] for x in r['runs']):.1f}, "
                      f"{statistics.median(x['ms_p95'] for x in r['runs']):.1f}"),
        row("ray caster, fps (ms median)",
            lambda r: f"{r['render']['ray_fps']:.0f} ({r['render']['ray_ms_median']:.1f})"),
        row("simulated camera, fps (ms median)",
            lambda r: f"{r['render']['camera_fps']:.0f} ({r['render']['camera_ms_median']:.1f})",
            ">= 30", lambda r: r["render"]["camera_fps"] >= 30),
        row("  its renderer", lambda r: r["render"]["camera_renderer"]),
    ]
    for name, (world, ablation) in ablations.items():
        cell = f"{ablation['percent']:.3f} %, {ablation['drift_per_m']:.4f}, {ablation['failed']}"
        rows.append([f"ablation {name}: ATE / length, drift, failed",
                     *(cell if w == world else "" for w in worlds), "", ""])
    return rows


def print_table(rows: list[list[str]]) -> None:
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    last = len(rows[0]) - 1
    for k, row in enumerate(rows):
        cells = [cell.ljust(w) if i in (0, last - 1, last) else cell.rjust(w)
                 for i, (cell, w) in enumerate(zip(row, widths, strict=True))]
        print(" | ".join(cells).rstrip())
        if k == 0:
            print("-+-".join("-" * w for w in widths))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=3, help="VO runs over each sequence (speed: their median)")
    parser.add_argument("--cpu", type=int, help="the CPU to pin to (default: the last one allowed)")
    parser.add_argument("--max-frames", type=int, help="use only the first N frames")
    parser.add_argument("--worlds", default=",".join(WORLDS), help=f"comma-separated (default {','.join(WORLDS)})")
    parser.add_argument("--render-frames", type=int, default=150, help="poses timed per renderer (default 150)")
    parser.add_argument("--no-ablation", action="store_true", help="skip the run without depth refinement")
    parser.add_argument("--quick", action="store_true", help="smoke test: 150 frames, 1 run, no ablation")
    parser.add_argument("--json", type=Path, default=None,
                        help=f"default {DEFAULT_JSON} ({DEFAULT_PATROL_JSON} with --patrol)")
    patrol = parser.add_argument_group("the whole patrol (--patrol)")
    patrol.add_argument("--patrol", action="store_true", help="run whole patrols instead (see above)")
    patrol.add_argument("--runs", type=int, default=10, help="patrols per load (default 10)")
    patrol.add_argument("--limit", type=float, default=180.0, help="each patrol's time limit, s (default 180)")
    patrol.add_argument("--world", choices=WORLDS, default="realistic", help="the room's look (default realistic)")
    patrol.add_argument("--loads", default="quiet,hogs", help="comma-separated: quiet, hogs (default both)")
    patrol.add_argument("--keep", type=Path, help="copy each run's trajectory.png into this folder")
    args = parser.parse_args(argv)
    if args.patrol:
        return patrol_main(args, parser)
    args.json = args.json or DEFAULT_JSON
    worlds = [w for w in args.worlds.split(",") if w]
    unknown = [w for w in worlds if w not in WORLDS]
    if unknown or not worlds:
        parser.error(f"--worlds {args.worlds}: expected names from {', '.join(WORLDS)}")
    if args.quick:
        args.repeat, args.no_ablation = 1, True
        args.max_frames = min(args.max_frames or 150, 150)
        args.render_frames = min(args.render_frames, 30)

    started = time.monotonic()
    watch = LoadWatch()
    directories = {world: sequence_directory(world) for world in worlds}  # generating uses both cores
    sequences = {world: TumSequence.open(directory) for world, directory in directories.items()}
    cpu = pin_to_one_cpu(args.cpu)
    load_before = os.getloadavg()
    results: dict[str, dict[str, Any]] = {}
    for world, sequence in sequences.items():
        runs = [summarise(run_sequence(sequence, max_frames=args.max_frames), sequence) for _ in range(args.repeat)]
        if len({r["ate_rmse_m"] for r in runs}) != 1:
            print(f"note: {world}: the ATE differed between runs (the odometry should be deterministic): "
                  + ", ".join(f"{r['ate_rmse_m']:.6f}" for r in runs))
        results[world] = {"runs": runs, "render": render_speed(world, sequence, args.render_frames),
                          "sequence": {"directory": str(directories[world]), "frames": len(sequence),
                                       "metadata": sequence.metadata}}
    ablations: dict[str, tuple[str, dict[str, Any]]] = {}
    if not args.no_ablation and "easy" in sequences:
        ablations["no depth refinement"] = ("easy", summarise(
            run_sequence(sequences["easy"], max_frames=args.max_frames, use_depth=False), sequences["easy"]))
    if not args.no_ablation and "realistic" in sequences:
        ablations["FAST 20 only"] = ("realistic", summarise(
            run_sequence(sequences["realistic"], max_frames=args.max_frames, low_contrast_threshold=None),
            sequences["realistic"]))
    load_after = os.getloadavg()

    frames = results[worlds[0]]["runs"][0]["frames"]
    how = (f"TinMan visual odometry and simulated camera, worlds {', '.join(worlds)} ({frames} frames each "
          f"at {sequences[worlds[0]].frame_rate:.0f} fps), pinned to CPU {cpu}, OpenCV 1 thread, "
          f"Python {platform.python_version()}, OpenCV {cv2.__version__}, "
          f"load average {load_before[0]:.1f} -> {load_after[0]:.1f} on {os.cpu_count()} CPUs")
    print(how)
    print()
    rows = table(results, ablations)
    print_table(rows)

    document = {
        "benchmark": "tinman",
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                    "machine": platform.machine(), "processor": platform.processor(),
                    "python": platform.python_version(), "numpy": np.__version__, "opencv": cv2.__version__,
                    "pinned_cpu": cpu, "opencv_threads": 1,
                    "load_average_before": load_before, "load_average_after": load_after},
        "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "targets": {"ate_percent_max": ATE_TARGET_PERCENT, "fps_min": FPS_TARGET, "fps_aim": FPS_AIM},
        "wall_seconds": time.monotonic() - started,
        "table": rows,
        "worlds": {world: {**result, "fps_median": statistics.median(r["fps"] for r in result["runs"])}
                   for world, result in results.items()},
        "ablations": {name: {"world": world, **summary} for name, (world, summary) in ablations.items()},
    }
    write_results(args.json, document, started, title="TinMan visual odometry", how=how, watch=watch)
    return 0


def patrol_main(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """``--patrol``: whole patrols, the loads interleaved run by run; a table and the JSON."""
    from patrol_runs import LOAD_NAMES, LOADS, run_patrol, summarise
    from patrol_runs import table as patrol_table

    loads = [load for load in args.loads.split(",") if load]
    if not loads or any(load not in LOADS for load in loads):
        parser.error(f"--loads {args.loads}: expected names from {', '.join(LOADS)}")
    if args.runs < 1 or not args.limit > 0:
        parser.error("--runs and --limit must be positive")
    started = time.monotonic()
    watch = LoadWatch()
    runs: dict[str, list[dict[str, Any]]] = {load: [] for load in loads}
    for number in range(1, args.runs + 1):
        for load in loads:
            result = run_patrol(args.limit, args.world, load, args.keep)
            watch.sample()
            runs[load].append(result)
            ended = f"completed in {result['time_s']:.1f} s" if result.get("completed") else result.get("ended_by")
            shown = result.get("error") or (f"{ended}, {result['waypoints']} waypoints, {result['bumps']} bumps, "
                                             f"VO ATE {result['vo_ate_percent']}%")
            print(f"run {number}/{args.runs} {load}: {shown}", flush=True)
    summary = {load: summarise(found) for load, found in runs.items()}
    rows = patrol_table(summary)
    how = (f"TinMan's whole patrol (`anodize run tinman --patrol --world {args.world} --duration {args.limit:g}`: "
           f"five waypoints, then back to the dock, or the time limit), {args.runs} "
           f"{'run' if args.runs == 1 else 'runs'} per load ({', '.join(LOAD_NAMES[load] for load in loads)}), "
           f"the loads interleaved run by run; medians, the range in brackets; Python {platform.python_version()} "
           f"on {os.cpu_count()} CPUs")
    if args.runs < 3:  # a proof that the benchmark works, not a measurement to compare
        how += (f"; ONLY {args.runs} {'RUN' if args.runs == 1 else 'RUNS'} PER LOAD: this shows the benchmark "
                "works, it is not a measurement (the issue's is 10 per load)")
    print(how)
    print()
    print_table(rows)
    document = {
        "benchmark": "tinman_patrol", "script": "bench/tinman.py --patrol",
        "source": source_state(REPO, "anodize", "tinman", "bench"),
        "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "table": rows, "summary": summary, "runs": runs,
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()},
    }
    write_results(args.json or DEFAULT_PATROL_JSON, document, started, title="TinMan's whole patrol", how=how,
                  watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
