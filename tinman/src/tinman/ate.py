"""Absolute trajectory error, computed as the TUM benchmark's ``evaluate_ate.py`` does.

Stamps are associated (``max_difference`` 0.02 s), the estimate's positions are
aligned to the ground truth's by Horn's closed-form method (rotation and translation,
no scale), and the error of each pair is the distance left after alignment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .tum import associate

__all__ = ["AteResult", "align", "evaluate_ate", "trajectory_length"]


@dataclass(frozen=True)
class AteResult:
    """The translational ATE statistics (metres) over ``pairs`` associated poses.

    Attributes:
        errors: the per-pair distances after alignment.
        rotation, translation: the alignment taking the estimate onto the ground truth.
        length: the ground truth's path length over the associated stamps.
    """

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    pairs: int
    length: float
    errors: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray

    @property
    def percent(self) -> float:
        """RMSE as a percentage of the path length (nan for a path of length 0)."""
        return 100.0 * self.rmse / self.length if self.length > 0 else float("nan")


def align(model: np.ndarray, data: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Horn's method: the rotation and translation taking ``model`` (3xN) onto ``data`` (3xN).

    Returns:
        ``(rotation 3x3, translation 3x1, per-column errors)``, as the benchmark's ``align``.
    """
    model_centred = model - model.mean(axis=1, keepdims=True)
    data_centred = data - data.mean(axis=1, keepdims=True)
    w = model_centred @ data_centred.T
    u, _, vh = np.linalg.svd(w.T)
    s = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vh) < 0:
        s[2, 2] = -1.0
    rotation = u @ s @ vh
    translation = data.mean(axis=1, keepdims=True) - rotation @ model.mean(axis=1, keepdims=True)
    aligned = rotation @ model + translation
    errors = np.sqrt(((aligned - data) ** 2).sum(axis=0))
    return rotation, translation, errors


def trajectory_length(positions: np.ndarray) -> float:
    """The length of a polyline of positions (N x 3)."""
    if len(positions) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())


def evaluate_ate(truth_stamps: np.ndarray, truth_positions: np.ndarray, estimate_stamps: np.ndarray,
                 estimate_positions: np.ndarray, offset: float = 0.0, max_difference: float = 0.02,
                 scale: float = 1.0) -> AteResult:
    """ATE of an estimate (positions N x 3 with stamps) against the ground truth.

    Raises:
        ValueError: fewer than three stamps could be associated (no alignment is defined).
    """
    truth = {float(stamp): i for i, stamp in enumerate(truth_stamps)}
    estimate = {float(stamp): i for i, stamp in enumerate(estimate_stamps)}
    matches = associate(truth, estimate, offset, max_difference)
    if len(matches) < 3:
        raise ValueError(f"only {len(matches)} poses of the estimate match ground-truth stamps "
                         f"within {max_difference} s; expected at least 3")
    first = np.array([truth_positions[truth[a]] for a, _ in matches], dtype=float).T
    second = np.array([estimate_positions[estimate[b]] for _, b in matches], dtype=float).T * scale
    rotation, translation, errors = align(second, first)
    return AteResult(
        rmse=float(np.sqrt(np.dot(errors, errors) / len(errors))), mean=float(np.mean(errors)),
        median=float(np.median(errors)), std=float(np.std(errors)), min=float(np.min(errors)),
        max=float(np.max(errors)), pairs=len(matches), length=trajectory_length(first.T),
        errors=errors, rotation=rotation, translation=translation)
