"""The world's real-time factor in TinMan's report: the seconds the simulator's physics
stepped against the wall seconds it ran, and the camera frames it rendered against those due."""

from __future__ import annotations

from tinman.outcome import world_clock, world_clock_line


def test_the_factor_is_simulated_seconds_over_wall_seconds() -> None:
    world = world_clock({"simulated_s": 9.0, "wall_s": 10.0, "camera_frames": 150, "camera_frames_due": 300})
    assert world == {"simulated_s": 9.0, "wall_s": 10.0, "real_time_factor": 0.9,
                     "camera_frames_rendered": 150, "camera_frames_due": 300}
    assert world_clock_line(world) == ("world (real time): real-time factor 0.90 (9.00 s simulated in 10.00 s); "
                                       "camera rendered 150 of 300 frames due")


def test_a_world_that_left_no_record_gives_no_factor_and_no_line() -> None:
    for gazebo in ({}, {"simulated_s": 1.0, "wall_s": 0.0}, {"simulated_s": "x", "wall_s": 1.0}):
        world = world_clock(gazebo)
        assert world["real_time_factor"] is None
        assert world_clock_line(world) is None


def test_without_a_camera_the_line_gives_the_physics_only() -> None:
    assert world_clock_line(world_clock({"simulated_s": 2.0, "wall_s": 2.0})) == (
        "world (real time): real-time factor 1.00 (2.00 s simulated in 2.00 s)")
