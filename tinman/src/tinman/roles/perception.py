"""The perception group (priority 50, memory bound): Camera and VisOdom."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

import cv2
import numpy as np

from anodize import TIMEOUT, Endpoint, PeerFailedError, RoleStopped

from ..contract import contract_of
from ..dataset import TumSequence
from ..estimator import MAX_REFUSED, PoseFilter
from ..faults import STALL_FOR, STALL_FROM, lied, start_faults
from ..geometry import FR1, camera_pose, depth_metres, robot_pose
from ..messages import (
    Header,
    Image,
    LaserScan,
    Odometry,
    PoseStamped,
    image_array,
    odometry_planar,
    pose_from_matrix,
    seconds,
    stamp_from_seconds,
)
from ..outcome import FUSED_ESTIMATE, VO_ESTIMATE
from ..records import percentiles, records_folder, save_record
from ..scan_match import match_scan
from ..settings import current
from ..tum import write_trajectory
from ..vo import VisualOdometry
from ..world import DEFAULT_WORLD, World

__all__ = ["camera", "visodom", "STALE_FRAMES", "MATCH_EVERY", "Lateness", "Recoveries", "Fusion"]

STALE_FRAMES = 2.0  # a frame later than this many frame periods is dropped, not tracked
MATCH_EVERY = 5  # scans per match on the map: 10 Hz of the wheels' 50 (a match costs about a millisecond)

cv2.setNumThreads(1)  # one core per role: the group's CPU use stays what its threads are


def camera(ep: Endpoint) -> None:
    """The RGB-D camera's driver: publishes every frame the simulator's camera takes.

    Every frame is two ``sensor_msgs/Image`` messages from Gazebo's camera (rendered
    live from the robot's true pose, or a recording played back: :mod:`tinman.cameras`),
    colour (``rgb8``) then depth (``16UC1``, 5000 units per metre), each stamped with its
    capture time, passed on as a camera driver publishes them.
    """
    start_faults("Camera")
    published = waited = 0
    try:
        while True:
            message = ep.recv("Gazebo")
            if message.label == TIMEOUT:  # no frame for the protocol's second: the camera is stalled; wait on
                waited += 1
                continue
            color: Image = message.payload
            depth: Image = ep.recv("Gazebo").payload
            ep.send("VisOdom", "color", color)
            ep.send("VisOdom", "depth", depth)
            published += 1
    finally:
        save_record("Camera", {"frames_published": published, "frame_timeouts": waited, "contract": contract_of(ep)})


def visodom(ep: Endpoint) -> None:
    """RGB-D visual odometry fused with the wheels': one pose for every frame; the latest to the planner.

    The estimator (:mod:`tinman.estimator`) takes every wheel odometry reading (Gazebo's
    ``nav_msgs/Odometry``) as its prediction and every pose the camera's odometry tracks as a
    measurement, and so is the pose a range scan finds on the room's known map (every
    ``MATCH_EVERY``-th scan, :mod:`tinman.scan_match`), which bounds both odometries' drift; its
    pose is the one VisOdom publishes, to the Visualizer, Move and the Planner.
    When the camera's odometry loses track the estimate goes on with the wheels alone (the pose
    is then published in the ``odom`` frame: Move drives slower while it is), and the camera's
    odometry relocalises from the estimate: against the keyframe it saw before, else a new one
    at the estimate (:meth:`tinman.vo.VisualOdometry.track`'s ``prior``). Each time it tracks
    again is a recovery, timed from the first frame it lost. With a recorded camera
    (``--dataset``) the frames are not the simulated robot's: the wheels are not fused and the
    camera's odometry is the pose.
    """
    settings = current()
    start_faults("VisOdom")
    odometry = _odometry(settings.dataset)
    # Fig. 16's single loop brings a scan with every frame, already at the camera's rate: match each.
    fusion = Fusion(None if settings.dataset else DEFAULT_WORLD.start, match_every=1 if settings.paper else MATCH_EVERY)
    latest = _Latest()
    period = 1.0 / (TumSequence.open(settings.dataset).frame_rate if settings.dataset else settings.camera_rate)
    if not settings.paper:  # the planning loop (the latest pose at the planner's rate) and the wheels' loop
        branches = ep.fork()  # each thread acts through its own branch (a replay reads each one's clock)
        planning = next(branch for branch in branches if "Planner" in branch.sent)
        wheels = next(branch for branch in branches if "Gazebo" in branch.received)
        threading.Thread(target=_feed_planner, args=(planning, latest, settings.replan_period),
                         name="VisOdom-planner", daemon=True).start()
        threading.Thread(target=_take_wheels, args=(wheels, fusion), name="VisOdom-wheels", daemon=True).start()
    stamps: list[float] = []
    poses: list[np.ndarray] = []
    fused_stamps: list[float] = []
    fused_poses: list[np.ndarray] = []
    track_ms: list[float] = []
    dropped = 0
    lost: list[float] = []  # capture stamps of the frames tracking failed on
    recoveries = Recoveries()
    lateness = Lateness()
    last: PoseStamped | None = None
    stall = settings.fault_for("VisOdom") == "stalled-pose"  # read the clock for it only when injected
    began_at = ep.now() if stall else 0.0
    stalls = 0
    try:
        while True:
            if fusion.broken is not None:  # the wheels' thread failed: say so as this role's failure
                raise fusion.broken
            color: Image = ep.recv("Camera").payload  # the protocol's order: colour, then depth
            depth: Image = ep.recv("Camera").payload
            if settings.paper:  # Fig. 16's single loop: a wheel odometry reading with every frame
                fusion.odometry(ep.recv("Gazebo").payload)
                fusion.scan(ep.recv("Gazebo").payload)
            captured = seconds(color.header.stamp)
            # Late against its capture stamp, not a publish stamp (an Image has none): see Lateness.
            late = lateness(captured, ep.now())  # the endpoint's clock: a replay gives back the run's
            if last is not None and late > STALE_FRAMES * period:
                dropped += 1  # catch up: the Visualizer gets the latest estimate again (the wheels' since, if fused)
                fused = fusion.fuse(captured, None)
                if fused is not None:
                    last = _published(fused[0], lied("VisOdom", fused[1]), wheels_only=recoveries.lost)
                    latest.set(last)
            else:
                began = time.perf_counter()
                failures = odometry.failures
                pose = odometry.track(_pixels(color, "rgb8"), depth_metres(_pixels(depth, "16UC1")), captured,
                                      prior=fusion.prior(captured))
                track_ms.append((time.perf_counter() - began) * 1000.0)
                stamps.append(captured)
                poses.append(pose)
                failed = odometry.failures > failures
                if failed:
                    lost.append(captured)
                recoveries.frame(captured, failed)
                # A clock reading right before the shared estimator, as the wheels' thread takes one
                # before each of its updates: a replay takes the threads through the estimator in the
                # run's order by them (the reading before the tracking is too far from it to).
                ep.now()
                fused = fusion.fuse(captured, None if failed else pose)
                if fusion.reanchor is not None:
                    odometry.reanchor(fusion.reanchor)
                    fusion.reanchor = None
                if fused is not None:  # the one pose: fresh with every frame, the wheels' alone while lost
                    fused_stamps.append(fused[0])
                    fused = (fused[0], lied("VisOdom", fused[1]))  # "lying-pose": the estimate the robot uses
                    fused_poses.append(fused[1])
                    last = _published(*fused, wheels_only=failed)
                    latest.set(last)
                elif last is None or not failed:
                    last = PoseStamped(header=Header(stamp=color.header.stamp, frame_id="map"),
                                       pose=pose_from_matrix(lied("VisOdom", pose)))
                    latest.set(last)
                # Unfused and lost: no new estimate. The last one goes again with its own stamp, so Move
                # sees its estimate go stale and stops (a fresh stamp would claim a fix VO does not have).
            ep.send("Visualizer", "Pose", last)
            if settings.paper:
                ep.send("Planner", "Pose", last)
            if stall and not stalls and ep.now() - began_at >= STALL_FROM:  # "stalled-pose": Move waits in vain
                stalls += 1
                ep.sleep(STALL_FOR)
            ep.send("Move", "Pose", last)
    finally:
        out = records_folder()
        if out is not None:  # a launched run (a replay writes nothing)
            out.mkdir(parents=True, exist_ok=True)
            write_trajectory(out / VO_ESTIMATE, stamps, poses, comment="TinMan VisOdom estimate")
            if fused_stamps:
                write_trajectory(out / FUSED_ESTIMATE, fused_stamps, fused_poses,
                                 comment="TinMan fused estimate (wheel and visual odometry), camera poses")
        save_record("VisOdom", {
            "frames_processed": len(stamps), "frames_dropped": dropped, "track_ms": percentiles(track_ms),
            "lost_frames": odometry.failures, "lost_stamps": lost[-200:], "vo_reanchored": odometry.reanchored,
            **recoveries.record(), **fusion.record(), "stalls": stalls, "contract": contract_of(ep)})


def _published(stamp: float, t_wc: np.ndarray, wheels_only: bool) -> PoseStamped:
    """The fused pose as VisOdom publishes it: in the ``map`` frame, or ``odom`` while the camera's
    odometry is lost and the wheels alone carry it (Move then drives slower)."""
    return PoseStamped(header=Header(stamp=stamp_from_seconds(stamp), frame_id="odom" if wheels_only else "map"),
                       pose=pose_from_matrix(t_wc))


class Recoveries:
    """Times to recover: from the first frame the camera's odometry lost to the next one it tracked."""

    def __init__(self) -> None:
        self.times: list[float] = []
        self._lost_since: float | None = None

    @property
    def lost(self) -> bool:
        """Whether the last frame tracked was lost."""
        return self._lost_since is not None

    def frame(self, stamp: float, failed: bool) -> None:
        """A frame captured at ``stamp`` was tracked (``failed`` False) or not."""
        if failed and self._lost_since is None:
            self._lost_since = stamp
        elif not failed and self._lost_since is not None:
            self.times.append(stamp - self._lost_since)
            self._lost_since = None

    def record(self) -> dict[str, object]:
        """The record's ``recoveries`` (how many), ``recovery_s`` (p50 and max, seconds),
        ``recovery_times_s`` (the last 50) and ``lost_at_the_end``."""
        times = self.times
        return {"recoveries": len(times),
                "recovery_s": {"p50": round(float(np.median(times)), 3) if times else None,
                               "max": round(max(times), 3) if times else None},
                "recovery_times_s": [round(t, 3) for t in times[-50:]],
                "lost_at_the_end": self._lost_since is not None}


class Fusion:
    """The estimator shared by VisOdom's tracking thread and its wheels thread (None: not fused).

    Args:
        start: the robot's dock, where the estimate starts; None for a recorded camera.
        match_every: every how many scans one is matched on the room's map.
        world: the known map (the room the Planner plans on).
    """

    def __init__(self, start: tuple[float, float, float] | None, match_every: int = MATCH_EVERY,
                 world: World = DEFAULT_WORLD) -> None:
        self.filter = PoseFilter(start) if start is not None else None
        self.readings = 0
        self.scans = 0
        self.scans_unmatched = 0  # matched, but the matcher refused the result (see tinman.scan_match)
        self.match_ms: list[float] = []
        self._match_every = match_every
        self._world = world
        self.reanchor: np.ndarray | None = None  # where the camera's odometry should be, at the last capture
        self.broken: Exception | None = None  # what ended the wheels' thread, if not the run's end
        self._lock = threading.Lock()

    def odometry(self, message: Odometry) -> None:
        """A wheel odometry reading (the prediction)."""
        with self._lock:
            self.readings += 1
            if self.filter is not None:
                self.filter.odometry(seconds(message.header.stamp), odometry_planar(message))

    def scan(self, message: LaserScan, before_update: Callable[[], object] | None = None) -> None:
        """A range scan: every ``match_every``-th is matched on the map near the estimate, and the
        pose found is a measurement of it. The matching runs outside the lock (about a millisecond):
        the tracking thread may update the estimate meanwhile, which the late measurement allows.
        ``before_update`` is called once the matching is done, before the measurement goes in (the
        wheels' thread reads its clock there: a replay orders the update among the other thread's by it)."""
        with self._lock:
            self.scans += 1
            if self.filter is None or self.filter.stamp is None or self.scans % self._match_every:
                return
            stamp = seconds(message.header.stamp)
            prior = self.filter.pose_at(stamp)
        ranges = np.asarray(message.ranges, dtype=np.float64)
        angles = message.angle_min + np.arange(len(ranges)) * message.angle_increment
        began = time.perf_counter()
        found = match_scan(self._world, prior, ranges, angles)
        spent = (time.perf_counter() - began) * 1000.0
        if before_update is not None:
            before_update()
        with self._lock:
            self.match_ms.append(spent)
            if found is None:
                self.scans_unmatched += 1
            else:
                self.filter.locate(stamp, found.pose, found.covariance)

    def prior(self, captured: float) -> np.ndarray | None:
        """The camera's pose at ``captured`` by the estimate; None before the wheels' first reading."""
        with self._lock:
            if self.filter is None or self.filter.stamp is None:
                return None
            return camera_pose(*self.filter.pose_at(captured))

    def fuse(self, captured: float, t_wc: np.ndarray | None) -> tuple[float, np.ndarray] | None:
        """Take the camera's pose captured at ``captured`` (None: it lost track); the estimate's
        stamp and camera pose after it, or None when not fused."""
        with self._lock:
            if self.filter is None:
                return None
            if t_wc is not None:
                self.filter.measure(captured, robot_pose(t_wc))
            if self.filter.refused_in_a_row >= MAX_REFUSED:  # the camera's odometry went astray: set it right
                self.reanchor = camera_pose(*self.filter.pose_at(captured))
                self.filter.refused_in_a_row = 0
            stamp = captured if self.filter.stamp is None else max(self.filter.stamp, captured)
            return stamp, camera_pose(*self.filter.pose)

    def record(self) -> dict[str, object]:
        with self._lock:
            f = self.filter
            return {"fused": f is not None, "wheel_readings": self.readings,
                    "fused_updates": f.updates if f is not None else None,
                    "fused_refused": f.refused if f is not None else None,
                    "scans": self.scans, "scan_matches": f.located if f is not None else None,
                    "scan_matches_gated": f.map_refused if f is not None else None,
                    "relocated_on_the_map": f.relocated if f is not None else None,
                    "scans_unmatched": self.scans_unmatched, "scan_match_ms": percentiles(self.match_ms)}


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


def _take_wheels(ep: Endpoint, fusion: Fusion) -> None:
    try:
        while True:
            reading = ep.recv("Gazebo").payload
            scan = ep.recv("Gazebo").payload  # taken with the reading, at its instant
            ep.now()  # a clock reading before the shared estimator: a replay orders the threads' turns by them
            fusion.odometry(reading)
            fusion.scan(scan, before_update=ep.now)  # and one before a matched scan's measurement goes in
    except (PeerFailedError, RoleStopped):  # the simulator is gone, or the run stops: the camera goes on alone
        pass
    except Exception as error:  # a bug, or a reading no estimator takes: the role fails, not this thread alone
        fusion.broken = error
