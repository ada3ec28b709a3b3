"""Localisation on the known map with the range scan (issue 28, items 2-4): the matcher finds the
true pose from a wrong prior, and refuses what it cannot trust."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tinman.scan_match import expected_ranges, match_scan
from tinman.scanner import beam_angles, cast
from tinman.world import DEFAULT_WORLD, ROBOT_RADIUS, World

ANGLES = beam_angles()


def _free_pose(rng: np.random.Generator) -> tuple[float, float, float]:
    for _ in range(1000):  # bounded: the room is mostly free
        x, y = rng.uniform(0.0, DEFAULT_WORLD.width), rng.uniform(0.0, DEFAULT_WORLD.depth)
        if not DEFAULT_WORLD.collides(x, y, ROBOT_RADIUS + 0.05):
            return x, y, rng.uniform(-math.pi, math.pi)
    raise AssertionError("no free pose found")


def _perturbed(pose: tuple[float, float, float], rng: np.random.Generator) -> tuple[float, float, float]:
    """A prior 0 to 0.3 m away in any direction and 0 to 10 degrees off."""
    distance, direction = rng.uniform(0.0, 0.3), rng.uniform(0.0, math.tau)
    return (pose[0] + distance * math.cos(direction), pose[1] + distance * math.sin(direction),
            pose[2] + rng.uniform(-1.0, 1.0) * math.radians(10.0))


def test_the_expected_ranges_are_the_scanners_without_noise_for_several_poses_at_once() -> None:
    poses = np.array([[1.0, 1.0, 0.0], [4.0, 1.0, 1.0], [7.0, 5.0, -2.0]])
    ranges = expected_ranges(DEFAULT_WORLD, poses, ANGLES)
    for pose, row in zip(poses, ranges, strict=True):
        scanned = cast(DEFAULT_WORLD, tuple(pose), ANGLES)
        near = np.isfinite(scanned)
        assert np.allclose(row[near], scanned[near], atol=1e-4)
        assert np.all(row[~near] > 3.4)


def test_from_a_prior_a_third_of_a_metre_and_ten_degrees_off_it_finds_the_true_pose() -> None:
    rng = np.random.default_rng(28)
    matched = 0
    for _ in range(100):
        truth = _free_pose(rng)
        found = match_scan(DEFAULT_WORLD, _perturbed(truth, rng), cast(DEFAULT_WORLD, truth, ANGLES, rng), ANGLES)
        if found is None:
            continue
        matched += 1
        assert math.hypot(found.pose[0] - truth[0], found.pose[1] - truth[1]) < 0.03, (truth, found)
        assert abs(math.remainder(found.pose[2] - truth[2], math.tau)) < math.radians(1.0), (truth, found)
        assert found.rms < 0.03 and np.all(np.linalg.eigvalsh(found.covariance) > 0)
    assert matched >= 95  # a refusal is allowed (a pose by a corner may be ambiguous), a wrong pose is not


def test_a_garbage_scan_is_refused() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        truth = _free_pose(rng)
        assert match_scan(DEFAULT_WORLD, truth, rng.uniform(0.2, 3.4, len(ANGLES)), ANGLES) is None


def test_a_scan_with_too_few_readings_is_refused() -> None:
    truth = (1.0, 1.0, 0.0)
    ranges = cast(DEFAULT_WORLD, truth, ANGLES).astype(np.float64)
    ranges[6:] = np.inf  # a scanner that sees nothing but a few beams
    assert match_scan(DEFAULT_WORLD, truth, ranges, ANGLES) is None


def test_a_corridor_longer_than_the_scanner_reaches_is_refused_it_does_not_say_where_along() -> None:
    corridor = World(width=30.0, depth=1.2, start=(15.0, 0.6, 0.0))
    rng = np.random.default_rng(5)
    truth = (15.0, 0.6, 0.2)
    assert match_scan(corridor, (15.1, 0.65, 0.25), cast(corridor, truth, ANGLES, rng), ANGLES) is None


@pytest.mark.parametrize("seed", [0, 1])
def test_something_not_on_the_map_is_outvoted_by_the_beams_that_are(seed: int) -> None:
    rng = np.random.default_rng(seed)
    truth = (1.5, 4.5, 0.3)
    ranges = cast(DEFAULT_WORLD, truth, ANGLES, rng).astype(np.float64)
    ranges[10:14] = 0.6  # a person standing by the robot blocks four beams
    found = match_scan(DEFAULT_WORLD, (1.7, 4.35, 0.4), ranges, ANGLES)
    assert found is not None and found.beams <= len(ANGLES) - 4
    assert math.hypot(found.pose[0] - truth[0], found.pose[1] - truth[1]) < 0.03
