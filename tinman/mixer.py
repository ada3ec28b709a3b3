"""Move's logic: teleop wins when it commands anything, else pure pursuit on the latest path.

Move has no sensor of its own: it tracks the robot with a model of the drive (the
simulator's kinematics and limits, stepped with every command it sends), which is
what wheel odometry would report. Teleop is "active" while Control's twist is not
zero: Control sends a twist every cycle, so a centred stick means "no command"
(as with ROS's twist_mux, where a silent teleop topic yields to navigation).
"""

from __future__ import annotations

import threading

from .messages import Path, Twist, path_points, twist_planar
from .pursuit import PurePursuit
from .sim import DiffDrive
from .world import World

__all__ = ["Mixer", "IDLE_EPSILON"]

IDLE_EPSILON = 1e-3  # m/s or rad/s: a twist this small commands nothing


class Mixer:
    """Mixes teleop and path following, one control period at a time.

    Args:
        world: the room (for the drive model).
        period: the control period in seconds (each command drives that long).

    Attributes:
        sources: how many commands came from each source (``teleop``, ``path``, ``idle``).
    """

    def __init__(self, world: World, period: float, pursuit: PurePursuit | None = None) -> None:
        self.model = DiffDrive(world)
        self.period = period
        self.pursuit = pursuit or PurePursuit()
        self.sources = {"teleop": 0, "path": 0, "idle": 0}
        self.paths_received = 0
        self._path: list[tuple[float, float]] = []
        self._lock = threading.Lock()  # the planning branch's thread hands paths over

    def set_path(self, path: Path) -> None:
        """Follow ``path`` from now on (the latest plan always wins)."""
        points = path_points(path)
        with self._lock:
            self._path = points
            self.paths_received += 1

    def step(self, teleop: Twist) -> tuple[Twist, str]:
        """The command for this period and where it came from; advances the drive model."""
        v, w = teleop.linear.x, teleop.angular.z
        if abs(v) > IDLE_EPSILON or abs(w) > IDLE_EPSILON:
            source = "teleop"
        else:
            with self._lock:
                path = self._path
            if len(path) >= 2 and not self.pursuit.at_goal(self.model.pose, path):
                v, w = self.pursuit.command(self.model.pose, path)
                source = "path"
            else:
                v, w, source = 0.0, 0.0, "idle"
        self.model.step(v, w, self.period)
        self.sources[source] += 1
        return twist_planar(v, w), source
