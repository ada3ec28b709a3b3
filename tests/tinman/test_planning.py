"""Planners: collision-free paths between the right ends (RRT-Connect and A*), errors, the patrol."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from budget import examples
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from tinman.planning import NoPathError, Patrol, Planner, plan_astar, plan_rrt_connect, shortcut, simplify
from tinman.world import CLEARANCE, DEFAULT_WORLD, ROBOT_RADIUS, Box, World

PLANNERS = {method: Planner(DEFAULT_WORLD, method, seed=1) for method in ("rrt", "astar")}
GRID = PLANNERS["rrt"].grid


def length(path) -> float:
    return float(sum(math.dist(a, b) for a, b in itertools.pairwise(path)))


def assert_path_is_safe(world: World, grid, path, start, goal) -> None:
    assert path[0] == tuple(start) and path[-1] == tuple(goal)
    for a, b in itertools.pairwise(path):
        assert grid.segment_free(a, b), (a, b)
        # Finer than the grid check: the robot's disc along the whole segment.
        for t in np.linspace(0.0, 1.0, max(2, int(math.dist(a, b) / 0.01) + 1)):
            x, y = a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t
            assert not world.collides(x, y, ROBOT_RADIUS), (x, y)


def free_points(world: World, grid):
    point = st.tuples(st.floats(0.0, world.width), st.floats(0.0, world.depth))
    return point.filter(lambda p: grid.free(*p))


@given(start=free_points(DEFAULT_WORLD, GRID), goal=free_points(DEFAULT_WORLD, GRID),
       method=st.sampled_from(["rrt", "astar"]))
@settings(max_examples=examples(60), deadline=None)
def test_paths_in_the_default_world_are_collision_free_and_join_the_ends(start, goal, method):
    path = PLANNERS[method].plan(start, goal)
    assert_path_is_safe(DEFAULT_WORLD, GRID, path, start, goal)


@st.composite
def worlds(draw) -> World:
    width, depth = draw(st.floats(3.0, 6.0)), draw(st.floats(3.0, 5.0))
    boxes = []
    for _ in range(draw(st.integers(0, 4))):
        x0, y0 = draw(st.floats(0.0, width - 0.2)), draw(st.floats(0.0, depth - 0.2))
        x1, y1 = draw(st.floats(x0 + 0.1, min(width, x0 + 2.0))), draw(st.floats(y0 + 0.1, min(depth, y0 + 2.0)))
        boxes.append(Box(x0, y0, x1, y1, 1.0))
    return World(width=width, depth=depth, boxes=tuple(boxes))


@pytest.mark.slow  # builds two planners (and A*'s cell graph) per random world
@given(world=worlds(), data=st.data(), seed=st.integers(0, 2**32 - 1))
@settings(max_examples=examples(30), deadline=None,
          suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow])
def test_paths_in_random_worlds_are_safe_and_both_methods_agree_on_reachability(world, data, seed):
    rrt, astar = Planner(world, "rrt", seed=seed), Planner(world, "astar")
    assume(rrt.grid.occupied.mean() < 0.9)
    start = data.draw(free_points(world, rrt.grid), label="start")
    goal = data.draw(free_points(world, rrt.grid), label="goal")
    failures: list[str | None] = []  # each planner's NoPathError reason, None when it found a path
    for planner in (rrt, astar):
        try:
            path = planner.plan(start, goal)
        except NoPathError as error:
            failures.append(error.reason)
        else:
            assert_path_is_safe(world, planner.grid, path, start, goal)
            failures.append(None)
    assert set(failures) <= {None, "the goal is unreachable"}
    assert failures[0] == failures[1]


@pytest.mark.parametrize("method", ["rrt", "astar"])
def test_a_goal_inside_a_box_has_no_path(method):
    with pytest.raises(NoPathError, match=r"^no path from \(1\.00, 1\.00\) to \(3\.00, 3\.00\): "
                                          r"the goal is not free$") as caught:
        PLANNERS[method].plan((1.0, 1.0), (3.0, 3.0))
    assert (caught.value.start, caught.value.goal) == ((1.0, 1.0), (3.0, 3.0))


@pytest.mark.parametrize("method", ["rrt", "astar"])
def test_a_walled_off_goal_is_unreachable(method):
    world = World(width=6.0, depth=4.0, boxes=(Box(2.9, 0.0, 3.1, 4.0, 2.0),))
    with pytest.raises(NoPathError, match=r"^no path from \(1\.00, 2\.00\) to \(5\.00, 2\.00\): "
                                          r"the goal is unreachable$"):
        Planner(world, method).plan((1.0, 2.0), (5.0, 2.0))


def test_the_bare_planners_give_up_with_an_error():
    world = World(width=6.0, depth=4.0, boxes=(Box(2.9, 0.0, 3.1, 4.0, 2.0),))
    grid = world.occupancy()
    with pytest.raises(NoPathError, match=r"RRT-Connect found none in 200 iterations$"):
        plan_rrt_connect(grid, (1.0, 2.0), (5.0, 2.0), np.random.default_rng(0), max_iterations=200)
    with pytest.raises(NoPathError, match=r"the goal is unreachable$"):
        plan_astar(grid, (1.0, 2.0), (5.0, 2.0))
    with pytest.raises(NoPathError, match=r"the start is not free$"):
        plan_astar(grid, (3.0, 2.0), (5.0, 2.0))


@pytest.mark.parametrize("method", ["rrt", "astar"])
def test_a_start_against_the_wall_goes_to_the_nearest_free_cell_first(method):
    start = (ROBOT_RADIUS + 0.01, 3.0)             # touching distance: inside the grid's margin
    assert not GRID.free(*start) and not DEFAULT_WORLD.collides(*start)
    path = PLANNERS[method].plan(start, (7.0, 3.0))
    assert path[0] == start
    assert math.dist(path[0], path[1]) < CLEARANCE - ROBOT_RADIUS + 0.05  # out of the margin, to a cell centre
    assert_path_is_safe(DEFAULT_WORLD, GRID, path[1:], path[1], (7.0, 3.0))


def test_a_start_deep_inside_a_box_has_no_path():
    with pytest.raises(NoPathError, match=r"^no path from \(3\.00, 3\.00\) to \(1\.00, 1\.00\): "
                                          r"the start is not free$"):
        PLANNERS["rrt"].plan((3.0, 3.0), (1.0, 1.0))


def test_in_open_floor_the_path_is_the_straight_line():
    for planner in PLANNERS.values():
        assert planner.plan((1.0, 1.0), (4.0, 1.5)) == [(1.0, 1.0), (4.0, 1.5)]
        assert planner.plan((1.0, 1.0), (1.0, 1.0)) == [(1.0, 1.0), (1.0, 1.0)]


def test_astar_goes_round_a_box_nearly_as_short_as_possible():
    world = World(width=6.0, depth=6.0, boxes=(Box(2.6, 2.2, 3.4, 3.8, 1.0),))
    planner = Planner(world, "astar")
    path = planner.plan((1.0, 3.0), (5.0, 3.0))
    # The grid grows the box by a square margin: round its corners (2.22, 1.82) and (3.78, 1.82),
    # or the mirror image above.
    margin = CLEARANCE
    corner = 3.0 - (2.2 - margin)
    optimal = 2 * math.hypot(1.0 + 0.6 - margin, corner) + (0.8 + 2 * margin)
    assert optimal - 0.05 <= length(path) <= optimal * 1.03


def test_planners_are_deterministic():
    queries = [((0.6, 0.6), (7.4, 5.4)), ((6.9, 2.9), (1.2, 4.6)), ((4.2, 5.1), (4.3, 1.1))]
    for method in ("rrt", "astar"):
        first, second = Planner(DEFAULT_WORLD, method, seed=5), Planner(DEFAULT_WORLD, method, seed=5)
        assert [first.plan(*q) for q in queries] == [second.plan(*q) for q in queries]
    other = Planner(DEFAULT_WORLD, "rrt", seed=6)
    assert [other.plan(*q) for q in queries] != [Planner(DEFAULT_WORLD, "rrt", seed=5).plan(*q) for q in queries]


@given(start=free_points(DEFAULT_WORLD, GRID), goal=free_points(DEFAULT_WORLD, GRID), seed=st.integers(0, 1000))
@settings(max_examples=examples(30), deadline=None)
def test_smoothing_keeps_the_ends_and_never_lengthens(start, goal, seed):
    rng = np.random.default_rng(seed)
    raw = plan_rrt_connect(GRID, start, goal, rng, step=0.2)
    smooth = shortcut(GRID, raw, rng, iterations=50)
    assert length(smooth) <= length(raw) + 1e-9
    assert_path_is_safe(DEFAULT_WORLD, GRID, smooth, start, goal)
    simple = simplify(GRID, smooth)
    assert length(simple) <= length(smooth) + 1e-9
    assert all(point in smooth for point in simple)
    assert_path_is_safe(DEFAULT_WORLD, GRID, simple, start, goal)


def test_an_unknown_method_is_refused():
    with pytest.raises(ValueError, match=r"^unknown planning method 'dijkstra'; expected 'rrt' or 'astar'$"):
        Planner(DEFAULT_WORLD, "dijkstra")


def test_patrol_advances_within_tolerance_and_loops():
    patrol = Patrol(DEFAULT_WORLD, tolerance=0.3)
    first, second = DEFAULT_WORLD.waypoints[0], DEFAULT_WORLD.waypoints[1]
    assert patrol.goal_for(1.0, 1.0) == first
    assert patrol.goal_for(first[0] - 0.31, first[1]) == first
    assert patrol.goal_for(first[0] - 0.29, first[1]) == second
    assert patrol.goal_for(*first) == second          # one waypoint per call
    assert patrol.reached == 1
    for waypoint in DEFAULT_WORLD.waypoints[1:]:
        patrol.goal_for(*waypoint)
    assert patrol.index == 0 and patrol.reached == len(DEFAULT_WORLD.waypoints)
    assert patrol.goal_for(0.0, 0.0) == first


def test_patrol_needs_waypoints():
    with pytest.raises(ValueError, match="no waypoints"):
        Patrol(World())
