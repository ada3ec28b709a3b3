"""The simulation and view group (priority 10): Gazebo and Visualizer."""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Callable

import numpy as np

from anodize import Endpoint, PeerFailedError, RoleStopped, lower_thread_priority

from ..cameras import LiveCamera, RecordedCamera
from ..contract import contract_of
from ..faults import blinded, start_faults
from ..messages import Header, PoseStamped, Twist, odometry_message, seconds, stamp_now
from ..outcome import CAMERA_TRUTH
from ..picture import draw_run
from ..records import records_folder, save_record
from ..scanner import beam_angles, cast, scan_message
from ..settings import Settings, current
from ..sim import DiffDrive
from ..tum import write_trajectory
from ..wheels import WheelOdometry
from ..world import DEFAULT_WORLD

__all__ = ["gazebo", "visualizer", "REDRAW_PERIOD", "SCAN_RATE"]

REDRAW_PERIOD = 5.0  # seconds between two live pictures
MAX_BUMP_EVENTS = 1000  # bumps whose place the Gazebo record keeps (the count is kept whole)
SCAN_RATE = 25.0  # Hz: the range scanner's (a 2-D lidar's 10 to 40 Hz)
LOCALISATION_STREAM = 2  # the scans to VisOdom draw their noise from a stream of their own (seeded)
SWITCH_INTERVAL = 0.001  # seconds a thread of Gazebo's process may hold the interpreter while another waits


def gazebo(ep: Endpoint) -> None:
    """The robot in the room, the camera on it, its range scanner and its wheel odometry.

    Each command drives the robot for one control period (lockstep). The range scanner's
    ray sensor reads the room from the robot's true pose and Gazebo hands Move each scan
    (``sensor_msgs/LaserScan``), which the safety layer checks commands against
    (:mod:`tinman.safety`): in ``TinManParallel`` at the scanner's own rate, ``SCAN_RATE``,
    in a thread of its own; in Fig. 16's single loop, one before each step. The camera takes
    frames at its own rate: rendered from the robot's true pose (or a recording played
    back, with ``--dataset``) and handed to the Camera role's driver. In
    ``TinManParallel`` the two run side by side (the camera in a thread of its own); in
    Fig. 16's single loop, a frame then a command, in turn. The wheels' encoders integrate
    every step the robot truly made, with their errors (:mod:`tinman.wheels`), and Gazebo
    hands VisOdom the pose they give (``nav_msgs/Odometry``, as a diff-drive plugin
    publishes it): in ``TinManParallel`` at the control rate in a thread of its own, in
    Fig. 16's single loop, one with every frame. Each reading goes with a scan taken at the same
    instant, which VisOdom matches against the room's map (:mod:`tinman.scan_match`).
    """
    settings = current()
    start_faults("Gazebo")
    # The scanner and the steps run while the camera thread renders in the same process: hand
    # the interpreter over every millisecond, not every 5 ms (Python's default), so a scan or a
    # step is not held up several times 5 ms behind a rendering.
    sys.setswitchinterval(SWITCH_INTERVAL)
    robot = _Robot(DiffDrive(DEFAULT_WORLD), WheelOdometry(DEFAULT_WORLD.start, seed=settings.seed))
    # The camera is set up in its own thread: building the room's look takes seconds, and Move
    # waits for the first scan before it sends a command.
    films: list[_Film] = []
    if settings.paper:
        films.append(_Film(settings))
    else:
        ep.fork()
        threading.Thread(target=_run_camera, args=(ep, robot, films, settings), name="Gazebo-camera",
                         daemon=True).start()
        threading.Thread(target=_run_scanner, args=(ep, robot, settings.seed), name="Gazebo-scanner",
                         daemon=True).start()
        threading.Thread(target=_run_wheels, args=(ep, robot, 1.0 / settings.control_rate, settings.seed),
                         name="Gazebo-wheels", daemon=True).start()
    period = 1.0 / settings.control_rate
    start = time.monotonic()
    trace: list[list[float]] = []
    bumped: list[list[float]] = []  # [t, x, y] of each refused step, for the map (the first MAX_BUMP_EVENTS)
    angles = beam_angles()
    noise = np.random.default_rng(settings.seed)
    localisation_noise = np.random.default_rng([settings.seed, LOCALISATION_STREAM])
    try:
        while True:
            if settings.paper and not films[0].shoot(ep, *robot.state()):
                ep.sleep(math.inf)  # a recording is over: the camera, hence the single loop, stops
            if settings.paper:
                _wheels(ep, robot, angles, localisation_noise, period)
                _scan(ep, robot, angles, noise, period)
            twist: Twist = ep.recv("Move").payload
            bumps = robot.drive.bumps
            x, y, theta = robot.step(twist.linear.x, twist.angular.z, period)
            t = round(time.monotonic() - start, 3)
            trace.append([t, round(x, 4), round(y, 4), round(theta, 4),
                          round(robot.drive.velocity[0], 3), round(robot.drive.velocity[1], 3)])
            if robot.drive.bumps > bumps and len(bumped) < MAX_BUMP_EVENTS:
                bumped.append([t, round(x, 4), round(y, 4)])
    finally:
        # The world's own clock is real time (it stands for the physical world: decision 0030), so
        # it reads time.monotonic(), not an endpoint's clock; the report compares the two.
        ended = time.monotonic()
        film = films[0] if films else None  # None: the run stopped before the camera was set up
        if film is not None:
            film.save(settings)
        save_record("Gazebo", {"trajectory": trace, "odometer_m": robot.drive.odometer, "bumps": robot.drive.bumps,
                               "bump_events": bumped, "wheel_odometry_pose": list(robot.wheels.pose),
                               "wheel_scales": list(robot.wheels.scales),
                               "columns": ["t", "x", "y", "theta", "v", "w"],
                               # The physics' seconds against the wall's, from the first step to the last
                               # (the robot's start and the run's stop are not the world's to keep up with).
                               "simulated_s": round(len(trace) * period, 6), "contract": contract_of(ep),
                               "wall_s": round(trace[-1][0] - trace[0][0] + period, 6) if trace else 0.0,
                               **(film.record(ended) if film is not None else {})})


class _Robot:
    """The simulated robot and its wheels' odometry, shared by Gazebo's control loop and its threads."""

    def __init__(self, drive: DiffDrive, wheels: WheelOdometry) -> None:
        self.drive = drive
        self.wheels = wheels
        self._lock = threading.Lock()

    def step(self, v: float, w: float, dt: float) -> tuple[float, float, float]:
        """Drive one step; the wheels measure the motion the robot really made (none after a bump)."""
        with self._lock:
            pose = self.drive.step(v, w, dt)
            if dt > 0:
                self.wheels.step(*self.drive.velocity, dt)
            return pose

    def odometry(self) -> tuple[tuple[float, float, float], tuple[float, float]]:
        """The wheel odometry's pose and measured velocity, read together."""
        with self._lock:
            return self.wheels.pose, self.wheels.velocity

    def sensed(self) -> tuple[tuple[tuple[float, float, float], tuple[float, float]], tuple[float, float, float]]:
        """The wheel odometry's pose and velocity, and the true pose the scanner reads from, together."""
        with self._lock:
            return (self.wheels.pose, self.wheels.velocity), self.drive.pose

    def state(self) -> tuple[tuple[float, float, float], tuple[float, float]]:
        """The pose and the velocity ``(v, w)``, read together."""
        with self._lock:
            return self.drive.pose, self.drive.velocity


class _Film:
    """Gazebo's camera: frames at the camera's rate, and the camera's true path (for ATE)."""

    def __init__(self, settings: Settings) -> None:
        self.live: LiveCamera | None = None
        self.recorded: RecordedCamera | None = None
        if settings.dataset:
            self.recorded = RecordedCamera(settings.dataset)
            self.period = 1.0 / self.recorded.frame_rate
        else:
            self.live = LiveCamera(DEFAULT_WORLD, seed=settings.seed, look=settings.world)
            self.period = 1.0 / settings.camera_rate
        self.start = self.begun = time.monotonic()
        self.taken = self.skipped = 0
        self.stamps: list[float] = []
        self.poses: list[np.ndarray] = []

    def due(self) -> float | None:
        """When the next frame is due (monotonic), or None once a recording is over."""
        if self.recorded is None:
            return self.start + self.taken * self.period
        index = self.taken + self.skipped
        return self.start + self.recorded.offset(index) if index < len(self.recorded) else None

    def shoot(self, ep: Endpoint, robot: tuple[float, float, float],
              velocity: tuple[float, float] = (0.0, 0.0)) -> bool:
        """Take the next frame when it is due and hand it to the Camera (the robot's velocity blurs
        it in the realistic world); False once a recording is over."""
        due = self.due()
        if due is None:
            return False
        ep.sleep(due - time.monotonic())
        if self.recorded is not None:
            color, depth = self.recorded.frame(self.taken + self.skipped)
        else:
            assert self.live is not None
            stamp = time.time()  # a camera stamps its frames with the time they were taken
            color, depth, t_wc = self.live.capture(robot, stamp, blind=blinded("Gazebo", time.monotonic() - self.begun),
                                                   velocity=velocity)
            self.stamps.append(stamp)
            self.poses.append(t_wc)
        ep.send("Camera", "color", color)
        ep.send("Camera", "depth", depth)
        self.taken += 1
        return True

    def skip_late(self) -> None:
        """Frames a camera that fell behind drops, as a real one does."""
        while (due := self.due()) is not None and time.monotonic() - due > self.period:
            if self.recorded is None:
                self.start += self.period  # a live camera takes its next frame from now on
            self.skipped += 1

    def save(self, settings: Settings) -> None:
        if self.stamps and records_folder() is not None:  # a launched run (a replay writes nothing)
            settings.records.mkdir(parents=True, exist_ok=True)
            write_trajectory(settings.records / CAMERA_TRUTH, self.stamps, self.poses,
                             comment="TinMan Gazebo: the simulated camera's true path")

    def frames_due(self, ended: float) -> int:
        """Frames that fell due between the camera's first frame and ``ended`` (monotonic)."""
        if ended < self.begun:
            return 0
        if self.recorded is None:
            return int((ended - self.begun) / self.period) + 1
        return sum(1 for index in range(len(self.recorded)) if self.recorded.offset(index) <= ended - self.begun)

    def record(self, ended: float | None = None) -> dict[str, object]:
        """What the camera did (frames due up to ``ended``, monotonic; now if None)."""
        return {"camera_frames": self.taken, "camera_frames_skipped": self.skipped,
                "camera_frames_due": self.frames_due(time.monotonic() if ended is None else ended),
                "camera": "live" if self.live is not None else "recorded", "camera_rate": 1.0 / self.period,
                "world": self.live.look.name if self.live is not None else None}


def _scan(ep: Endpoint, robot: _Robot, angles: np.ndarray, noise: np.random.Generator, period: float) -> None:
    """One scan from the robot's true pose, to Move."""
    pose, _ = robot.state()
    ep.send("Move", "LaserScan", scan_message(cast(DEFAULT_WORLD, pose, angles, noise),
                                              Header(stamp=stamp_now(), frame_id="base_scan"), period))


def _run_scanner(ep: Endpoint, robot: _Robot, seed: int) -> None:
    """The range scanner at ``SCAN_RATE``, as a lidar's driver publishes (to Move)."""
    angles, noise, period = beam_angles(), np.random.default_rng(seed), 1.0 / SCAN_RATE
    _at_a_fixed_rate(ep, period, lambda: _scan(ep, robot, angles, noise, period))  # ends when Move is gone


def _wheels(ep: Endpoint, robot: _Robot, angles: np.ndarray, noise: np.random.Generator, period: float) -> None:
    """The wheel odometry's latest reading, to VisOdom (in the ``odom`` frame, which starts at the dock),
    then a scan taken at the same instant, for the localisation on the map (one stamp for both)."""
    (pose, velocity), truth = robot.sensed()
    stamp = stamp_now()
    ep.send("VisOdom", "Odometry", odometry_message(Header(stamp=stamp, frame_id="odom"), pose, velocity))
    ep.send("VisOdom", "LaserScan", scan_message(cast(DEFAULT_WORLD, truth, angles, noise),
                                                 Header(stamp=stamp, frame_id="base_scan"), period))


def _run_wheels(ep: Endpoint, robot: _Robot, period: float, seed: int) -> None:
    """The wheel odometry at the control rate, as a diff-drive plugin publishes it, each reading with
    its scan (to VisOdom)."""
    angles, noise = beam_angles(), np.random.default_rng([seed, LOCALISATION_STREAM])
    _at_a_fixed_rate(ep, period, lambda: _wheels(ep, robot, angles, noise, period))  # ends when VisOdom is gone


def _at_a_fixed_rate(ep: Endpoint, period: float, step: Callable[[], None]) -> None:
    """``step`` every ``period`` seconds until the run stops or the peer it sends to is gone: due times
    on a fixed grid, and a step that fell behind by more than a period is skipped, not made late.
    After a late step the next waits at least half a period (as Joy does): a sensor that fell
    behind does not burst to catch up, so a period with a jitter of half the period holds on
    the early side."""
    due = time.monotonic()
    try:
        while True:
            step()
            done = time.monotonic()
            due += period
            if done - due > period:  # behind by more than a step: start again from now
                due = done
            ep.sleep(max(due, done + period / 2) - time.monotonic())
    except (RoleStopped, PeerFailedError):
        pass


def _run_camera(ep: Endpoint, robot: _Robot, films: list[_Film], settings: Settings) -> None:
    film = _Film(settings)
    films.append(film)
    try:
        while True:
            film.skip_late()
            if not film.shoot(ep, *robot.state()):
                ep.sleep(math.inf)  # a recording is over: the camera stays silent until the run stops
    except (RoleStopped, PeerFailedError):  # the run stops, or perception is gone: the robot drives on
        pass


def visualizer(ep: Endpoint) -> None:
    """Keeps the estimated trajectory; a painter thread redraws the live picture every few seconds."""
    settings = current()
    start_faults("Visualizer")
    estimate: list[tuple[float, float, float, float]] = []
    last_stamp: float | None = None
    painter = _Painter(settings)
    try:
        while True:
            pose: PoseStamped = ep.recv("VisOdom").payload
            stamp = seconds(pose.header.stamp)
            if stamp != last_stamp:  # a dropped frame repeats the last estimate
                last_stamp = stamp
                p = pose.pose.position
                estimate.append((stamp, p.x, p.y, p.z))
                painter.offer(estimate)
    finally:
        save_record("Visualizer", {"poses_received": len(estimate)})


class _Painter:
    """Draws the live picture in a thread of its own at ordinary, niced priority.

    Drawing takes a few hundred milliseconds. Done in the Visualizer's thread at the
    group's real-time priority, it stalled Gazebo's camera thread in the same process,
    and the camera skipped frames every redraw: the odometry lost track when that fell
    on a turn. The painter only gets the CPU the simulated robot leaves.
    """

    def __init__(self, settings: Settings) -> None:
        self._settings = settings
        self._estimate: list[tuple[float, float, float, float]] = []
        self._lock = threading.Lock()
        threading.Thread(target=self._paint, name="Visualizer-painter", daemon=True).start()

    def offer(self, estimate: list[tuple[float, float, float, float]]) -> None:
        """The estimate so far (the painter copies what it draws)."""
        with self._lock:
            self._estimate = estimate

    def _paint(self) -> None:
        lower_thread_priority()
        if records_folder() is None:  # not a launched run (a replay): no live picture
            return
        live = self._settings.records / "live.png"
        while True:
            time.sleep(REDRAW_PERIOD)  # a plain thread, not a role: it takes no step of the protocol
            with self._lock:
                estimate = list(self._estimate)
            draw_run(live, self._settings, estimate=estimate)
