"""Move's mixing: teleop wins when it commands anything, else pure pursuit on the latest path."""

from __future__ import annotations

import math

from tinman.messages import Header, Path, Time, path_through, twist_planar
from tinman.mixer import BRIDGE_GAP, BRIDGE_JUMP, BRIDGE_TURN, Mixer
from tinman.world import DEFAULT_WORLD

PERIOD = 0.02


def path_of(points: list[tuple[float, float]]) -> Path:
    return path_through(points, Header(stamp=Time(sec=0, nanosec=0), frame_id="map"))


def test_without_a_path_or_a_stick_the_robot_stays_put() -> None:
    mixer = Mixer(DEFAULT_WORLD, PERIOD, clock=lambda: 0.0)  # the estimate never goes stale here
    command, source = mixer.step(twist_planar(0.0, 0.0))
    assert (command, source) == (twist_planar(0.0, 0.0), "idle")
    assert mixer.model.pose == DEFAULT_WORLD.start


def test_the_robot_follows_the_latest_path_to_its_end() -> None:
    mixer = Mixer(DEFAULT_WORLD, PERIOD, clock=lambda: 0.0)  # the estimate never goes stale here
    x, y, _ = DEFAULT_WORLD.start
    mixer.set_path(path_of([(x, y), (x + 0.5, y + 2.0)]))  # superseded before it is used
    mixer.set_path(path_of([(x, y), (x + 1.5, y)]))
    for _ in range(int(20 / PERIOD)):
        command, source = mixer.step(twist_planar(0.0, 0.0))
    assert source == "idle" and command == twist_planar(0.0, 0.0)  # arrived: stopped
    assert math.dist(mixer.model.pose[:2], (x + 1.5, y)) < 0.2
    assert mixer.sources["path"] > 0 and mixer.paths_received == 2


def test_teleop_wins_over_the_path_while_it_commands_anything() -> None:
    mixer = Mixer(DEFAULT_WORLD, PERIOD, clock=lambda: 0.0)  # the estimate never goes stale here
    x, y, _ = DEFAULT_WORLD.start
    mixer.set_path(path_of([(x, y), (x + 2.0, y)]))
    command, source = mixer.step(twist_planar(0.0, 0.8))
    assert (command, source) == (twist_planar(0.0, 0.8), "teleop")
    command, source = mixer.step(twist_planar(0.0, 0.0))  # the stick is back in the centre: the path resumes
    assert source == "path" and command.linear.x >= 0.0
    assert mixer.sources == {"teleop": 1, "path": 1, "idle": 0, "lost": 0}


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_the_robot_steers_by_the_odometrys_estimate_and_stops_when_it_goes_stale() -> None:
    clock = Clock()
    mixer = Mixer(DEFAULT_WORLD, PERIOD, clock=clock)
    x, y, _ = DEFAULT_WORLD.start
    mixer.set_path(path_of([(x, y), (x + 3.0, y)]))
    assert mixer.step(twist_planar(0.0, 0.0))[1] == "path"
    # A fresh estimate puts the robot where the odometry says, whatever Move's model thought.
    mixer.set_estimate(1.0, (x + 0.5, y + 0.1, 0.0))
    assert mixer.model.pose[:2] == (x + 0.5, y + 0.1) and mixer.estimates == 1
    # The same stamp again (VisOdom lost track and repeats its last estimate) is no news: after
    # LOST_AFTER seconds without a fresh one, path following stops the robot, once counted.
    for _ in range(10):
        clock.now += 0.1
        mixer.set_estimate(1.0, (x + 0.5, y + 0.1, 0.0))
        command, source = mixer.step(twist_planar(0.0, 0.0))
    assert (command, source) == (twist_planar(0.0, 0.0), "lost") and mixer.stops == 1
    # A person at the stick still drives.
    assert mixer.step(twist_planar(0.2, 0.0))[1] == "teleop"
    # Tracking is back: the robot drives on.
    mixer.set_estimate(2.0, (x + 0.6, y + 0.1, 0.0))
    command, source = mixer.step(twist_planar(0.0, 0.0))
    assert source == "path" and command.linear.x > 0 and mixer.resumed == 1 and mixer.stops == 1


def test_after_a_gap_in_the_odometry_the_drive_model_bridges_it_and_the_odometry_is_read_relative() -> None:
    clock = Clock()
    mixer = Mixer(DEFAULT_WORLD, PERIOD, clock=clock)
    x, y, _ = DEFAULT_WORLD.start
    mixer.set_estimate(1.0, (x, y, 0.0))
    for _ in range(10):  # the robot turns on the spot for 0.2 s: 0.1 rad by its commands
        mixer.step(twist_planar(0.0, 0.5))
    turned = mixer.model.pose
    # The odometry lost track meanwhile and restarted from its last pose: its next estimate, after
    # a gap, says the robot never turned. Move keeps what its commands did ...
    mixer.set_estimate(1.0 + 5 * BRIDGE_GAP, (x, y, 0.0))
    assert mixer.model.pose == turned and mixer.bridged == 1
    # ... and reads the odometry's later estimates in its own frame: 0.1 m ahead in the odometry's
    # frame is 0.1 m along the turned heading.
    mixer.set_estimate(1.0 + 5 * BRIDGE_GAP + 0.033, (x + 0.1, y, 0.0))
    bx, by, btheta = mixer.model.pose
    assert math.isclose(bx, turned[0] + 0.1 * math.cos(turned[2]), abs_tol=1e-9)
    assert math.isclose(by, turned[1] + 0.1 * math.sin(turned[2]), abs_tol=1e-9)
    assert math.isclose(btheta, turned[2], abs_tol=1e-9) and mixer.bridged == 1


def test_an_estimate_that_jumps_from_where_the_commands_took_the_robot_is_a_false_fix() -> None:
    mixer = Mixer(DEFAULT_WORLD, PERIOD, clock=lambda: 0.0)
    x, y, _ = DEFAULT_WORLD.start
    mixer.set_estimate(1.0, (x, y, 0.0))
    mixer.set_estimate(1.033, (x + 0.01, y, 0.01))  # close to where the robot is: taken as it is
    assert mixer.model.pose == (x + 0.01, y, 0.01) and mixer.bridged == 0
    mixer.set_estimate(1.066, (x + 0.01 + 2 * BRIDGE_JUMP, y, 0.01))  # a step no robot makes in 33 ms
    assert mixer.model.pose == (x + 0.01, y, 0.01) and mixer.bridged == 1
    mixer.set_estimate(1.1, (x + 0.01, y, 0.01 + 2 * BRIDGE_TURN))  # nor such a turn
    assert mixer.bridged == 2


def test_path_following_drives_no_further_toward_a_box_it_believes_it_is_about_to_hit() -> None:
    # A path from a drifted odometry pose can lead the robot (by Move's own pose) straight at a
    # box: the cabinet's west face is at x = 2.6; the robot stands 0.3 m from it, facing it.
    mixer = Mixer(DEFAULT_WORLD, PERIOD, clock=lambda: 0.0)
    mixer.set_estimate(1.0, (2.6 - 0.3, 3.0, 0.0))
    mixer.set_path(path_of([(2.3, 3.0), (3.0, 3.0)]))
    command, source = mixer.step(twist_planar(0.0, 0.0))
    assert source == "path" and command.linear.x == 0.0 and mixer.held_back == 1
    # Far from anything, the same path ahead is driven.
    free = Mixer(DEFAULT_WORLD, PERIOD, clock=lambda: 0.0)
    free.set_estimate(1.0, (1.0, 1.0, 0.0))
    free.set_path(path_of([(1.0, 1.0), (2.0, 1.0)]))
    command, _ = free.step(twist_planar(0.0, 0.0))
    assert command.linear.x > 0.0 and free.held_back == 0
