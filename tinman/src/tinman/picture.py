"""The picture of a run: the room from above, the VO error over time, camera frames, headline numbers.

Drawn from files (the dataset's ground truth and images, the roles' records and,
after the run, ``report.json``), so the Visualizer can draw the live picture
during the run and the launcher the final one after it, with the same code.

Layout (about 1600 x 1000 px):

- the room from above (metres, equal aspect): walls and boxes, the planner's grown
  obstacles, the patrol's waypoints, the camera's ground truth (a recording's
  ``groundtruth.txt``, or the simulated camera's true path that Gazebo records), the
  simulated robot's true path (the Gazebo record), the VO estimate aligned to the
  ground truth as TUM's ``evaluate_ate.py`` aligns it, the latest and earlier plans,
  start and end markers, letters where the camera frames below were taken, the waypoints the
  robot reached (ringed, with the time it reached each) and where it bumped into the room
  (crosses; both from :func:`tinman.mission_outcome.mission_marks`, as the report counts them);
- the VO estimate's position error over time (after that alignment) and its RMSE;
- a row of camera frames along the run, each with its time (a recording's images, or the
  simulated camera's view rendered again from its true pose: its images are not saved);
- a title with the run's headline numbers.

Colours are the Okabe-Ito palette (told apart with any colour vision); the ground
truth is drawn wide and below, the estimate thin, dashed and on top, so neither hides
the other where they agree.
"""

from __future__ import annotations

import json
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # headless: files only, no display needed

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle
from matplotlib.path import Path as MarkerPath
from matplotlib.transforms import Affine2D

from .ate import AteResult, evaluate_ate
from .dataset import DatasetError, TumSequence
from .geometry import FR1
from .mission import DOCK, WAYPOINT_TOLERANCE
from .mission_outcome import counted, mission_marks
from .outcome import FUSED_ESTIMATE, VO_ESTIMATE, truth_path
from .records import load_records
from .settings import Settings
from .tum import associate, read_trajectory
from .world import CLEARANCE, DEFAULT_WORLD, World

__all__ = ["draw_run", "run_figure", "FIGURE_SIZE", "DPI", "THUMBNAILS", "COLOURS"]

FIGURE_SIZE = (16.0, 10.0)  # inches: at DPI, a 1600 x 1000 px PNG
DPI = 100
THUMBNAILS = 4  # camera frames along the run

# Okabe & Ito (2008), "Color Universal Design": distinct for every common colour vision.
COLOURS = {
    "truth": "#009E73",      # bluish green: the camera's ground truth
    "robot": "#0072B2",      # blue: the simulated robot
    "estimate": "#D55E00",   # vermillion: the VO estimate
    "plan": "#CC79A7",       # reddish purple: the planner's paths
    "waypoint": "#F0E442",   # yellow: the patrol's waypoints
    "marker": "#000000",     # black: start, RMSE
    "gap": "#56B4E9",        # sky blue: stretches with no VO pose
}
_WALL = "0.30"
_GROWN = "0.86"
_TRUTH_MARGIN = 0.05  # seconds of ground truth kept beyond the run's first and last frame
_MAX_DIFFERENCE = 0.02  # seconds: evaluate_ate's association


class _Frames:
    """The camera's colour frames: their ``stamps``, and the image of each by index."""

    caption = ""

    def __init__(self, stamps: np.ndarray) -> None:
        self.stamps = stamps

    def image(self, index: int) -> np.ndarray:
        raise NotImplementedError


class _RecordedFrames(_Frames):
    """The frames of the recorded sequence the camera played back (``--dataset``)."""

    def __init__(self, sequence: TumSequence) -> None:
        super().__init__(sequence.stamps)
        self.sequence = sequence
        self.caption = f"Camera frames: colour images of the recording {sequence.directory.name}."

    def image(self, index: int) -> np.ndarray:
        return self.sequence.rgb(index)


class _RenderedFrames(_Frames):
    """The simulated camera's frames, rendered again from its true poses (the live camera's
    images are not saved): the same view, without the sensor's noise."""

    caption = ("Camera frames: rendered again from the simulated camera's true pose at those moments "
               "(the live camera's images are not saved; these lack its sensor noise).")

    def __init__(self, stamps: np.ndarray, poses: np.ndarray, world: World, seed: int, look: str = "easy") -> None:
        super().__init__(stamps)
        self.poses = poses
        self.world = world
        self.seed = seed
        self.look = look

    def image(self, index: int) -> np.ndarray:
        rgb, _ = _renderer(self.world, self.seed, self.look).render(self.poses[index])
        return np.asarray(rgb)


@lru_cache(maxsize=1)
def _renderer(world: World, seed: int, look: str = "easy") -> Any:
    """The simulated camera's renderer (painting its textures takes a second or so: kept)."""
    from .render import RoomRenderer
    from .worlds import world_look

    return RoomRenderer(world, FR1, seed, paint=world_look(look).paint)  # as tinman.cameras.LiveCamera's


@dataclass
class _Run:
    """What the picture is drawn from, read once."""

    records: dict[str, dict[str, Any]]
    report: dict[str, Any] | None  # report.json, only when written after this run's records
    recorded: bool  # the camera played a recording back (else the simulated camera rendered the room)
    frames: _Frames | None
    t0: float | None  # the time origin (s): the camera's first frame, else the first stamp known
    span: tuple[float, float] | None  # the stamps of the run's first and last frame
    truth: tuple[np.ndarray, np.ndarray] | None  # (stamps, positions N x 3) over the span
    estimate: tuple[np.ndarray, np.ndarray] | None  # (stamps, positions N x 3), aligned when ate is set
    ate: AteResult | None
    ate_stamps: np.ndarray  # the ground-truth stamp of each of ate.errors
    ate_problem: str  # why there is no ATE ("" when there is one)
    patrol: bool = False  # the whole patrol once (--patrol): the dock is its end
    name: str = "VO estimate"  # what the estimate is: "fused estimate" (the pose the robot steers by) or VO's


def draw_run(path: str | Path, settings: Settings, estimate: Sequence[Sequence[float]] | None = None,
             title: str = "", world: World = DEFAULT_WORLD) -> Path:
    """Draw what is known of the run into ``path`` (PNG, about 1600 x 1000 px), atomically.

    Args:
        estimate: ``(stamp, x, y, z)`` of the VO estimate; read from the records when None.
        title: the headline (e.g. the ATE); a plain one when empty. The run's numbers go
            under it (from ``report.json`` once the run has written it, else the records).
    """
    figure = run_figure(settings, estimate, title, world)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.stem}.partial.png")
    figure.savefig(partial, dpi=DPI)
    partial.replace(path)
    return path


def run_figure(settings: Settings, estimate: Sequence[Sequence[float]] | None = None, title: str = "",
               world: World = DEFAULT_WORLD) -> Figure:
    """The picture as a matplotlib figure (no pyplot: safe in any thread); see :func:`draw_run`."""
    run = _read_run(settings, estimate, world)
    figure = Figure(figsize=FIGURE_SIZE, dpi=DPI)
    grid = figure.add_gridspec(2, 2, width_ratios=(1.22, 1.0), height_ratios=(2.45, 1.0),
                               left=0.045, right=0.985, bottom=0.04, top=0.855, wspace=0.12, hspace=0.17)
    room = figure.add_subplot(grid[0, 0], label="room")
    right = grid[0, 1].subgridspec(2, 1, height_ratios=(1.0, 0.62), hspace=0.3)
    error = figure.add_subplot(right[0], label="error")
    key = figure.add_subplot(right[1], label="key")
    strip = grid[1, :].subgridspec(1, THUMBNAILS, wspace=0.06)
    thumbnails = [figure.add_subplot(strip[0, i], label=f"thumbnail {i}") for i in range(THUMBNAILS)]

    moments = _moments(run)
    handles = _draw_room(room, run, world, moments)
    _draw_error(error, run, moments)
    _draw_key(key, handles)
    _draw_thumbnails(thumbnails, run, moments)
    _draw_title(figure, run, title)
    return figure


# --- reading -------------------------------------------------------------------------------------


def _read_run(settings: Settings, estimate: Sequence[Sequence[float]] | None, world: World) -> _Run:
    records = load_records(settings.records)
    recorded = bool(settings.dataset)
    truth_all = _read_truth(settings)
    frames: _Frames | None = None
    if recorded:
        sequence = _open_sequence(settings)
        frames = _RecordedFrames(sequence) if sequence is not None else None
    elif truth_all is not None:  # the simulated camera's true path: one pose per frame it took
        frames = _RenderedFrames(truth_all[0], truth_all[1], world, settings.seed, settings.world)
    stamps, positions, name = _read_estimate(settings, estimate)
    first = (float(frames.stamps[0]) if frames is not None and len(frames.stamps)
             else float(stamps.min()) if len(stamps)
             else float(truth_all[0][0]) if truth_all is not None else None)
    span = _span(settings, records, frames, stamps, first)
    truth = None
    if truth_all is not None and span is not None:
        keep = (truth_all[0] >= span[0] - _TRUTH_MARGIN) & (truth_all[0] <= span[1] + _TRUTH_MARGIN)
        truth = (truth_all[0][keep], truth_all[1][keep, :3, 3])
    ate, ate_stamps, problem = None, np.empty(0), ""
    if len(stamps) and truth_all is not None:
        try:
            ate = evaluate_ate(truth_all[0], truth_all[1][:, :3, 3], stamps, positions,
                               max_difference=_MAX_DIFFERENCE)
        except ValueError as error:
            problem = str(error)
        else:  # the same association evaluate_ate made: errors[i] belongs to matches[i]
            matches = associate(truth_all[0].tolist(), stamps.tolist(), 0.0, _MAX_DIFFERENCE)
            ate_stamps = np.array([a for a, _ in matches], dtype=float)
            positions = (ate.rotation @ positions.T + ate.translation).T
    elif len(stamps):
        problem = ("the recording has no readable groundtruth.txt" if recorded
                   else "no true path yet: the simulated camera's is saved when the run stops")
    return _Run(records=records, report=_fresh_report(settings), recorded=recorded, frames=frames, t0=first,
                span=span, truth=truth, estimate=(stamps, positions) if len(stamps) else None, ate=ate,
                ate_stamps=ate_stamps, ate_problem=problem, patrol=settings.patrol, name=name)


def _open_sequence(settings: Settings) -> TumSequence | None:
    try:
        return TumSequence.open(settings.dataset)
    except DatasetError:
        return None


def _read_truth(settings: Settings) -> tuple[np.ndarray, np.ndarray] | None:
    """``(stamps, poses N x 4 x 4)`` of the camera's true path, the file the report's ATE reads."""
    try:
        stamps, poses = read_trajectory(truth_path(settings))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    return (stamps, poses) if len(stamps) else None


def _read_estimate(settings: Settings, estimate: Sequence[Sequence[float]] | None
                   ) -> tuple[np.ndarray, np.ndarray, str]:
    """``(stamps, positions, name)``: the estimate given (the Visualizer's: the pose VisOdom
    published, fused but with a recorded camera), else the fused estimate's file, else (a
    recorded camera: nothing fused) VO's."""
    if estimate is not None:
        data = np.array(estimate, dtype=float).reshape(-1, 4)
        return data[:, 0], data[:, 1:4], "VO estimate" if settings.dataset else "fused estimate"
    for file, name in ((FUSED_ESTIMATE, "fused estimate"), (VO_ESTIMATE, "VO estimate")):
        try:
            stamps, poses = read_trajectory(settings.records / file)
        except (OSError, UnicodeDecodeError, ValueError):
            continue
        return stamps, poses[:, :3, 3], name
    return np.empty(0), np.empty((0, 3)), "VO estimate"


def _span(settings: Settings, records: dict[str, dict[str, Any]], frames: _Frames | None,
          stamps: np.ndarray, first: float | None) -> tuple[float, float] | None:
    """The stamps of the run's first and last frame: from the camera's first frame to the last
    one it took (all of the simulated camera's; of a recording, as many as Gazebo played) or
    the estimate's last, whichever is later. Without either, ``duration`` seconds (or less, to
    the recording's end)."""
    if first is None:
        return None
    ends = [float(stamps.max())] if len(stamps) else []
    if isinstance(frames, _RenderedFrames):
        ends.append(float(frames.stamps[-1]))
    elif frames is not None and len(frames.stamps):
        gazebo = records.get("Gazebo", {})
        taken, skipped = gazebo.get("camera_frames"), gazebo.get("camera_frames_skipped")
        if isinstance(taken, int) and isinstance(skipped, int) and taken + skipped > 0:
            ends.append(float(frames.stamps[min(taken + skipped, len(frames.stamps)) - 1]))
        elif not ends:
            ends.append(min(first + settings.duration, float(frames.stamps[-1])))
    return first, max(ends) if ends else first + settings.duration


def _fresh_report(settings: Settings) -> dict[str, Any] | None:
    """``report.json`` if this run wrote it: not older than the records folder, which the
    launcher makes anew for every run and every record written since touches."""
    file = Path(settings.out) / "report.json"
    try:
        if file.stat().st_mtime < settings.records.stat().st_mtime:
            return None
        data = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _moments(run: _Run) -> list[tuple[float, int]]:
    """``(stamp, frame index)`` of the thumbnails: frames evenly spread over the run."""
    if run.frames is None or not len(run.frames.stamps) or run.span is None:
        return []
    stamps = run.frames.stamps
    chosen: list[tuple[float, int]] = []
    for target in np.linspace(run.span[0], run.span[1], THUMBNAILS):
        index = int(np.argmin(np.abs(stamps - target)))
        if not chosen or chosen[-1][1] != index:
            chosen.append((float(stamps[index]), index))
    return chosen


# --- drawing -------------------------------------------------------------------------------------


def _draw_room(axes: Axes, run: _Run, world: World, moments: list[tuple[float, int]]) -> list[Any]:
    """The room from above; returns the legend's handles: the lines and areas, then the markers."""
    handles: list[Any] = []  # lines and areas
    marks: list[Any] = []
    grown = CLEARANCE  # as World.occupancy's default: what the planner keeps clear of
    for box in world.boxes:
        axes.add_patch(Rectangle((box.x0 - grown, box.y0 - grown), box.x1 - box.x0 + 2 * grown,
                                 box.y1 - box.y0 + 2 * grown, facecolor=_GROWN, edgecolor="none", zorder=0.5))
    for x, y, w, h in ((0, 0, world.width, grown), (0, world.depth - grown, world.width, grown),
                       (0, 0, grown, world.depth), (world.width - grown, 0, grown, world.depth)):
        axes.add_patch(Rectangle((x, y), w, h, facecolor=_GROWN, edgecolor="none", zorder=0.5))  # along the walls
    for box in world.boxes:
        axes.add_patch(Rectangle((box.x0, box.y0), box.x1 - box.x0, box.y1 - box.y0, facecolor=_WALL,
                                 edgecolor="none", zorder=1))
    axes.add_patch(Rectangle((0, 0), world.width, world.depth, fill=False, lw=3.0, edgecolor=_WALL, zorder=1))

    if world.waypoints:
        wx, wy = zip(*world.waypoints, strict=True)
        marks.append(axes.scatter(wx, wy, marker="*", s=260, facecolor=COLOURS["waypoint"], edgecolor="black",
                                  lw=0.8, zorder=7, label="patrol waypoints, in order"))
        for number, (x, y) in enumerate(world.waypoints, 1):
            axes.annotate(str(number), (x, y), xytext=(7, 5), textcoords="offset points", fontsize=9,
                          fontweight="bold", zorder=7)

    if run.truth is not None and len(run.truth[0]):
        xy = run.truth[1]
        source = "groundtruth.txt" if run.recorded else "simulated camera"
        handles.append(axes.plot(xy[:, 0], xy[:, 1], color=COLOURS["truth"], lw=6.0, alpha=0.55,
                                 solid_capstyle="round", zorder=3, label=f"camera ground truth ({source})")[0])
    robot = _robot_path(run.records.get("Gazebo", {}))
    if len(robot):
        handles.append(axes.plot(robot[:, 0], robot[:, 1], color=COLOURS["robot"], lw=1.8, zorder=4,
                                 label="robot's true path (Gazebo)")[0])
    if run.estimate is not None:
        xy = run.estimate[1]
        label = f"{run.name}, aligned (evaluate_ate)" if run.ate is not None else f"{run.name}, not aligned"
        handles.append(axes.plot(xy[:, 0], xy[:, 1], color=COLOURS["estimate"], lw=1.4, ls=(0, (4.0, 2.5)),
                                 zorder=5, label=label)[0])

    handles += _draw_plans(axes, run.records.get("Planner"))
    handles.append(Patch(facecolor=_WALL, label="walls and boxes"))
    handles.append(Patch(facecolor=_GROWN, label=f"kept clear by the planner (+{grown:.2f} m)"))
    marks.append(axes.scatter([world.start[0]], [world.start[1]], marker="s", s=90, facecolor="white",
                              edgecolor="black", lw=1.6, zorder=8, label="start (the robot's dock)"))
    marks += _draw_ends(axes, run, robot)
    marks += _draw_mission(axes, run, world, DOCK if run.patrol else None)
    marks += _draw_moment_marks(axes, run, moments)

    xs = [0.0, world.width]
    ys = [0.0, world.depth]
    for xy in ([run.truth[1]] if run.truth is not None else []) + ([run.estimate[1]] if run.estimate else []):
        if len(xy):
            xs += [float(xy[:, 0].min()), float(xy[:, 0].max())]
            ys += [float(xy[:, 1].min()), float(xy[:, 1].max())]
    reach = 4.0  # metres beyond the walls at most: an estimate gone astray shows where it went
    axes.set_xlim(max(min(xs), -reach) - 0.25, min(max(xs), world.width + reach) + 0.25)
    axes.set_ylim(max(min(ys), -reach) - 0.25, min(max(ys), world.depth + reach) + 0.25)
    axes.set_aspect("equal")
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.set_title("The room from above", fontsize=12, loc="left")
    axes.grid(True, color="0.92", lw=0.6, zorder=0)
    axes.set_axisbelow(True)
    return handles + marks


def _robot_path(record: dict[str, Any]) -> np.ndarray:
    """``(x, y, theta)`` rows of the Gazebo record's trajectory (by its ``columns``); none if unreadable."""
    columns = list(record.get("columns") or ["t", "x", "y", "theta"])
    try:
        rows = np.array(record.get("trajectory") or [], dtype=float)
        picked = rows[:, [columns.index("x"), columns.index("y"), columns.index("theta")]]
    except (ValueError, IndexError, TypeError):
        return np.empty((0, 3))
    finite: np.ndarray = picked[np.isfinite(picked).all(axis=1)]
    return finite


def _draw_mission(axes: Axes, run: _Run, world: World, dock: tuple[float, float] | None) -> list[Any]:
    """The waypoints reached (a ring on each, its time beside it), the contacts (a cross each) and,
    on a whole patrol, the dock once the robot was back at it (a ring with its time)."""
    found = mission_marks(run.records, world.waypoints, WAYPOINT_TOLERANCE, dock=dock)
    marks: list[Any] = []
    if found.waypoints:
        places = [world.waypoints[w.number - 1] for w in found.waypoints]
        marks.append(axes.scatter([x for x, _ in places], [y for _, y in places], marker="o", s=520,
                                  facecolor="none", edgecolor=COLOURS["truth"], lw=2.2, zorder=7.5,
                                  label=f"waypoints reached ({len(found.waypoints)}), each with its time"))
        for w, (x, y) in zip(found.waypoints, places, strict=True):
            axes.annotate(f"{w.t:.1f} s", (x, y), xytext=(7, -12 - 9 * (w.lap - 1)), textcoords="offset points",
                          fontsize=8, color=COLOURS["truth"], zorder=7.5)
    if found.contacts:
        recorded = run.records.get("Gazebo", {}).get("bumps")  # events are kept up to a bound; the count is whole
        bumps = recorded if isinstance(recorded, int) else sum(c.bumps for c in found.contacts)
        marks.append(axes.scatter([c.x for c in found.contacts], [c.y for c in found.contacts], marker="X", s=140,
                                  facecolor="#E00000", edgecolor="black", lw=0.8, zorder=9.5,
                                  label=f"bumps: {counted(bumps, 'bump')} in "
                                        f"{counted(len(found.contacts), 'contact')}"))
    if found.dock is not None and dock is not None:
        marks.append(axes.scatter([dock[0]], [dock[1]], marker="o", s=520, facecolor="none",
                                  edgecolor=COLOURS["truth"], lw=2.2, ls="--", zorder=7.5,
                                  label=f"back at the dock at {found.dock.t:.1f} s: patrol done"))
        axes.annotate(f"{found.dock.t:.1f} s", dock, xytext=(7, 6), textcoords="offset points",
                      fontsize=8, color=COLOURS["truth"], zorder=7.5)
    return marks


def _draw_plans(axes: Axes, record: dict[str, Any] | None) -> list[Any]:
    plans = [np.array(plan["points"], dtype=float).reshape(-1, 2)
             for plan in (record or {}).get("recent_plans") or [] if plan.get("points")]
    handles: list[Any] = []
    for i, points in enumerate(plans[:-1]):
        line = axes.plot(points[:, 0], points[:, 1], color=COLOURS["plan"], lw=0.9, alpha=0.55, ls=(0, (1.5, 1.5)),
                         zorder=2, label=f"earlier plans (last {len(plans) - 1} recorded)" if i == 0 else None)[0]
        if i == 0:
            handles.append(line)
    if plans:
        latest = plans[-1]
        handles.append(axes.plot(latest[:, 0], latest[:, 1], color=COLOURS["plan"], lw=2.4, ls=(0, (6.0, 2.0)),
                                 zorder=2.5, label="latest plan (Planner)")[0])
    return handles[::-1]


def _draw_ends(axes: Axes, run: _Run, robot: np.ndarray) -> list[Any]:
    handles: list[Any] = []
    if len(robot):
        x, y, theta = robot[-1]
        # from where the robot stopped, 0.5 m along its heading: clear of the other ends' markers
        tip = (x + 0.5 * np.cos(theta), y + 0.5 * np.sin(theta))
        axes.annotate("", xy=tip, xytext=(x, y), zorder=9,
                      arrowprops={"arrowstyle": "-|>", "color": COLOURS["robot"], "lw": 2.2, "mutation_scale": 18,
                                  "shrinkA": 0, "shrinkB": 0})
        handles.append(Line2D([], [], ls="none", marker=_arrowhead(0.0), markersize=16,
                              markerfacecolor=COLOURS["robot"], markeredgecolor="white",
                              label="end: robot, arrow along its heading"))
    if run.truth is not None and len(run.truth[0]):
        x, y = run.truth[1][-1, :2]
        handles.append(axes.scatter([x], [y], marker="o", s=300, facecolor="none", edgecolor=COLOURS["truth"],
                                    lw=2.2, zorder=8, label="end: camera ground truth"))
    if run.estimate is not None:
        x, y = run.estimate[1][-1, :2]
        handles.append(axes.scatter([x], [y], marker="X", s=80, facecolor=COLOURS["estimate"], edgecolor="white",
                                    lw=0.8, zorder=9, label=f"end: {run.name}"))
    return handles


def _arrowhead(theta: float) -> MarkerPath:
    """A marker shaped like an arrowhead pointing along ``theta`` (radians from +x, counter-clockwise)."""
    head = MarkerPath([(1.0, 0.0), (-0.7, 0.6), (-0.3, 0.0), (-0.7, -0.6), (1.0, 0.0)],
                      [MarkerPath.MOVETO, MarkerPath.LINETO, MarkerPath.LINETO, MarkerPath.LINETO,
                       MarkerPath.CLOSEPOLY])
    return head.transformed(Affine2D().rotate(theta))


def _draw_moment_marks(axes: Axes, run: _Run, moments: list[tuple[float, int]]) -> list[Any]:
    """Letters where the camera was (ground truth) when each thumbnail was taken."""
    if run.truth is None or not len(run.truth[0]) or not moments:
        return []
    stamps, xyz = run.truth
    for letter, (stamp, _) in zip(_letters(len(moments)), moments, strict=True):
        x = float(np.interp(stamp, stamps, xyz[:, 0]))
        y = float(np.interp(stamp, stamps, xyz[:, 1]))
        axes.annotate(letter, (x, y), xytext=(-14, 12), textcoords="offset points", ha="center", va="center",
                      fontsize=9, fontweight="bold", zorder=10,
                      bbox={"boxstyle": "circle,pad=0.2", "facecolor": "white", "edgecolor": "black", "lw": 0.8},
                      arrowprops={"arrowstyle": "-", "color": "black", "lw": 0.8, "shrinkA": 0, "shrinkB": 1})
    return [Line2D([], [], ls="none", marker="$A$", markersize=8, color="black",
                   label=f"{_letters(len(moments))[0]}-{_letters(len(moments))[-1]}: where the frames below "
                         "were taken" if len(moments) > 1 else "A: where the frame below was taken")]


def _draw_key(axes: Axes, handles: list[Any]) -> None:
    axes.axis("off")
    if handles:
        axes.legend(handles=handles, loc="upper left", ncol=2, fontsize=9.5, frameon=True, framealpha=1.0,
                    edgecolor="0.8", title="The room from above (left)", title_fontsize=10, alignment="left",
                    borderaxespad=0.0, handlelength=3.2, columnspacing=1.2)


def _draw_error(axes: Axes, run: _Run, moments: list[tuple[float, int]]) -> None:
    vo = run.records.get("VisOdom", {})
    lost = vo.get("lost_frames")
    lost_stamps = [float(t) for t in vo.get("lost_stamps") or []]
    if lost_stamps:
        lost_text = f"VO lost track on {len(lost_stamps)} frame{'' if len(lost_stamps) == 1 else 's'} (red ticks)"
    elif isinstance(lost, int):
        lost_text = f"VO lost track on {lost} frame{'' if lost == 1 else 's'}"
    else:
        lost_text = "VO's lost-track count: not recorded"
    axes.set_title(f"Position error of the {run.name} after alignment (evaluate_ate)\n{lost_text}", fontsize=11,
                   loc="left")
    axes.set_xlabel("time since the camera's first frame (s)")
    axes.set_ylabel("position error (m)")
    axes.grid(True, color="0.9", lw=0.6)
    t0 = run.t0 or 0.0
    if run.span is not None:
        axes.set_xlim(run.span[0] - t0, max(run.span[1] - t0, run.span[0] - t0 + 1e-3))
    for stamp in lost_stamps:  # each frame the odometry failed on: Move's robot stops if they last
        axes.axvline(stamp - t0, ymin=0.0, ymax=0.06, color=COLOURS["estimate"], lw=1.2, zorder=3)
    for letter, (stamp, _) in zip(_letters(len(moments)), moments, strict=True):
        axes.axvline(stamp - t0, color="0.55", lw=0.8, ls=":", zorder=1)
        axes.annotate(letter, (stamp - t0, 1.0), xycoords=("data", "axes fraction"), xytext=(0, -2),
                      textcoords="offset points", ha="center", va="top", fontsize=9, fontweight="bold",
                      bbox={"boxstyle": "circle,pad=0.2", "facecolor": "white", "edgecolor": "black", "lw": 0.8})
    if run.ate is None:
        reason = ("no VO estimate recorded (VisOdom did not run, or its group failed)" if run.estimate is None
                  else f"no ATE: {run.ate_problem}")
        axes.text(0.5, 0.5, textwrap.fill(reason, 70), transform=axes.transAxes, ha="center", va="center",
                  fontsize=11, color="0.3")
        axes.set_ylim(0.0, 1.0)
        return
    times = run.ate_stamps - t0
    errors = run.ate.errors
    _shade_gaps(axes, run, t0)
    axes.plot(times, errors, color=COLOURS["estimate"], lw=1.3, zorder=3, label="per pose (matched stamps)")
    rmse = run.ate.rmse
    axes.axhline(rmse, color=COLOURS["marker"], lw=1.2, ls="--", zorder=4, label="ATE RMSE")
    axes.annotate(f"ATE RMSE {rmse:.4f} m ({rmse * 1000:.1f} mm) over {run.ate.pairs} poses, "
                  f"max {run.ate.max * 1000:.1f} mm", (0.01, rmse), xycoords=("axes fraction", "data"),
                  xytext=(2, 4), textcoords="offset points", fontsize=9.5, zorder=5,
                  bbox={"boxstyle": "round,pad=0.2", "facecolor": "white", "edgecolor": "none", "alpha": 0.85})
    top = float(max(errors.max(), rmse))
    axes.set_ylim(0.0, top * 1.5 if top > 0 else 1e-3)
    # one row under the letters, above the data (the headroom keeps them apart)
    axes.legend(loc="upper center", bbox_to_anchor=(0.5, 0.925), ncol=3, fontsize=9, framealpha=0.9,
                columnspacing=1.2, handlelength=2.2)


def _shade_gaps(axes: Axes, run: _Run, t0: float) -> None:
    """Stretches with no VO pose (frames dropped or not delivered): more than 1.5 frame periods."""
    if run.estimate is None or len(run.estimate[0]) < 3:
        return
    stamps = np.sort(run.estimate[0])
    steps = np.diff(stamps)
    period = float(np.median(steps))
    labelled = False
    for i in np.flatnonzero(steps > 1.5 * period):
        axes.axvspan(stamps[i] - t0, stamps[i + 1] - t0, color=COLOURS["gap"], alpha=0.35, lw=0, zorder=1,
                     label=None if labelled else "no VO pose (frame dropped or skipped)")
        labelled = True


def _draw_thumbnails(cells: list[Axes], run: _Run, moments: list[tuple[float, int]]) -> None:
    t0 = run.t0 or 0.0
    for cell in cells:
        cell.set_xticks([])
        cell.set_yticks([])
        for spine in cell.spines.values():
            spine.set_color("0.6")
    if run.frames is None or not moments:
        reason = ("no camera frames: the recording cannot be read" if run.recorded
                  else "no camera frames yet: the simulated camera's path is saved when the run stops")
        cells[0].text(0.02, 0.5, reason, transform=cells[0].transAxes, va="center", fontsize=11, color="0.3")
        for cell in cells:
            cell.axis("off")
        return
    cells[0].figure.text(0.045, 0.008, run.frames.caption, fontsize=9, color="0.3", va="bottom")
    for cell, letter, (stamp, index) in zip(cells, _letters(len(moments)), moments, strict=False):
        try:
            image = run.frames.image(index)
        except (DatasetError, IndexError):
            cell.text(0.5, 0.5, "frame unreadable", transform=cell.transAxes, ha="center", va="center")
        else:
            step = max(1, image.shape[1] // 400)  # a thumbnail needs no more pixels than it shows
            cell.imshow(image[::step, ::step], interpolation="antialiased")
        cell.set_title(f"{letter}   t = {stamp - t0:.1f} s   (frame {index})", fontsize=10, loc="left")
    for cell in cells[len(moments):]:
        cell.axis("off")


def _draw_title(figure: Figure, run: _Run, title: str) -> None:
    head = title or "TinMan"
    if not title and run.ate is not None:
        head += (f": VO ATE RMSE {run.ate.rmse * 100:.2f} cm over {run.ate.length:.2f} m "
                 f"({run.ate.percent:.2f}%)")
    figure.text(0.045, 0.982, head, fontsize=15, fontweight="bold", va="top")
    figure.text(0.045, 0.945, "\n".join(_wrap(_headline(run), 175)), fontsize=10.5, va="top", color="0.15",
                linespacing=1.5)


def _headline(run: _Run) -> list[str]:
    """The run's numbers: from report.json after the run, else (live) from the records."""
    report = run.report
    records = run.records
    vo = records.get("VisOdom", {})
    gazebo = records.get("Gazebo", {})
    planner = records.get("Planner", {})
    move = records.get("Move", {})
    parts: list[str] = []
    if report is not None:
        parts.append(f"system {report.get('outcome', '?')} after {_number(report.get('duration_s'), '.1f')} s")
        mission = report.get("mission") or {}
        if mission:
            reached = mission.get("waypoints_reached") or []
            head = (f"patrol completed in {_number(mission.get('completed_in_s'), '.1f')} s, "
                    if mission.get("completed_in_s") is not None
                    else "time limit, " if mission.get("ended_by") == "time limit" else "")
            parts.append(f"mission {mission.get('outcome', '?')}: {head}{len(reached)} of "
                         f"{_count(mission.get('patrol_waypoints'), 'waypoint')} reached")
        failed = [name for name, group in (report.get("groups") or {}).items() if group.get("status") == "failed"]
        injected = report.get("injected") or {}
        if failed:
            parts.append("failed: " + ", ".join(
                f"{name} ({injected[name]} injected)" if name in injected else name for name in failed))
        parts.append(f"VO {_count(report['frames_processed'], 'frame')} tracked, "
                     f"{_number(report.get('frames_dropped'))} "
                     f"dropped, {_number(vo.get('lost_frames'))} lost" if report.get("frames_processed") is not None
                     else "no VO record")
        period = report.get("control_period_ms") or {}
        parts.append(f"control period p50 {_number(period.get('p50'), '.1f')} ms, "
                     f"p99 {_number(period.get('p99'), '.1f')} ms")
        robot = report.get("robot") or {}
        parts.append(f"robot drove {_number(robot.get('distance_m'), '.2f')} m, {_count(robot.get('bumps'), 'bump')}")
        plans = report.get("planner") or {}
        parts.append(f"{_count(plans['plans'], 'plan')} ({plans.get('method') or '?'}), "
                     f"{_number(plans.get('failures'))} failed"
                     if plans.get("plans") is not None else "no planner record")
        parts.append(_count(report.get("violations"), "protocol violation"))
    else:
        parts.append("live: the run is not over (numbers from the records so far)")
        tracked = len(run.estimate[0]) if run.estimate is not None else vo.get("frames_processed")
        parts.append(f"VO {_count(tracked, 'frame')} tracked" if tracked is not None else "no VO estimate yet")
        if vo:
            parts.append(f"{_number(vo.get('frames_dropped'))} dropped, {_number(vo.get('lost_frames'))} lost")
        period = move.get("period_ms") or {}
        if period.get("p50") is not None:
            parts.append(f"control period p50 {period['p50']:.1f} ms, p99 {_number(period.get('p99'), '.1f')} ms")
        if gazebo:
            parts.append(f"robot drove {_number(gazebo.get('odometer_m'), '.2f')} m, "
                         f"{_count(gazebo.get('bumps'), 'bump')}")
        if planner:
            parts.append(f"{_count(planner.get('plans'), 'plan')} ({planner.get('method') or '?'})")
    return parts


def _wrap(parts: list[str], width: int) -> list[str]:
    """The parts joined with ``  |  `` into lines of at most ``width`` characters (a longer part alone)."""
    lines: list[str] = []
    for part in parts:
        if lines and len(lines[-1]) + 5 + len(part) <= width:
            lines[-1] += "  |  " + part
        else:
            lines.append(part)
    return lines


def _number(value: Any, spec: str = "") -> str:
    if value is None or isinstance(value, bool):
        return "n/a"
    try:
        return format(value, spec)
    except (TypeError, ValueError):
        return str(value)


def _count(value: Any, noun: str) -> str:
    """``1 bump``, ``3 bumps``; ``n/a bumps`` when not measured."""
    return counted(value, noun) if isinstance(value, int) and not isinstance(value, bool) else f"n/a {noun}s"


def _letters(count: int) -> list[str]:
    return [chr(ord("A") + i) for i in range(count)]
