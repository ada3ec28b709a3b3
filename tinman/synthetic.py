"""Synthetic TUM RGB-D sequences: rendered frames with Kinect-like noise, on disk.

:func:`generate_sequence` renders a camera trajectory through a world with
:class:`~tinman.render.RoomRenderer`, spoils the images as a Kinect would
(:func:`add_depth_noise`, :func:`add_image_noise`) and writes exactly the layout
of the TUM RGB-D benchmark, so the same code reads real and synthetic data.
"""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import numpy as np

from .geometry import DEPTH_SCALE, FR1, Intrinsics
from .render import RoomRenderer
from .tum import write_file_list, write_trajectory
from .world import DEFAULT_WORLD, World

__all__ = ["GENERATOR_VERSION", "METADATA_FILE", "add_depth_noise", "add_image_noise", "generate_sequence"]

GENERATOR_VERSION = 1
METADATA_FILE = "tinman.json"

MIN_RANGE = 0.4   # metres: the Kinect sees nothing closer
MAX_RANGE = 6.0   # metres: nor farther (TUM's freiburg1 data rarely has more)
DROPOUT = 0.015   # fraction of pixels that randomly read nothing
_EDGE_DROPOUT = 0.7  # chance that a pixel at a depth discontinuity reads nothing
_POOL_THRESHOLD = 50  # frames: below this, rendering in this process is faster than starting workers


def add_depth_noise(depth_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Kinect-like depth readings of an exact depth image, as TUM 16-bit PNG values.

    Axial noise grows with the square of the distance (sigma = 0.0012 +
    0.0019 (z - 0.4)^2 m, Nguyen, Izadi and Lovell 2012); readings are quantised
    to 1/5000 m; about 1.5% of pixels drop out at random and most pixels at depth
    discontinuities (the sensor's shadow at silhouettes) do too; nothing is read
    nearer than 0.4 m or beyond 6 m.

    Args:
        depth_m: float depths in metres (0 = no surface).
        rng: the random generator (the only source of randomness).

    Returns:
        uint16 values, ``DEPTH_SCALE`` (5000) per metre, 0 = no reading.
    """
    z = np.asarray(depth_m, dtype=np.float32)
    sigma = np.float32(0.0012) + np.float32(0.0019) * (z - np.float32(0.4)) ** 2
    noisy = z + sigma * _standard_normal(z.shape, rng)
    valid = (z >= MIN_RANGE) & (z <= MAX_RANGE) & (rng.random(z.shape, dtype=np.float32) >= DROPOUT)
    # A jump of more than 5% of the depth between neighbours is a silhouette, not a slope.
    kernel = np.ones((3, 3), np.uint8)
    spread = cv2.dilate(z, kernel) - cv2.erode(z, kernel)
    edge = spread > np.maximum(np.float32(0.05), np.float32(0.05) * z)
    valid &= ~(edge & (rng.random(z.shape, dtype=np.float32) < _EDGE_DROPOUT))
    counts: np.ndarray = np.rint(noisy * np.float32(DEPTH_SCALE))
    np.clip(counts, 1, np.iinfo(np.uint16).max, out=counts)
    counts *= valid
    return counts.astype(np.uint16)


def add_image_noise(rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A camera's view of a clean image: slight optical blur, then sensor noise.

    The noise is Gaussian, independent per pixel and channel, with a standard
    deviation of 2 levels in the dark growing to 3.6 in full light (read noise plus
    shot noise).

    Args:
        rgb: uint8 (H, W, 3) image.
        rng: the random generator.

    Returns:
        uint8 (H, W, 3).
    """
    blurred: np.ndarray = cv2.GaussianBlur(rgb, (3, 3), 0.6).astype(np.float32)
    sigma = np.float32(2.0) + blurred * np.float32(1.0 / 160.0)
    noisy: np.ndarray = blurred + sigma * _standard_normal(blurred.shape, rng) + np.float32(0.5)
    return noisy.clip(0, 255).astype(np.uint8)


def _standard_normal(shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """Standard normal float32 samples, drawn by OpenCV (three times faster than numpy)
    from a seed taken from ``rng``, so the result still depends only on ``rng``."""
    cv2.setRNGSeed(int(rng.integers(1, 2 ** 31 - 1)))
    # One channel: OpenCV would apply the scalar deviation to the first channel only.
    samples = np.empty((1, int(np.prod(shape))), np.float32)
    cv2.randn(samples, np.zeros(1), np.ones(1))
    return samples.reshape(shape)


def generate_sequence(directory: str | Path, world: World, frame_stamps: Sequence[float] | np.ndarray,
                      frame_poses: Sequence[np.ndarray] | np.ndarray, truth_stamps: Sequence[float] | np.ndarray,
                      truth_poses: Sequence[np.ndarray] | np.ndarray, intrinsics: Intrinsics = FR1,
                      seed: int = 0, workers: int = 2, world_name: str | None = None,
                      progress: Callable[[int, int], None] | None = None) -> Path:
    """Render and write a TUM RGB-D sequence.

    Writes ``rgb/<stamp>.png`` (8-bit colour), ``depth/<stamp>.png`` (16-bit,
    5000 per metre), ``rgb.txt``, ``depth.txt`` (each depth stamp 2-12 ms off its
    colour stamp, as the Kinect's are, so readers must associate them),
    ``groundtruth.txt`` (``truth_stamps``/``truth_poses``) and ``tinman.json``
    (generator, version, world, intrinsics, frame count, seed). Everything goes
    into a hidden sibling directory first, which is renamed to ``directory`` at
    the end (replacing an older sequence there), so an interrupted run never
    leaves half a sequence behind. The result depends only on the arguments
    (``workers`` changes the speed, not the output).

    Args:
        directory: where the sequence goes.
        world: the room to render.
        frame_stamps, frame_poses: camera frames (seconds; 4x4 ``T_wc``).
        truth_stamps, truth_poses: the ground truth trajectory to write.
        intrinsics: the camera.
        seed: seeds the textures and all noise.
        workers: rendering processes (spawned) for sequences of more than 50 frames.
        world_name: recorded in ``tinman.json``; defaults to ``"DEFAULT_WORLD"`` or ``"custom"``.
        progress: told ``(frames written, frames)`` before the first frame and after every one
            (e.g. a :class:`tinman.progress.FrameProgress`).

    Returns:
        The sequence directory.

    Raises:
        ValueError: stamps and poses differ in number, or stamps are not increasing.
    """
    target = Path(directory)
    stamps = np.asarray(frame_stamps, dtype=float)
    poses = np.asarray(frame_poses, dtype=float).reshape(-1, 4, 4)
    if len(stamps) != len(poses) or len(truth_stamps) != len(truth_poses):
        raise ValueError(f"stamps and poses differ in number: {len(stamps)} frames, {len(poses)} poses; "
                         f"{len(truth_stamps)} truth stamps, {len(truth_poses)} truth poses")
    if len(stamps) > 1 and np.any(np.diff(stamps) <= 0):
        raise ValueError("frame stamps must be strictly increasing")
    offsets = np.random.default_rng([seed, 2]).uniform(0.002, 0.012, len(stamps))
    offsets *= np.where(np.random.default_rng([seed, 3]).random(len(stamps)) < 0.5, -1.0, 1.0)
    depth_stamps = stamps + offsets
    partial = target.with_name(f".{target.name}.partial-{os.getpid()}")
    if partial.exists():
        shutil.rmtree(partial)
    try:
        (partial / "rgb").mkdir(parents=True)
        (partial / "depth").mkdir()
        jobs = [(i, float(stamps[i]), float(depth_stamps[i]), poses[i]) for i in range(len(stamps))]
        report = progress if progress is not None else _ignore
        report(0, len(jobs))
        if workers > 1 and len(jobs) > _POOL_THRESHOLD:
            context = multiprocessing.get_context("spawn")
            with context.Pool(workers, initializer=_start_worker,
                              initargs=(world, intrinsics, seed, str(partial))) as pool:
                for done, _ in enumerate(pool.imap_unordered(_render_job, jobs, chunksize=8), 1):
                    report(done, len(jobs))
        else:
            _start_worker(world, intrinsics, seed, str(partial), threads=None)
            for done, job in enumerate(jobs, 1):
                _render_job(job)
                report(done, len(jobs))
        write_file_list(partial / "rgb.txt", {float(s): f"rgb/{s:.6f}.png" for s in stamps},
                        comment="color images\nfile: tinman synthetic")
        write_file_list(partial / "depth.txt", {float(s): f"depth/{s:.6f}.png" for s in depth_stamps},
                        comment="depth maps\nfile: tinman synthetic")
        write_trajectory(partial / "groundtruth.txt", truth_stamps, np.asarray(truth_poses, dtype=float),
                         comment="ground truth trajectory\nfile: tinman synthetic")
        metadata = {
            "generator": "tinman.synthetic",
            "version": GENERATOR_VERSION,
            "world": world_name or ("DEFAULT_WORLD" if world == DEFAULT_WORLD else "custom"),
            "world_description": dataclasses.asdict(world),
            "intrinsics": dataclasses.asdict(intrinsics),
            "depth_scale": DEPTH_SCALE,
            "frames": len(stamps),
            "seed": seed,
        }
        (partial / METADATA_FILE).write_text(json.dumps(metadata, indent=2) + "\n", encoding="utf-8")
        _replace(partial, target)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    return target


def _ignore(done: int, total: int) -> None:
    pass


def _replace(partial: Path, target: Path) -> None:
    """Move the finished sequence into place, replacing an older one."""
    if target.exists():
        old = target.with_name(f".{target.name}.old-{os.getpid()}")
        target.rename(old)
        partial.rename(target)
        shutil.rmtree(old, ignore_errors=True)
    else:
        partial.rename(target)


# One renderer per worker process (built once: painting the textures takes a second or two).
_worker: dict[str, object] = {}


def _start_worker(world: World, intrinsics: Intrinsics, seed: int, directory: str,
                  threads: int | None = 1) -> None:
    if threads is not None:
        cv2.setNumThreads(threads)  # the pool already keeps every core busy
    key = (world, intrinsics, seed)
    if _worker.get("key") != key:
        _worker["renderer"] = RoomRenderer(world, intrinsics, seed)
        _worker["key"] = key
    _worker["directory"] = Path(directory)
    _worker["seed"] = seed


def _render_job(job: tuple[int, float, float, np.ndarray]) -> None:
    index, stamp, depth_stamp, pose = job
    renderer: RoomRenderer = _worker["renderer"]  # type: ignore[assignment]
    directory: Path = _worker["directory"]  # type: ignore[assignment]
    rng = np.random.default_rng([int(_worker["seed"]), 1, index])  # type: ignore[call-overload]
    rgb, depth = renderer.render(pose)
    colour = add_image_noise(rgb, rng)
    depth_png = add_depth_noise(depth, rng)
    # Noisy images hardly compress: Huffman coding alone is as small and much faster.
    png = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]
    _write_png(directory / "rgb" / f"{stamp:.6f}.png", cv2.cvtColor(colour, cv2.COLOR_RGB2BGR), png)
    _write_png(directory / "depth" / f"{depth_stamp:.6f}.png", depth_png, png)


def _write_png(path: Path, image: np.ndarray, params: list[int]) -> None:
    if not cv2.imwrite(str(path), image, params):
        raise OSError(f"could not write {path}")
