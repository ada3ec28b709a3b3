"""The picture of a run: the room, the true path, the VO estimate, the plan, the simulated robot.

Drawn from files (the dataset's ground truth, the roles' records), so the
Visualizer can draw the live picture during the run and the launcher the final
one after it, with the same code.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # headless: files only, no display needed

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Rectangle

from .records import load_records
from .settings import Settings
from .tum import read_trajectory
from .world import DEFAULT_WORLD, World

__all__ = ["draw_run"]


def draw_run(path: str | Path, settings: Settings, estimate: Sequence[Sequence[float]] | None = None,
             title: str = "", world: World = DEFAULT_WORLD) -> Path:
    """Draw what is known of the run into ``path`` (PNG), atomically.

    Args:
        estimate: ``(stamp, x, y, z)`` of the VO estimate; read from the records when None.
        title: the headline (e.g. the ATE); a plain one when empty.
    """
    records = load_records(settings.records)
    figure, axes = plt.subplots(figsize=(11.5, 6.4), dpi=110)
    _draw_room(axes, world)
    stamps_seen = _draw_estimate(axes, settings, estimate)
    _draw_truth(axes, settings, stamps_seen)
    _draw_plans(axes, records.get("Planner"))
    _draw_robot(axes, records.get("Gazebo"))
    axes.set_xlim(-0.2, world.width + 0.2)
    axes.set_ylim(-0.2, world.depth + 0.2)
    axes.set_aspect("equal")
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.set_title(title or "TinMan: estimated and true trajectories")
    axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    figure.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.stem}.partial.png")
    figure.savefig(partial)
    plt.close(figure)
    partial.replace(path)
    return path


def _draw_room(axes: Any, world: World) -> None:
    grid = world.occupancy()
    axes.imshow(grid.occupied, origin="lower", cmap="Greys", alpha=0.18,
                extent=(0, world.width, 0, world.depth), interpolation="nearest")
    axes.add_patch(Rectangle((0, 0), world.width, world.depth, fill=False, lw=2.5, color="0.25"))
    for box in world.boxes:
        axes.add_patch(Rectangle((box.x0, box.y0), box.x1 - box.x0, box.y1 - box.y0, color="0.35"))
    if world.waypoints:
        wx, wy = zip(*world.waypoints, strict=True)
        axes.scatter(wx, wy, marker="*", s=140, color="goldenrod", zorder=5, label="patrol waypoints")
    axes.scatter([world.start[0]], [world.start[1]], marker="s", s=60, color="black", zorder=5, label="start")


def _draw_estimate(axes: Any, settings: Settings, estimate: Sequence[Sequence[float]] | None) -> np.ndarray:
    if estimate is None:
        file = settings.records / "vo_estimate.txt"
        if not file.exists():
            return np.empty(0)
        try:
            stamps, poses = read_trajectory(file)
        except (OSError, ValueError):
            return np.empty(0)
        xy = poses[:, :2, 3] if len(poses) else np.empty((0, 2))
    else:
        data = np.array(estimate, dtype=float).reshape(-1, 4)
        stamps, xy = data[:, 0], data[:, 1:3]
    if len(xy):
        axes.plot(xy[:, 0], xy[:, 1], color="tab:red", lw=1.6, label="VO estimate (VisOdom)")
    return np.asarray(stamps)


def _draw_truth(axes: Any, settings: Settings, stamps_seen: np.ndarray) -> None:
    file = Path(settings.dataset) / "groundtruth.txt"
    if not settings.dataset or not file.exists():
        return
    try:
        stamps, poses = read_trajectory(file)
    except (OSError, ValueError):
        return
    if len(stamps_seen):  # only the stretch the run covered
        keep = (stamps >= stamps_seen.min() - 0.05) & (stamps <= stamps_seen.max() + 0.05)
        stamps, poses = stamps[keep], poses[keep]
    if len(poses):
        axes.plot(poses[:, 0, 3], poses[:, 1, 3], color="tab:green", lw=2.4, alpha=0.8,
                  label="true camera path (ground truth)")


def _draw_plans(axes: Any, record: dict[str, Any] | None) -> None:
    plans = (record or {}).get("recent_plans") or []
    for i, plan in enumerate(plans):
        points = np.array(plan["points"], dtype=float)
        latest = i == len(plans) - 1
        axes.plot(points[:, 0], points[:, 1], ls="--", lw=2.0 if latest else 0.8,
                  color="tab:blue", alpha=1.0 if latest else 0.3,
                  label="latest plan (Planner)" if latest else ("earlier plans" if i == 0 else None))


def _draw_robot(axes: Any, record: dict[str, Any] | None) -> None:
    trajectory = np.array((record or {}).get("trajectory") or [], dtype=float)
    if len(trajectory):
        axes.plot(trajectory[:, 1], trajectory[:, 2], color="tab:purple", lw=1.2, alpha=0.9,
                  label="simulated robot (Gazebo)")
        x, y, theta = trajectory[-1, 1:4]
        axes.arrow(x, y, 0.3 * np.cos(theta), 0.3 * np.sin(theta), width=0.03, color="tab:purple", zorder=6)
