"""The simulator's camera: rendered live from the robot's pose, or a recording played back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tinman.cameras import LiveCamera, RecordedCamera
from tinman.geometry import DEPTH_SCALE, FR1, camera_pose
from tinman.messages import image_array, seconds
from tinman.sequences import generate
from tinman.world import DEFAULT_WORLD


@pytest.fixture(scope="module")
def live() -> LiveCamera:
    return LiveCamera(DEFAULT_WORLD, seed=3)


def test_a_live_frame_is_what_the_camera_on_the_robot_sees(live: LiveCamera) -> None:
    robot = (1.5, 1.2, 0.4)
    color, depth, t_wc = live.capture(robot, 1_700_000_000.25)
    assert np.allclose(t_wc, camera_pose(*robot))
    assert (color.encoding, depth.encoding) == ("rgb8", "16UC1")
    assert (color.width, color.height, depth.width, depth.height) == (FR1.width, FR1.height) * 2
    assert seconds(color.header.stamp) == pytest.approx(1_700_000_000.25) == seconds(depth.header.stamp)
    # The noisy reading agrees with the exact depth of that view where the sensor read anything.
    exact = live.renderer.render(t_wc)[1]
    reading = image_array(depth).astype(np.float64) / DEPTH_SCALE
    seen = reading > 0
    assert seen.mean() > 0.8
    assert np.median(np.abs(reading[seen] - exact[seen])) < 0.01


def test_a_recording_is_played_back_with_its_stamps(tmp_path: Path) -> None:
    directory = generate(tmp_path / "room", duration=0.5)
    camera = RecordedCamera(str(directory))
    assert len(camera) == len(camera.sequence.stamps) > 5 and camera.offset(0) == 0.0
    color, depth = camera.frame(3)
    assert seconds(color.header.stamp) == pytest.approx(float(camera.sequence.stamps[3]))
    assert seconds(depth.header.stamp) == pytest.approx(float(camera.sequence.depth_stamps[3]))
    assert np.array_equal(image_array(color), camera.sequence.rgb(3))
    assert np.array_equal(image_array(depth), camera.sequence.depth_raw(3))
    assert camera.offset(3) == pytest.approx(float(camera.sequence.stamps[3] - camera.sequence.stamps[0]))
