"""DiffDrive: exact arc kinematics, speed and acceleration limits, bumps into walls and boxes."""

from __future__ import annotations

import math

import pytest
from budget import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from tinman.sim import DiffDrive, arc_pose
from tinman.world import DEFAULT_WORLD, Box, World

OPEN_ROOM = World(width=20.0, depth=20.0)


def free_robot(pose=(10.0, 10.0, 0.0), **limits) -> DiffDrive:
    """A robot without acceleration limits, so commands take effect at once."""
    limits.setdefault("max_linear_accel", math.inf)
    limits.setdefault("max_angular_accel", math.inf)
    return DiffDrive(OPEN_ROOM, pose, **limits)


def angle_difference(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


@given(v=st.floats(0.05, 0.5), theta=st.floats(-math.pi, math.pi), steps=st.integers(1, 300))
@settings(max_examples=examples(60), deadline=None)
def test_straight_line_covers_v_times_t(v, theta, steps):
    robot = free_robot((10.0, 10.0, theta))
    for _ in range(steps):
        robot.step(v, 0.0, 0.01)
    x, y, heading = robot.pose
    distance = v * steps * 0.01
    assert math.hypot(x - 10.0, y - 10.0) == pytest.approx(distance, abs=1e-9)
    assert (x - 10.0) == pytest.approx(distance * math.cos(theta), abs=1e-9)
    assert (y - 10.0) == pytest.approx(distance * math.sin(theta), abs=1e-9)
    assert angle_difference(heading, theta) < 1e-9
    assert robot.odometer == pytest.approx(distance)


@given(v=st.floats(0.05, 0.5), w=st.floats(0.5, 1.5).flatmap(lambda m: st.sampled_from([m, -m])),
       theta=st.floats(-math.pi, math.pi), dt=st.sampled_from([0.01, 0.03, 0.1]))
@settings(max_examples=examples(60), deadline=None)
def test_full_circle_returns_to_start_on_a_circle_of_radius_v_over_w(v, w, theta, dt):
    robot = free_robot((10.0, 10.0, theta))
    period = 2 * math.pi / abs(w)
    steps = int(period / dt)
    radius = v / abs(w)
    # The centre of the turn lies a radius to the left (w > 0) or right of the heading.
    side = 1.0 if w > 0 else -1.0
    centre = (10.0 - side * radius * math.sin(theta), 10.0 + side * radius * math.cos(theta))
    for _ in range(steps):
        x, y, _ = robot.step(v, w, dt)
        assert math.hypot(x - centre[0], y - centre[1]) == pytest.approx(radius, abs=1e-9)
    robot.step(v, w, period - steps * dt)
    x, y, heading = robot.pose
    assert math.hypot(x - 10.0, y - 10.0) < 1e-9
    assert angle_difference(heading, theta) < 1e-9
    assert robot.odometer == pytest.approx(2 * math.pi * radius)


def test_arc_integration_does_not_depend_on_the_step_size():
    one_step = arc_pose(1.0, 2.0, 0.3, 0.4, 0.8, 2.0)
    robot = free_robot((1.0, 2.0, 0.3))
    for _ in range(200):
        robot.step(0.4, 0.8, 0.01)
    assert robot.pose == pytest.approx(one_step, abs=1e-9)


def test_speeds_are_clamped_to_the_limits():
    robot = free_robot(max_linear=0.5, max_angular=1.5)
    robot.step(3.0, -9.0, 0.1)
    assert robot.velocity == (0.5, -1.5)
    robot.step(-3.0, 9.0, 0.1)
    assert robot.velocity == (-0.5, 1.5)
    assert robot.odometer == pytest.approx(0.1)


def test_accelerations_are_clamped():
    robot = DiffDrive(OPEN_ROOM, (10.0, 10.0, 0.0), max_linear_accel=1.0, max_angular_accel=2.0)
    speeds = [robot.step(0.5, 1.0, 0.1) and robot.velocity for _ in range(7)]
    assert [round(v, 9) for v, _ in speeds] == [0.1, 0.2, 0.3, 0.4, 0.5, 0.5, 0.5]
    assert [round(w, 9) for _, w in speeds] == [0.2, 0.4, 0.6, 0.8, 1.0, 1.0, 1.0]
    robot.step(0.0, 0.0, 0.1)
    assert robot.velocity == pytest.approx((0.4, 0.8))


def test_a_wall_stops_the_robot_and_counts_bumps():
    world = World(width=4.0, depth=4.0)
    robot = DiffDrive(world, (3.0, 2.0, 0.0), max_linear_accel=math.inf)
    for _ in range(200):
        robot.step(0.5, 0.0, 0.05)
    x, y, _ = robot.pose
    assert 3.7 < x < 4.0 - robot.radius
    assert not world.collides(x, y, robot.radius)
    assert robot.bumps >= 150
    assert robot.velocity == (0.0, 0.0)
    # Backing away is allowed.
    bumps = robot.bumps
    robot.step(-0.5, 0.0, 0.1)
    assert robot.pose[0] == pytest.approx(x - 0.05)
    assert robot.bumps == bumps


def test_a_box_stops_the_robot_and_turning_in_place_never_bumps():
    cabinet = DEFAULT_WORLD.boxes[0]
    robot = DiffDrive(DEFAULT_WORLD, (1.5, 3.0, 0.0), max_linear_accel=math.inf)
    for _ in range(100):
        robot.step(0.5, 0.0, 0.05)
    x, _, _ = robot.pose
    assert cabinet.x0 - robot.radius - 0.03 < x < cabinet.x0 - robot.radius
    assert robot.bumps > 0
    bumps = robot.bumps
    for _ in range(100):
        robot.step(0.0, 1.5, 0.05)
    assert robot.bumps == bumps


def test_one_long_step_cannot_jump_through_a_box():
    world = World(width=6.0, depth=3.0, boxes=(Box(3.0, 0.0, 3.05, 3.0, 1.0),))
    robot = DiffDrive(world, (1.0, 1.5, 0.0), max_linear_accel=math.inf)
    robot.step(0.5, 0.0, 8.0)
    assert robot.pose == (1.0, 1.5, 0.0)
    assert robot.bumps == 1


def test_a_colliding_start_or_a_bad_limit_is_refused():
    with pytest.raises(ValueError, match=r"^start pose \(0\.100, 1\.000\) collides with the world$"):
        DiffDrive(DEFAULT_WORLD, (0.1, 1.0, 0.0))
    with pytest.raises(ValueError, match="must be positive"):
        DiffDrive(DEFAULT_WORLD, max_linear=0.0)
    assert DiffDrive(DEFAULT_WORLD).pose == DEFAULT_WORLD.start
