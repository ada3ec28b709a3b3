"""The range scanner and the safety layer: the robot stops before contact whatever its pose estimate says."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tinman.messages import Header, LaserScan, Time, path_through, stamp_from_seconds, twist_planar
from tinman.mission import patrol_pursuit
from tinman.mixer import Mixer
from tinman.safety import BRAKE_DECEL, STOP_MARGIN, SafetyLayer, free_distance, safe_speed
from tinman.scanner import BEAMS, RANGE_MAX, beam_angles, cast, scan_message, scan_points
from tinman.sim import DiffDrive
from tinman.world import DEFAULT_WORLD, ROBOT_RADIUS

PERIOD = 0.02  # the control loop's, 50 Hz


def scan_at(pose: tuple[float, float, float], rng: np.random.Generator | None = None) -> LaserScan:
    ranges = cast(DEFAULT_WORLD, pose, beam_angles(), rng)
    return scan_message(ranges, Header(stamp=Time(sec=0, nanosec=0), frame_id="base_scan"), PERIOD)


def test_the_scanner_reads_the_walls_and_boxes_from_the_true_pose() -> None:
    angles = beam_angles()
    assert len(angles) == BEAMS and angles[BEAMS // 2] == 0.0  # a beam straight ahead
    ranges = cast(DEFAULT_WORLD, (2.0, 3.0, 0.0), angles)
    ahead, left, behind, right = (ranges[np.argmin(np.abs(np.remainder(angles - a + math.pi, math.tau) - math.pi))]
                                  for a in (0.0, math.pi / 2, math.pi, -math.pi / 2))
    assert ahead == pytest.approx(0.6, abs=1e-5)   # the cabinet's west face, x = 2.6
    assert behind == pytest.approx(2.0, abs=1e-5)  # the west wall
    assert right == pytest.approx(3.0, abs=1e-5)   # the south wall
    assert left == pytest.approx(3.0, abs=1e-5)    # the north wall, y = 6
    # Turned a quarter left, the same beams see the room turned: ahead is now the north wall.
    turned = cast(DEFAULT_WORLD, (2.0, 3.0, math.pi / 2), angles)
    assert turned[BEAMS // 2] == pytest.approx(3.0, abs=1e-5)
    # Nothing within range reads +inf, as REP 117 has it: east from the dock, the desk is 4.2 m away.
    assert cast(DEFAULT_WORLD, (1.0, 1.0, 0.0), angles)[BEAMS // 2] == math.inf and RANGE_MAX < 4.2


def test_a_scan_is_a_laser_scan_whose_points_are_where_the_walls_are() -> None:
    scan = scan_at((2.0, 3.0, 0.0), np.random.default_rng(0))
    assert scan.ranges.dtype == np.float32 and len(scan.ranges) == BEAMS
    assert scan.angle_min == -math.pi and scan.angle_increment == pytest.approx(math.tau / BEAMS)
    forward, left = scan_points(scan)
    ahead = np.abs(left) < 1e-3
    assert forward[ahead & (forward > 0)][0] == pytest.approx(0.6, abs=0.03)  # noisy, by millimetres


def test_the_braking_distance_fits_the_free_distance() -> None:
    # Nothing in the way: any speed.
    assert safe_speed(math.inf, PERIOD) == math.inf and safe_speed(0.0, PERIOD) == 0.0
    for free in (0.05, 0.1, 0.3):
        v = safe_speed(free, PERIOD)
        assert v * PERIOD + v * v / (2 * BRAKE_DECEL) == pytest.approx(free)
    # A wall 0.4 m ahead of the robot's centre: the footprint's edge is 0.2 m from it, less the margins.
    assert free_distance(np.array([0.4]), np.array([0.0])) == pytest.approx(0.4 - ROBOT_RADIUS - 0.02 - STOP_MARGIN)
    # Beside the robot, or behind it, is not in the way of driving forward.
    assert free_distance(np.array([0.3, -0.3]), np.array([0.25, 0.0])) == math.inf


def test_the_safety_layer_slows_then_stops_and_counts_one_stop() -> None:
    layer = SafetyLayer(PERIOD)
    assert layer.limit(0.4, 0.0, scan_at((2.0, 3.0, 0.0))) == (0.4, 0.0)  # cabinet 0.6 m ahead: room to brake
    v, _ = layer.limit(0.4, 0.0, scan_at((2.28, 3.0, 0.0)))               # 0.32 m: slow down
    assert 0 < v < 0.4 and layer.slowed == 1
    for _ in range(5):  # 0.25 m from the centre: 0.0 m of free distance, however often it is asked
        assert layer.limit(0.4, 0.3, scan_at((2.35, 3.0, 0.0))) == (0.0, 0.3)  # turning still goes
    assert layer.stops == 1
    assert layer.limit(-0.2, 0.0, scan_at((2.35, 3.0, 0.0))) == (-0.2, 0.0)  # backing away goes
    assert layer.limit(0.0, 1.0, scan_at((2.35, 3.0, 0.0))) == (0.0, 1.0)
    # Backing into the cabinet's east face (x = 3.4) is stopped too: the scan goes all round.
    assert layer.limit(-0.3, 0.0, scan_at((3.62, 3.0, 0.0)))[0] == 0.0 and layer.stops == 2


def turned_about_the_dock(pose: tuple[float, float, float], angle: float) -> tuple[float, float, float]:
    """The lie of ``--inject lying-pose``: the true pose, turned about the dock."""
    x0, y0, _ = DEFAULT_WORLD.start
    c, s = math.cos(angle), math.sin(angle)
    dx, dy = pose[0] - x0, pose[1] - y0
    return x0 + c * dx - s * dy, y0 + s * dx + c * dy, pose[2] + angle


def drive_at_a_wall(scanned: bool, seconds: float = 8.0) -> tuple[DiffDrive, Mixer, float]:
    """The robot follows a path east from its dock steering by an estimate turned 90 degrees
    (it leaves facing east and believes it faces north), so it drives south, at the wall 0.8 m
    away; Move gets the scan of every step when ``scanned``. Returns the true robot, Move's
    mixer and the nearest the robot came to the south wall (its centre's y)."""
    robot = DiffDrive(DEFAULT_WORLD)
    steps = 0
    mixer = Mixer(DEFAULT_WORLD, PERIOD, patrol_pursuit(), clock=lambda: steps * PERIOD)
    mixer.set_path(path_through([(1.0, 1.0), (4.3, 1.1)], Header(stamp=stamp_from_seconds(0.0), frame_id="map")))
    nearest = robot.pose[1]
    for steps in range(round(seconds / PERIOD)):
        if steps % 2 == 0:  # an estimate every other step (25 Hz)
            mixer.set_estimate(steps * PERIOD, turned_about_the_dock(robot.pose, math.pi / 2))
        command, _ = mixer.step(twist_planar(0.0, 0.0), scan_at(robot.pose) if scanned else None)
        robot.step(command.linear.x, command.angular.z, PERIOD)
        nearest = min(nearest, robot.pose[1])
    return robot, mixer, nearest


def test_a_lying_estimate_drives_the_robot_into_the_wall_without_the_scan() -> None:
    robot, mixer, _ = drive_at_a_wall(scanned=False)
    assert robot.bumps > 0 and mixer.safety.stops == 0  # what the safety layer is for


def test_with_the_scan_the_robot_stops_short_of_the_wall_whatever_the_estimate_says() -> None:
    robot, mixer, nearest = drive_at_a_wall(scanned=True)
    assert robot.bumps == 0
    assert mixer.safety.stops >= 1 and mixer.sources["path"] > 100  # it kept trying, and was held
    assert ROBOT_RADIUS < nearest < 0.5  # it drove at the wall, and stopped short of it
    assert nearest >= ROBOT_RADIUS + STOP_MARGIN / 2


def test_a_bump_is_the_safety_layers_failure_and_the_report_counts_safety_stops() -> None:
    from tinman.app import _judge, _lines
    from tinman.mission_outcome import mission_outcome
    from tinman.settings import Settings

    def data(bumps: int) -> dict[str, object]:
        records = {"Gazebo": {"bumps": bumps, "trajectory": [], "bump_events": [[1.0, 0.5, 0.5]] * bool(bumps)},
                   "Move": {"safety_stops": 1}}
        return {"violations": 0, "groups": {}, "roles": {}, "frames_processed": 10, "ate_rmse_m": None,
                "control_period_ms": {"p50": 20.0, "p99": 20.5},
                "control": {"commands": 500, "safety_stops": 1, "safety_slowed": 2, "safety_blind": 3,
                            "planner_lost": None},
                "robot": {"distance_m": 1.0, "bumps": bumps, "waypoints_reached": 0},
                "mission": mission_outcome(records)}

    assert _judge(data(0), Settings()) == (True, [])
    assert ("safety layer (range scan): 1 safety stop, 2 commands slowed near an obstacle, 3 commands held "
            "for want of a fresh scan") in _lines(data(0), [])
    ok, problems = _judge(data(3), Settings())
    assert not ok and problems == [("mission failed: the robot bumped into the room (3 bumps in 1 contact): "
                                    "the safety layer did not stop it")]


def test_an_old_scan_leaves_less_room_and_no_scan_or_a_stale_one_lets_the_robot_turn_but_not_drive() -> None:
    from tinman.safety import STALE_SCAN

    scan = scan_at((2.0, 3.0, 0.0))  # the cabinet 0.6 m ahead
    fresh = SafetyLayer(PERIOD)
    assert fresh.limit(0.3, 0.0, scan) == (0.3, 0.0)
    # The same scan 0.2 s old, the robot last let through at 0.3 m/s: 6 cm of the free distance are gone.
    aged = SafetyLayer(PERIOD)
    aged.limit(0.3, 0.0, scan)
    aged.limit(0.3, 0.0, scan, age=0.2)
    assert aged.free == pytest.approx(fresh.free - 0.3 * 0.2)
    blind = SafetyLayer(PERIOD)
    assert blind.limit(0.3, 0.5, None) == (0.0, 0.5)  # no scan yet: turning only
    assert blind.limit(0.3, 0.5, scan, age=STALE_SCAN + 0.01) == (0.0, 0.5)
    assert blind.limit(0.0, 0.5, None) == (0.0, 0.5)  # a command to stand still is no blind stop
    assert (blind.blind, blind.stops) == (2, 0)


def test_a_scanned_mixer_drives_by_the_latest_scan_and_its_age() -> None:
    now = [100.0]
    mixer = Mixer(DEFAULT_WORLD, PERIOD, patrol_pursuit(), clock=lambda: now[0], scanned=True)
    ahead = twist_planar(0.3, 0.0)
    assert mixer.step(ahead)[0].linear.x == 0.0 and mixer.safety.blind == 1  # no scan has come
    mixer.set_scan(scan_at((1.0, 1.0, 0.0)))  # open room ahead of the dock
    assert mixer.step(ahead)[0].linear.x == pytest.approx(0.3)
    now[0] += 1.0  # the scanner went silent for a second
    assert mixer.step(ahead)[0].linear.x == 0.0 and mixer.safety.blind == 2
