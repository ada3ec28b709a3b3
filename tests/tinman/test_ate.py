"""The ATE evaluator and the TUM text formats, against known errors and the benchmark's own code.

``_tum_*`` below are transcriptions of the TUM RGB-D benchmark's ``associate.py``
(``read_file_list``, ``associate``) and ``evaluate_ate.py`` (``align`` and the
RMSE in ``__main__``), ported from Python 2 / ``numpy.matrix`` to arrays but
otherwise line by line, so hypothesis can compare tinman's versions with them.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from budget import examples
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tinman.ate import align, evaluate_ate, trajectory_length
from tinman.geometry import matrix_from_quaternion, pose_matrix
from tinman.tum import associate, read_file_list, read_trajectory, write_file_list, write_trajectory

# ---- the benchmark's code, transcribed --------------------------------------------------------

def _tum_read_file_list(filename: Path) -> dict[float, list[str]]:
    with open(filename) as file:
        data = file.read()
    lines = data.replace(",", " ").replace("\t", " ").split("\n")
    rows = [[v.strip() for v in line.split(" ") if v.strip() != ""]
            for line in lines if len(line) > 0 and line[0] != "#"]
    pairs = [(float(row[0]), row[1:]) for row in rows if len(row) > 1]
    return dict(pairs)


def _tum_associate(first_list, second_list, offset, max_difference):  # type: ignore[no-untyped-def]
    first_keys = list(first_list)
    second_keys = list(second_list)
    potential_matches = [(abs(a - (b + offset)), a, b)
                         for a in first_keys
                         for b in second_keys
                         if abs(a - (b + offset)) < max_difference]
    potential_matches.sort()
    matches = []
    for _diff, a, b in potential_matches:
        if a in first_keys and b in second_keys:
            first_keys.remove(a)
            second_keys.remove(b)
            matches.append((a, b))
    matches.sort()
    return matches


def _tum_align(model: np.ndarray, data: np.ndarray):  # type: ignore[no-untyped-def]
    model_zerocentered = model - model.mean(1)[:, None]
    data_zerocentered = data - data.mean(1)[:, None]
    w = np.zeros((3, 3))
    for column in range(model.shape[1]):
        w += np.outer(model_zerocentered[:, column], data_zerocentered[:, column])
    u, _, vh = np.linalg.svd(w.transpose())
    s = np.identity(3)
    if np.linalg.det(u) * np.linalg.det(vh) < 0:
        s[2, 2] = -1
    rot = u @ s @ vh
    trans = data.mean(1)[:, None] - rot @ model.mean(1)[:, None]
    model_aligned = rot @ model + trans
    alignment_error = model_aligned - data
    trans_error = np.sqrt(np.sum(np.multiply(alignment_error, alignment_error), 0))
    return rot, trans, trans_error


def _tum_ate_rmse(first_list, second_list, offset=0.0, max_difference=0.02, scale=1.0):  # type: ignore[no-untyped-def]
    matches = _tum_associate(first_list, second_list, offset, max_difference)
    first_xyz = np.array([[float(value) for value in first_list[a][0:3]] for a, b in matches]).transpose()
    second_xyz = np.array([[float(value) * float(scale) for value in second_list[b][0:3]]
                           for a, b in matches]).transpose()
    _, _, trans_error = _tum_align(second_xyz, first_xyz)
    return len(matches), float(np.sqrt(np.dot(trans_error, trans_error) / len(trans_error)))


# ---- helpers ----------------------------------------------------------------------------------

def _rotation(rng: np.random.Generator) -> np.ndarray:
    return matrix_from_quaternion(rng.normal(size=4))


def _out_and_back(rng: np.random.Generator, n: int) -> np.ndarray:
    """A random 3D polyline walked out and then back, point for point (2n points)."""
    out = np.cumsum(rng.normal(scale=0.2, size=(n, 3)), axis=0)
    return np.concatenate([out, out[::-1]])


# ---- known errors -----------------------------------------------------------------------------

def test_a_rigidly_moved_copy_has_no_error() -> None:
    rng = np.random.default_rng(1)
    truth = np.cumsum(rng.normal(scale=0.1, size=(200, 3)), axis=0)
    rotation, shift = _rotation(rng), rng.normal(size=3) * 5
    estimate = truth @ rotation.T + shift
    stamps = np.arange(200) / 30.0
    result = evaluate_ate(stamps, truth, stamps, estimate)
    assert result.pairs == 200
    assert result.rmse < 1e-9 and result.max < 1e-9
    # The alignment found is the inverse of the motion applied.
    np.testing.assert_allclose(result.rotation, rotation.T, atol=1e-9)
    np.testing.assert_allclose(result.translation.ravel(), -rotation.T @ shift, atol=1e-9)
    assert result.length == pytest.approx(np.linalg.norm(np.diff(truth, axis=0), axis=1).sum())


@pytest.mark.parametrize("offset", [0.01, 0.05, 0.3])
def test_offsets_no_rigid_motion_can_explain_give_their_size_as_the_error(offset: float) -> None:
    # Walking out and back, +offset on the way out and -offset on the way back along
    # one direction u: the offsets sum to zero and sum(s_i p_i) = 0, so the cross
    # covariance gains nothing and the best alignment leaves every error at |offset|.
    rng = np.random.default_rng(7)
    truth = _out_and_back(rng, 60)
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    signs = np.r_[np.ones(60), -np.ones(60)]
    rotation, shift = _rotation(rng), rng.normal(size=3)
    estimate = (truth + offset * signs[:, None] * u) @ rotation.T + shift
    stamps = 100.0 + np.arange(120) * 0.1
    result = evaluate_ate(stamps, truth, stamps, estimate)
    assert result.rmse == pytest.approx(offset, rel=1e-9)
    assert result.mean == pytest.approx(offset, rel=1e-9)
    assert result.median == pytest.approx(offset, rel=1e-9)
    assert result.min == pytest.approx(offset, rel=1e-9) and result.max == pytest.approx(offset, rel=1e-9)
    assert result.std == pytest.approx(0.0, abs=1e-9)
    assert result.length == pytest.approx(trajectory_length(truth))
    assert result.percent == pytest.approx(100 * offset / trajectory_length(truth), rel=1e-9)


def test_stamps_are_associated_within_the_tolerance_and_the_rest_ignored() -> None:
    rng = np.random.default_rng(3)
    truth_stamps = np.arange(300) / 100.0                     # 100 Hz ground truth
    truth = np.cumsum(rng.normal(scale=0.01, size=(300, 3)), axis=0)
    est_stamps = truth_stamps[::10] + 0.004                   # 10 Hz estimate, 4 ms late
    estimate = truth[::10] + np.array([1.0, 2.0, 3.0])
    est_stamps = np.r_[est_stamps, 50.0]                      # one pose with no ground truth
    estimate = np.r_[estimate, [[9.0, 9.0, 9.0]]]
    result = evaluate_ate(truth_stamps, truth, est_stamps, estimate)
    assert result.pairs == 30
    assert result.rmse < 1e-9
    assert result.length == pytest.approx(trajectory_length(truth[::10]))


def test_time_offset_and_scale_are_applied_to_the_estimate() -> None:
    rng = np.random.default_rng(4)
    truth = np.cumsum(rng.normal(scale=0.1, size=(50, 3)), axis=0)
    stamps = np.arange(50) * 0.5
    result = evaluate_ate(stamps, truth, stamps - 1.0, truth / 2.0, offset=1.0, scale=2.0)
    assert (result.pairs, result.rmse < 1e-9) == (50, True)
    unscaled = evaluate_ate(stamps, truth, stamps - 1.0, truth / 2.0, offset=1.0)
    assert unscaled.rmse > 0.01


def test_too_few_matches_is_an_error() -> None:
    stamps = np.array([0.0, 1.0, 2.0])
    xyz = np.zeros((3, 3))
    with pytest.raises(ValueError, match=r"^only 2 poses of the estimate match ground-truth stamps "
                                         r"within 0\.02 s; expected at least 3$"):
        evaluate_ate(stamps, xyz, np.array([0.0, 1.0, 5.0]), xyz)


def test_percent_of_a_path_of_no_length_is_nan() -> None:
    stamps = np.arange(5.0)
    result = evaluate_ate(stamps, np.zeros((5, 3)), stamps, np.zeros((5, 3)))
    assert result.length == 0.0 and math.isnan(result.percent)


# ---- against the benchmark's code -------------------------------------------------------------

# How closely tinman's numbers must match the benchmark's is set by the input: both compute
# the same closed form, but the cross-covariance W = sum (m_i - m)(d_i - d)^T is summed in a
# different order (BLAS here, a Python loop there; and BLAS differs between machines), so
# they are the exact answers for two inputs a rounding error apart. The tolerances below
# bound what that rounding can do, from the input's scale and conditioning; on a
# well-posed input they are far tighter than a fixed 1e-9, and on a near-degenerate one
# (a rotation the points barely determine) they grow as far as the problem allows.

_EPS = float(np.finfo(float).eps)


def _conditioning(model: np.ndarray, data: np.ndarray) -> tuple[float, float, float]:
    """``(rounding, gap, size)`` of aligning ``model`` onto ``data`` (both 3xN).

    - ``rounding`` bounds the rounding error of W in any summation order, plus LAPACK's
      backward error in its SVD: ``(N + 10) eps |M_c|_F |D_c|_F``.
    - ``gap`` is ``sigma_2 + s sigma_3`` of W's singular values, ``s`` the sign of
      ``det W`` (whether the best rotation has to flip W's weakest axis): the rotation
      maximising ``tr(R W)`` is unique when the gap is positive, and an error ``dW`` in W
      moves it by about ``|dW| / gap``.
    - ``size`` is the largest coordinate, which sets the rounding of each residual.
    """
    model_centred = model - model.mean(axis=1, keepdims=True)
    data_centred = data - data.mean(axis=1, keepdims=True)
    w = model_centred @ data_centred.T
    sigma = np.linalg.svd(w, compute_uv=False)
    gap = float(sigma[1] + math.copysign(sigma[2], np.linalg.det(w)))
    rounding = (model.shape[1] + 10) * _EPS * float(np.linalg.norm(model_centred) * np.linalg.norm(data_centred))
    return rounding, gap, float(max(np.abs(model).max(), np.abs(data).max()))


def _rotation_tolerance(model: np.ndarray, data: np.ndarray) -> float:
    """How far apart (per entry) two correct computations of the best rotation can be."""
    rounding, gap, _ = _conditioning(model, data)
    return 8.0 * rounding / gap if gap > 0 else math.inf


def _rmse_tolerance(model: np.ndarray, data: np.ndarray) -> float:
    """How far apart two correct computations of the RMSE after alignment can be.

    The least sum of squares is unique even when the rotation is not: a rotation off by
    ``dR`` raises it only by about ``gap |dR|^2``, so by at most ``rounding^2 / gap`` and,
    however small the gap, by at most a few times ``rounding``.
    """
    rounding, gap, size = _conditioning(model, data)
    squares = 32.0 * (min(rounding, rounding * rounding / gap) if gap > 0 else rounding)
    return math.sqrt(squares / model.shape[1]) + 32.0 * _EPS * size


_positions = hnp.arrays(float, st.tuples(st.integers(3, 40), st.just(3)),
                        elements=st.floats(-50, 50, allow_nan=False, width=32))


@settings(max_examples=examples(150), deadline=None)
@given(truth=_positions, noise=st.floats(0.0, 2.0), seed=st.integers(0, 2**32 - 1),
       scale=st.sampled_from([1.0, 0.5, 1.7]))
def test_rmse_equals_the_benchmarks(truth: np.ndarray, noise: float, seed: int, scale: float) -> None:
    rng = np.random.default_rng(seed)
    n = len(truth)
    truth_stamps = np.round(np.cumsum(rng.uniform(0.005, 0.1, n)), 3)
    est_stamps = truth_stamps + np.round(rng.uniform(-0.03, 0.03, n), 3)
    estimate = (truth + rng.normal(scale=noise, size=truth.shape)) @ _rotation(rng).T + rng.normal(size=3)
    first = {float(t): [repr(float(v)) for v in p] for t, p in zip(truth_stamps, truth, strict=True)}
    second = {float(t): [repr(float(v)) for v in p] for t, p in zip(est_stamps, estimate, strict=True)}
    matches = _tum_associate(first, second, 0.0, 0.02)
    if len(matches) < 3:
        with pytest.raises(ValueError, match=rf"^only {len(matches)} poses of the estimate match ground-truth"):
            evaluate_ate(np.array(list(first)), truth, np.array(list(second)), estimate, scale=scale)
        return
    expected_pairs, expected_rmse = _tum_ate_rmse(first, second, scale=scale)
    result = evaluate_ate(np.array(list(first)), np.array([[float(v) for v in p] for p in first.values()]),
                          np.array(list(second)), np.array([[float(v) for v in p] for p in second.values()]),
                          scale=scale)
    assert result.pairs == expected_pairs
    data = np.array([[float(v) for v in first[a]] for a, _ in matches]).T
    model = np.array([[float(v) * scale for v in second[b]] for _, b in matches]).T
    assert result.rmse == pytest.approx(expected_rmse, rel=0.0, abs=_rmse_tolerance(model, data))


@settings(max_examples=examples(150), deadline=None)
@given(model=hnp.arrays(float, st.tuples(st.just(3), st.integers(3, 30)), elements=st.floats(-10, 10, width=32)),
       noise=st.sampled_from([0.3, 0.0]), seed=st.integers(0, 2**32 - 1))
# Degenerate models, where the rotation is not unique but the errors still are.
@example(model=np.zeros((3, 4)), noise=0.3, seed=0)                                  # one point
@example(model=np.array([[0.0, 1.0, 2.0, 3.0], [0.0, 2.0, 4.0, 6.0], [0.0] * 4]), noise=0.0, seed=1)  # a line
@example(model=np.array([[0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0], [5.0] * 4]), noise=0.3, seed=2)  # a plane
def test_align_equals_the_benchmarks(model: np.ndarray, noise: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    data = _rotation(rng) @ model + rng.normal(size=(3, 1)) + rng.normal(scale=noise, size=model.shape)
    rotation, translation, errors = align(model, data)
    tum_rotation, tum_translation, tum_errors = _tum_align(model, data)
    n = model.shape[1]
    assert math.sqrt(errors @ errors / n) == pytest.approx(math.sqrt(tum_errors @ tum_errors / n), rel=0.0,
                                                             abs=_rmse_tolerance(model, data))
    # The rotation is compared as closely as the points determine it: to rounding on a
    # well-spread model, and hardly at all (entries of two rotations differ by 2 at most)
    # where it is not unique: collinear points, or W's two weakest axes equally strong
    # when one of them must flip.
    entry = min(_rotation_tolerance(model, data), 2.0)
    np.testing.assert_allclose(rotation, tum_rotation, rtol=0.0, atol=entry)
    rounding = 32.0 * _EPS * _conditioning(model, data)[2]
    # t = mean(data) - R mean(model), and |dR x| <= 3 * entry * max|x|.
    np.testing.assert_allclose(translation, tum_translation, rtol=0.0,
                               atol=3 * entry * float(np.abs(model.mean(axis=1)).max()) + rounding)
    # Each error moves with the rotation by at most |dR| times its point's distance from the centroid.
    lever = np.linalg.norm(model - model.mean(axis=1, keepdims=True), axis=0)
    assert (np.abs(errors - tum_errors) <= 3 * entry * lever + rounding).all(), (errors, tum_errors)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), rtol=0.0, atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0, rel=0.0, abs=1e-12)


_stamps = st.lists(st.integers(0, 400).map(lambda k: k * 0.005), max_size=40, unique=True)


@settings(max_examples=examples(300), deadline=None)
@given(first=_stamps, second=_stamps, offset=st.sampled_from([0.0, 0.01, -0.013]),
       max_difference=st.sampled_from([0.005, 0.02, 0.1]))
def test_associate_equals_the_benchmarks(first: list[float], second: list[float], offset: float,
                                         max_difference: float) -> None:
    # Stamps on a 5 ms grid make ties (equal differences) common: the order they are
    # broken in is part of the contract.
    expected = _tum_associate(dict.fromkeys(first), dict.fromkeys(second), offset, max_difference)
    assert associate(first, second, offset, max_difference) == expected


# ---- the file formats -------------------------------------------------------------------------

_field = st.text(alphabet="abc./_019\x0c", min_size=1, max_size=6)  # \f: whitespace to strip
_line = st.one_of(
    st.tuples(st.integers(0, 10**6).map(lambda k: f"{k / 1000:.3f}"), st.lists(_field, max_size=3),
              st.sampled_from([" ", "\t", ",", " , ", "  "])).map(lambda t: t[2].join([t[0], *t[1]])),
    st.sampled_from(["# a comment", "", "#", "   ", "\t"]),
)


@settings(max_examples=examples(200), deadline=None)
@given(lines=st.lists(_line, max_size=12), newline=st.sampled_from(["\n", "\r\n"]))
def test_read_file_list_equals_the_benchmarks(tmp_path_factory: pytest.TempPathFactory, lines: list[str],
                                              newline: str) -> None:
    path = tmp_path_factory.mktemp("lists") / "list.txt"
    path.write_bytes(newline.join(lines).encode())
    assert read_file_list(path) == _tum_read_file_list(path)


def test_read_file_list_names_the_line_of_a_bad_timestamp(tmp_path: Path) -> None:
    path = tmp_path / "rgb.txt"
    path.write_text("# timestamp filename\n1.0 rgb/1.png\nnow rgb/2.png\n")
    with pytest.raises(ValueError, match=r"rgb\.txt:3: expected a timestamp, got 'now'$"):
        read_file_list(path)


@settings(max_examples=examples(50), deadline=None)
@given(poses=hnp.arrays(float, st.tuples(st.integers(0, 10), st.just(7)), elements=st.floats(-1, 1, width=32)))
def test_trajectory_round_trip(tmp_path_factory: pytest.TempPathFactory, poses: np.ndarray) -> None:
    quaternions = poses[:, 3:] + [0.0, 0.0, 0.0, 2.0]      # well away from zero norm
    matrices = [pose_matrix(p[:3] * 10, q) for p, q in zip(poses, quaternions, strict=True)]
    stamps = 1305031102.175304 + np.arange(len(poses)) / 30.0
    path = tmp_path_factory.mktemp("traj") / "groundtruth.txt"
    write_trajectory(path, stamps, matrices, comment="ground truth\nsynthetic")
    assert path.read_text().startswith("# ground truth\n# synthetic\n# timestamp tx ty tz qx qy qz qw\n")
    read_stamps, read_poses = read_trajectory(path)
    np.testing.assert_allclose(read_stamps, stamps, atol=1e-6)
    assert read_poses.shape == (len(poses), 4, 4)
    for written, read in zip(matrices, read_poses, strict=True):
        np.testing.assert_allclose(read, written, atol=5e-6)    # six decimals in the file


def test_read_trajectory_rejects_short_lines(tmp_path: Path) -> None:
    path = tmp_path / "est.txt"
    path.write_text("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 1\n")
    with pytest.raises(ValueError, match=r"est\.txt: at 2\.000000: expected 'tx ty tz qx qy qz qw', "
                                         r"got '0 0 0 0 0 1'$"):
        read_trajectory(path)


def test_read_trajectory_rejects_a_quaternion_of_no_length(tmp_path: Path) -> None:
    path = tmp_path / "est.txt"
    path.write_text("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 0\n")
    with pytest.raises(ValueError, match=r"est\.txt: at 2\.000000: expected a quaternion of finite, non-zero length, "
                                         r"got \(0\.0, 0\.0, 0\.0, 0\.0\)$"):
        read_trajectory(path)


def test_file_list_round_trip(tmp_path: Path) -> None:
    entries = {1305031102.175304: "rgb/1305031102.175304.png", 1305031102.211214: "rgb/1305031102.211214.png"}
    write_file_list(tmp_path / "rgb.txt", entries, comment="color images")
    assert not list(tmp_path.glob("*.partial"))
    assert read_file_list(tmp_path / "rgb.txt") == {t: [name] for t, name in entries.items()}
    assert (tmp_path / "rgb.txt").read_text().splitlines()[:2] == ["# color images", "# timestamp filename"]
