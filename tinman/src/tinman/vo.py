"""RGB-D visual odometry: ORB features, depth back-projection and PnP against a keyframe.

Each frame's ORB features are matched against those of the current keyframe, whose
3D points come from its depth image: first near where a constant-velocity
prediction puts them, else among all features. ``cv2.solvePnPRansac`` finds the
frame's pose relative to the keyframe, and Gauss-Newton refines it on the inliers
with two kinds of residual: reprojection errors, and the difference between the
depth this frame reads at a feature and the depth its keyframe point should have.
The second kind matters: from reprojections alone a small sideways step is hard to
tell from a small turn when the points lie at similar depths.

Measuring against a keyframe rather than the previous frame keeps frame-to-frame
noise from adding up: error accumulates only when the keyframe changes, which
happens when too few of its points are still seen.

It is honest 6-DoF odometry: nothing assumes the camera stays level or at a known
height, and nothing but the initial pose comes from outside the images.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import cv2
import numpy as np

from .geometry import Intrinsics

__all__ = ["VisualOdometry", "TrackStats", "VoRun", "run_sequence", "FrameSource"]


@dataclass(frozen=True)
class TrackStats:
    """What happened to one frame in :meth:`VisualOdometry.track`.

    Attributes:
        frame: the frame's index (0 for the first frame given).
        features: ORB features found in the frame.
        matches: descriptor matches with the keyframe that passed the ratio and motion tests.
        inliers: matches consistent with the pose found (0 when tracking failed).
        keyframe: whether this frame became the keyframe.
        failed: whether no pose could be found (the previous pose was kept).
        ms: the time ``track`` took, in milliseconds.
    """

    frame: int
    features: int
    matches: int
    inliers: int
    keyframe: bool
    failed: bool
    ms: float


@dataclass
class _Keyframe:
    pose: np.ndarray            # T_wk
    points: np.ndarray          # N x 3 in the keyframe's camera frame (float32)
    descriptors: np.ndarray     # N x 32 uint8, the features that have depth
    reference_inliers: int = 0  # inliers of the first frame tracked against it


class VisualOdometry:
    """Frame-to-keyframe RGB-D odometry.

    Args:
        intrinsics: the camera (the depth image is registered to the colour image).
        initial_pose: ``T_wc`` of the first frame (identity by default).
        features: how many ORB features to detect per frame.
        min_inliers: fewer PnP inliers than this and the frame counts as failed.
        keyframe_fraction: switch keyframe when the inliers fall below this fraction
            of those the keyframe's first tracked frame had ...
        keyframe_inliers: ... or below this absolute count.
        min_depth, max_depth: depth readings outside this range (metres) are not used.
        reprojection_error: the RANSAC inlier threshold, in pixels.
        ratio: a match's descriptor distance must be below this fraction of the runner-up's.
        search_radius: how far (pixels) from its predicted position a keyframe point is looked for.
        max_failures: after this many failed frames in a row, restart from the current
            frame as a keyframe (the view has moved on), at the pose the camera coasted to.
        max_coast: through up to this many failed frames in a row the camera is taken to go on
            moving as it did between the last two frames tracked (then to stand still); the
            pose returned for a failed frame stays the last one tracked.
        max_turn_per_frame, max_step_per_frame: the most a camera's pose departs from the motion
            model's prediction (radians, metres) per frame period; a pose further off is a false
            PnP solution (repeated patterns, a few matches on a plain surface) and the frame
            fails. The bound grows with the frames since the last one tracked.
        pyramid_levels, scale_factor, fast_threshold: ORB's detector settings.
        low_contrast_threshold: where ``fast_threshold`` finds fewer than half of ``features``
            (plain walls, dim light, blur), detect again with this lower FAST threshold, as
            ORB-SLAM does (its 20 and 7; 4 here: in front of a plain painted box, 7 leaves
            too few corners to track a turn); None: never.
        use_depth: refine with this frame's depth readings too (else reprojection only,
            with ``cv2.solvePnPRefineLM``).
        pixel_sigma: the feature position noise assumed by the refinement, in pixels.
        prior_turn, prior_step: while lost and given a prior, the most a pose found may depart
            from it (radians, metres): a relocalisation further off matched the wrong place.

    Attributes:
        pose: ``T_wc`` of the last frame tracked (the initial pose before any).
        last: statistics of the last frame tracked (None before any).
        frames, failures, keyframes: counts so far.
        reanchored: how often :meth:`reanchor` moved the odometry onto another estimate.
    """

    def __init__(self, intrinsics: Intrinsics, initial_pose: np.ndarray | None = None, features: int = 1000, *,
                 min_inliers: int = 20, keyframe_fraction: float = 0.5, keyframe_inliers: int = 80,
                 min_depth: float = 0.3, max_depth: float = 6.0, reprojection_error: float = 2.0,
                 ratio: float = 0.8, search_radius: float = 20.0, max_failures: int = 3,
                 max_coast: int = 6, max_turn_per_frame: float = 0.05, max_step_per_frame: float = 0.05,
                 pyramid_levels: int = 2, scale_factor: float = 1.3, fast_threshold: int = 20,
                 low_contrast_threshold: int | None = 4,
                 use_depth: bool = True, pixel_sigma: float = 2.0, prior_turn: float = 0.15,
                 prior_step: float = 0.2) -> None:
        self.intrinsics = intrinsics
        self.camera_matrix = intrinsics.matrix()
        self.pose = np.eye(4) if initial_pose is None else np.array(initial_pose, dtype=float)
        self.min_inliers = min_inliers
        self.keyframe_fraction = keyframe_fraction
        self.keyframe_inliers = keyframe_inliers
        self.min_depth, self.max_depth = min_depth, max_depth
        self.reprojection_error = reprojection_error
        self.ratio = ratio
        self.search_radius = search_radius
        self.use_depth = use_depth
        self.pixel_sigma = pixel_sigma
        self.max_failures = max_failures
        self.max_coast = max_coast
        self.max_turn_per_frame, self.max_step_per_frame = max_turn_per_frame, max_step_per_frame
        self.last: TrackStats | None = None
        self.frames = 0
        self.failures = 0
        self.keyframes = 0
        self._orb = cv2.ORB.create(nfeatures=features, scaleFactor=scale_factor, nlevels=pyramid_levels,
                                   fastThreshold=fast_threshold)
        self._low_contrast_orb = None
        if low_contrast_threshold is not None and low_contrast_threshold < fast_threshold:
            self._low_contrast_orb = cv2.ORB.create(nfeatures=features, scaleFactor=scale_factor,
                                                    nlevels=pyramid_levels, fastThreshold=low_contrast_threshold)
        self._enough_features = features // 2
        self._matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
        self._keyframe: _Keyframe | None = None
        self._relative = np.eye(4)  # T_kc of the last frame tracked
        self._motion = np.eye(4)    # the last frame-to-frame motion, to predict the next
        self._motion_seconds: float | None = None  # how long that motion took (None: no stamps)
        self._stamp: float | None = None           # the last frame's, tracked or coasted through
        self._step = np.eye(4)                     # the motion predicted from the last frame to this one
        self._seconds_ago: float | None = None     # from the last frame to this one
        self._failed_in_a_row = 0
        self._from_prior = False  # this frame is matched from a prior's prediction
        self.prior_turn, self.prior_step = prior_turn, prior_step
        self.reanchored = 0

    def track(self, rgb: np.ndarray, depth_m: np.ndarray, stamp: float | None = None,
              prior: np.ndarray | None = None) -> np.ndarray:
        """Estimate the pose of the next frame.

        Args:
            rgb: the colour image, uint8 H x W x 3 in RGB order (or H x W grey).
            depth_m: the registered depth image in metres, 0 where there is no reading.
            stamp: the frame's capture time in seconds, if known: the motion model then predicts
                over the time since the last frame (frames dropped in between are allowed for),
                else over one frame.
            prior: ``T_wc`` of this frame as another estimate has it (the fused pose, carried by the
                wheels while the camera saw nothing). Used only once tracking has failed: the
                frame is then matched against the keyframe from where the prior puts it (not
                where the camera coasted to), and a restart makes the new keyframe at the prior.
                That is relocalisation: against the keyframe seen before, else from the prior.

        Returns:
            ``T_wc`` (4x4) of this frame; the previous frame's when tracking failed.

        Raises:
            ValueError: the two images differ in size.
        """
        start = time.perf_counter()
        if rgb.shape[:2] != depth_m.shape[:2] or depth_m.ndim != 2:
            raise ValueError(f"colour image {rgb.shape} and depth image {depth_m.shape} "
                             "must have the same height and width (depth: one channel)")
        gray = rgb if rgb.ndim == 2 else cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        # Features only where there is depth: a keyframe needs them in 3D, and a frame's
        # features are only useful if they can match a keyframe's.
        mask = ((depth_m >= self.min_depth) & (depth_m <= self.max_depth)).view(np.uint8)
        keypoints, descriptors = self._orb.detectAndCompute(gray, mask)
        if len(keypoints) < self._enough_features and self._low_contrast_orb is not None:
            keypoints, descriptors = self._low_contrast_orb.detectAndCompute(gray, mask)
        pixels = np.asarray(cv2.KeyPoint.convert(keypoints) if keypoints else (), dtype=np.float32).reshape(-1, 2)
        index = self.frames
        self.frames += 1
        steps = self._steps_since_last(stamp)
        self._step = _scaled(self._motion, steps)
        self._stamp = stamp
        self._from_prior = prior is not None and self._failed_in_a_row > 0 and self._keyframe is not None
        if self._from_prior:
            assert self._keyframe is not None and prior is not None
            self._relative = np.linalg.inv(self._keyframe.pose) @ np.asarray(prior, dtype=float)
            self._step = np.eye(4)
        if self._keyframe is None:
            made = self._make_keyframe(pixels, descriptors, depth_m, self.pose)
            self.failures += not made
            self._finish(start, index, len(keypoints), 0, 0, made, failed=not made)
            return self.pose.copy()

        matches, inliers, relative = self._relative_pose(pixels, descriptors, depth_m)
        if relative is not None and not self._plausible(relative, steps):
            relative, inliers = None, 0
        if relative is None:
            self.failures += 1
            self._failed_in_a_row += 1
            self._coast()
            restart = False
            if self._failed_in_a_row >= self.max_failures:  # measure from what is in view now, where it coasted to
                assert self._keyframe is not None
                coasted = self._keyframe.pose @ self._relative
                restart = self._make_keyframe(pixels, descriptors, depth_m, coasted)
                if restart:
                    self.pose = coasted
            self._finish(start, index, len(keypoints), matches, 0, restart, failed=True)
            return self.pose.copy()

        keyframe = self._keyframe
        pose: np.ndarray = keyframe.pose @ relative
        if self._failed_in_a_row == 0:  # from a coasted guess the motion would be the guess's error
            self._motion = np.linalg.inv(self._relative) @ relative
            self._motion_seconds = self._seconds_ago
        self._failed_in_a_row = 0
        self._relative = relative
        self.pose = pose
        if keyframe.reference_inliers == 0:
            keyframe.reference_inliers = inliers
        switch = (inliers < self.keyframe_inliers
                  or inliers < self.keyframe_fraction * keyframe.reference_inliers)
        if switch:
            switch = self._make_keyframe(pixels, descriptors, depth_m, pose)
        self._finish(start, index, len(keypoints), matches, inliers, switch, failed=False)
        return pose.copy()

    # ---- steps ---------------------------------------------------------------------------

    def _relative_pose(self, pixels: np.ndarray, descriptors: np.ndarray | None, depth_m: np.ndarray
                       ) -> tuple[int, int, np.ndarray | None]:
        """``(matches, inliers, T_kc)`` of the frame against the keyframe; ``T_kc`` None on failure.

        Matches are first searched near where the constant-velocity prediction puts the
        keyframe's points (fast, and few outliers); if that finds too little, among all
        features (a turn started, or tracking was lost).
        """
        keyframe = self._keyframe
        assert keyframe is not None
        if descriptors is None or len(keyframe.descriptors) < 2 or len(descriptors) < 2:
            return 0, 0, None
        camera_from_keyframe = np.linalg.inv(self._relative @ self._step)  # predicted
        rvec, _ = cv2.Rodrigues(camera_from_keyframe[:3, :3])
        tvec = camera_from_keyframe[:3, 3].reshape(3, 1).copy()
        projected = self._project(keyframe.points, camera_from_keyframe)
        best: tuple[int, int, np.ndarray | None] = (0, 0, None)
        if self._failed_in_a_row == 0:
            query, train = _guided_matches(projected, keyframe.descriptors, pixels, descriptors,
                                           self.search_radius, self.ratio, self.intrinsics)
            best = self._solve(keyframe.points[query], pixels[train], depth_m, rvec, tvec)
            if best[2] is not None and best[1] >= self.keyframe_inliers:
                return best
        query, train = self._global_matches(keyframe.descriptors, descriptors)
        # Drop matches far from where the point should be: it removes most outliers
        # before RANSAC sees them (unless the prediction itself is off).
        near = np.linalg.norm(projected[query] - pixels[train], axis=1) < 80.0
        if near.sum() >= self.min_inliers:
            query, train = query[near], train[near]
        found = self._solve(keyframe.points[query], pixels[train], depth_m, rvec, tvec)
        return found if found[1] > best[1] else best

    def _coast(self) -> None:
        """Carry the camera on through a failed frame with its last frame-to-frame motion (the
        constant-velocity model that predicts every frame), for at most ``max_coast`` frames;
        after that it is held still. A robot turning on the spot in front of a plain wall loses
        track for a few frames and turns on meanwhile: restarting where it was would lose the turn."""
        if self._failed_in_a_row > self.max_coast:
            self._motion, self._step = np.eye(4), np.eye(4)
        self._relative = self._relative @ self._step

    def _steps_since_last(self, stamp: float | None) -> float:
        """How many of the last motion's durations have passed since the last frame (1 without stamps)."""
        self._seconds_ago = None if stamp is None or self._stamp is None else stamp - self._stamp
        if self._seconds_ago is None or not self._motion_seconds or self._seconds_ago <= 0:
            return 1.0
        return self._seconds_ago / self._motion_seconds

    def _plausible(self, relative: np.ndarray, steps: float) -> bool:
        """Whether ``relative`` (``T_kc``) lies near enough the motion model's prediction for the
        ``steps`` frame periods since the last frame (tracked or coasted through): a physical
        camera does not jump, nor change its velocity much from one frame to the next."""
        surprise = np.linalg.inv(self._relative @ self._step) @ relative
        frames = self._failed_in_a_row + max(1.0, steps)
        cosine = np.clip((np.trace(surprise[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
        if self._from_prior:  # the prior is known to a few centimetres: the bound does not grow while lost
            return bool(np.arccos(cosine) <= self.prior_turn and np.linalg.norm(surprise[:3, 3]) <= self.prior_step)
        return bool(np.arccos(cosine) <= self.max_turn_per_frame * frames
                    and np.linalg.norm(surprise[:3, 3]) <= self.max_step_per_frame * frames)

    def reanchor(self, t_wc: np.ndarray) -> None:
        """Take ``t_wc`` as the camera's pose now, and move the keyframe with it (what is tracked
        from here on is relative to that). For an estimate that knows better: the fused pose, when
        this odometry has gone on disagreeing with it (a relocalisation that matched the wrong place)."""
        t_wc = np.asarray(t_wc, dtype=float)
        if self._keyframe is not None:
            self._keyframe.pose = t_wc @ np.linalg.inv(self._relative)
        self.pose = t_wc.copy()
        self.reanchored += 1

    def _project(self, points: np.ndarray, camera_from_points: np.ndarray) -> np.ndarray:
        """Pixel positions of 3D points (N x 2); far outside the image for points behind the camera."""
        camera = points @ camera_from_points[:3, :3].T + camera_from_points[:3, 3]
        z = camera[:, 2]
        in_front = z > 0.05
        safe_z = np.where(in_front, z, 1.0)
        k = self.intrinsics
        pixels = np.column_stack([k.fx * camera[:, 0] / safe_z + k.cx, k.fy * camera[:, 1] / safe_z + k.cy])
        pixels[~in_front] = -1e6
        return pixels

    def _global_matches(self, query: np.ndarray, train: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ratio-tested nearest neighbours of every query descriptor among all train descriptors."""
        pairs = self._matcher.knnMatch(query, train, k=2)
        kept = [(a.queryIdx, a.trainIdx) for a, b in (p for p in pairs if len(p) == 2)
                if a.distance < self.ratio * b.distance]
        indices = np.array(kept, dtype=np.int64).reshape(-1, 2)
        return indices[:, 0], indices[:, 1]

    def _solve(self, objects: np.ndarray, image: np.ndarray, depth_m: np.ndarray, rvec: np.ndarray,
               tvec: np.ndarray) -> tuple[int, int, np.ndarray | None]:
        """PnP with RANSAC, refined on the inliers with this frame's depth too:
        ``(matches, inliers, T_kc or None)``."""
        matches = len(objects)
        if matches < self.min_inliers:
            return matches, 0, None
        found, rvec, tvec, inliers = cv2.solvePnPRansac(
            objects, image.astype(np.float32), self.camera_matrix, None, rvec.copy(), tvec.copy(),
            useExtrinsicGuess=False, iterationsCount=100, reprojectionError=self.reprojection_error,
            confidence=0.999, flags=cv2.SOLVEPNP_AP3P)
        if not found or inliers is None or len(inliers) < self.min_inliers:
            return matches, 0 if inliers is None else len(inliers), None
        inliers = inliers.ravel()
        camera_from_keyframe = np.eye(4)
        camera_from_keyframe[:3, :3] = cv2.Rodrigues(rvec)[0]
        camera_from_keyframe[:3, 3] = tvec.ravel()
        if self.use_depth:
            depths = _depth_at(depth_m, image[inliers], self.min_depth, self.max_depth)
            camera_from_keyframe = _refine(camera_from_keyframe, objects[inliers], image[inliers].astype(np.float64),
                                           depths, self.intrinsics, self.pixel_sigma)
        else:
            rvec, tvec = cv2.solvePnPRefineLM(objects[inliers], image[inliers].astype(np.float32),
                                              self.camera_matrix, None, rvec, tvec)
            camera_from_keyframe[:3, :3] = cv2.Rodrigues(rvec)[0]
            camera_from_keyframe[:3, 3] = tvec.ravel()
        return matches, len(inliers), np.linalg.inv(camera_from_keyframe)

    def _make_keyframe(self, pixels: np.ndarray, descriptors: np.ndarray | None, depth_m: np.ndarray,
                       pose: np.ndarray) -> bool:
        """Make this frame the keyframe at ``pose``; False (nothing changed) if too few points have depth."""
        if descriptors is None or len(pixels) == 0:
            return False
        z = _depth_at(depth_m, pixels, self.min_depth, self.max_depth)
        valid = z > 0
        if valid.sum() < self.min_inliers:
            return False
        k = self.intrinsics
        z = z[valid]
        points = np.column_stack([(pixels[valid, 0] - k.cx) * z / k.fx, (pixels[valid, 1] - k.cy) * z / k.fy, z])
        self._keyframe = _Keyframe(pose.copy(), points.astype(np.float32), descriptors[valid])
        self._relative = np.eye(4)
        self.keyframes += 1
        return True

    def _finish(self, start: float, index: int, features: int, matches: int, inliers: int, keyframe: bool,
                failed: bool) -> None:
        self.last = TrackStats(index, features, matches, inliers, keyframe, failed,
                               (time.perf_counter() - start) * 1000.0)


def _scaled(motion: np.ndarray, factor: float) -> np.ndarray:
    """The motion ``factor`` times as long at the same velocities (rotation vector and translation
    scaled: exact for a straight move or a turn on the spot, close for a frame's arc)."""
    if factor == 1.0:
        return motion
    scaled = np.eye(4)
    rotation_vector, _ = cv2.Rodrigues(motion[:3, :3])
    scaled[:3, :3] = cv2.Rodrigues(rotation_vector * factor)[0]
    scaled[:3, 3] = motion[:3, 3] * factor
    return scaled


_MAX_HAMMING = 64  # of 256 bits: above this two ORB descriptors are not the same corner


def _guided_matches(projected: np.ndarray, query: np.ndarray, pixels: np.ndarray, train: np.ndarray,
                    radius: float, ratio: float, intrinsics: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Match each projected query point with the features within ``radius`` pixels of it.

    The features are bucketed in a grid of ``radius``-sized cells, so each point compares
    its descriptor only with those in the 3x3 cells around it. A match must be the
    point's nearest descriptor there, clearly nearer than the second (``ratio``), near
    enough (``_MAX_HAMMING``), and each feature is used at most once (its nearest point).

    Returns:
        ``(query indices, train indices)`` of the matches.
    """
    empty = np.zeros(0, dtype=np.intp)
    # Bucket the features in cells, with a border of empty cells all round so that
    # every point's 3x3 neighbourhood exists: counts/starts give each cell's run in order.
    stride = int(intrinsics.width // radius) + 3
    cell_count = (int(intrinsics.height // radius) + 3) * stride
    feature_x, feature_y = pixels[:, 0], pixels[:, 1]
    feature_cells = ((feature_y // radius).astype(np.intp) + 1) * stride + (feature_x // radius).astype(np.intp) + 1
    order = np.argsort(feature_cells, kind="stable")
    counts = np.bincount(feature_cells, minlength=cell_count)
    starts = np.cumsum(counts) - counts

    point_x, point_y = projected[:, 0], projected[:, 1]
    points = np.flatnonzero((point_x >= 0) & (point_x < intrinsics.width)
                            & (point_y >= 0) & (point_y < intrinsics.height))
    centre = (((point_y[points] // radius).astype(np.intp) + 1) * stride
              + (point_x[points] // radius).astype(np.intp) + 1)
    neighbourhood = np.array([row * stride + column for row in (-1, 0, 1) for column in (-1, 0, 1)])
    cells = (centre[:, None] + neighbourhood).ravel()
    lengths = counts[cells]
    total = int(lengths.sum())
    if total == 0:
        return empty, empty
    # Every (point, feature in its neighbourhood) pair; a point's pairs stay contiguous.
    candidate_query = np.repeat(np.repeat(points, 9), lengths)
    run_start = np.cumsum(lengths) - lengths
    candidate_train = order[np.repeat(starts[cells] - run_start, lengths) + np.arange(total)]
    dx = point_x[candidate_query] - feature_x[candidate_train]
    dy = point_y[candidate_query] - feature_y[candidate_train]
    near = dx * dx + dy * dy < radius * radius
    candidate_query, candidate_train = candidate_query[near], candidate_train[near]
    if len(candidate_query) == 0:
        return empty, empty
    # Hamming distances of the 256-bit descriptors, as four 64-bit words each.
    words_query = np.ascontiguousarray(query).view(np.uint64)
    words_train = np.ascontiguousarray(train).view(np.uint64)
    distance = np.bitwise_count(words_query[candidate_query] ^ words_train[candidate_train]).sum(
        axis=1, dtype=np.int32)

    # Best and second best of each point's (contiguous) group of candidates.
    new_group = np.r_[True, candidate_query[1:] != candidate_query[:-1]]
    group_start = np.flatnonzero(new_group)
    group = np.cumsum(new_group) - 1
    best = np.minimum.reduceat(distance, group_start)
    at_best = np.flatnonzero(distance == best[group])
    best_index = at_best[np.r_[True, group[at_best][1:] != group[at_best][:-1]]]
    runner_up = distance.copy()
    runner_up[best_index] = 1 << 16
    second = np.minimum.reduceat(runner_up, group_start)
    keep = best_index[(best <= _MAX_HAMMING) & (best < ratio * second)]
    # One feature, one point: the nearest descriptor wins.
    keep = keep[np.argsort(distance[keep], kind="stable")]
    _, unique = np.unique(candidate_train[keep], return_index=True)
    keep = keep[unique]
    return candidate_query[keep], candidate_train[keep]


def _depth_at(depth_m: np.ndarray, pixels: np.ndarray, min_depth: float, max_depth: float) -> np.ndarray:
    """The depth at each pixel, averaged over its 3x3 neighbourhood; 0 where it is not reliable.

    Not reliable: a reading missing or out of range in the neighbourhood, or a spread
    over it above 8% of the depth. A corner feature often sits on a depth edge, where
    the reading may belong to the background or the foreground; a far floor seen at
    a grazing angle spreads about 4%.
    """
    height, width = depth_m.shape
    columns = np.clip(np.rint(pixels[:, 0]).astype(np.intp), 1, width - 2)
    rows = np.clip(np.rint(pixels[:, 1]).astype(np.intp), 1, height - 2)
    offsets = np.array([-1, 0, 1])
    patch = depth_m[(rows[:, None] + offsets)[:, :, None], (columns[:, None] + offsets)[:, None, :]]
    patch = patch.reshape(len(pixels), 9).astype(np.float32)
    low, high, mean = patch.min(axis=1), patch.max(axis=1), patch.mean(axis=1)
    reliable = (low >= min_depth) & (high <= max_depth) & (high - low <= 0.08 * mean)
    return np.where(reliable, mean, 0.0).astype(np.float32)


def _depth_sigma(z: np.ndarray) -> np.ndarray:
    """The Kinect's axial noise at depth ``z`` (Nguyen, Izadi and Lovell 2012), metres."""
    return 0.0012 + 0.0019 * (z - 0.4) ** 2


def _refine(camera_from_keyframe: np.ndarray, points: np.ndarray, pixels: np.ndarray, depths: np.ndarray,
            intrinsics: Intrinsics, pixel_sigma: float, iterations: int = 6) -> np.ndarray:
    """Gauss-Newton on the pose: reprojection errors of the keyframe's points in this frame and,
    where this frame has depth at the feature, the difference of the two depths.

    Reprojection alone cannot tell a sideways step from a turn when the points lie
    at similar depths; this frame's depth readings can. Each residual is scaled by
    its noise (``pixel_sigma``; the sensor's depth noise of both readings) and
    down-weighted beyond two sigmas (Huber).

    Returns:
        The refined ``camera_from_keyframe`` (4x4).
    """
    fx, fy, cx, cy = intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy
    rotation = camera_from_keyframe[:3, :3].copy()
    translation = camera_from_keyframe[:3, 3].copy()
    points = points.astype(np.float64)
    has_depth = depths > 0
    measured = depths[has_depth].astype(np.float64)
    depth_weight = 1.0 / np.hypot(_depth_sigma(points[has_depth, 2]), _depth_sigma(measured))
    n = len(points)
    for _ in range(iterations):
        camera = points @ rotation.T + translation
        x, y, z = camera[:, 0], camera[:, 1], camera[:, 2]
        if np.any(z <= 0.05):
            break
        inverse_z = 1.0 / z
        residual_u = (fx * x * inverse_z + cx - pixels[:, 0]) / pixel_sigma
        residual_v = (fy * y * inverse_z + cy - pixels[:, 1]) / pixel_sigma
        # Jacobians for a left perturbation T <- exp(delta) T, delta = (translation, rotation).
        jacobian_u = np.column_stack([fx * inverse_z, np.zeros(n), -fx * x * inverse_z ** 2,
                                      -fx * x * y * inverse_z ** 2, fx + fx * x * x * inverse_z ** 2,
                                      -fx * y * inverse_z]) / pixel_sigma
        jacobian_v = np.column_stack([np.zeros(n), fy * inverse_z, -fy * y * inverse_z ** 2,
                                      -fy - fy * y * y * inverse_z ** 2, fy * x * y * inverse_z ** 2,
                                      fy * x * inverse_z]) / pixel_sigma
        xd, yd, zd = x[has_depth], y[has_depth], z[has_depth]
        residual_z = (zd - measured) * depth_weight
        jacobian_z = np.column_stack([np.zeros_like(zd), np.zeros_like(zd), np.ones_like(zd),
                                      yd, -xd, np.zeros_like(zd)]) * depth_weight[:, None]
        residuals = np.concatenate([residual_u, residual_v, residual_z])
        jacobian = np.concatenate([jacobian_u, jacobian_v, jacobian_z])
        weights = np.minimum(1.0, 2.0 / np.maximum(np.abs(residuals), 1e-12))  # Huber at 2 sigma
        weighted = jacobian * weights[:, None]
        step = -np.linalg.solve(weighted.T @ jacobian + 1e-9 * np.eye(6), weighted.T @ residuals)
        turn = cv2.Rodrigues(step[3:].reshape(3, 1))[0]
        rotation = turn @ rotation
        translation = turn @ translation + step[:3]
        if np.abs(step).max() < 1e-7:
            break
    refined = np.eye(4)
    refined[:3, :3] = rotation
    refined[:3, 3] = translation
    return refined


# ---- running over a recorded sequence ----------------------------------------------------------

class FrameSource(Protocol):
    """What :func:`run_sequence` needs of a sequence (``tinman.dataset.TumSequence`` is one)."""

    intrinsics: Intrinsics

    @property
    def stamps(self) -> np.ndarray: ...
    def __len__(self) -> int: ...
    def rgb(self, index: int) -> np.ndarray: ...
    def depth(self, index: int) -> np.ndarray: ...
    @property
    def groundtruth(self) -> tuple[np.ndarray, np.ndarray] | None: ...


@dataclass(frozen=True)
class VoRun:
    """The trajectory visual odometry estimated over a sequence.

    Attributes:
        stamps: the frames' timestamps (N,).
        poses: the estimated ``T_wc`` of every frame (N x 4 x 4).
        stats: what :meth:`VisualOdometry.track` reported for each frame.
        seconds: the time spent inside ``track`` (reading images is not counted).
    """

    stamps: np.ndarray
    poses: np.ndarray
    stats: tuple[TrackStats, ...]
    seconds: float

    @property
    def fps(self) -> float:
        """Frames tracked per second of tracking time."""
        return len(self.stats) / self.seconds if self.seconds > 0 else float("nan")

    @property
    def failures(self) -> int:
        """Frames whose pose could not be found (the previous one was kept)."""
        return sum(s.failed for s in self.stats)

    @property
    def keyframes(self) -> int:
        """How many frames became keyframes (the first one included)."""
        return sum(s.keyframe for s in self.stats)


def run_sequence(sequence: FrameSource, max_frames: int | None = None,
                 progress: Callable[[int, int], None] | None = None, **options: Any) -> VoRun:
    """Run :class:`VisualOdometry` over a sequence's frames, in order.

    The first frame's pose is the ground truth's nearest pose within 20 ms when the
    sequence has ground truth (so the estimate starts in the same frame), the identity
    otherwise. Nothing else is taken from the ground truth.

    Args:
        sequence: the frames (and intrinsics, stamps, optional ground truth).
        max_frames: stop after this many frames (all by default).
        progress: told ``(frames tracked, frames)`` before the first frame and after every one
            (e.g. a :class:`tinman.progress.FrameProgress`).
        options: passed on to :class:`VisualOdometry`.

    Returns:
        The estimated trajectory with per-frame statistics.
    """
    count = len(sequence) if max_frames is None else min(len(sequence), max_frames)
    stamps = np.asarray(sequence.stamps, dtype=float)[:count]
    initial = np.eye(4)
    truth = sequence.groundtruth
    if truth is not None and count and len(truth[0]):
        nearest = int(np.argmin(np.abs(np.asarray(truth[0]) - stamps[0])))
        if abs(truth[0][nearest] - stamps[0]) < 0.02:
            initial = truth[1][nearest]
    odometry = VisualOdometry(sequence.intrinsics, initial, **options)
    poses = np.empty((count, 4, 4))
    stats: list[TrackStats] = []
    seconds = 0.0
    if progress is not None:
        progress(0, count)
    for i in range(count):
        rgb, depth = sequence.rgb(i), sequence.depth(i)
        start = time.perf_counter()
        poses[i] = odometry.track(rgb, depth, float(stamps[i]))
        seconds += time.perf_counter() - start
        assert odometry.last is not None
        stats.append(odometry.last)
        if progress is not None:
            progress(i + 1, count)
    return VoRun(stamps, poses, tuple(stats), seconds)
