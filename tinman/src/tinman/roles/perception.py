"""The perception group (priority 50, memory bound): Camera and VisOdom."""

from __future__ import annotations

import math
import threading
import time

import cv2
import numpy as np

from anodize import Endpoint, PeerFailedError, RoleStopped

from ..dataset import TumSequence
from ..faults import lied, start_faults
from ..geometry import FR1, camera_pose, depth_metres
from ..messages import Header, Image, PoseStamped, image_array, pose_from_matrix, seconds
from ..records import percentiles, records_folder, save_record
from ..settings import current
from ..tum import write_trajectory
from ..vo import VisualOdometry
from ..world import DEFAULT_WORLD

__all__ = ["camera", "visodom", "STALE_FRAMES", "Lateness"]

STALE_FRAMES = 2.0  # a frame later than this many frame periods is dropped, not tracked

cv2.setNumThreads(1)  # one core per role: the group's CPU use stays what its threads are


def camera(ep: Endpoint) -> None:
    """The RGB-D camera's driver: publishes every frame the simulator's camera takes.

    Every frame is two ``sensor_msgs/Image`` messages from Gazebo's camera (rendered
    live from the robot's true pose, or a recording played back: :mod:`tinman.cameras`),
    colour (``rgb8``) then depth (``16UC1``, 5000 units per metre), each stamped with its
    capture time, passed on as a camera driver publishes them.
    """
    start_faults("Camera")
    published = 0
    try:
        while True:
            color: Image = ep.recv("Gazebo").payload
            depth: Image = ep.recv("Gazebo").payload
            ep.send("VisOdom", "color", color)
            ep.send("VisOdom", "depth", depth)
            published += 1
    finally:
        save_record("Camera", {"frames_published": published})


def visodom(ep: Endpoint) -> None:
    """RGB-D visual odometry: a pose for every frame; the latest pose to the planner."""
    settings = current()
    start_faults("VisOdom")
    odometry = _odometry(settings.dataset)
    latest = _Latest()
    period = 1.0 / (TumSequence.open(settings.dataset).frame_rate if settings.dataset else settings.camera_rate)
    if not settings.paper:  # the planning loop: the latest pose at the planner's rate
        planning = next(branch for branch in ep.fork() if "Planner" in branch.sent)  # its thread acts through it
        threading.Thread(target=_feed_planner, args=(planning, latest, settings.replan_period),
                         name="VisOdom-planner", daemon=True).start()
    stamps: list[float] = []
    poses: list[np.ndarray] = []
    track_ms: list[float] = []
    dropped = 0
    lost: list[float] = []  # capture stamps of the frames tracking failed on
    lateness = Lateness()
    last: PoseStamped | None = None
    try:
        while True:
            color: Image = ep.recv("Camera").payload  # the protocol's order: colour, then depth
            depth: Image = ep.recv("Camera").payload
            captured = seconds(color.header.stamp)
            # Late against its capture stamp, not a publish stamp (an Image has none): see Lateness.
            late = lateness(captured, ep.now())  # the endpoint's clock: a replay gives back the run's
            if last is not None and late > STALE_FRAMES * period:
                dropped += 1  # catch up: the Visualizer gets the latest estimate again
            else:
                began = time.perf_counter()
                failures = odometry.failures
                pose = lied("VisOdom", odometry.track(_pixels(color, "rgb8"), depth_metres(_pixels(depth, "16UC1")),
                                                     captured))
                track_ms.append((time.perf_counter() - began) * 1000.0)
                stamps.append(captured)
                poses.append(pose)
                if odometry.failures > failures:
                    lost.append(captured)
                if last is None or odometry.failures == failures:
                    last = PoseStamped(header=Header(stamp=color.header.stamp, frame_id="map"),
                                       pose=pose_from_matrix(pose))
                    latest.set(last)
                # Lost: no new estimate. The last one goes again with its own stamp, so Move sees
                # its estimate go stale and stops (a fresh stamp would claim a fix VO does not have).
            ep.send("Visualizer", "Pose", last)
            if settings.paper:
                ep.send("Planner", "Pose", last)
            ep.send("Move", "Pose", last)
    finally:
        out = records_folder()
        if out is not None:  # a launched run (a replay writes nothing)
            out.mkdir(parents=True, exist_ok=True)
            write_trajectory(out / "vo_estimate.txt", stamps, poses, comment="TinMan VisOdom estimate")
        save_record("VisOdom", {
            "frames_processed": len(stamps), "frames_dropped": dropped, "track_ms": percentiles(track_ms),
            "lost_frames": odometry.failures, "lost_stamps": lost})


def _odometry(dataset: str) -> VisualOdometry:
    """Odometry for the camera at hand. The robot knows where it starts (its dock): the simulated
    robot's start, or a recording's first ground-truth pose, if it has one."""
    if not dataset:
        return VisualOdometry(FR1, camera_pose(*DEFAULT_WORLD.start))
    sequence = TumSequence.open(dataset)
    truth = sequence.groundtruth
    return VisualOdometry(sequence.intrinsics, truth[1][0] if truth is not None else None)


class Lateness:
    """How late a frame reaches VisOdom, from its capture stamp and VisOdom's own clock.

    A frame used to carry the time it was published, on the wall clock both roles
    share; a ``sensor_msgs/Image`` carries only its capture stamp, on the camera's
    clock (for a replayed sequence, the dataset's times, years ago). The two clocks'
    offset plus the least transport delay is estimated as the smallest ``arrived -
    captured`` seen so far (the quickest frame); a frame is late by how much longer
    than that it took. This needs no shared clock, and it counts what matters for
    dropping: frames queued behind a slow tracker arrive ever later against their
    capture times. Until a quicker frame comes, the first frame is the reference: a
    first frame that was itself slow makes the next ones look early, never late.
    """

    def __init__(self) -> None:
        self._offset = math.inf

    def __call__(self, captured: float, arrived: float) -> float:
        """Seconds by which a frame captured at ``captured`` (camera clock) that arrived at
        ``arrived`` (this role's monotonic clock) is later than the quickest frame so far."""
        delay = arrived - captured
        self._offset = min(self._offset, delay)
        return delay - self._offset


def _pixels(image: Image, encoding: str) -> np.ndarray:
    """The image's pixels (a view of its data), which must be in ``encoding``."""
    if image.encoding != encoding:
        raise ValueError(f"VisOdom takes {encoding} images on this channel, got {image.encoding}")
    return image_array(image)


class _Latest:
    """The newest pose, handed from the tracking thread to the planner feed."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._pose: PoseStamped | None = None

    def set(self, pose: PoseStamped) -> None:
        with self._lock:
            self._pose = pose

    def get(self) -> PoseStamped | None:
        with self._lock:
            return self._pose


def _feed_planner(ep: Endpoint, latest: _Latest, period: float) -> None:
    try:
        while True:
            pose = latest.get()
            if pose is not None:
                ep.send("Planner", "Pose", pose)
            ep.sleep(period)
    except PeerFailedError:  # the planner is gone: only this loop ends, tracking goes on
        pass
    except RoleStopped:
        pass
