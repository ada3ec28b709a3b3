"""The one pose: the EKF fusing wheel odometry (prediction) with visual odometry (measurement),
and the wheel odometry the simulator publishes (issue 28, items 2 and 3)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tinman.estimator import GATE, MAP_RELOCATE, MAX_REFUSED, PoseFilter, between, compose
from tinman.mission import simulate_mission
from tinman.wheels import WheelNoise, WheelOdometry
from tinman.world import DEFAULT_WORLD

START = DEFAULT_WORLD.start


def test_between_undoes_compose() -> None:
    a, b = (1.0, 2.0, 0.7), (0.3, -0.1, 2.9)
    x, y, theta = compose(a, between(a, b))
    assert math.isclose(x, b[0]) and math.isclose(y, b[1]) and math.isclose(theta, b[2])


def test_wheel_odometry_drifts_by_its_seeded_wheel_errors_and_is_reproducible() -> None:
    runs = []
    for _ in range(2):
        wheels = WheelOdometry((0.0, 0.0, 0.0), seed=3)
        for _ in range(250):  # 5 s straight ahead at 0.4 m/s: 2 m
            wheels.step(0.4, 0.0, 0.02)
        runs.append(wheels.pose)
    assert runs[0] == runs[1]  # the seed decides everything
    x, y, theta = runs[0]
    left, right = WheelOdometry((0.0, 0.0, 0.0), seed=3).scales
    assert abs(left - 1.0) <= WheelNoise().scale and abs(right - 1.0) <= WheelNoise().scale
    assert abs(x - 2.0) < 0.1 and x != 2.0  # a few per cent off in length ...
    assert theta != 0.0 and y != 0.0  # ... and a straight line became an arc
    standing = WheelOdometry((1.0, 1.0, 0.5), seed=3)
    assert standing.step(0.0, 0.0, 0.02) == (1.0, 1.0, 0.5)  # wheels that do not turn measure nothing
    with pytest.raises(ValueError, match="positive duration"):
        standing.step(0.1, 0.0, 0.0)


def test_the_wheels_move_the_estimate_and_its_uncertainty_grows() -> None:
    fused = PoseFilter((0.0, 0.0, 0.0))
    fused.odometry(0.0, (5.0, 5.0, 1.0))  # the odometry's own frame: only its motions count
    before = np.trace(fused.covariance)
    fused.odometry(1.0, compose((5.0, 5.0, 1.0), (0.5, 0.0, 0.1)))
    x, y, theta = fused.pose
    assert math.isclose(x, 0.5) and abs(y) < 1e-12 and math.isclose(theta, 0.1)
    assert np.trace(fused.covariance) > before and fused.predictions == 1
    fused.odometry(0.5, (0.0, 0.0, 0.0))  # an older reading is no news
    assert fused.predictions == 1 and math.isclose(fused.pose[0], 0.5)


def test_a_camera_pose_pulls_the_estimate_and_shrinks_its_uncertainty() -> None:
    fused = PoseFilter((0.0, 0.0, 0.0))
    fused.odometry(0.0, (0.0, 0.0, 0.0))
    fused.odometry(1.0, (1.0, 0.0, 0.0))  # the wheels say 1 m
    spread = np.trace(fused.covariance)
    assert fused.measure(1.0, (1.05, 0.0, 0.0))  # the camera says 1.05 m
    assert 1.0 < fused.pose[0] < 1.05
    assert np.trace(fused.covariance) < spread and fused.updates == 1


def test_a_late_camera_pose_is_carried_forward_by_the_wheels_motion_since_its_capture() -> None:
    fused = PoseFilter((0.0, 0.0, 0.0))
    for i in range(11):  # 0.1 m every 0.01 s by the wheels, which are right
        fused.odometry(i * 0.01, (0.1 * i, 0.0, 0.0))
    fused.pose = (0.8, 0.2, 0.0)  # the estimate went astray sideways
    fused.covariance = np.diag([0.04, 0.04, 0.001])
    # The camera saw the robot at its true place (0.5, 0) when the wheels read 0.5, 50 ms ago.
    assert fused.measure(0.05, (0.5, 0.0, 0.0))
    assert abs(fused.pose[0] - 1.0) < 0.01 and abs(fused.pose[1]) < 0.01  # where it is now, not then
    back = fused.pose_at(0.05)
    assert abs(back[0] - 0.5) < 0.01  # and carried back to a capture time, for the camera's prior


def test_a_false_fix_is_refused_however_often_the_camera_insists() -> None:
    fused = PoseFilter((0.0, 0.0, 0.0))
    fused.odometry(0.0, (0.0, 0.0, 0.0))
    fused.odometry(0.1, (0.04, 0.0, 0.0))
    far = (2.0, 1.0, 1.5)
    spread = fused.covariance + fused.measurement_covariance
    innovation = np.array(far) - np.array(fused.pose)
    assert float(innovation @ np.linalg.solve(spread, innovation)) > GATE
    for _ in range(MAX_REFUSED + 5):
        assert not fused.measure(0.1, far)
    # The caller learns the camera's odometry went astray (VisOdom then re-anchors it on the estimate).
    assert fused.refused == fused.refused_in_a_row == MAX_REFUSED + 5 and fused.pose == (0.04, 0.0, 0.0)
    assert fused.measure(0.1, (0.05, 0.0, 0.0))  # a pose that fits is taken again
    assert fused.refused_in_a_row == 0


def _fused_and_vo_errors(seed: int, blind: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The offline patrol (mission.py) with the simulator's wheel odometry and a camera odometry that
    drifts, is noisy, and is blind for 2 s (it repeats its last pose, as VisOdom records a lost frame);
    the position errors of VO alone and of the fused estimate at every camera frame."""
    rate, camera_every, latency = 50.0, 2, 2  # 50 Hz wheels, 25 Hz camera, poses 40 ms late
    trace = simulate_mission(duration=30.0, rate=rate)
    truth, dt = trace.poses, 1.0 / rate
    wheels = WheelOdometry(START, seed=seed)
    fused = PoseFilter(START)
    fused.odometry(0.0, wheels.pose)
    noise = np.random.default_rng(seed)
    drift = np.zeros(3)
    held: np.ndarray | None = None
    vo_errors, fused_errors = [], []
    for i in range(1, len(truth)):
        step = between(tuple(truth[i - 1]), tuple(truth[i]))
        wheels.step(math.copysign(math.hypot(step[0], step[1]), step[0]) / dt, step[2] / dt, dt)
        fused.odometry(i * dt, wheels.pose)
        if i % camera_every or i < latency:
            continue
        drift += noise.normal(0.0, [0.002, 0.002, 0.001])
        seen = truth[i - latency] + drift + noise.normal(0.0, [0.02, 0.02, 0.02])
        if blind and 10.0 <= i * dt < 12.0:  # blind: no measurement; VO alone stays where it was
            seen = held if held is not None else seen
        else:
            held = seen
            fused.measure((i - latency) * dt, (float(seen[0]), float(seen[1]), float(seen[2])))
        vo_errors.append(math.hypot(seen[0] - truth[i - latency][0], seen[1] - truth[i - latency][1]))
        now = fused.pose
        fused_errors.append(math.hypot(now[0] - truth[i][0], now[1] - truth[i][1]))
    return np.array(vo_errors), np.array(fused_errors)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_fused_pose_is_nearer_the_truth_than_visual_odometry_alone(seed: int) -> None:
    vo, fused = _fused_and_vo_errors(seed)
    rmse = lambda errors: float(np.sqrt(np.mean(errors ** 2)))  # noqa: E731
    assert rmse(fused) < 0.8 * rmse(vo), (rmse(fused), rmse(vo))
    assert fused.max() < vo.max()  # the blind spell above all: the wheels carry the fused pose


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_with_the_camera_tracking_throughout_the_fused_pose_is_still_the_nearer(seed: int) -> None:
    """The camera's drift is what both share; its frame-to-frame noise is what the wheels smooth."""
    vo, fused = _fused_and_vo_errors(seed, blind=False)
    assert np.sqrt(np.mean(fused ** 2)) < np.sqrt(np.mean(vo ** 2))
    assert fused.max() < vo.max()


def test_a_pose_found_on_the_map_is_counted_apart_and_never_as_the_cameras_refusal() -> None:
    fused = PoseFilter((0.0, 0.0, 0.0))
    fused.odometry(0.0, (0.0, 0.0, 0.0))
    fused.odometry(1.0, (1.0, 0.0, 0.0))
    tight = np.diag([1e-6, 1e-6, 1e-6])
    assert fused.locate(1.0, (1.04, 0.01, 0.0), tight)
    assert 1.0 < fused.pose[0] < 1.04 and fused.located == 1 and fused.updates == 0
    assert not fused.locate(1.0, (3.0, 2.0, 1.0), tight)  # another place: the gate refuses it
    assert fused.map_refused == 1 and fused.refused == fused.refused_in_a_row == 0


def _patrol_errors(seed: int, on_the_map: bool) -> tuple[float, float]:
    """The offline whole patrol (mission.py) fused as VisOdom fuses it: the simulator's wheel odometry,
    a camera odometry whose heading drifts (as VO's does facing plain walls) and, with ``on_the_map``,
    a scan every 5th wheel reading matched on the known map; the fused pose's final and largest
    position errors."""
    from tinman.scan_match import match_scan
    from tinman.scanner import beam_angles, cast

    rate, camera_every, latency = 50.0, 2, 2
    trace = simulate_mission(duration=70.0, rate=rate, dock=START[:2])
    truth, dt = trace.poses, 1.0 / rate
    wheels = WheelOdometry(START, seed=seed)
    fused = PoseFilter(START)
    fused.odometry(0.0, wheels.pose)
    noise = np.random.default_rng(seed)
    angles = beam_angles()
    drift = np.zeros(3)
    worst = 0.0
    for i in range(1, len(truth)):
        step = between(tuple(truth[i - 1]), tuple(truth[i]))
        wheels.step(math.copysign(math.hypot(step[0], step[1]), step[0]) / dt, step[2] / dt, dt)
        fused.odometry(i * dt, wheels.pose)
        worst = max(worst, math.hypot(fused.pose[0] - truth[i][0], fused.pose[1] - truth[i][1]))
        if on_the_map and i % 5 == 0:
            found = match_scan(DEFAULT_WORLD, fused.pose, cast(DEFAULT_WORLD, tuple(truth[i]), angles, noise), angles)
            if found is not None:
                fused.locate(i * dt, found.pose, found.covariance)
        if i % camera_every or i < latency:
            continue
        moved = math.hypot(step[0], step[1])
        drift += noise.normal(0.0, [0.002, 0.002, 0.001]) + np.array([0.0, 0.0, 0.02 * moved * camera_every])
        seen = truth[i - latency] + drift + noise.normal(0.0, [0.02, 0.02, 0.02])
        c, s = math.cos(drift[2]), math.sin(drift[2])  # a heading off turns the path travelled since the dock
        offset = truth[i - latency][:2] - np.array(START[:2])
        seen[:2] = np.array(START[:2]) + np.array([c * offset[0] - s * offset[1], s * offset[0] + c * offset[1]]) \
            + drift[:2]
        fused.measure((i - latency) * dt, (float(seen[0]), float(seen[1]), float(seen[2])))
    return math.hypot(fused.pose[0] - truth[-1][0], fused.pose[1] - truth[-1][1]), worst


@pytest.mark.parametrize("seed", [0, 1])
def test_matched_on_the_map_the_whole_patrols_error_is_bounded_whatever_vo_drifts(seed: int) -> None:
    final, worst = _patrol_errors(seed, on_the_map=True)
    assert final < 0.1 and worst < 0.1, (final, worst)
    _, unbounded = _patrol_errors(seed, on_the_map=False)
    assert unbounded > 0.1  # what the map bounds: VO's drift, which the wheels alone cannot refuse


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_a_reading_or_a_measurement_that_is_not_a_number_never_poisons_the_estimate(bad: float) -> None:
    """Wheel odometry and poses may come from the network (an external ROS node playing Gazebo):
    a NaN compares false with the gate, so it would have been taken."""
    estimate = PoseFilter((0.0, 0.0, 0.0))
    estimate.odometry(0.0, (0.0, 0.0, 0.0))
    estimate.odometry(0.1, (0.1, bad, 0.0))
    estimate.odometry(bad, (0.2, 0.0, 0.0))
    assert estimate.measure(0.1, (bad, 0.0, 0.0)) is False
    assert estimate.locate(0.1, (0.1, 0.0, bad), np.eye(3) * 1e-4) is False
    assert all(math.isfinite(v) for v in estimate.pose) and np.isfinite(estimate.covariance).all()
    estimate.odometry(0.2, (0.1, 0.0, 0.0))
    assert estimate.pose == pytest.approx((0.1, 0.0, 0.0))


def test_an_estimate_the_map_keeps_refusing_is_relocalised_on_the_map() -> None:
    """The camera's poses, each within the gate, can pull the estimate away from where the robot
    is; the map, whose matches then fall outside the gate, would be refused for good. Refused
    ``MAP_RELOCATE`` times in a row, the map's pose is taken as the estimate."""
    estimate = PoseFilter((0.0, 0.0, 0.0))
    estimate.odometry(0.0, (0.0, 0.0, 0.0))
    estimate.odometry(1.8, (0.0, 0.0, 0.0))
    estimate.pose = (0.0, 0.4, 0.0)  # where poses astray took it, sure of itself
    estimate.covariance = np.diag([1e-4, 1e-4, 1e-4])
    tight = np.eye(3) * 1e-4
    taken = [estimate.locate(1.8, (0.0, 0.0, 0.0), tight) for _ in range(MAP_RELOCATE)]
    assert taken == [False] * (MAP_RELOCATE - 1) + [True]
    assert estimate.relocated == 1 and estimate.map_refused == MAP_RELOCATE - 1
    assert estimate.pose == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    assert estimate.locate(1.8, (0.005, 0.0, 0.0), tight)  # from there, the map is taken as it comes
