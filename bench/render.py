#!/usr/bin/env python3
"""Frames per second of TinMan's two renderers at 640x480 on one core: ray caster and face warps.

  ray caster    ``tinman.render.RoomRenderer``: every pixel's ray against the room's planes
                and boxes, trilinear texture samples, supersampled face borders.
  warp          ``tinman.render_warp.WarpRenderer``: per visible face, near-plane clipping,
                row spans and an exact plane depth test, then ``cv2.warpPerspective`` of its
                texture at the mip levels it needs, blended as the ray caster blends them.
                It does not supersample face borders.
  ray caster without border supersampling
                for reference only: the ray caster with its ``_antialias_borders`` step
                switched off, to show what the warps themselves buy (both renderers spend
                most of a frame sampling textures: two bilinear taps and a blend per pixel).

Both render the default room (``DEFAULT_WORLD``, textures from seed 0) with the freiburg1
camera (640x480) from the camera poses of the robot's patrol: the mission simulation's path
(``tinman.mission.simulate_mission``, the one the default synthetic sequence is filmed along),
sampled at 30 fps for --seconds. The process is pinned to one CPU (``os.sched_setaffinity``)
and OpenCV to one thread. A run renders every pose once; fps = frames / seconds of that run;
the table gives the median over --repeat runs, the renderers taking turns within every run (in
reversed order every other run) so drift in the machine's load hits all of them. "Share of a core
at 30 fps" is the median time per frame times 30. A few frames are rendered
untimed first, by each renderer. The load average is recorded: the machine is shared.

Agreement: on every 30th pose, the fraction of pixels whose depths agree within 1e-6 relative,
and the colour difference (per pixel, the largest of the three channels): mean and the fraction
above 8 levels. All pixels count, so the ray caster's supersampled face borders show up there
(the tests compare away from the borders).

Usage:
  .venv/bin/python bench/render.py [--repeat 5] [--seconds 30] [--cpu 0] [--quick] [--json PATH]
"""

from __future__ import annotations

import argparse
import datetime
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
# bench/ holds a tinman.py: with bench/ on the path, 'import tinman' would import it.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != BENCH]
sys.path.insert(0, str(REPO))
sys.path.append(str(BENCH))  # last: bench's shared helpers (runs.py), after the real tinman package

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from runs import LoadWatch, write_results  # noqa: E402

from tinman.geometry import FR1, camera_pose  # noqa: E402
from tinman.mission import simulate_mission  # noqa: E402
from tinman.render import RoomRenderer  # noqa: E402
from tinman.render_warp import WarpRenderer  # noqa: E402
from tinman.world import DEFAULT_WORLD  # noqa: E402

DEFAULT_JSON = BENCH / "results" / "render.json"
FRAME_RATE = 30.0
FPS_TARGET = 30.0
WARM_UP = 5
AGREEMENT_EVERY = 30
COLOUR_LEVELS = 8

RAY, WARP, RAY_PLAIN = "ray caster", "warp", "ray caster without border supersampling"

Renderer = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def renderers() -> dict[str, Renderer]:
    """The renderers, built for the default room (painting the textures takes a second each)."""
    plain = RoomRenderer(DEFAULT_WORLD, FR1, seed=0)
    plain._antialias_borders = lambda *args: None  # type: ignore[method-assign]
    return {RAY: RoomRenderer(DEFAULT_WORLD, FR1, seed=0).render,
            WARP: WarpRenderer(DEFAULT_WORLD, FR1, seed=0).render,
            RAY_PLAIN: plain.render}


def patrol_poses(seconds: float) -> np.ndarray:
    """Camera poses (``T_wc``) of the robot's patrol, at ``FRAME_RATE`` for ``seconds``."""
    trace = simulate_mission(DEFAULT_WORLD, duration=seconds, rate=100.0, seed=0)
    stamps = np.asarray(trace.stamps, dtype=float)
    path = np.asarray(trace.poses, dtype=float)
    times = np.arange(0.0, seconds - 1e-9, 1.0 / FRAME_RATE)
    x, y = np.interp(times, stamps, path[:, 0]), np.interp(times, stamps, path[:, 1])
    theta = np.interp(times, stamps, np.unwrap(path[:, 2]))
    return np.array([camera_pose(*p) for p in zip(x, y, theta, strict=True)])


def timed_run(render: Renderer, poses: np.ndarray) -> dict[str, float]:
    """Render every pose once: fps of the run and per-frame milliseconds."""
    ms = []
    started = time.perf_counter()
    for pose in poses:
        begin = time.perf_counter()
        render(pose)
        ms.append((time.perf_counter() - begin) * 1000.0)
    seconds = time.perf_counter() - started
    return {"fps": len(poses) / seconds, "ms_median": float(np.median(ms)), "ms_p95": float(np.percentile(ms, 95)),
            "ms_max": float(max(ms))}


def agreement(ray: Renderer, warp: Renderer, poses: np.ndarray) -> dict[str, float]:
    """How closely the warp renderer's frames match the ray caster's (all pixels)."""
    depth_close, colour_mean, colour_far = [], [], []
    for pose in poses:
        rgb_ray, depth_ray = ray(pose)
        rgb_warp, depth_warp = warp(pose)
        relative = np.abs(depth_warp.astype(np.float64) - depth_ray) / depth_ray
        depth_close.append(float(np.mean(relative <= 1e-6)))
        difference = np.abs(rgb_warp.astype(np.int16) - rgb_ray).max(axis=2)
        colour_mean.append(float(difference.mean()))
        colour_far.append(float(np.mean(difference > COLOUR_LEVELS)))
    return {"frames": len(poses), "depth_within_1e-6": float(np.mean(depth_close)),
            "colour_mean_abs": float(np.mean(colour_mean)), "colour_above_8": float(np.mean(colour_far))}


def table(results: dict[str, list[dict[str, float]]], agree: dict[str, float]) -> list[list[str]]:
    rows = [["renderer", f"fps on one core (median of {len(results[RAY])})", "ms/frame (median, p95)",
             "speed vs ray caster", f"share of a core at {FPS_TARGET:g} fps", f">= {FPS_TARGET:g} fps?"]]
    base = statistics.median(r["fps"] for r in results[RAY])
    for name, runs in results.items():
        fps = statistics.median(r["fps"] for r in runs)
        ms = statistics.median(r["ms_median"] for r in runs)
        p95 = statistics.median(r["ms_p95"] for r in runs)
        rows.append([name, f"{fps:.1f}", f"{ms:.2f}, {p95:.2f}", f"{fps / base:.2f}x",
                     f"{ms * FPS_TARGET / 10:.0f} %", "yes" if fps >= FPS_TARGET else "NO"])
    rows.append([f"warp vs ray caster ({agree['frames']} poses, all pixels)",
                 f"depth within 1e-6: {100 * agree['depth_within_1e-6']:.2f} %",
                 f"colour: mean abs diff {agree['colour_mean_abs']:.2f}",
                 f"> {COLOUR_LEVELS} levels: {100 * agree['colour_above_8']:.2f} % of pixels", "", ""])
    return rows


def print_table(rows: list[list[str]]) -> None:
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    for k, row in enumerate(rows):
        print("| " + " | ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)) + " |")
        if k == 0:
            print("|" + "|".join("-" * (w + 2) for w in widths) + "|")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=5, help="runs per renderer (fps: their median)")
    parser.add_argument("--seconds", type=float, default=30.0, help="seconds of patrol (30 poses each)")
    parser.add_argument("--cpu", type=int, default=0, help="the CPU to pin to (default 0)")
    parser.add_argument("--quick", action="store_true", help="smoke test: 3 s of patrol, 2 runs")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON, help=f"default {DEFAULT_JSON}")
    args = parser.parse_args(argv)
    if args.quick:
        args.repeat, args.seconds = 2, 3.0

    started = time.monotonic()
    watch = LoadWatch()
    if args.cpu not in os.sched_getaffinity(0):
        raise SystemExit(f"bench/render.py: CPU {args.cpu} is not available to this process")
    os.sched_setaffinity(0, {args.cpu})
    cv2.setNumThreads(1)
    poses = patrol_poses(args.seconds)
    chosen = renderers()
    for render in chosen.values():
        for pose in poses[:WARM_UP]:
            render(pose)
    load_before = os.getloadavg()
    results: dict[str, list[dict[str, float]]] = {name: [] for name in chosen}
    for run in range(args.repeat):
        for name in (list(chosen) if run % 2 == 0 else list(reversed(chosen))):
            results[name].append(timed_run(chosen[name], poses))
    load_after = os.getloadavg()
    agree = agreement(chosen[RAY], chosen[WARP], poses[::AGREEMENT_EVERY])

    how = (f"TinMan renderers, DEFAULT_WORLD at {FR1.width}x{FR1.height}, {len(poses)} poses of the patrol "
          f"({args.seconds:g} s at {FRAME_RATE:g} fps), pinned to CPU {args.cpu}, OpenCV {cv2.__version__} "
          f"(1 thread), numpy {np.__version__}, Python {platform.python_version()}, "
          f"load average {load_before[0]:.2f} -> {load_after[0]:.2f} on {os.cpu_count()} CPUs")
    print(how)
    print()
    rows = table(results, agree)
    print_table(rows)

    document: dict[str, Any] = {
        "benchmark": "render",
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                    "machine": platform.machine(), "processor": platform.processor(),
                    "python": platform.python_version(), "numpy": np.__version__, "opencv": cv2.__version__,
                    "pinned_cpu": args.cpu, "load_average_before": load_before, "load_average_after": load_after},
        "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "scene": {"world": "DEFAULT_WORLD", "intrinsics": "FR1", "seed": 0, "poses": len(poses)},
        "targets": {"fps_min": FPS_TARGET},
        "wall_seconds": time.monotonic() - started,
        "table": rows,
        "runs": results,
        "fps_median": {name: statistics.median(r["fps"] for r in runs) for name, runs in results.items()},
        "agreement": agree,
    }
    write_results(args.json, document, started, title="TinMan's simulated camera", how=how, watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
