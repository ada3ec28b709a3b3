"""The run's picture from small hand-made records: its size, its named layers, the VO
alignment and error panel, and what it draws when records are missing."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from tinman.ate import evaluate_ate
from tinman.geometry import camera_pose
from tinman.outcome import CAMERA_TRUTH
from tinman.picture import DPI, FIGURE_SIZE, draw_run, run_figure
from tinman.settings import Settings
from tinman.tum import read_trajectory, write_trajectory

FIRST = 1_700_000_000.0
FRAMES = 12  # at 10 Hz: 1.1 s of run


def _path(t: float) -> tuple[float, float, float]:
    """The camera's (x, y, theta) at t seconds: along y = 1 from the dock, then turning left."""
    return 1.0 + 0.8 * t, 1.0 + 0.2 * t * t, math.atan2(0.4 * t, 0.8)


def make_dataset(root: Path) -> Path:
    """A TUM directory: FRAMES small colour and depth frames at 10 Hz, ground truth at 100 Hz."""
    (root / "rgb").mkdir(parents=True)
    (root / "depth").mkdir()
    rgb, depth = ["# timestamp filename"], ["# timestamp filename"]
    for i in range(FRAMES):
        stamp = FIRST + 0.1 * i
        image = np.zeros((24, 32, 3), np.uint8)
        image[:, : 2 * (i + 1)] = (40, 160, 220)
        cv2.imwrite(str(root / f"rgb/{stamp:.6f}.png"), image)
        cv2.imwrite(str(root / f"depth/{stamp:.6f}.png"), np.full((24, 32), 5000, np.uint16))
        rgb.append(f"{stamp:.6f} rgb/{stamp:.6f}.png")
        depth.append(f"{stamp:.6f} depth/{stamp:.6f}.png")
    (root / "rgb.txt").write_text("\n".join(rgb) + "\n")
    (root / "depth.txt").write_text("\n".join(depth) + "\n")
    times = np.arange(0.0, 0.1 * FRAMES + 0.2, 0.01)
    write_trajectory(root / "groundtruth.txt", FIRST + times, [camera_pose(*_path(t)) for t in times])
    return root


def write_records(records: Path, *, estimate: bool = True, plans: bool = True, robot: bool = True,
                  lost: int = 2, offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
    """The records a run leaves: the estimate is the ground truth turned by ``offset[2]`` radians
    about the dock and moved by ``offset[:2]`` (a rigid motion: alignment removes it exactly)."""
    records.mkdir(parents=True, exist_ok=True)
    dx, dy, turn = offset
    c, s = math.cos(turn), math.sin(turn)
    motion = np.array([[c, -s, 0.0, dx], [s, c, 0.0, dy], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    if estimate:
        stamps = [FIRST + 0.1 * i for i in range(FRAMES)]
        write_trajectory(records / "vo_estimate.txt", stamps,
                         [motion @ camera_pose(*_path(0.1 * i)) for i in range(FRAMES)])
        _record(records, "VisOdom", {"frames_processed": FRAMES, "frames_dropped": 0,
                                     "track_ms": {"p50": 5.0, "p99": 7.0}, "lost_frames": lost})
    _record(records, "Camera", {"frames_published": FRAMES, "frames_skipped": 0, "frames_in_sequence": FRAMES})
    if plans:
        recent = [{"stamp": FIRST + 0.5 * k, "goal": [4.3, 1.1],
                   "points": [[1.0 + 0.4 * k, 1.0], [2.5, 1.05], [4.3, 1.1]]} for k in range(3)]
        _record(records, "Planner", {"method": "rrt", "plans": 3, "failures": [], "failure_count": 0,
                                     "plan_ms": [0.2, 0.3, 0.2], "recent_plans": recent})
    if robot:
        trajectory = [[round(0.02 * k, 3), 1.0 + 0.016 * k, 1.0 + 0.002 * k, 0.1, 0.4, 0.0] for k in range(60)]
        _record(records, "Gazebo", {"trajectory": trajectory, "odometer_m": 0.96, "bumps": 0,
                                    "columns": ["t", "x", "y", "theta", "v", "w"]})


def _record(records: Path, name: str, data: dict[str, Any]) -> None:
    (records / f"{name}.json").write_text(json.dumps(data))


@pytest.fixture
def run(tmp_path: Path) -> Settings:
    dataset = make_dataset(tmp_path / "sequence")
    settings = Settings(out=str(tmp_path / "out"), dataset=str(dataset), duration=1.2)
    write_records(settings.records, offset=(0.3, -0.2, 0.25))
    return settings


def _axes(figure: Any, label: str) -> Any:
    return next(axes for axes in figure.axes if axes.get_label() == label)


def _legend(figure: Any) -> list[str]:
    return [text.get_text() for axes in figure.axes if axes.get_legend() is not None
            for text in axes.get_legend().get_texts()]


def _has(labels: list[str], start: str) -> bool:
    return any(label.startswith(start) for label in labels)


def test_a_png_of_the_expected_size(run: Settings, tmp_path: Path) -> None:
    path = draw_run(tmp_path / "pictures" / "trajectory.png", run, title="TinMan: a test")
    image = cv2.imread(str(path))
    assert image is not None
    assert image.shape[:2] == (round(FIGURE_SIZE[1] * DPI), round(FIGURE_SIZE[0] * DPI))  # 1000 x 1600
    assert not list(path.parent.glob(".*partial*"))  # written whole, then renamed


def test_the_legend_names_every_layer(run: Settings) -> None:
    labels = _legend(run_figure(run))
    for layer in ("walls and boxes", "kept clear by the planner", "patrol waypoints", "camera ground truth",
                  "robot's true path (Gazebo)", "VO estimate, aligned", "latest plan", "earlier plans (last 2",
                  "start", "end: robot", "end: camera ground truth", "end: VO estimate", "A-D: where the frames",
                  "per pose", "ATE RMSE"):
        assert _has(labels, layer), f"no legend entry {layer!r} in {labels}"


def test_the_estimate_is_drawn_above_the_truth_and_thinner(run: Settings) -> None:
    room = _axes(run_figure(run), "room")
    lines = {line.get_label(): line for line in room.get_lines()}
    truth = lines["camera ground truth (groundtruth.txt)"]
    estimate = next(line for label, line in lines.items() if label.startswith("VO estimate"))
    robot = lines["robot's true path (Gazebo)"]
    assert estimate.get_zorder() > robot.get_zorder() > truth.get_zorder()
    assert estimate.get_linewidth() < robot.get_linewidth() < truth.get_linewidth()
    assert estimate.get_linestyle() != "-"


def test_the_estimate_is_aligned_as_evaluate_ate_does(run: Settings) -> None:
    """A rigidly moved estimate lands on the ground truth, and its error is zero."""
    figure = run_figure(run)
    room = _axes(figure, "room")
    estimate = next(line for line in room.get_lines() if line.get_label().startswith("VO estimate, aligned"))
    expected = np.array([_path(0.1 * i)[:2] for i in range(FRAMES)])
    assert np.allclose(np.column_stack(estimate.get_data()), expected, atol=1e-4)
    error = _axes(figure, "error")
    per_pose = next(line for line in error.get_lines() if line.get_label().startswith("per pose"))
    times, errors = (np.asarray(values, dtype=float) for values in per_pose.get_data())
    assert len(errors) == FRAMES
    assert np.allclose(times, 0.1 * np.arange(FRAMES), atol=1e-6)  # seconds since the first frame
    assert np.all(errors < 1e-4)


def test_the_error_panel_shows_the_error_and_the_lost_count(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "sequence")
    settings = Settings(out=str(tmp_path / "out"), dataset=str(dataset))
    write_records(settings.records, lost=3)
    # a non-rigid error: every pose of the estimate 2 cm off along z, alternately up and down
    stamps = [FIRST + 0.1 * i for i in range(FRAMES)]
    poses = []
    for i in range(FRAMES):
        pose = camera_pose(*_path(0.1 * i))
        pose[2, 3] += 0.02 if i % 2 else -0.02
        poses.append(pose)
    write_trajectory(settings.records / "vo_estimate.txt", stamps, poses)
    truth_stamps, truth = read_trajectory(dataset / "groundtruth.txt")
    expected = evaluate_ate(truth_stamps, truth[:, :3, 3], np.array(stamps), np.array(poses)[:, :3, 3])
    assert 0.01 < expected.rmse < 0.03
    error = _axes(run_figure(settings), "error")
    per_pose = next(line for line in error.get_lines() if line.get_label().startswith("per pose"))
    assert np.allclose(np.asarray(per_pose.get_ydata(), dtype=float), expected.errors)
    rmse = next(line for line in error.get_lines() if line.get_label() == "ATE RMSE")
    assert np.asarray(rmse.get_ydata(), dtype=float)[0] == pytest.approx(expected.rmse)
    assert "lost track on 3 frames" in error.get_title(loc="left")
    assert any(f"ATE RMSE {expected.rmse:.4f} m" in text.get_text() for text in error.texts)


def test_thumbnails_are_camera_frames_labelled_with_their_time(run: Settings) -> None:
    figure = run_figure(run)
    cells = [axes for axes in figure.axes if str(axes.get_label()).startswith("thumbnail")]
    assert len(cells) == 4
    titles = [cell.get_title(loc="left") for cell in cells]
    assert [title.split()[0] for title in titles] == ["A", "B", "C", "D"]
    assert "t = 0.0 s" in titles[0] and "t = 1.1 s" in titles[-1]
    assert all(len(cell.images) == 1 for cell in cells)
    first, last = (np.asarray(cells[i].images[0].get_array()) for i in (0, -1))
    assert first.shape[:2] == (24, 32) and first[0, 0].tolist() == [220, 160, 40]  # RGB, not BGR
    assert not np.array_equal(first, last)


def test_a_failed_perception_group_leaves_no_estimate(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "sequence")
    settings = Settings(out=str(tmp_path / "out"), dataset=str(dataset), duration=1.0)
    write_records(settings.records, estimate=False)
    figure = run_figure(settings)
    labels = _legend(figure)
    assert _has(labels, "camera ground truth") and _has(labels, "robot's true path")
    assert not _has(labels, "VO estimate") and not _has(labels, "end: VO estimate")
    error = _axes(figure, "error")
    assert any("no VO estimate recorded" in text.get_text() for text in error.texts)
    assert draw_run(tmp_path / "trajectory.png", settings).exists()


def test_the_ground_truth_covers_the_frames_the_camera_played(run: Settings) -> None:
    """VO tracked only the first frames, but Gazebo played all of them: the camera's path is all drawn."""
    stamps = [FIRST + 0.1 * i for i in range(3)]
    write_trajectory(run.records / "vo_estimate.txt", stamps, [camera_pose(*_path(0.1 * i)) for i in range(3)])
    _record(run.records, "Gazebo", {"trajectory": [], "camera_frames": FRAMES, "camera_frames_skipped": 0})
    figure = run_figure(run)
    truth = next(line for line in _axes(figure, "room").get_lines() if line.get_label().startswith("camera ground"))
    assert max(np.asarray(truth.get_xdata(), dtype=float)) == pytest.approx(_path(0.1 * (FRAMES - 1))[0], abs=0.05)
    assert _axes(figure, "error").get_xlim()[1] == pytest.approx(0.1 * (FRAMES - 1))


def test_no_plans_and_no_robot(tmp_path: Path) -> None:
    dataset = make_dataset(tmp_path / "sequence")
    settings = Settings(out=str(tmp_path / "out"), dataset=str(dataset))
    write_records(settings.records, plans=False, robot=False)
    labels = _legend(run_figure(settings))
    assert not _has(labels, "latest plan") and not _has(labels, "earlier plans")
    assert not _has(labels, "robot's true path") and not _has(labels, "end: robot")
    assert _has(labels, "VO estimate, aligned")


def test_the_robot_path_is_read_by_its_columns(run: Settings) -> None:
    record = {"columns": ["x", "y", "theta", "t"], "trajectory": [[1.0, 1.0, 0.0, 0.0], [1.5, 1.2, 0.3, 0.5]]}
    _record(run.records, "Gazebo", record)
    room = _axes(run_figure(run), "room")
    robot = next(line for line in room.get_lines() if line.get_label() == "robot's true path (Gazebo)")
    assert np.asarray(robot.get_xdata(), dtype=float).tolist() == [1.0, 1.5]
    _record(run.records, "Gazebo", {"trajectory": "garbled"})
    assert not _has(_legend(run_figure(run)), "robot's true path")


def test_nothing_recorded_and_no_dataset(tmp_path: Path) -> None:
    settings = Settings(out=str(tmp_path / "out"), dataset="")
    figure = run_figure(settings)
    labels = _legend(figure)
    assert _has(labels, "walls and boxes") and _has(labels, "patrol waypoints") and _has(labels, "start")
    thumbnails = [axes for axes in figure.axes if str(axes.get_label()).startswith("thumbnail")]
    assert any("no camera frames" in text.get_text() for axes in thumbnails for text in axes.texts)
    path = draw_run(tmp_path / "trajectory.png", settings)
    image = cv2.imread(str(path))
    assert image is not None and image.shape[:2] == (1000, 1600)


def test_a_dataset_that_cannot_be_read(tmp_path: Path) -> None:
    settings = Settings(out=str(tmp_path / "out"), dataset=str(tmp_path / "missing"))
    write_records(settings.records)
    labels = _legend(run_figure(settings))
    assert _has(labels, "VO estimate, not aligned")  # no ground truth to align with
    assert not _has(labels, "camera ground truth")


def test_the_simulated_camera_truth_and_its_frames_rendered_again(tmp_path: Path) -> None:
    """Without --dataset the camera renders the room live: its true path is Gazebo's record, and
    the thumbnails are rendered again from it (its images are not saved)."""
    settings = Settings(out=str(tmp_path / "out"), dataset="")
    write_records(settings.records, offset=(0.1, 0.0, 0.1))
    times = np.arange(FRAMES) * 0.1
    write_trajectory(settings.records / CAMERA_TRUTH, FIRST + times, [camera_pose(*_path(t)) for t in times])
    figure = run_figure(settings)
    labels = _legend(figure)
    assert "camera ground truth (simulated camera)" in labels and _has(labels, "VO estimate, aligned")
    cells = [axes for axes in figure.axes if str(axes.get_label()).startswith("thumbnail")]
    assert all(len(cell.images) == 1 for cell in cells)
    assert np.asarray(cells[0].images[0].get_array()).shape == (480, 640, 3)  # the simulated camera's frame
    assert any("rendered again from the simulated camera's true pose" in text.get_text() for text in figure.texts)


def test_the_live_picture_draws_the_estimate_it_is_given(run: Settings, tmp_path: Path) -> None:
    (run.records / "vo_estimate.txt").unlink()  # during the run, VisOdom has not written it yet
    given = [(FIRST + 0.1 * i, *_path(0.1 * i)[:2], 0.5) for i in range(5)]
    figure = run_figure(run, estimate=given)
    room = _axes(figure, "room")
    estimate = next(line for line in room.get_lines() if line.get_label().startswith("VO estimate, aligned"))
    assert len(estimate.get_xdata()) == 5
    assert any(text.get_text().startswith("live:") for text in figure.texts)


def test_the_title_has_the_report_numbers_once_the_run_wrote_it(run: Settings) -> None:
    report = {"outcome": "stopped, no failures", "duration_s": 13.4, "frames_processed": 360,
              "frames_dropped": 1, "control_period_ms": {"p50": 20.0, "p99": 20.3},
              "robot": {"distance_m": 4.35, "bumps": 0}, "planner": {"method": "rrt", "plans": 21, "failures": 0},
              "violations": 0, "injected": {"perception": "memory-hog"},
              "groups": {"perception": {"status": "failed"}, "control": {"status": "stopped"}}}
    file = Path(run.out) / "report.json"
    file.write_text(json.dumps(report))
    stale = run.records.stat().st_mtime - 60
    os.utime(file, (stale, stale))  # an older run's report: not this run's numbers
    assert not any("360 frames tracked" in text.get_text() for text in run_figure(run).texts)
    os.utime(file, None)
    figure = run_figure(run, title="TinMan: headline")
    texts = [text.get_text() for text in figure.texts]
    assert "TinMan: headline" in texts
    assert any("360 frames tracked" in text and "failed: perception (memory-hog injected)" in text
               and "4.35 m" in text for text in texts)


def test_a_plain_title_carries_the_ate(run: Settings) -> None:
    texts = [text.get_text() for text in run_figure(run).texts]
    assert any(text.startswith("TinMan: VO ATE RMSE") for text in texts)
