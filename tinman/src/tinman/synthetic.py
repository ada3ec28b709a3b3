"""Synthetic TUM RGB-D sequences: rendered frames with Kinect-like noise, on disk.

:func:`generate_sequence` renders a camera trajectory through a world with
:class:`~tinman.render.RoomRenderer`, spoils the images as a Kinect would
(:func:`add_depth_noise`, :func:`add_image_noise`; in the realistic world also
:func:`add_motion_blur` and flickering lamps, see :func:`simulate_frame`) and
writes exactly the layout of the TUM RGB-D benchmark, so the same code reads
real and synthetic data.
"""

from __future__ import annotations

import dataclasses
import json
import math
import multiprocessing
import os
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import cv2
import numpy as np

from .geometry import DEPTH_SCALE, FR1, Intrinsics
from .lamps import FlickeringLamps
from .render import RoomRenderer
from .tum import write_file_list, write_trajectory
from .world import DEFAULT_WORLD, World
from .worlds import world_look

if TYPE_CHECKING:
    from .render_warp import WarpRenderer

__all__ = ["GENERATOR_VERSION", "METADATA_FILE", "add_depth_noise", "add_image_noise", "add_motion_blur",
           "image_motion", "simulate_frame", "generate_sequence"]

GENERATOR_VERSION = 2  # changes the cached sequences: 2, the planner keeps the robot further from boxes
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


def image_motion(open_pose: np.ndarray, close_pose: np.ndarray, depth_m: np.ndarray,
                 intrinsics: Intrinsics) -> tuple[float, float]:
    """How far the image moved while the shutter was open: the mean displacement (pixels,
    ``(du, dv)``) of the scene points seen on a 5 x 5 grid of pixels, from where the camera
    saw them at ``open_pose`` to where it sees them at ``close_pose`` (both ``T_wc``).

    Args:
        open_pose, close_pose: the camera's poses when the shutter opened and closed.
        depth_m: the depth image (metres, 0 = none) seen from ``close_pose``.
        intrinsics: the camera.

    Returns:
        ``(0.0, 0.0)`` when no grid pixel has depth.
    """
    k = intrinsics
    rows, cols = depth_m.shape
    v, u = np.meshgrid(np.linspace(0.1, 0.9, 5) * (rows - 1), np.linspace(0.1, 0.9, 5) * (cols - 1), indexing="ij")
    z = depth_m[np.rint(v).astype(int), np.rint(u).astype(int)].astype(np.float64)
    seen = z > 0
    if not seen.any():
        return 0.0, 0.0
    u, v, z = u[seen], v[seen], z[seen]
    camera = np.stack([(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z])
    opened = np.linalg.inv(open_pose) @ close_pose
    before = opened[:3, :3] @ camera + opened[:3, 3:4]
    ahead = before[2] > 1e-3
    if not ahead.any():
        return 0.0, 0.0
    du = u[ahead] - (k.fx * before[0, ahead] / before[2, ahead] + k.cx)
    dv = v[ahead] - (k.fy * before[1, ahead] / before[2, ahead] + k.cy)
    return float(du.mean()), float(dv.mean())


def add_motion_blur(rgb: np.ndarray, motion: tuple[float, float]) -> np.ndarray:
    """The image smeared evenly along ``motion`` (pixels ``(du, dv)`` the image moved during the
    exposure), centred: it shows the scene as at mid-exposure.

    One straight line kernel for the whole image (``cv2.filter2D``): exact for a camera that
    turns about its vertical axis, an approximation where translation makes near things move
    more than far ones.

    Args:
        rgb: uint8 ``(H, W, 3)``.
        motion: the displacement in pixels.

    Returns:
        The blurred image; ``rgb`` itself (unchanged) when the motion is under half a pixel.
    """
    length = math.hypot(*motion)
    if length < 0.5:
        return rgb
    half = math.ceil(length / 2) + 1
    size = 2 * half + 1
    kernel = np.zeros((size, size), np.float32)
    # Splat points along the segment bilinearly, four per pixel of length.
    steps = np.linspace(-0.5, 0.5, max(2, math.ceil(4 * length) + 1))
    x = half + steps * motion[0]
    y = half + steps * motion[1]
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0).astype(np.float32), (y - y0).astype(np.float32)
    for dy, wy in ((0, 1 - fy), (1, fy)):
        for dx, wx in ((0, 1 - fx), (1, fx)):
            np.add.at(kernel, (y0 + dy, x0 + dx), wy * wx)
    kernel /= kernel.sum()
    # filter2D correlates; the kernel is point-symmetric, so that is the convolution.
    blurred: np.ndarray = cv2.filter2D(rgb, -1, kernel, borderType=cv2.BORDER_REFLECT_101)
    return blurred


def simulate_frame(renderer: RoomRenderer | WarpRenderer, t_wc: np.ndarray, rng: np.random.Generator,
                   lamp_gains: np.ndarray | None = None,
                   shutter: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """What the simulated Kinect delivers for one frame: the rendered view (relit for the lamps'
    ``lamp_gains``, blurred by the camera's motion from ``shutter[0]`` to ``shutter[1]``, the
    poses when the shutter opened and closed), then image and depth noise.

    Args:
        renderer: renders the room (only the ray caster can relight it for ``lamp_gains``).
        t_wc: the camera's pose (at mid-exposure).
        rng: the noise's random generator.
        lamp_gains: each lamp's brightness (None: as the textures were lit).
        shutter: the camera's poses at the start and end of the exposure (None: no blur).

    Returns:
        ``(rgb, depth)``: uint8 ``(H, W, 3)`` and TUM's uint16 depth (5000 per metre, 0 = none).

    Raises:
        ValueError: ``lamp_gains`` for a renderer that cannot relight.
    """
    if lamp_gains is None:
        rgb, depth = renderer.render(t_wc)
    elif isinstance(renderer, RoomRenderer):
        rgb, depth = renderer.render(t_wc, lamp_gains)
    else:
        raise ValueError(f"{type(renderer).__name__} cannot relight a frame for lamp gains; use RoomRenderer")
    if shutter is not None:
        rgb = add_motion_blur(rgb, image_motion(shutter[0], shutter[1], depth, renderer.intrinsics))
    return add_image_noise(rgb, rng), add_depth_noise(depth, rng)


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
                      progress: Callable[[int, int], None] | None = None, look: str = "easy",
                      shutter_poses: Sequence[np.ndarray] | np.ndarray | None = None) -> Path:
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
        look: the named world (:data:`tinman.worlds.WORLDS`): its textures, and whether its lamps
            flicker (their time is the frame's stamp minus the first frame's). Recorded in
            ``tinman.json``.
        shutter_poses: per frame, the camera's poses when the shutter opened and closed
            (``(N, 2, 4, 4)``), for motion blur; None: a still shutter. Used only when the
            world's camera has an exposure time.

    Returns:
        The sequence directory.

    Raises:
        ValueError: stamps and poses differ in number, or stamps are not increasing.
        tinman.worlds.UnknownWorldError: ``look`` names no world.
    """
    target = Path(directory)
    stamps = np.asarray(frame_stamps, dtype=float)
    poses = np.asarray(frame_poses, dtype=float).reshape(-1, 4, 4)
    if len(stamps) != len(poses) or len(truth_stamps) != len(truth_poses):
        raise ValueError(f"stamps and poses differ in number: {len(stamps)} frames, {len(poses)} poses; "
                         f"{len(truth_stamps)} truth stamps, {len(truth_poses)} truth poses")
    if len(stamps) > 1 and np.any(np.diff(stamps) <= 0):
        raise ValueError("frame stamps must be strictly increasing")
    blur = world_look(look).exposure > 0 and shutter_poses is not None
    shutters = np.asarray(shutter_poses, dtype=float).reshape(-1, 2, 4, 4) if blur else None
    if shutters is not None and len(shutters) != len(stamps):
        raise ValueError(f"shutter poses and frames differ in number: {len(shutters)} and {len(stamps)}")
    offsets = np.random.default_rng([seed, 2]).uniform(0.002, 0.012, len(stamps))
    offsets *= np.where(np.random.default_rng([seed, 3]).random(len(stamps)) < 0.5, -1.0, 1.0)
    depth_stamps = stamps + offsets
    partial = target.with_name(f".{target.name}.partial-{os.getpid()}")
    if partial.exists():
        shutil.rmtree(partial)
    try:
        (partial / "rgb").mkdir(parents=True)
        (partial / "depth").mkdir()
        jobs = [_Job(i, float(stamps[i]), float(depth_stamps[i]), poses[i], float(stamps[i] - stamps[0]),
                     None if shutters is None else (shutters[i, 0], shutters[i, 1])) for i in range(len(stamps))]
        report = progress if progress is not None else _ignore
        report(0, len(jobs))
        if workers > 1 and len(jobs) > _POOL_THRESHOLD:
            context = multiprocessing.get_context("spawn")
            with context.Pool(workers, initializer=_start_worker,
                              initargs=(world, intrinsics, seed, str(partial), 1, look)) as pool:
                for done, _ in enumerate(pool.imap_unordered(_render_job, jobs, chunksize=8), 1):
                    report(done, len(jobs))
        else:
            _start_worker(world, intrinsics, seed, str(partial), threads=None, look=look)
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
            "look": look,
            "motion_blur": shutters is not None,
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


class _Job(NamedTuple):
    """One frame to render and write."""

    frame: int
    stamp: float
    depth_stamp: float
    pose: np.ndarray
    time: float  # seconds since the first frame (the lamps' clock)
    shutter: tuple[np.ndarray, np.ndarray] | None


# One renderer per worker process (built once: painting the textures takes a second or two).
_worker: dict[str, object] = {}


def _start_worker(world: World, intrinsics: Intrinsics, seed: int, directory: str,
                  threads: int | None = 1, look: str = "easy") -> None:
    if threads is not None:
        cv2.setNumThreads(threads)  # the pool already keeps every core busy
    key = (world, intrinsics, seed, look)
    if _worker.get("key") != key:
        kind = world_look(look)
        renderer = RoomRenderer(world, intrinsics, seed, paint=kind.paint)
        _worker["renderer"] = renderer
        lighting = renderer._atlas.lighting
        _worker["lamps"] = (FlickeringLamps(len(lighting.lamps), seed)
                            if kind.flickering_lamps and lighting is not None else None)
        _worker["key"] = key
    _worker["directory"] = Path(directory)
    _worker["seed"] = seed


def _render_job(job: _Job) -> None:
    renderer: RoomRenderer = _worker["renderer"]  # type: ignore[assignment]
    lamps: FlickeringLamps | None = _worker["lamps"]  # type: ignore[assignment]
    directory: Path = _worker["directory"]  # type: ignore[assignment]
    rng = np.random.default_rng([int(_worker["seed"]), 1, job.frame])  # type: ignore[call-overload]
    gains = lamps.gains(job.time) if lamps is not None else None
    colour, depth_png = simulate_frame(renderer, job.pose, rng, gains, job.shutter)
    # Noisy images hardly compress: Huffman coding alone is as small and much faster.
    png = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]
    _write_png(directory / "rgb" / f"{job.stamp:.6f}.png", cv2.cvtColor(colour, cv2.COLOR_RGB2BGR), png)
    _write_png(directory / "depth" / f"{job.depth_stamp:.6f}.png", depth_png, png)


def _write_png(path: Path, image: np.ndarray, params: list[int]) -> None:
    if not cv2.imwrite(str(path), image, params):
        raise OSError(f"could not write {path}")
