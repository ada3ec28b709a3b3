"""The default synthetic sequence: the robot's patrol, filmed by its camera, cached.

The robot's path comes from the mission simulation (the same planner, pure
pursuit, joystick script and drive model the live system runs); the camera's
frames are rendered along it and written in the TUM RGB-D layout with the path
as ground truth. Generating takes about a minute, so the result is cached under
``$TINMAN_CACHE`` (default ``~/.cache/tinman``) by a name that changes with
everything that would change the frames.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .geometry import FR1, Intrinsics, camera_pose
from .mission import simulate_mission
from .synthetic import GENERATOR_VERSION, generate_sequence
from .world import DEFAULT_WORLD, World
from .worlds import world_look

__all__ = ["DEFAULT_DURATION", "FRAME_RATE", "TRUTH_RATE", "FIRST_STAMP", "cache_dir", "default_sequence",
           "generate"]

DEFAULT_DURATION = 30.0  # seconds of the default sequence
FRAME_RATE = 30.0        # Hz, the Kinect's
TRUTH_RATE = 100.0       # Hz, the TUM motion-capture system's
FIRST_STAMP = 1_700_000_000.0  # TUM stamps are Unix times; ours start here


def cache_dir() -> Path:
    """Where generated sequences are kept."""
    configured = os.environ.get("TINMAN_CACHE")
    if configured:
        return Path(configured)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "tinman"


def default_sequence(duration: float = DEFAULT_DURATION, log: Callable[[str], None] | None = None,
                     progress: Callable[[int, int], None] | None = None, look: str = "easy") -> Path:
    """The default sequence's directory, generated on first use.

    Args:
        log: told (one line) when a sequence has to be generated, and when it is done.
        progress: told ``(frames rendered, frames)`` while it is generated (see :func:`generate`).
        look: the named world filmed (:data:`tinman.worlds.WORLDS`).
    """
    name = "room" if look == "easy" else f"{look}-room"
    directory = cache_dir() / f"tinman-{name}-{duration:g}s-v{GENERATOR_VERSION}"
    if (directory / "tinman.json").exists():
        return directory
    if log is not None:
        log(f"generating the synthetic RGB-D sequence ({duration:g} s at {FRAME_RATE:g} fps) "
            f"into {directory}; this happens once")
    generate(directory, duration, progress=progress, look=look)
    if log is not None:
        log("sequence ready")
    return directory


def generate(directory: str | Path, duration: float = DEFAULT_DURATION, world: World = DEFAULT_WORLD,
             intrinsics: Intrinsics = FR1, seed: int = 0, workers: int = 2,
             progress: Callable[[int, int], None] | None = None, look: str = "easy") -> Path:
    """Simulate the patrol for ``duration`` seconds and film it into ``directory`` (TUM layout).

    ``progress`` is told ``(frames rendered, frames)`` before the first frame and after every
    one (simulating the patrol, before that, takes a fraction of a second). ``look`` is the
    named world filmed (:data:`tinman.worlds.WORLDS`); where its camera has an exposure time,
    the camera's poses at the start and end of each exposure blur the frame.

    Raises:
        tinman.worlds.UnknownWorldError: ``look`` names no world.
    """
    exposure = world_look(look).exposure
    trace = simulate_mission(world, duration=duration, rate=TRUTH_RATE, seed=seed)
    truth_stamps = FIRST_STAMP + np.asarray(trace.stamps, dtype=float)
    truth_poses = np.array([camera_pose(x, y, theta) for x, y, theta in trace.poses])
    frame_times = np.arange(0.0, duration - 1e-9, 1.0 / FRAME_RATE)
    frame_poses = np.array([camera_pose(*_pose_at(trace.stamps, trace.poses, t)) for t in frame_times])
    shutter_poses = None
    if exposure > 0:
        shutter_poses = np.array([[camera_pose(*_pose_at(trace.stamps, trace.poses, t + side * exposure / 2))
                                   for side in (-1, 1)] for t in frame_times])
    return generate_sequence(directory, world, FIRST_STAMP + frame_times, frame_poses, truth_stamps,
                             truth_poses, intrinsics=intrinsics, seed=seed, workers=workers, progress=progress,
                             look=look, shutter_poses=shutter_poses)


def _pose_at(stamps: np.ndarray, poses: np.ndarray, t: float) -> tuple[float, float, float]:
    """The robot's pose at time ``t``, interpolated between the simulation's steps."""
    x = float(np.interp(t, stamps, poses[:, 0]))
    y = float(np.interp(t, stamps, poses[:, 1]))
    theta = float(np.interp(t, stamps, np.unwrap(poses[:, 2])))
    return x, y, theta
