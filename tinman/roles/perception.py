"""The perception group (priority 50, memory bound): Camera and VisOdom."""

from __future__ import annotations

import math
import threading
import time

import cv2
import numpy as np

from anodize import Endpoint, PeerFailedError, RoleStopped

from ..dataset import TumSequence
from ..faults import start_faults
from ..geometry import depth_metres
from ..messages import Header, Image, Pose, PoseStamped, RGBDFrame, Time
from ..records import percentiles, save_record
from ..settings import current
from ..tum import write_trajectory
from ..vo import VisualOdometry

__all__ = ["camera", "visodom", "STALE_FRAMES"]

STALE_FRAMES = 2.0  # a frame older than this many frame periods is dropped, not tracked

cv2.setNumThreads(1)  # one core per role: the group's CPU use stays what its threads are


def camera(ep: Endpoint) -> None:
    """Replays the RGB-D sequence at its frame rate, as a camera driver publishes frames."""
    settings = current()
    start_faults("Camera")
    sequence = TumSequence.open(settings.dataset)
    first = float(sequence.stamps[0])
    period = 1.0 / sequence.frame_rate
    start = time.monotonic()
    published = skipped = 0
    try:
        for index, stamp in enumerate(sequence.stamps):
            due = start + (float(stamp) - first)
            if time.monotonic() - due > period:  # reading fell behind: a real camera drops frames
                skipped += 1
                continue
            ep.sleep(due - time.monotonic())
            captured = Header(Time.from_seconds(float(stamp)), "camera_optical")
            rgb = Image.of(sequence.rgb(index), "rgb8", captured)
            depth = Image.of(sequence.depth_raw(index), "16UC1", captured)
            ep.send("VisOdom", "Image", RGBDFrame(Header(Time.now(), "camera"), rgb, depth, index))
            published += 1
        ep.sleep(math.inf)  # the sequence is over: the camera stays silent until the run stops
    finally:
        save_record("Camera", {"frames_published": published, "frames_skipped": skipped,
                               "frames_in_sequence": len(sequence), "frame_rate": sequence.frame_rate})


def visodom(ep: Endpoint) -> None:
    """RGB-D visual odometry: a pose for every frame; the latest pose to the planner."""
    settings = current()
    start_faults("VisOdom")
    sequence = TumSequence.open(settings.dataset)
    truth = sequence.groundtruth
    # The robot knows where it starts (its dock): the first ground-truth pose, if any.
    odometry = VisualOdometry(sequence.intrinsics, truth[1][0] if truth is not None else None)
    latest = _Latest()
    period = 1.0 / sequence.frame_rate
    if not settings.paper:  # the planning loop: the latest pose at the planner's rate
        ep.fork()
        threading.Thread(target=_feed_planner, args=(ep, latest, settings.replan_period),
                         name="VisOdom-planner", daemon=True).start()
    stamps: list[float] = []
    poses: list[np.ndarray] = []
    track_ms: list[float] = []
    dropped = 0
    last: PoseStamped | None = None
    try:
        while True:
            frame: RGBDFrame = ep.recv("Camera").payload
            late = time.time() - frame.header.stamp.seconds()
            if last is not None and late > STALE_FRAMES * period:
                dropped += 1  # catch up: the Visualizer gets the latest estimate again
            else:
                began = time.perf_counter()
                pose = odometry.track(frame.rgb.data, depth_metres(frame.depth.data))
                track_ms.append((time.perf_counter() - began) * 1000.0)
                stamps.append(frame.rgb.header.stamp.seconds())
                poses.append(pose)
                last = PoseStamped(Header(frame.rgb.header.stamp, "map"), Pose.from_matrix(pose))
                latest.set(last)
            ep.send("Visualizer", "Pose", last)
            if settings.paper:
                ep.send("Planner", "Pose", last)
    finally:
        out = settings.records
        out.mkdir(parents=True, exist_ok=True)
        write_trajectory(out / "vo_estimate.txt", stamps, poses, comment="TinMan VisOdom estimate")
        save_record("VisOdom", {
            "frames_processed": len(stamps), "frames_dropped": dropped, "track_ms": percentiles(track_ms),
            "lost_frames": odometry.failures})


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
