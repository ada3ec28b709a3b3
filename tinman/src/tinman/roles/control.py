"""The control group (priority 90): Joy, Control and Move, the loop that must keep its rate."""

from __future__ import annotations

import threading

import numpy as np

from anodize import TIMEOUT, Endpoint, PeerFailedError, RoleStopped, client_input

from ..contract import contract_of
from ..faults import overspeed, start_faults
from ..geometry import robot_pose
from ..joystick import AXES, BUTTONS, scripted_joy, twist_from_joy
from ..keyboard import Keyboard
from ..messages import (
    Header,
    Joy,
    LaserScan,
    Path,
    PoseStamped,
    Twist,
    pose_matrix,
    seconds,
    stamp_from_seconds,
    twist_planar,
)
from ..messages import joy as joy_message
from ..mission import CRUISE_SPEED, patrol_pursuit
from ..mixer import Mixer
from ..records import percentiles, save_record
from ..settings import current
from ..world import DEFAULT_WORLD

__all__ = ["joy", "control", "move"]

CLIENT_HOLD = 0.5  # seconds a Foxglove client's joystick state counts after it arrived
MAX_PATH_SPEED = 0.5  # m/s: the protocol refuses faster commands (Control -> Move's refinement)


def joy(ep: Endpoint) -> None:
    """The joystick: its state every control period, on an absolute schedule.

    With ``--foxglove``, a joystick in the Foxglove app (a client publishing
    ``sensor_msgs/Joy`` on ``/joy``) takes over while it publishes: its latest state,
    fitted to this gamepad's layout, is what Joy sends.

    Time is the endpoint's clock (``ep.now()``, ``ep.wall()`` for the stamps), so that
    ``anodize replay`` of a recorded run gives Joy the times it read then.
    """
    settings = current()
    start_faults("Joy")
    period = 1.0 / settings.control_rate
    keyboard = Keyboard.open() if settings.teleop else None
    read = keyboard.read if keyboard is not None else scripted_joy
    client = client_input(ep, "Control", "Joy")  # None without --foxglove
    start = ep.now()
    tick = 0
    try:
        while True:
            axes, buttons = read(ep.now() - start)
            held = client.latest(max_age=CLIENT_HOLD) if client is not None else None
            if isinstance(held, Joy):
                axes, buttons = _fitted(held)
            ep.send("Control", "Joy", joy_message(Header(stamp=stamp_from_seconds(ep.wall()), frame_id="joy"),
                                                  axes, buttons))
            sent = ep.now()
            tick += 1
            late = sent - (start + tick * period)
            if late > period:  # fell behind (e.g. the machine was busy): do not burst to catch up
                tick += int(late / period)
            # The protocol's period allows 15 ms either way: after a late send, the next waits at
            # least half a period (10 ms) rather than follow at once.
            ep.sleep(max(start + tick * period, sent + period / 2) - ep.now())
    finally:
        if keyboard is not None:
            keyboard.close()
        save_record("Joy", {"contract": contract_of(ep)})


def _fitted(state: Joy) -> tuple[tuple[float, ...], tuple[int, ...]]:
    """A client's Joy as this gamepad's: its axes within [-1, 1] (not a number: centred) and its
    buttons 0 or 1, as many of each as the gamepad has (missing ones centred or released)."""
    axes = np.nan_to_num(np.clip(np.asarray(state.axes, np.float64)[:AXES], -1.0, 1.0), nan=0.0)
    buttons = (np.asarray(state.buttons)[:BUTTONS] != 0).astype(int)
    return (tuple(float(a) for a in axes) + (0.0,) * (AXES - len(axes)),
            tuple(int(b) for b in buttons) + (0,) * (BUTTONS - len(buttons)))


def control(ep: Endpoint) -> None:
    """Joystick to velocity command."""
    start_faults("Control")
    try:
        while True:
            state: Joy = ep.recv("Joy").payload
            v, w, _ = twist_from_joy(state.axes, state.buttons)
            ep.send("Move", "Twist", twist_planar(*overspeed("Control", v, w)))
    finally:
        save_record("Control", {"contract": contract_of(ep)})


def move(ep: Endpoint, *, max_speed: float = CRUISE_SPEED) -> None:
    """The mixer: a command to the robot for every command from Control, steering by the
    fused estimate (VisOdom's Pose: wheel and visual odometry in one estimator), each checked
    by the safety layer against the range scanner's latest scan (Gazebo's LaserScan) before it
    goes to the robot.

    ``max_speed`` (a role parameter, m/s): the speed it follows the planned path at
    (``anodize run tinman -p Move.max_speed=0.3``; ``[params.Move]`` in a system file).

    Time is the endpoint's clock: each of Move's threads reads the clock of the branch it
    acts through (:class:`_ThreadClock`), so ``anodize replay`` gives each the times it read
    in the recorded run."""
    if not 0 < max_speed <= MAX_PATH_SPEED:
        raise ValueError(f"Move's parameter max_speed: expected a speed in m/s, 0 < max_speed <= {MAX_PATH_SPEED}, "
                         f"got {max_speed}")
    settings = current()
    start_faults("Move")
    clock = _ThreadClock(ep)
    mixer = Mixer(DEFAULT_WORLD, 1.0 / settings.control_rate, patrol_pursuit(max_speed),  # as the mission drives
                  clock=clock, scanned=True)
    planner_lost: list[str] = []
    perception_lost: list[str] = []
    scanner_lost: list[str] = []
    if not settings.paper:  # the scan, planning and perception loops run beside the control loop: threads
        branches = ep.fork()
        threading.Thread(target=_take_scans, args=(_branch_from(branches, "Gazebo"), mixer, scanner_lost, clock),
                         name="Move-scans", daemon=True).start()
        threading.Thread(target=_take_paths, args=(_branch_from(branches, "Planner"), mixer, planner_lost, clock),
                         name="Move-paths", daemon=True).start()
        threading.Thread(target=_take_estimates, args=(_branch_from(branches, "VisOdom"), mixer, perception_lost,
                                                       clock), name="Move-estimates", daemon=True).start()
    sent: list[float] = []
    teleop_after_loss = 0
    stops = 0  # safety stops logged so far (the safety layer counts one per stop, not per command)
    try:
        while True:
            teleop: Twist = ep.recv("Control").payload
            if settings.paper:
                _estimate(mixer, ep.recv("VisOdom").payload)
                path: Path = ep.recv("Planner").payload
                mixer.set_path(path)
            scan: LaserScan | None = ep.recv("Gazebo").payload if settings.paper else None  # else the latest
            command, source = mixer.step(teleop, scan)
            ep.send("Gazebo", "Twist", command)
            if mixer.safety.stops > stops:  # after the send: the command goes first, the words after
                stops = mixer.safety.stops
                ep.logger.warning("safety stop: an obstacle within stopping distance; the robot stands (stop %d)",
                                  stops)
            sent.append(ep.now())
            if planner_lost and source == "teleop":
                teleop_after_loss += 1
    finally:
        periods = np.diff(np.array(sent)) * 1000.0
        save_record("Move", {
            "commands": len(sent), "sources": mixer.sources, "paths_received": mixer.paths_received,
            "period_ms": percentiles(periods), "planner_lost": planner_lost[0] if planner_lost else None,
            "teleop_commands_after_planner_lost": teleop_after_loss,
            "estimates": mixer.estimates, "stops_for_lost_tracking": mixer.stops,
            "path_commands_after_a_stop": mixer.resumed, "recovering_commands": mixer.recovering,
            "path_commands_after_recovering": mixer.recovered,
            "held_back": mixer.held_back,
            "perception_lost": perception_lost[0] if perception_lost else None,
            "estimated_pose": list(mixer.model.pose),
            "safety_stops": mixer.safety.stops, "safety_slowed": mixer.safety.slowed,
            "safety_blind": mixer.safety.blind, "scanner_lost": scanner_lost[0] if scanner_lost else None,
            "estimate_timeouts": mixer.estimate_timeouts, "scan_timeouts": mixer.scan_timeouts,
            "contract": contract_of(ep)})


def _estimate(mixer: Mixer, pose: PoseStamped) -> None:
    mixer.set_estimate(seconds(pose.header.stamp), robot_pose(pose_matrix(pose.pose)),
                       wheels_only=pose.header.frame_id == "odom")


def _branch_from(branches: tuple[Endpoint, ...], peer: str) -> Endpoint:
    """The parallel branch (of ``ep.fork()``'s) that receives from ``peer``."""
    return next(branch for branch in branches if peer in branch.received)


class _ThreadClock:
    """The mixer's clock: each of Move's threads reads the clock of the endpoint it acts through
    (the role's own until it says otherwise), so each endpoint's readings are one thread's."""

    def __init__(self, ep: Endpoint) -> None:
        self._role = ep
        self._local = threading.local()

    def use(self, ep: Endpoint) -> None:
        """From now on the calling thread reads ``ep``'s clock."""
        self._local.endpoint = ep

    def __call__(self) -> float:
        endpoint: Endpoint = getattr(self._local, "endpoint", self._role)
        return endpoint.now()


def _take_estimates(ep: Endpoint, mixer: Mixer, perception_lost: list[str], clock: _ThreadClock) -> None:
    clock.use(ep)
    try:
        while True:
            message = ep.recv("VisOdom")
            if message.label == TIMEOUT:  # the protocol's deadline passed with no pose: stop following the path
                mixer.estimate_timed_out()
            else:
                _estimate(mixer, message.payload)
    except PeerFailedError as error:  # no more estimates: path following stops, teleop goes on
        perception_lost.append(str(error))
        ep.logger.error("perception lost (%s): path following stops, teleop goes on", error)
    except RoleStopped:
        pass


def _take_scans(ep: Endpoint, mixer: Mixer, scanner_lost: list[str], clock: _ThreadClock) -> None:
    clock.use(ep)
    try:
        while True:
            message = ep.recv("Gazebo")
            if message.label == TIMEOUT:  # the protocol's deadline passed with no scan: the robot is blind
                mixer.scan_timed_out()
            else:
                mixer.set_scan(message.payload)
    except PeerFailedError as error:  # no more scans: the safety layer lets the robot turn, not drive
        scanner_lost.append(str(error))
        ep.logger.error("range scanner lost (%s): the robot may turn, not drive", error)
    except RoleStopped:
        pass


def _take_paths(ep: Endpoint, mixer: Mixer, planner_lost: list[str], clock: _ThreadClock) -> None:
    clock.use(ep)
    try:
        while True:
            mixer.set_path(ep.recv("Planner").payload)
    except PeerFailedError as error:  # only the planning branch ends: control goes on
        planner_lost.append(str(error))
    except RoleStopped:
        pass

