"""Move's logic: teleop wins when it commands anything, else pure pursuit on the latest path.

Move steers by the robot's one estimate of its place, the fused pose VisOdom publishes
(wheel and visual odometry in one estimator, :mod:`tinman.estimator`): each fresh estimate
sets Move's model of the drive, which carries the pose forward with every command sent
until the next one comes (a prediction from the estimate, not a second estimate). While
the estimate is the wheels' alone (the camera's odometry lost track and relocalises: the
pose comes in the ``odom`` frame), path following drives at ``RECOVERING_SPEED`` of its
speed. When no fresh estimate has come for ``LOST_AFTER`` seconds (perception is gone),
path following stops the robot and counts the stop; it resumes with the next fresh estimate.
The protocol states the same bound as Move's patience (``VisOdom -> Move : Pose within 500ms else
timeout``): when Move's estimates thread takes that timeout (:meth:`Mixer.estimate_timed_out`),
path following has stopped by this rule already; likewise a scan's timeout (250 ms) finds the
safety layer's blind rule in force.

Path following looks ahead before it drives: if the arc commanded would, in
``CLEAR_AHEAD`` seconds, bring the robot (by Move's pose, in the room's known map)
within ``CLEAR_MARGIN`` of a wall or box, it drives no further (turning on the spot
still goes) and counts it (``held_back``). Teleop
is "active" while Control's twist is not zero: Control sends a twist every cycle, so
a centred stick means "no command" (as with ROS's twist_mux, where a silent teleop
topic yields to navigation); a person driving is not stopped by the map.

Last, every command, teleop's too, passes the safety layer (:mod:`tinman.safety`)
with the scanner's latest scan and its age: that sees the room as it is, not as the
estimate places the robot in the map, and slows or stops the robot before contact; a
robot with a scanner and no fresh scan may turn, not drive. Nothing above can override it.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from .messages import LaserScan, Path, Twist, path_points, twist_planar
from .pursuit import PurePursuit
from .safety import SafetyLayer
from .sim import DiffDrive, arc_pose
from .world import ROBOT_RADIUS, World

__all__ = ["Mixer", "IDLE_EPSILON", "LOST_AFTER", "RECOVERING_SPEED", "CLEAR_AHEAD", "CLEAR_MARGIN"]

IDLE_EPSILON = 1e-3  # m/s or rad/s: a twist this small commands nothing
LOST_AFTER = 0.5  # seconds without a fresh estimate before path following stops the robot
RECOVERING_SPEED = 0.5  # of path following's speed while the estimate is the wheels' alone

CLEAR_AHEAD = 0.5  # seconds of the commanded arc checked against the map
CLEAR_MARGIN = 0.05  # metres beyond the robot's radius

Pose = tuple[float, float, float]


class Mixer:
    """Mixes teleop and path following, one control period at a time.

    Args:
        world: the room (for the drive model).
        period: the control period in seconds (each command drives that long).
        clock: seconds, for how fresh the estimate and the latest scan are (``time.monotonic``).
        scanned: the robot has a scanner whose scans come through :meth:`set_scan`: a step
            with no fresh one may turn, not drive (the safety layer's ``blind``).

    Attributes:
        sources: how many commands came from each source (``teleop``, ``path``, ``idle``,
            ``lost``: stopped for want of a fresh estimate).
        estimates: fresh estimates taken.
        stops: how often path following stopped because the estimate went stale.
        recovering: path commands given while the estimate was the wheels' alone (slower).
        recovered: path commands given on a relocalised estimate after the first of those.
        held_back: path commands whose forward motion was dropped: it led too near a wall or box.
        safety: the safety layer every command passes (its ``stops`` and ``slowed`` count what it did).
    """

    def __init__(self, world: World, period: float, pursuit: PurePursuit | None = None,
                 clock: Callable[[], float] = time.monotonic, scanned: bool = False) -> None:
        self.model = DiffDrive(world)
        self.scanned = scanned
        self.period = period
        self.pursuit = pursuit or PurePursuit()
        self.sources = {"teleop": 0, "path": 0, "idle": 0, "lost": 0}
        self.paths_received = 0
        self.estimates = 0
        self.stops = 0
        self.resumed = 0  # path commands after the first stop: tracking came back
        self.recovering = 0
        self.recovered = 0
        self.held_back = 0  # path commands that would have driven too near a wall or box
        self._wheels_only = False  # the latest estimate is the wheels' alone
        self.safety = SafetyLayer(period)
        self._path: list[tuple[float, float]] = []
        self._stamp: float | None = None
        self._clock = clock
        self._fresh_at = clock()  # the robot starts knowing its pose: its dock
        self.path_at: float | None = None  # when the latest path came (clock)
        self._lost = False
        self.estimate_timeouts = 0  # the protocol's deadline for a pose passed with none (Move's patience)
        self.scan_timeouts = 0  # the protocol's deadline for a scan passed with none
        self._scan: tuple[LaserScan, float] | None = None  # the latest scan, and when it came (clock)
        self._lock = threading.Lock()  # the planning and perception branches' threads hand over

    def set_scan(self, scan: LaserScan) -> None:
        """The scanner's latest scan (the scan branch's thread hands it over as it comes)."""
        came = self._clock()  # read outside the lock: a replay may hold a thread at its clock (its turn)
        with self._lock:
            self._scan = (scan, came)

    def set_path(self, path: Path) -> None:
        """Follow ``path`` from now on (the latest plan always wins)."""
        points = path_points(path)
        self.path_at = self._clock()  # when the latest plan came (it orders this thread's turns in a replay)
        with self._lock:
            self._path = points
            self.paths_received += 1

    def set_estimate(self, stamp: float, pose: Pose, wheels_only: bool = False) -> None:
        """The fused estimate of the robot at ``stamp`` (``wheels_only``: the camera's odometry is
        lost and the wheels carry it); a repeated stamp is no news. The robot is then where it says."""
        came = self._clock()  # outside the lock, as in set_scan
        with self._lock:
            if stamp == self._stamp:
                return
            self._stamp = stamp
            self._fresh_at = came
            self.model.pose = pose
            self._wheels_only = wheels_only
            self.estimates += 1

    def estimate_timed_out(self) -> None:
        """No pose came within the protocol's deadline (Move's estimates thread took the timeout).

        Counted only: the deadline, 500 ms from the branch's previous pose, is ``LOST_AFTER`` from
        the last *fresh* one at the latest, so path following has already stopped by the mixer's
        own rule, judged on the clock (which a replay gives back; a timeout it cannot)."""
        with self._lock:
            self.estimate_timeouts += 1

    def scan_timed_out(self) -> None:
        """No scan came within the protocol's deadline: counted only, as for a pose. The deadline
        (250 ms) is the safety layer's ``STALE_SCAN``: from then on it lets the robot turn, not
        drive (its blind rule), until the next scan."""
        with self._lock:
            self.scan_timeouts += 1

    def tracking(self) -> bool:
        """Whether a fresh estimate came within ``LOST_AFTER`` seconds."""
        return self._tracking_at(self._clock())  # read outside the lock, as in set_scan

    def _tracking_at(self, now: float) -> bool:
        with self._lock:
            return now - self._fresh_at <= LOST_AFTER

    def _clear_ahead(self, pose: Pose, v: float, w: float) -> bool:
        """Whether the arc ``(v, w)`` keeps the robot clear of the room's walls and boxes for
        ``CLEAR_AHEAD`` seconds (checked at its middle and its end)."""
        world = self.model.world
        return not any(world.collides(*arc_pose(*pose, v, w, t)[:2], ROBOT_RADIUS + CLEAR_MARGIN)
                       for t in (CLEAR_AHEAD / 2, CLEAR_AHEAD))

    def step(self, teleop: Twist, scan: LaserScan | None = None) -> tuple[Twist, str]:
        """The command for this period and where it came from; advances the drive model.

        The safety layer limits the command first: against ``scan`` when given (Fig. 16's
        single loop hands over this step's), else against the latest :meth:`set_scan` gave,
        as old as it is."""
        # Time first, before the state the other threads hand over is read: a replay orders the
        # threads at their clock readings (anodize replay), so what follows sees what it saw live.
        now = self._clock()
        v, w = teleop.linear.x, teleop.angular.z
        if abs(v) > IDLE_EPSILON or abs(w) > IDLE_EPSILON:
            source = "teleop"
        else:
            with self._lock:
                path = self._path
                pose = self.model.pose
            if len(path) < 2 or self.pursuit.at_goal(pose, path):
                v, w, source = 0.0, 0.0, "idle"
            elif not self._tracking_at(now):
                v, w, source = 0.0, 0.0, "lost"
                self.stops += not self._lost
            else:
                v, w = self.pursuit.command(pose, path)
                if self._wheels_only:  # relocalising: slower, so the camera's odometry catches up sooner
                    v, w = v * RECOVERING_SPEED, w * RECOVERING_SPEED
                    self.recovering += 1
                else:
                    self.recovered += self.recovering > 0
                if v > 0 and not self._clear_ahead(pose, v, w):
                    v = 0.0
                    self.held_back += 1
                source = "path"
                self.resumed += self.stops > 0
            self._lost = source == "lost"
        if scan is not None:
            v, w = self.safety.limit(v, w, scan)
        elif self.scanned:
            with self._lock:
                latest = self._scan
            v, w = (self.safety.limit(v, w, None) if latest is None
                    else self.safety.limit(v, w, latest[0], now - latest[1]))
        with self._lock:
            self.model.step(v, w, self.period)
        self.sources[source] += 1
        return twist_planar(v, w), source
