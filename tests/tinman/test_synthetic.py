"""Kinect-like noise statistics and synthetic sequences read back as TUM data."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tinman.dataset import TumSequence
from tinman.geometry import FR1, Intrinsics, camera_pose
from tinman.render import RoomRenderer
from tinman.synthetic import GENERATOR_VERSION, add_depth_noise, add_image_noise, generate_sequence
from tinman.world import Box, World

SMALL = Intrinsics(fx=FR1.fx / 8, fy=FR1.fy / 8, cx=(FR1.cx + 0.5) / 8 - 0.5, cy=(FR1.cy + 0.5) / 8 - 0.5,
                   width=80, height=60)
ROOM = World(width=4.0, depth=3.0, boxes=(Box(2.0, 1.0, 2.6, 1.8, 0.8),), start=(1.0, 1.0, 0.0))


def axial_sigma(z: float) -> float:
    return 0.0012 + 0.0019 * (z - 0.4) ** 2


@pytest.mark.parametrize("z", [0.8, 2.0, 4.5])
def test_depth_noise_follows_the_kinect_model(z: float) -> None:
    counts = add_depth_noise(np.full((480, 640), z, np.float32), np.random.default_rng(1))
    assert counts.dtype == np.uint16
    valid = counts > 0
    assert 0.01 < 1 - valid.mean() < 0.02  # random dropouts
    metres = counts[valid] / 5000.0
    assert metres.mean() == pytest.approx(z, abs=0.1 * axial_sigma(z))
    assert metres.std() == pytest.approx(np.hypot(axial_sigma(z), 0.0002 / np.sqrt(12)), rel=0.05)


def test_depth_outside_the_sensor_range_reads_nothing() -> None:
    depth = np.array([[0.0, 0.3, 0.39, 6.05, 7.5]], np.float32).repeat(100, axis=0)
    assert not add_depth_noise(depth, np.random.default_rng(0)).any()


def test_depth_discontinuities_mostly_drop_out() -> None:
    depth = np.full((200, 200), 3.0, np.float32)
    depth[:, :100] = 1.0  # a box edge in front of a wall
    counts = add_depth_noise(depth, np.random.default_rng(2))
    at_edge = counts[:, 99:101] == 0
    assert 0.5 < at_edge.mean() < 0.9
    assert (counts[:, 10:90] == 0).mean() < 0.03  # elsewhere only the random dropouts


def test_noise_depends_only_on_the_generator() -> None:
    depth = np.linspace(0.5, 5.0, 60 * 80, dtype=np.float32).reshape(60, 80)
    rgb = np.random.default_rng(0).integers(0, 256, (60, 80, 3), dtype=np.uint8)
    for noise, image in ((add_depth_noise, depth), (add_image_noise, rgb)):
        a = noise(image, np.random.default_rng(7))
        b = noise(image, np.random.default_rng(7))
        c = noise(image, np.random.default_rng(8))
        assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_image_noise_is_gaussian_growing_with_brightness() -> None:
    for level, sigma in ((40, 2.25), (128, 2.8), (220, 3.375)):
        noisy = add_image_noise(np.full((240, 320, 3), level, np.uint8), np.random.default_rng(3))
        assert noisy.dtype == np.uint8 and noisy.shape == (240, 320, 3)
        assert noisy.mean() == pytest.approx(level, abs=0.1)
        assert noisy.astype(float).std() == pytest.approx(np.hypot(sigma, 1 / np.sqrt(12)), rel=0.05)


def test_image_noise_blurs_slightly() -> None:
    image = np.zeros((9, 9, 3), np.uint8)
    image[4, 4] = 255
    noisy = add_image_noise(image, np.random.default_rng(0)).astype(float)
    assert 80 < noisy[4, 4].mean() < 200  # the point keeps most of its light
    assert noisy[4, 3].mean() > 15 and noisy[0, 0].mean() < 8


def trajectory(frames: int, rate: float = 30.0) -> tuple[np.ndarray, list[np.ndarray]]:
    stamps = 1305031102.175304 + np.arange(frames) / rate
    poses = [camera_pose(0.8 + 0.1 * t, 0.8 + 0.03 * t, 0.3 + 0.2 * t) for t in stamps - stamps[0]]
    return stamps, poses


def generate(directory: Path, frames: int = 10, workers: int = 1, seed: int = 5,
             progress: Callable[[int, int], None] | None = None) -> Path:
    stamps, poses = trajectory(frames)
    truth_stamps, truth_poses = trajectory(3 * frames, rate=90.0)
    return generate_sequence(directory, ROOM, stamps, poses, truth_stamps, truth_poses,
                             intrinsics=SMALL, seed=seed, workers=workers, progress=progress)


def test_a_generated_sequence_reads_back_as_tum_data(tmp_path: Path) -> None:
    reports: list[tuple[int, int]] = []
    root = generate(tmp_path / "synthetic", progress=lambda done, total: reports.append((done, total)))
    assert reports == [(done, 10) for done in range(11)]  # before the first frame, then after each
    assert sorted(p.name for p in tmp_path.iterdir()) == ["synthetic"]  # no partial directory left
    assert sorted(p.name for p in root.iterdir()) == ["depth", "depth.txt", "groundtruth.txt", "rgb", "rgb.txt",
                                                      "tinman.json"]
    sequence = TumSequence.open(root)
    stamps, poses = trajectory(10)
    assert len(sequence) == 10
    np.testing.assert_allclose(sequence.stamps, stamps, atol=1e-6)
    offsets = np.abs(sequence.depth_stamps - sequence.stamps)
    assert offsets.min() >= 0.002 - 1e-6 and offsets.max() <= 0.012 + 1e-6  # association mattered
    assert sequence.intrinsics == SMALL and sequence.frame_rate == pytest.approx(30.0, rel=1e-3)
    metadata = json.loads((root / "tinman.json").read_text())
    assert {k: metadata[k] for k in ("generator", "version", "world", "frames", "seed", "depth_scale")} == {
        "generator": "tinman.synthetic", "version": GENERATOR_VERSION, "world": "custom", "frames": 10, "seed": 5,
        "depth_scale": 5000.0}
    assert metadata["world_description"]["boxes"][0]["x0"] == 2.0
    truth_stamps, truth_poses = sequence.groundtruth
    expected_stamps, expected_poses = trajectory(30, rate=90.0)
    np.testing.assert_allclose(truth_stamps, expected_stamps, atol=1e-6)
    np.testing.assert_allclose(truth_poses, np.array(expected_poses), atol=2e-6)
    # The images are the renderer's, spoiled by the noise models.
    renderer = RoomRenderer(ROOM, SMALL, seed=5)
    for i in (0, 9):
        clean_rgb, clean_depth = renderer.render(poses[i])
        depth = sequence.depth(i)
        valid = depth > 0
        assert valid.mean() > 0.8
        error = depth[valid] - clean_depth[valid]
        assert np.median(np.abs(error)) < 0.01
        rgb = sequence.rgb(i)
        assert rgb.shape == (60, 80, 3)
        assert np.abs(rgb.astype(float) - clean_rgb).mean() < 12


def test_generating_again_replaces_the_sequence(tmp_path: Path) -> None:
    root = generate(tmp_path / "synthetic", frames=3, seed=1)
    first = (root / "rgb.txt").read_text()
    generate(tmp_path / "synthetic", frames=4, seed=1)
    assert len(TumSequence.open(root)) == 4 and (root / "rgb.txt").read_text() != first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["synthetic"]


def test_a_failed_run_leaves_nothing_behind(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []

    def failing(job: object) -> None:
        calls.append(job)
        if len(calls) == 3:
            raise RuntimeError("power cut")

    monkeypatch.setattr("tinman.synthetic._render_job", failing)
    with pytest.raises(RuntimeError, match="power cut"):
        generate(tmp_path / "synthetic", frames=5)
    assert list(tmp_path.iterdir()) == []
    stamps, poses = trajectory(3)
    with pytest.raises(ValueError, match=r"^stamps and poses differ in number: 3 frames, 2 poses"):
        generate_sequence(tmp_path / "x", ROOM, stamps, poses[:2], stamps, poses, intrinsics=SMALL)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # starts two spawned worker processes and renders 112 frames
def test_worker_processes_write_the_same_sequence(tmp_path: Path) -> None:
    serial = generate(tmp_path / "serial", frames=56, workers=1)
    reports: list[tuple[int, int]] = []
    parallel = generate(tmp_path / "parallel", frames=56, workers=2,
                        progress=lambda done, total: reports.append((done, total)))
    assert reports == [(done, 56) for done in range(57)]  # the pool's frames are counted as they come
    for name in ("rgb.txt", "depth.txt", "groundtruth.txt"):
        assert (serial / name).read_text() == (parallel / name).read_text()
    for folder in ("rgb", "depth"):
        files = sorted((serial / folder).iterdir())
        assert len(files) == 56
        assert all(f.read_bytes() == (parallel / folder / f.name).read_bytes() for f in files)
