"""The offline patrol: deterministic, collision-free, moving, teleop exactly in the script's windows."""

from __future__ import annotations

import itertools
import math
from functools import cache

import numpy as np
import pytest
from budget import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from tinman.joystick import JOY_SCRIPT
from tinman.mission import MAX_TURN_RATE, MissionTrace, simulate_mission
from tinman.planning import Planner
from tinman.world import DEFAULT_WORLD, ROBOT_RADIUS


@cache
def mission(method: str = "rrt", seed: int = 0, duration: float = 30.0) -> MissionTrace:
    return simulate_mission(DEFAULT_WORLD, duration=duration, rate=100.0, method=method, seed=seed)


def turn_rates(trace: MissionTrace) -> np.ndarray:
    return np.diff(np.unwrap(trace.poses[:, 2])) / np.diff(trace.stamps)


def assert_collision_free(trace: MissionTrace) -> None:
    assert trace.bumps == 0
    assert not any(DEFAULT_WORLD.collides(x, y, ROBOT_RADIUS) for x, y, _ in trace.poses)
    # Steps are short (a centimetre at most), so no obstacle hides between two stamps.
    assert np.hypot(*np.diff(trace.poses[:, :2], axis=0).T).max() <= 0.5 * np.diff(trace.stamps).max() + 1e-12


def test_the_trace_has_one_entry_per_step():
    trace = mission()
    assert trace.stamps.shape == (3001,) and trace.poses.shape == (3001, 3) and trace.teleop.shape == (3001,)
    assert trace.stamps[0] == 0.0 and trace.stamps[-1] == pytest.approx(30.0)
    assert np.allclose(np.diff(trace.stamps), 0.01)
    assert tuple(trace.poses[0]) == DEFAULT_WORLD.start


def test_the_mission_is_deterministic():
    first, second = mission(), simulate_mission(DEFAULT_WORLD, duration=30.0, rate=100.0, method="rrt", seed=0)
    assert np.array_equal(first.poses, second.poses)
    assert np.array_equal(first.teleop, second.teleop)
    assert first.plans == second.plans


@pytest.mark.parametrize("method", ["rrt", "astar"])
def test_the_default_mission_is_collision_free_and_keeps_moving(method):
    trace = mission(method)
    assert_collision_free(trace)
    assert trace.planning_failures == []
    assert 0.28 <= trace.odometer / 30.0 <= 0.45               # about 0.3 m/s on average
    assert trace.waypoints_reached >= 3
    speeds = np.hypot(*np.diff(trace.poses[:, :2], axis=0).T) / 0.01
    assert np.mean(speeds < 0.02) < 0.15                        # standing still (turning) rarely
    # Gentle turns for the camera: never faster than the patrol's limit.
    assert np.abs(turn_rates(trace)).max() <= MAX_TURN_RATE + 1e-9


def test_teleop_drives_exactly_in_the_script_windows():
    trace = mission()
    in_window = np.zeros_like(trace.teleop)
    for start, end, _, _ in JOY_SCRIPT:
        in_window |= (trace.stamps >= start - 1e-9) & (trace.stamps < end - 1e-9)
    assert np.array_equal(trace.teleop[:-1], in_window[:-1])
    # In the second window the stick turns the robot on the spot.
    # (After half a second: the robot needs 0.4 s to brake from cruising speed.)
    second = (trace.stamps > JOY_SCRIPT[1][0] + 0.5) & (trace.stamps < JOY_SCRIPT[1][1])
    assert np.ptp(trace.poses[second, 0]) < 1e-9 and np.ptp(trace.poses[second, 1]) < 1e-9
    assert np.all(turn_rates(trace)[second[1:]] > 0.5)


def test_without_a_script_the_planner_drives_all_the_time():
    trace = simulate_mission(duration=5.0, script=())
    assert not trace.teleop.any()
    assert trace.odometer > 1.5


def test_plans_start_at_the_robot_end_at_a_waypoint_and_avoid_obstacles():
    trace = mission()
    grid = Planner(DEFAULT_WORLD).grid
    times = [t for t, _ in trace.plans]
    assert times == pytest.approx(list(np.arange(0.0, 30.0, 0.5)))
    for t, path in trace.plans:
        step = round(t * 100)
        assert path[0] == pytest.approx(tuple(trace.poses[step, :2]))
        assert path[-1] in DEFAULT_WORLD.waypoints
        # From the first free point on: a robot against a wall starts inside the grid's margin.
        assert all(grid.segment_free(a, b) for a, b in itertools.pairwise(path[1:]))
    goals = [path[-1] for _, path in trace.plans]
    assert goals[0] == DEFAULT_WORLD.waypoints[0]
    assert len(set(goals)) == trace.waypoints_reached + 1


@pytest.mark.slow  # two 8 s missions per example
@given(method=st.sampled_from(["rrt", "astar"]), seed=st.integers(0, 10_000))
@settings(max_examples=examples(8), deadline=None)
def test_short_missions_are_collision_free_and_repeatable_for_any_seed(method, seed):
    trace = simulate_mission(duration=8.0, rate=50.0, method=method, seed=seed)
    assert_collision_free(trace)
    assert trace.planning_failures == []
    again = simulate_mission(duration=8.0, rate=50.0, method=method, seed=seed)
    assert np.array_equal(trace.poses, again.poses)


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="must be positive"):
        simulate_mission(duration=0.0)
    with pytest.raises(ValueError, match="unknown planning method"):
        simulate_mission(duration=1.0, method="bfs")
    assert math.isclose(simulate_mission(duration=0.5, rate=10.0).stamps[-1], 0.5)
