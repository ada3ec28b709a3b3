"""The patrol mission, simulated offline: what the live system does, without processes or clocks.

It runs the live roles' logic in one loop on simulated time: the Planner role's
(``Patrol`` goal, a fresh ``Planner`` path every ``replan_period``, the last path kept
when planning fails), Joy and Control's (the scripted gamepad through
``twist_from_joy``) and Move's (``Mixer``: teleop wins while it commands anything,
else pure pursuit on the latest path, the drive model stepped with every command).
The result depends on nothing but the arguments, so the synthetic camera sequence
rendered along it is reproducible.

Two differences from the live system, both because there is nothing to wait for:
the planner sees the true pose (live, it sees visual odometry's estimate), and a plan
takes no time (live, the path arrives a few milliseconds after the pose it started from).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .joystick import JOY_SCRIPT, JoyWindow, scripted_joy, twist_from_joy
from .messages import Header, path_through, stamp_from_seconds, twist_planar
from .mixer import Mixer
from .planning import NoPathError, Patrol, Planner
from .pursuit import PurePursuit
from .world import DEFAULT_WORLD, World

__all__ = ["CRUISE_SPEED", "MAX_TURN_RATE", "WAYPOINT_TOLERANCE", "DOCK_TOLERANCE", "DOCKING_TOLERANCE", "DOCK",
           "REPLAN_PERIOD",
           "patrol_pursuit",
           "MissionTrace", "simulate_mission"]

# How the patrol drives. The camera films the robot's way, so turns are kept gentle
# (at 1 rad/s and 30 fps the view moves 2 degrees a frame) and the robot takes the
# next waypoint as its goal half a metre early, which rounds the corner instead of
# stopping on the spot; the cruising speed then still covers three waypoints of the
# default room in 30 seconds.
CRUISE_SPEED = 0.4        # m/s
MAX_TURN_RATE = 1.0       # rad/s
WAYPOINT_TOLERANCE = 0.5  # metres
# Back at the dock, the whole patrol is done: the Planner counts the robot docked within
# DOCKING_TOLERANCE of the dock by its pose, wider than the path follower's 0.15 m (it stops that
# near its path's end, by Move's pose), so the robot cannot stop short of it. The report judges
# the true path against the wider DOCK_TOLERANCE: a few centimetres of pose error is no failure.
DOCKING_TOLERANCE = 0.2   # metres
DOCK_TOLERANCE = 0.3      # metres
DOCK = (DEFAULT_WORLD.start[0], DEFAULT_WORLD.start[1])  # where the robot starts and a whole patrol ends
REPLAN_PERIOD = 0.5       # seconds, the live Planner's default


def patrol_pursuit(speed: float = CRUISE_SPEED) -> PurePursuit:
    """The path follower the patrol drives with (give it to ``Mixer`` live, too), cruising at
    ``speed`` m/s (Move's parameter ``max_speed``: ``anodize run tinman -p Move.max_speed=0.3``)."""
    return PurePursuit(speed=speed, max_angular=MAX_TURN_RATE)


@dataclass(frozen=True)
class MissionTrace:
    """What the robot did, one entry per control step.

    Attributes:
        stamps: seconds since the start, ``(N,)``, evenly spaced at the control rate.
        poses: the robot's ``(x, y, theta)`` at each stamp, ``(N, 3)``.
        teleop: whether the command issued at that stamp came from the gamepad, ``(N,)``.
        plans: ``(t, path)`` for every plan made, ``path`` a list of ``(x, y)``.
        waypoints_reached: how many patrol waypoints the robot came within tolerance of.
        planning_failures: the messages of the plans that failed (the last path was kept).
        bumps: steps the drive refused because of a collision (0 in a sound mission).
        odometer: the distance driven (metres).
        completed_at: seconds since the start when the robot, on a patrol done once (a
            ``dock`` given), was back at the dock (None: not done, or a looping patrol).
    """

    stamps: np.ndarray
    poses: np.ndarray
    teleop: np.ndarray
    plans: list[tuple[float, list[tuple[float, float]]]]
    waypoints_reached: int
    planning_failures: list[str]
    bumps: int
    odometer: float
    completed_at: float | None = None


def simulate_mission(world: World = DEFAULT_WORLD, duration: float = 30.0, rate: float = 100.0,
                     method: str = "rrt", seed: int = 0, script: tuple[JoyWindow, ...] = JOY_SCRIPT,
                     replan_period: float = REPLAN_PERIOD, pursuit: PurePursuit | None = None,
                     waypoint_tolerance: float = WAYPOINT_TOLERANCE,
                     dock: tuple[float, float] | None = None) -> MissionTrace:
    """Patrol ``world``'s waypoints for ``duration`` seconds, deterministically.

    Args:
        world: the room, its start pose and its waypoints.
        duration: simulated seconds.
        rate: control steps per second (the drive is stepped once per step).
        method: the planner's, ``"rrt"`` or ``"astar"``.
        seed: the planner's random samples.
        script: the gamepad's timed windows (``()`` for none).
        replan_period: seconds between two plans.
        pursuit: the path follower; ``patrol_pursuit()`` when omitted.
        waypoint_tolerance: how near a waypoint counts as reached (``Patrol``'s tolerance).
        dock: the whole patrol once, then back to ``dock`` (``world.start[:2]``, say), where the
            robot then stays (an empty path, as the live Planner sends); None: the patrol loops.

    Returns:
        The trace: ``round(duration * rate) + 1`` stamps from 0 to ``duration``; the
        pose at a stamp is where the robot is before that step's command.

    Raises:
        ValueError: a non-positive duration, rate or replan period, or an unknown method.
    """
    if duration <= 0 or rate <= 0 or replan_period <= 0:
        raise ValueError("duration, rate and replan period must be positive")
    period = 1.0 / rate
    planner = Planner(world, method=method, seed=seed)
    patrol = Patrol(world, tolerance=waypoint_tolerance, dock=dock, dock_tolerance=DOCKING_TOLERANCE)
    completed_at: float | None = None
    # Offline the drive model is the truth (perfect odometry): its estimate never goes stale.
    mixer = Mixer(world, period, pursuit if pursuit is not None else patrol_pursuit(), clock=lambda: 0.0)
    robot = mixer.model
    steps = round(duration * rate)
    # Integer step counts, not accumulated float seconds, decide when to replan.
    replan_every = max(1, round(replan_period * rate))
    stamps = np.arange(steps + 1) * period
    poses = np.empty((steps + 1, 3))
    teleop = np.zeros(steps + 1, dtype=bool)
    plans: list[tuple[float, list[tuple[float, float]]]] = []
    failures: list[str] = []
    for step in range(steps + 1):
        t = float(stamps[step])
        poses[step] = robot.pose
        if step == steps:
            break
        if step % replan_every == 0 and completed_at is None:
            x, y, _ = robot.pose
            goal = patrol.goal_for(x, y)
            if patrol.done:  # back at the dock: an empty path, and the robot stays
                completed_at = t
                mixer.set_path(path_through([], Header(stamp=stamp_from_seconds(t), frame_id="map")))
            else:
                try:
                    path = planner.plan((x, y), goal)
                except NoPathError as error:
                    failures.append(str(error))
                else:
                    plans.append((t, path))
                    mixer.set_path(path_through(path, Header(stamp=stamp_from_seconds(t), frame_id="map")))
        axes, buttons = scripted_joy(t, script)
        v, w, _ = twist_from_joy(axes, buttons)
        _, source = mixer.step(twist_planar(v, w))
        teleop[step] = source == "teleop"
    teleop[steps] = teleop[steps - 1] if steps else False
    return MissionTrace(stamps=stamps, poses=poses, teleop=teleop, plans=plans,
                        waypoints_reached=patrol.reached, planning_failures=failures,
                        bumps=robot.bumps, odometer=robot.odometer, completed_at=completed_at)
