"""Localisation on the known map: the pose that best explains a range scan, near a prior.

A real robot that knows its room localises against the room's map with its laser
(ROS's AMCL). TinMan knows its room (:data:`tinman.world.DEFAULT_WORLD`, which the
Planner plans on) and its start (the dock), and its fused pose is never far wrong, so
no particle filter is needed: from the fused pose as the prior, Gauss-Newton (with
Marquardt's diagonal damping, and each step clipped to a trust region) moves ``(x, y, theta)``
until the ranges the map predicts
(:func:`expected_ranges`, the scanner's ray casting without noise, for several poses at
once) match the ranges read. The Jacobian is numeric (the map's ranges jump at box
corners, so there is no useful closed form); beams that the map cannot explain
(a reading beyond range, a corner, something not on the map) are weighted down by a
Huber loss and dropped past ``GATE_M``.

A match is refused (None) when it cannot be trusted: too few beams explained, an
inlier residual above ``MAX_RMS``, a result far from the prior, or a geometry that
constrains some direction too little (a corridor: the information matrix's smallest
eigenvalue, with the heading scaled by a metre, below ``MIN_INFORMATION``). Pure: no
clock, no state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .scanner import RANGE_MAX, RANGE_MIN, ray_ranges
from .world import World

__all__ = ["Match", "expected_ranges", "match_scan", "BEAM_SIGMA", "GATE_M", "MAX_RMS", "MIN_INFORMATION",
           "MIN_BEAMS"]

Pose = tuple[float, float, float]

BEAM_SIGMA = 0.02      # metres: one beam's error against the map (the reading's 5 mm, the map's own, the beams' width)
HUBER_M = 0.03         # metres: residuals beyond this weigh linearly, not quadratically
GATE_M = 0.25          # metres: a beam further off than this at the end is not on the map (or not this pose)
SEARCH_GATE_M = 0.5    # metres: the same while searching, wider: a prior 0.3 m off puts good beams that far off
MAX_RMS = 0.03         # metres: the inliers' residual of a match worth taking
MIN_BEAMS = 12         # beams explained: a third of the scanner's 36
MIN_INLIERS = 0.6      # of the beams with a reading
MIN_INFORMATION = 2000.0  # least eigenvalue of J^T W J / BEAM_SIGMA^2 (1/m^2): a sigma of ~2 cm in its worst direction
MAX_SHIFT_M = 0.6      # metres from the prior: further is another place, not a correction
MAX_TURN = 0.4         # radians from the prior, likewise
ITERATIONS = 12
STEP = (1e-4, 1e-4, 1e-4)  # numeric Jacobian's steps (metres, metres, radians)


@dataclass(frozen=True)
class Match:
    """A pose found on the map.

    Attributes:
        pose: ``(x, y, theta)`` in the map.
        covariance: its 3x3 covariance (from the information matrix, beams taken as independent).
        rms: the inliers' root mean square residual (metres).
        beams: how many beams it explains (the inliers).
    """

    pose: Pose
    covariance: np.ndarray
    rms: float
    beams: int


def expected_ranges(world: World, poses: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """The ranges a noiseless scanner reads from each of ``poses`` (``k x 3``): ``k x beams``, not
    clipped to the scanner's range (the matcher decides what a beam beyond it means)."""
    poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    return ray_ranges(world, poses[:, 0:1], poses[:, 1:2], poses[:, 2:3] + angles[np.newaxis, :])


def match_scan(world: World, prior: Pose, ranges: np.ndarray, angles: np.ndarray) -> Match | None:
    """The pose near ``prior`` whose map ranges best match ``ranges`` (one per beam of ``angles``,
    ``+inf`` or NaN for none), or None when no match can be trusted (see the module's docstring)."""
    read = np.asarray(ranges, dtype=np.float64)
    angles = np.asarray(angles, dtype=np.float64)
    valid = np.isfinite(read) & (read >= RANGE_MIN) & (read < RANGE_MAX)
    if int(valid.sum()) < MIN_BEAMS:
        return None
    read, angles = read[valid], angles[valid]
    pose = np.array(prior, dtype=np.float64)
    steps = np.diag(STEP)
    damping = 1e-3  # Marquardt's, fixed: the clipped steps below keep the iteration from overshooting
    weights = np.ones(len(read))
    residual = np.zeros(len(read))
    jacobian = np.zeros((len(read), 3))
    for _ in range(ITERATIONS):
        # The pose and its three nudged copies in one cast: the residuals and their numeric Jacobian.
        cast = expected_ranges(world, np.vstack([pose, pose + steps]), angles)
        residual = read - cast[0]
        jacobian = (-(cast[1:] - cast[0]) / np.array(STEP)[:, np.newaxis]).T  # beams x 3: d residual / d pose
        usable = np.isfinite(residual) & np.all(np.isfinite(jacobian), axis=1) & (cast[0] < RANGE_MAX)
        magnitude = np.abs(np.where(usable, residual, np.inf))
        weights = np.where(magnitude <= HUBER_M, 1.0, HUBER_M / np.maximum(magnitude, 1e-12))
        weights = np.where(usable & (magnitude <= SEARCH_GATE_M), weights, 0.0)
        r = np.where(weights > 0, residual, 0.0)
        j = np.where(weights[:, np.newaxis] > 0, jacobian, 0.0)
        hessian = j.T @ (weights[:, np.newaxis] * j)
        gradient = j.T @ (weights * r)
        try:
            delta = -np.linalg.solve(hessian + damping * np.diag(np.diag(hessian) + 1e-9), gradient)
        except np.linalg.LinAlgError:
            return None
        delta[:2] = np.clip(delta[:2], -0.15, 0.15)  # a trust region: the map's ranges are only piecewise smooth
        delta[2] = float(np.clip(delta[2], -0.1, 0.1))
        pose = pose + delta
        pose[2] = math.remainder(float(pose[2]), math.tau)
        if np.all(np.abs(delta) < 1e-4):  # a tenth of a millimetre, a hundredth of a degree: converged
            break
    cast0 = expected_ranges(world, pose[np.newaxis, :], angles)[0]
    residual = read - cast0
    inliers = np.isfinite(residual) & (np.abs(residual) <= GATE_M) & (cast0 < RANGE_MAX)
    count = int(inliers.sum())
    if count < MIN_BEAMS or count < MIN_INLIERS * len(read):
        return None
    rms = float(np.sqrt(np.mean(residual[inliers] ** 2)))
    if rms > MAX_RMS:
        return None
    j = jacobian[inliers]
    if not np.all(np.isfinite(j)):
        return None
    information = j.T @ j / BEAM_SIGMA ** 2
    if float(np.linalg.eigvalsh(information).min()) < MIN_INFORMATION:
        return None  # some direction (a corridor's length) the scan hardly constrains
    shift = math.hypot(pose[0] - prior[0], pose[1] - prior[1])
    if shift > MAX_SHIFT_M or abs(math.remainder(pose[2] - prior[2], math.tau)) > MAX_TURN:
        return None
    covariance = np.linalg.inv(information)
    return Match((float(pose[0]), float(pose[1]), float(pose[2])), covariance, rms, count)
