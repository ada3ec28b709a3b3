"""Pure pursuit: arcs toward the lookahead point, turning in place, slowing down, arriving."""

from __future__ import annotations

import itertools
import math

import pytest
from budget import examples
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tinman.pursuit import PurePursuit
from tinman.sim import DiffDrive
from tinman.world import World

OPEN_ROOM = World(width=20.0, depth=20.0)


def distance_to_path(x: float, y: float, path) -> float:
    best = math.inf
    for (ax, ay), (bx, by) in itertools.pairwise(path):
        span = math.hypot(bx - ax, by - ay)
        ux, uy = ((bx - ax) / span, (by - ay) / span) if span > 0 else (0.0, 0.0)
        along = max(0.0, min(span, (x - ax) * ux + (y - ay) * uy))
        best = min(best, math.hypot(ax + along * ux - x, ay + along * uy - y))
    return best


def drive(pursuit: PurePursuit, path, pose, seconds: float = 60.0, rate: float = 50.0):
    """Follow the path in the simulator; the poses visited, until arrival or timeout."""
    robot = DiffDrive(OPEN_ROOM, pose)
    poses = [robot.pose]
    for _ in range(int(seconds * rate)):
        if pursuit.at_goal(robot.pose, path):
            break
        v, w = pursuit.command(robot.pose, path)
        poses.append(robot.step(v, w, 1.0 / rate))
    return robot, poses


def test_follows_an_l_shaped_path_to_its_end():
    path = [(5.0, 5.0), (9.0, 5.0), (9.0, 8.0)]
    pursuit = PurePursuit()
    robot, poses = drive(pursuit, path, (5.0, 5.0, 0.0))
    assert pursuit.at_goal(robot.pose, path)
    assert pursuit.command(robot.pose, path) == (0.0, 0.0)
    assert robot.bumps == 0
    # Corner cutting stays within the lookahead's reach of the path.
    assert max(distance_to_path(x, y, path) for x, y, _ in poses) < 0.25
    # About the path's length (less the corner cut and the goal tolerance), at about cruising speed.
    assert 6.6 <= robot.odometer <= 7.0
    assert len(poses) / 50.0 < 7.0 / 0.35 + 4.0


def test_a_target_behind_is_faced_by_turning_in_place():
    pursuit = PurePursuit(max_angular=1.5)
    v, w = pursuit.command((5.0, 5.0, 0.0), [(5.0, 5.0), (3.0, 5.5)])
    assert v == 0.0 and w == 1.5           # behind and a little to the left: turn left, fast
    v, w = pursuit.command((5.0, 5.0, 0.0), [(5.0, 5.0), (4.0, 3.0)])
    assert v == 0.0 and w == -1.5
    # 63 degrees to the left: past the 60 degree limit; the turn rate is the gain times the angle.
    v, w = PurePursuit(max_angular=3.0, turn_gain=2.0).command((5.0, 5.0, 0.0), [(5.0, 5.0), (5.3, 5.6)])
    assert v == 0.0 and w == pytest.approx(2.0 * math.atan2(0.6, 0.3))
    # 57 degrees: an arc instead.
    v, w = pursuit.command((5.0, 5.0, 0.0), [(5.0, 5.0), (5.3, 5.46)])
    assert v > 0.0 and w > 0.0


def test_a_target_ahead_gives_the_arc_through_it():
    pursuit = PurePursuit(lookahead=0.5, speed=0.35)
    assert pursuit.command((0.0, 0.0, 0.0), [(0.0, 0.0), (5.0, 0.0)]) == (0.35, 0.0)
    # Robot a little right of a path along +x: the target is 0.5 ahead, 0.1 to the left.
    v, w = pursuit.command((1.0, -0.1, 0.0), [(0.0, 0.0), (5.0, 0.0)])
    assert v == 0.35
    assert w == pytest.approx(0.35 * 2 * 0.1 / (0.5 ** 2 + 0.1 ** 2))
    v, w = pursuit.command((1.0, 0.1, 0.0), [(0.0, 0.0), (5.0, 0.0)])
    assert w < 0


def test_slows_down_near_the_goal_and_stops_there():
    pursuit = PurePursuit(speed=0.4, slowdown_distance=0.5, goal_tolerance=0.15)
    path = [(0.0, 0.0), (3.0, 0.0)]
    assert pursuit.command((2.0, 0.0, 0.0), path)[0] == 0.4
    assert pursuit.command((2.75, 0.0, 0.0), path)[0] == pytest.approx(0.2)
    assert pursuit.command((2.84, 0.0, 0.0), path)[0] == pytest.approx(0.4 * 0.16 / 0.5)
    assert pursuit.command((2.9, 0.0, 0.0), path) == (0.0, 0.0)
    assert pursuit.command((1.0, 1.0, 0.0), []) == (0.0, 0.0)


def test_a_tight_arc_is_driven_slower_not_left():
    pursuit = PurePursuit(lookahead=0.3, speed=0.35, max_angular=0.5)
    v, w = pursuit.command((0.0, 0.0, 0.0), [(0.0, 0.0), (0.2, 0.2), (0.2, 5.0)])
    assert w == 0.5
    assert 0 < v < 0.35


def test_the_target_is_the_lookahead_along_the_path_past_the_nearest_point():
    pursuit = PurePursuit(lookahead=0.5)
    path = [(0.0, 0.0), (1.0, 0.0), (1.0, 2.0)]
    assert pursuit.target((0.2, 0.3, 0.0), path) == pytest.approx((0.7, 0.0))
    assert pursuit.target((0.8, -0.1, 0.0), path) == pytest.approx((1.0, 0.3))
    assert pursuit.target((1.0, 1.9, 0.0), path) == pytest.approx((1.0, 2.0))
    assert pursuit.target((3.0, 3.0, 0.0), [(1.0, 1.0)]) == (1.0, 1.0)
    with pytest.raises(ValueError, match="empty path"):
        pursuit.target((0.0, 0.0, 0.0), [])


def test_segments_too_short_to_square_are_followed_like_any_other():
    # 2.3e-281 ** 2 underflows to 0.0: the nearest point is found without dividing by it.
    tiny = [(0.0, 0.0), (0.0, 2.3e-281)]
    assert PurePursuit().target((1.0, 0.0, 0.0), tiny) == (0.0, 2.3e-281)
    assert PurePursuit(max_angular=1.5).command((1.0, 0.0, 0.0), tiny) == (0.0, 1.5)  # behind: turn
    # Within a longer path, a tiny (or empty) step counts as its length and no more.
    for step in (2.3e-281, 1e-200, 5e-324, 0.0):
        path = [(0.0, 0.0), (1.0, 0.0), (1.0, step), (1.0, 2.0)]
        pursuit = PurePursuit(lookahead=0.5)
        assert pursuit.target((0.8, 0.1, 0.0), path) == pytest.approx((1.0, 0.3))
        assert pursuit.target((1.1, 0.9, 0.0), path) == pytest.approx((1.0, 1.4))
        v, w = pursuit.command((1.1, 0.9, math.pi / 2), path)
        assert v == 0.35 and math.isfinite(w)


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="must be positive"):
        PurePursuit(lookahead=0.0)


poses = st.tuples(st.floats(0.0, 10.0), st.floats(0.0, 10.0), st.floats(-math.pi, math.pi))
paths = st.lists(st.tuples(st.floats(0.0, 10.0), st.floats(0.0, 10.0)), min_size=1, max_size=6)


@given(pose=poses, path=paths, max_angular=st.floats(0.3, 2.0), speed=st.floats(0.1, 0.6))
# A segment whose squared length underflows to 0 once divided the projection by zero.
@example(pose=(1.0, 0.0, 0.0), path=[(0.0, 0.0), (0.0, 2.3e-281)], max_angular=1.5, speed=0.35)
def test_commands_stay_within_the_limits_and_never_reverse(pose, path, max_angular, speed):
    pursuit = PurePursuit(speed=speed, max_angular=max_angular)
    v, w = pursuit.command(pose, path)
    assert 0.0 <= v <= speed
    assert abs(w) <= max_angular + 1e-12
    assert (v, w) != (0.0, 0.0) or pursuit.at_goal(pose, path)


@given(pose=poses, path=paths)
@example(pose=(1.0, 0.0, 0.0), path=[(0.0, 0.0), (0.0, 2.3e-281), (1.0, 1e-300), (1.0, 1e-300)])
def test_the_target_lies_on_the_path(pose, path):
    target = PurePursuit().target(pose, path)
    if len(path) == 1:
        assert target == path[0]
    else:
        assert distance_to_path(*target, path) < 1e-9


@given(start=poses, path=st.lists(st.tuples(st.floats(3.0, 17.0), st.floats(3.0, 17.0)), min_size=2, max_size=5))
@settings(max_examples=examples(25), deadline=None)
def test_any_path_is_followed_to_its_end(start, path):
    pursuit = PurePursuit()
    robot, _ = drive(pursuit, path, (path[0][0], path[0][1], start[2]), seconds=200.0, rate=20.0)
    assert pursuit.at_goal(robot.pose, path)


def test_a_path_that_turns_back_on_itself_is_followed_in_order():
    # Down to (5, 3) first, then back up past the start to (5, 7).
    path = [(5.0, 5.0), (5.0, 3.0), (5.0, 7.0)]
    pursuit = PurePursuit()
    robot, poses = drive(pursuit, path, (5.0, 5.0, -math.pi / 2))
    assert pursuit.at_goal(robot.pose, path)
    assert min(y for _, y, _ in poses) < 3.3
    assert robot.odometer > 5.5


def test_progress_along_a_path_only_goes_forward_and_a_new_path_starts_over():
    pursuit = PurePursuit(lookahead=0.5)
    hairpin = [(0.0, 0.0), (4.0, 0.0), (4.0, 1.0), (0.0, 1.0)]
    assert pursuit.target((0.5, 0.2, 0.0), hairpin) == pytest.approx((1.0, 0.0))
    assert pursuit.target((3.0, 0.1, 0.0), hairpin) == pytest.approx((3.5, 0.0))
    # Back near the start, which is nearest; the path's next stretch within reach is the way on.
    assert pursuit.target((0.3, 0.9, 0.0), hairpin) == pytest.approx((2.5, 1.0))
    # A controller without that history starts from the beginning.
    assert PurePursuit(lookahead=0.5).target((0.3, 0.9, 0.0), hairpin) == pytest.approx((0.8, 0.0))
    other = [(0.0, 0.5), (4.0, 0.5)]
    assert pursuit.target((1.0, 0.5, 0.0), other) == pytest.approx((1.5, 0.5))
    assert pursuit.target((0.3, 0.9, 0.0), hairpin) == pytest.approx((0.8, 0.0))
    pursuit.target((3.0, 0.1, 0.0), hairpin)
    pursuit.reset()
    assert pursuit.target((0.3, 0.1, 0.0), hairpin) == pytest.approx((0.8, 0.0))
