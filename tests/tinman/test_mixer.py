"""Move's mixing: teleop wins when it commands anything, else pure pursuit on the latest path."""

from __future__ import annotations

import math

import numpy as np

from tinman.messages import Header, LaserScan, Path, Time, path_through, twist_planar
from tinman.mixer import Mixer
from tinman.safety import STALE_SCAN
from tinman.scanner import beam_angles, cast, scan_message
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


def open_scan() -> LaserScan:
    """A noiseless scan from the dock, where the way ahead (east) is clear."""
    ranges = cast(DEFAULT_WORLD, DEFAULT_WORLD.start, beam_angles(), np.random.default_rng(0))
    return scan_message(ranges, Header(stamp=Time(sec=0, nanosec=0), frame_id="base_scan"), PERIOD)


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


def test_move_takes_the_one_fused_pose_as_it_is_and_keeps_no_estimate_of_its_own() -> None:
    """Issue 28 item 2: no bridged estimate beside the fused one. A pose that jumps from where
    Move's commands took the robot (the estimator corrected it) is where the robot is."""
    mixer = Mixer(DEFAULT_WORLD, PERIOD, clock=lambda: 0.0)
    x, y, _ = DEFAULT_WORLD.start
    mixer.set_estimate(1.0, (x, y, 0.0))
    for _ in range(10):  # Move's commands carry its model forward between two estimates ...
        mixer.step(twist_planar(0.0, 0.5))
    assert mixer.model.pose != (x, y, 0.0)
    mixer.set_estimate(1.2, (x + 0.3, y, 0.2))  # ... and the next fused pose replaces it, however far
    assert mixer.model.pose == (x + 0.3, y, 0.2)
    assert not hasattr(mixer, "offset") and not hasattr(mixer, "bridged")


def test_while_the_pose_is_the_wheels_alone_path_following_drives_slower() -> None:
    x, y, _ = DEFAULT_WORLD.start
    speeds = []
    for wheels_only in (False, True):
        mixer = Mixer(DEFAULT_WORLD, PERIOD, clock=lambda: 0.0)
        mixer.set_path(path_of([(x, y), (x + 3.0, y)]))
        mixer.set_estimate(1.0, (x, y, 0.0), wheels_only=wheels_only)
        command, source = mixer.step(twist_planar(0.0, 0.0))
        assert source == "path"
        speeds.append(command.linear.x)
        assert mixer.recovering == int(wheels_only)
        mixer.set_estimate(1.1, (x, y, 0.0))  # the camera tracks again: full speed
        assert mixer.step(twist_planar(0.0, 0.0))[0].linear.x == speeds[0]
        assert mixer.recovered == int(wheels_only)  # a path command after recovering
    assert 0 < speeds[1] < speeds[0]


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


def test_by_a_pose_deadline_s_timeout_path_following_has_stopped_and_the_timeout_is_counted() -> None:
    """The protocol's ``VisOdom -> Move : Pose within 500ms else timeout`` is the mixer's
    ``LOST_AFTER``: when the estimates thread takes the timeout (500 ms after its last pose, fresh
    or not), the mixer has stopped path following by its own clock, and counts the timeout."""
    clock = Clock()
    mixer = Mixer(DEFAULT_WORLD, PERIOD, clock=clock)
    x, y, theta = DEFAULT_WORLD.start
    mixer.set_path(path_of([(x, y), (x + 3.0, y)]))
    mixer.set_estimate(0.0, (x, y, theta))
    assert mixer.step(twist_planar(0.0, 0.0))[1] == "path"
    clock.now = 0.3
    mixer.set_estimate(0.0, (x, y, theta))  # a repeated stamp: a pose, but no news
    clock.now = 0.8 + 1e-6  # the deadline from that pose: the timeout
    mixer.estimate_timed_out()
    assert mixer.step(twist_planar(0.0, 0.0)) == (twist_planar(0.0, 0.0), "lost")
    assert (mixer.estimate_timeouts, mixer.stops) == (1, 1)
    mixer.set_estimate(0.9, (x, y, theta))
    assert mixer.step(twist_planar(0.0, 0.0))[1] == "path"


def test_by_a_scan_deadline_s_timeout_the_safety_layer_is_blind_and_the_timeout_is_counted() -> None:
    """``Gazebo -> Move : LaserScan within 250ms else timeout`` is the safety layer's ``STALE_SCAN``:
    at the timeout a forward command is held (the robot may turn), until the next scan."""
    clock = Clock()
    mixer = Mixer(DEFAULT_WORLD, PERIOD, clock=clock, scanned=True)
    mixer.set_scan(open_scan())
    assert mixer.step(twist_planar(0.2, 0.0))[0] == twist_planar(0.2, 0.0)
    clock.now = STALE_SCAN + 1e-6
    mixer.scan_timed_out()
    assert mixer.step(twist_planar(0.2, 0.3))[0] == twist_planar(0.0, 0.3)
    assert (mixer.scan_timeouts, mixer.safety.blind) == (1, 1)
    mixer.set_scan(open_scan())
    assert mixer.step(twist_planar(0.2, 0.0))[0] == twist_planar(0.2, 0.0)
