"""TumSequence on hand-made TUM directories: association, image decoding, ground
truth, camera choice and the errors for broken datasets."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from budget import examples
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tinman.dataset import FREIBURG_INTRINSICS, DatasetError, TumSequence
from tinman.geometry import FR1, camera_pose
from tinman.tum import write_trajectory


def make_sequence(root: Path, rgb_stamps: list[float], depth_stamps: list[float],
                  groundtruth: bool = True, size: tuple[int, int] = (8, 6)) -> Path:
    """A TUM directory with tiny images: colour frame i is filled with (i, 2i, 3i) in RGB,
    depth frame j with 5000 + j counts (1 m + j / 5000)."""
    (root / "rgb").mkdir(parents=True)
    (root / "depth").mkdir()
    width, height = size
    rgb_lines, depth_lines = ["# color images", "# timestamp filename"], ["# depth maps"]
    for i, stamp in enumerate(rgb_stamps):
        name = f"rgb/{stamp:.6f}.png"
        image = np.zeros((height, width, 3), np.uint8)
        image[..., 2], image[..., 1], image[..., 0] = i, 2 * i, 3 * i  # BGR on disk
        cv2.imwrite(str(root / name), image)
        rgb_lines.append(f"{stamp:.6f} {name}")
    for j, stamp in enumerate(depth_stamps):
        name = f"depth/{stamp:.6f}.png"
        cv2.imwrite(str(root / name), np.full((height, width), 5000 + j, np.uint16))
        depth_lines.append(f"{stamp:.6f} {name}")
    (root / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    (root / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    if groundtruth:
        stamps = np.arange(rgb_stamps[0] - 0.1, rgb_stamps[-1] + 0.1, 0.01)
        poses = [camera_pose(0.1 * k, 0.05 * k, 0.01 * k) for k in range(len(stamps))]
        write_trajectory(root / "groundtruth.txt", stamps, poses)
    return root


def test_frames_are_paired_by_time_and_decoded(tmp_path: Path) -> None:
    rgb = [100.0 + i / 30 for i in range(6)]
    depth = [s + (0.008 if i % 2 else -0.011) for i, s in enumerate(rgb)]
    del depth[3]  # a dropped depth frame: its colour frame goes unpaired
    root = make_sequence(tmp_path / "seq", rgb, depth)
    sequence = TumSequence.open(root)
    assert len(sequence) == 5
    # Stamps are written with six decimals.
    np.testing.assert_allclose(sequence.stamps, [rgb[i] for i in (0, 1, 2, 4, 5)], atol=1e-6)
    np.testing.assert_allclose(sequence.depth_stamps, depth, atol=1e-6)
    image = sequence.rgb(3)  # colour frame 4
    assert image.dtype == np.uint8 and image.shape == (6, 8, 3)
    assert tuple(image[0, 0]) == (4, 8, 12)  # RGB order
    depth_image = sequence.depth(3)  # the fourth depth file
    assert depth_image.dtype == np.float32
    assert depth_image[0, 0] == pytest.approx((5000 + 3) / 5000)
    assert sequence.frame_rate == pytest.approx(30.0, rel=1e-3)
    assert sequence.intrinsics == FR1
    assert sequence.metadata == {}


@settings(max_examples=examples(20), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.floats(-0.015, 0.015), min_size=2, max_size=8))
def test_depth_within_15_ms_of_its_colour_frame_is_always_paired(tmp_path_factory: pytest.TempPathFactory,
                                                                   offsets: list[float]) -> None:
    rgb = [50.0 + i / 30 for i in range(len(offsets))]
    depth = [s + o for s, o in zip(rgb, offsets, strict=True)]
    sequence = TumSequence.open(make_sequence(tmp_path_factory.mktemp("seq"), rgb, depth, groundtruth=False))
    assert len(sequence) == len(rgb)
    np.testing.assert_allclose(sequence.depth_stamps - sequence.stamps, offsets, atol=2e-6)


def test_groundtruth_is_read_when_present(tmp_path: Path) -> None:
    rgb = [10.0, 10.1, 10.2]
    with_truth = TumSequence.open(make_sequence(tmp_path / "a", rgb, rgb))
    stamps, poses = with_truth.groundtruth
    assert poses.shape == (len(stamps), 4, 4)
    np.testing.assert_allclose(poses[3], camera_pose(0.3, 0.15, 0.03), atol=1e-6)
    assert TumSequence.open(make_sequence(tmp_path / "b", rgb, rgb, groundtruth=False)).groundtruth is None


@pytest.mark.parametrize(("name", "number"), [("rgbd_dataset_freiburg1_xyz", 1),
                                              ("rgbd_dataset_freiburg2_desk", 2),
                                              ("rgbd_dataset_freiburg3_long_office_household", 3)])
def test_the_camera_follows_the_freiburg_number(tmp_path: Path, name: str, number: int) -> None:
    sequence = TumSequence.open(make_sequence(tmp_path / name, [1.0, 1.1], [1.0, 1.1]))
    assert sequence.intrinsics == FREIBURG_INTRINSICS[number]


def test_the_metadata_camera_wins(tmp_path: Path) -> None:
    root = make_sequence(tmp_path / "rgbd_dataset_freiburg2_x", [1.0, 1.1], [1.0, 1.1])
    intrinsics = {"fx": 100.0, "fy": 101.0, "cx": 3.5, "cy": 2.5, "width": 8, "height": 6}
    (root / "tinman.json").write_text(json.dumps({"intrinsics": intrinsics, "seed": 4}))
    sequence = TumSequence.open(root)
    assert sequence.intrinsics.fx == 100.0 and sequence.intrinsics.width == 8
    assert sequence.metadata["seed"] == 4


def test_errors_name_the_path_at_fault(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere"
    with pytest.raises(DatasetError, match=rf"^{missing}: no such sequence directory$") as error:
        TumSequence.open(missing)
    assert error.value.path == missing
    root = make_sequence(tmp_path / "seq", [1.0, 1.1, 1.2], [1.0, 1.1, 1.2])
    (root / "rgb" / "1.100000.png").unlink()
    (root / "depth" / "1.200000.png").write_bytes(b"not a png")
    sequence = TumSequence.open(root)
    with pytest.raises(DatasetError, match=rf"^{root}/rgb/1.100000.png: no such image file$"):
        sequence.rgb(1)
    with pytest.raises(DatasetError, match=rf"^{root}/depth/1.200000.png: missing or unreadable image$"):
        sequence.depth(2)
    cv2.imwrite(str(root / "depth" / "1.000000.png"), np.zeros((6, 8), np.uint8))
    with pytest.raises(DatasetError, match=r"depth/1.000000.png: expected a 16-bit depth image, got uint8"):
        sequence.depth(0)
    (root / "groundtruth.txt").write_text("1.0 1 2 3\n")
    with pytest.raises(DatasetError, match=r"groundtruth.txt: .*expected 'tx ty tz qx qy qz qw'"):
        _ = sequence.groundtruth
    (root / "tinman.json").write_text("{oops")
    with pytest.raises(DatasetError, match=r"tinman.json: unreadable metadata"):
        TumSequence.open(root)
    (root / "tinman.json").unlink()
    (root / "rgb.txt").unlink()
    with pytest.raises(DatasetError, match=rf"^{root}/rgb.txt: no such file list$"):
        TumSequence.open(root)


def test_lists_without_frames_or_pairs_are_refused(tmp_path: Path) -> None:
    root = make_sequence(tmp_path / "seq", [1.0, 2.0], [1.5, 2.5], groundtruth=False)
    with pytest.raises(DatasetError, match=r"no colour frame has a depth frame within 0.02 s \(2 colour, 2 depth"):
        TumSequence.open(root)
    (root / "depth.txt").write_text("# nothing here\n")
    with pytest.raises(DatasetError, match=r"depth.txt: the file list names no frames$"):
        TumSequence.open(root)
