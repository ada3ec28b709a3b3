#!/usr/bin/env python3
"""TinMan's visual odometry on the default synthetic sequence: accuracy and speed on one core.

The sequence is ``tinman.sequences.default_sequence()``: the robot's 30 s patrol of
the default room (planner, pure pursuit, scripted joystick, drive model), rendered
at 30 fps with Kinect-like noise and written in the TUM RGB-D layout (generated
once, then cached). ``tinman.vo.run_sequence`` runs the odometry over every frame,
starting from the ground truth's first pose and using nothing else from it.

  accuracy  ATE RMSE after Horn alignment, exactly as the TUM benchmark's
            evaluate_ate.py (``tinman.ate``), over the trajectory's length.
            Target: <= 1.0 % of the length. The odometry is deterministic
            (OpenCV's RANSAC seeds itself), so every repetition gives the same
            ATE; the bench checks that.
  speed     frames per second of tracking time, the process pinned to one CPU
            (``os.sched_setaffinity``); reading and decoding the PNGs is not
            counted. Median over --repeat runs. Target: >= 15 fps (aim: 30, as
            the odometry shares two cores with the rest of the system).
  ablation  the same run with the depth refinement switched off (reprojection
            errors only, ``cv2.solvePnPRefineLM``), to show what it buys.

The machine's load average is recorded with the results: on a shared machine
other work slows the odometry down, so read fps with the load in mind.

Usage:
  .venv/bin/python bench/tinman.py [--repeat 3] [--cpu N] [--max-frames N]
      [--sequence DIR] [--no-ablation] [--quick] [--json PATH]
"""

from __future__ import annotations

import argparse
import datetime
import json
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
sys.path.insert(0, str(REPO))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from tinman.ate import evaluate_ate  # noqa: E402
from tinman.dataset import TumSequence  # noqa: E402
from tinman.vo import VoRun, run_sequence  # noqa: E402

DEFAULT_JSON = BENCH / "results" / "tinman.json"
ATE_TARGET_PERCENT = 1.0
FPS_TARGET = 15.0
FPS_AIM = 30.0


def default_sequence_directory() -> Path:
    """The default sequence (generated on first use), or SystemExit with what to do instead."""
    try:
        from tinman.sequences import default_sequence
    except ImportError as error:
        raise SystemExit(f"bench/tinman.py: tinman.sequences.default_sequence is not available ({error}); "
                         "write a sequence with 'tinman generate DIR' and pass --sequence DIR") from None
    return default_sequence(log=lambda line: print(line, flush=True))


def pin_to_one_cpu(cpu: int | None) -> int:
    """Pin this process to one CPU (the last one unless told); return it."""
    allowed = sorted(os.sched_getaffinity(0))
    chosen = allowed[-1] if cpu is None else cpu
    if chosen not in allowed:
        raise SystemExit(f"bench/tinman.py: CPU {chosen} is not available to this process (allowed: {allowed})")
    os.sched_setaffinity(0, {chosen})
    return chosen


def summarise(run: VoRun, sequence: TumSequence) -> dict[str, Any]:
    """ATE, speed and tracking counts of one run."""
    truth = sequence.groundtruth
    if truth is None:
        raise SystemExit(f"bench/tinman.py: {sequence.directory} has no groundtruth.txt")
    result = evaluate_ate(truth[0], truth[1][:, :3, 3], run.stamps, run.poses[:, :3, 3])
    ms = np.array([s.ms for s in run.stats])
    return {
        "frames": len(run.stats), "failed": run.failures, "keyframes": run.keyframes,
        "ate_rmse_m": result.rmse, "ate_max_m": result.max, "ate_median_m": result.median,
        "length_m": result.length, "percent": result.percent, "pairs": result.pairs,
        "fps": run.fps, "ms_median": float(np.median(ms)), "ms_p95": float(np.percentile(ms, 95)),
        "ms_max": float(ms.max()),
        "median_inliers": float(np.median([s.inliers for s in run.stats[1:]])) if len(run.stats) > 1 else 0.0,
    }


def table(runs: list[dict[str, Any]], ablation: dict[str, Any] | None) -> list[list[str]]:
    first = runs[0]
    fps = statistics.median(r["fps"] for r in runs)
    ms = statistics.median(r["ms_median"] for r in runs)
    p95 = statistics.median(r["ms_p95"] for r in runs)
    yes = {True: "yes", False: "NO"}
    rows = [
        ["measure", "value", "target", "met?"],
        ["ATE RMSE, m", f"{first['ate_rmse_m']:.4f}", "", ""],
        ["trajectory length, m", f"{first['length_m']:.2f}", "", ""],
        ["ATE / length", f"{first['percent']:.3f} %", f"<= {ATE_TARGET_PERCENT:g} %",
         yes[first["percent"] <= ATE_TARGET_PERCENT]],
        [f"speed on one core, fps (median of {len(runs)})", f"{fps:.1f}", f">= {FPS_TARGET:g} (aim {FPS_AIM:g})",
         yes[fps >= FPS_TARGET]],
        ["per frame, ms (median, p95)", f"{ms:.1f}, {p95:.1f}", "", ""],
        ["frames (failed, keyframes)", f"{first['frames']} ({first['failed']}, {first['keyframes']})", "", ""],
    ]
    if ablation is not None:
        rows.append(["ablation: ATE / length without depth refinement", f"{ablation['percent']:.3f} %", "", ""])
    return rows


def print_table(rows: list[list[str]]) -> None:
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    for k, row in enumerate(rows):
        cells = [cell.ljust(w) if i in (0, 2, 3) else cell.rjust(w)
                 for i, (cell, w) in enumerate(zip(row, widths, strict=True))]
        print(" | ".join(cells).rstrip())
        if k == 0:
            print("-+-".join("-" * w for w in widths))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=3, help="runs over the sequence (speed: their median)")
    parser.add_argument("--cpu", type=int, help="the CPU to pin to (default: the last one allowed)")
    parser.add_argument("--max-frames", type=int, help="use only the first N frames")
    parser.add_argument("--sequence", type=Path, help="a TUM sequence directory instead of the default one")
    parser.add_argument("--no-ablation", action="store_true", help="skip the run without depth refinement")
    parser.add_argument("--quick", action="store_true", help="smoke test: 150 frames, 1 run, no ablation")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON, help=f"default {DEFAULT_JSON}")
    args = parser.parse_args(argv)
    if args.quick:
        args.repeat, args.no_ablation = 1, True
        args.max_frames = min(args.max_frames or 150, 150)

    started = time.monotonic()
    directory = args.sequence if args.sequence is not None else default_sequence_directory()
    sequence = TumSequence.open(directory)
    cpu = pin_to_one_cpu(args.cpu)
    load_before = os.getloadavg()
    runs = [summarise(run_sequence(sequence, max_frames=args.max_frames), sequence) for _ in range(args.repeat)]
    if len({r["ate_rmse_m"] for r in runs}) != 1:
        print("note: the ATE differed between runs (the odometry should be deterministic): "
              + ", ".join(f"{r['ate_rmse_m']:.6f}" for r in runs))
    ablation = None
    if not args.no_ablation:
        ablation = summarise(run_sequence(sequence, max_frames=args.max_frames, use_depth=False), sequence)
    load_after = os.getloadavg()

    print(f"TinMan visual odometry on {directory} ({runs[0]['frames']} of {len(sequence)} frames at "
          f"{sequence.frame_rate:.0f} fps), "
          f"pinned to CPU {cpu}, Python {platform.python_version()}, OpenCV {cv2.__version__}, "
          f"load average {load_before[0]:.1f} -> {load_after[0]:.1f} on {os.cpu_count()} CPUs")
    print()
    rows = table(runs, ablation)
    print_table(rows)

    document = {
        "benchmark": "tinman",
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                    "machine": platform.machine(), "processor": platform.processor(),
                    "python": platform.python_version(), "numpy": np.__version__, "opencv": cv2.__version__,
                    "pinned_cpu": cpu, "load_average_before": load_before, "load_average_after": load_after},
        "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "sequence": {"directory": str(directory), "frames": len(sequence), "metadata": sequence.metadata},
        "targets": {"ate_percent_max": ATE_TARGET_PERCENT, "fps_min": FPS_TARGET, "fps_aim": FPS_AIM},
        "wall_seconds": time.monotonic() - started,
        "table": rows,
        "runs": runs,
        "fps_median": statistics.median(r["fps"] for r in runs),
        "ablation_without_depth_refinement": ablation,
    }
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    print(f"\nwrote {args.json} ({time.monotonic() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
