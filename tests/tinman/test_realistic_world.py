"""The realistic world: photographs, plain walls, repeated patterns, flickering lamps, motion blur,
and the ``--world`` option that chooses it."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from tinman import photos
from tinman.app import TinMan, TinManError
from tinman.ate import evaluate_ate
from tinman.cameras import LiveCamera
from tinman.cli import _parser
from tinman.geometry import FR1, camera_pose, depth_metres, robot_pose
from tinman.lamps import GAIN_RANGE, FlickeringLamps
from tinman.messages import image_array
from tinman.mission import simulate_mission
from tinman.realistic import FLOOR_TILE, POSTER, POSTER_CENTRES, build_realistic_atlas, paint_surface
from tinman.render import RoomRenderer
from tinman.roles.simulation import _Film
from tinman.settings import ENVIRONMENT_VARIABLE, current
from tinman.sim import arc_pose
from tinman.synthetic import add_motion_blur, image_motion
from tinman.textures import TEXEL, Atlas, Surface, build_atlas, picture_coordinates, room_surfaces
from tinman.vo import VisualOdometry
from tinman.world import DEFAULT_WORLD
from tinman.worlds import WORLDS, UnknownWorldError, world_look

SURFACES = room_surfaces(DEFAULT_WORLD)
SOUTH_WALL = next(s for s in SURFACES if s.name == "south wall")
FLOOR = next(s for s in SURFACES if s.name == "floor")
# Views along the patrol: the dock looking east, the desk, the shelf, the brick wall, the window.
VIEWS = [(1.0, 1.0, 0.0), (4.3, 1.1, 0.8), (6.9, 2.9, 2.2), (4.2, 5.1, 3.0), (1.2, 4.6, -1.6)]


@pytest.fixture(scope="module")
def realistic() -> RoomRenderer:
    return RoomRenderer(DEFAULT_WORLD, FR1, seed=0, paint=build_realistic_atlas)


@pytest.fixture(scope="module")
def easy_atlas() -> Atlas:
    return build_atlas(DEFAULT_WORLD, SURFACES, 0)


def picture(atlas: Atlas, surface: Surface) -> np.ndarray:
    """A surface's lit level-0 picture in the atlas (without its margin), grey."""
    i = SURFACES.index(surface)
    cols = sorted(h * atlas.scale_h[i] + atlas.offset_h[i] for h in surface.h_range)
    rows = sorted(v * atlas.scale_v[i] + atlas.offset_v[i] for v in surface.v_range)
    block = atlas.image[math.ceil(rows[0]):math.floor(rows[1]), math.ceil(cols[0]):math.floor(cols[1]), :3]
    grey: np.ndarray = cv2.cvtColor(np.ascontiguousarray(block), cv2.COLOR_RGB2GRAY)
    return grey


def flat_fraction(grey: np.ndarray) -> float:
    """The fraction of texels whose 9 x 9 neighbourhood varies by less than 1.5 grey levels (std)."""
    image = grey.astype(np.float32)
    mean = cv2.blur(image, (9, 9))
    variance = cv2.blur(image * image, (9, 9)) - mean * mean
    return float((variance < 1.5 ** 2).mean())


def ncc(a: np.ndarray, b: np.ndarray) -> float:
    a = a.astype(np.float64).ravel() - a.mean()
    b = b.astype(np.float64).ravel() - b.mean()
    return float(a @ b / np.sqrt((a @ a) * (b @ b)))


# ---- textures ------------------------------------------------------------------------------------

def test_walls_are_mostly_plain_paint_where_the_easy_room_has_texture_everywhere(
        realistic: RoomRenderer, easy_atlas: Atlas) -> None:
    walls = [s for s in SURFACES if s.kind == "wall"]
    easy = [flat_fraction(picture(easy_atlas, wall)) for wall in walls]
    real = [flat_fraction(picture(realistic._atlas, wall)) for wall in walls]
    assert max(easy) < 0.05
    assert min(real) > 0.4 and float(np.mean(real)) > 0.6
    # ORB, as the odometry runs it, finds far fewer corners on the same view.
    orb = cv2.ORB.create(nfeatures=5000, scaleFactor=1.3, nlevels=2, fastThreshold=20)
    easy_renderer = RoomRenderer(DEFAULT_WORLD, FR1, seed=0)
    pose = camera_pose(1.3, 1.2, -math.pi / 2)  # the south wall, close
    counts = [len(orb.detect(cv2.cvtColor(r.render(pose)[0], cv2.COLOR_RGB2GRAY), None))
              for r in (easy_renderer, realistic)]
    assert counts[1] < 0.1 * counts[0]


def test_the_posters_and_prints_are_the_photographs() -> None:
    wall = paint_surface(SOUTH_WALL, np.random.default_rng(0))
    h, v = picture_coordinates(SOUTH_WALL)
    image = photos.photo(POSTER)
    width = 0.55
    height = width * image.shape[0] / image.shape[1]
    bottom = 1.0 + 0.012  # over the frame
    for centre in POSTER_CENTRES:
        cols = np.flatnonzero((h >= centre - width / 2 + 0.01) & (h < centre + width / 2 - 0.01))
        rows = np.flatnonzero((v >= bottom + 0.01) & (v < bottom + height - 0.01))
        block = wall[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
        inner = cv2.resize(image, (round(width / 0.004), round(height / 0.004)), interpolation=cv2.INTER_AREA)
        inner = inner[3:3 + block.shape[0], 3:3 + block.shape[1]].astype(np.float32)
        assert ncc(block, inner) > 0.9


def test_the_floor_tiles_and_the_poster_repeat() -> None:
    floor = paint_surface(FLOOR, np.random.default_rng(0))
    size = round(FLOOR_TILE / TEXEL["floor"])
    tile = floor[10 * size:11 * size, 10 * size:11 * size]
    assert np.array_equal(tile, floor[11 * size:12 * size, 10 * size:11 * size])
    assert np.array_equal(tile, floor[10 * size:11 * size, 3 * size:4 * size])
    # The poster hangs three times: the same texels at 1.2 m spacing (the frame's edge aside).
    wall = paint_surface(SOUTH_WALL, np.random.default_rng(0))
    h, v = picture_coordinates(SOUTH_WALL)
    rows = np.flatnonzero((v >= 1.05) & (v < 1.3))
    blocks = []
    for centre in POSTER_CENTRES:
        cols = np.flatnonzero((h >= centre - 0.2) & (h < centre + 0.2))
        blocks.append(wall[rows[0]:rows[-1] + 1, cols[0]:cols[0] + 90])
    assert ncc(blocks[0], blocks[1]) > 0.98 and ncc(blocks[1], blocks[2]) > 0.98


def test_a_missing_photograph_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    photos.photo.cache_clear()
    monkeypatch.setitem(photos.PHOTOS, "brick", "no-such-brick.png")
    with pytest.raises(photos.PhotoMissingError) as error:
        photos.photo("brick")
    assert error.value.name == "brick" and error.value.path is not None
    assert str(error.value) == (
        f"the realistic world needs scikit-image's bundled sample image 'brick' ({error.value.path}): "
        "the file is not in the installed package; install scikit-image (pip install 'scikit-image>=0.22'), "
        "or use --world easy")
    monkeypatch.setattr("importlib.util.find_spec", lambda name: None)
    with pytest.raises(photos.PhotoMissingError, match=r"'camera': scikit-image is not installed; install"):
        photos.photo_path("camera")
    photos.photo.cache_clear()


def test_only_bundled_photographs_are_read_and_nothing_is_downloaded(monkeypatch: pytest.MonkeyPatch) -> None:
    import skimage.data

    def no_download(*args: object, **kwargs: object) -> None:
        raise AssertionError("the realistic world must not download scikit-image data")

    monkeypatch.setattr(skimage.data, "download_all", no_download)
    photos.photo.cache_clear()
    for name in photos.PHOTOS:
        image = photos.photo(name)
        assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3 and min(image.shape[:2]) >= 256
        assert photos.photo_path(name).parent == Path(skimage.data.__file__).parent


# ---- lamps ---------------------------------------------------------------------------------------

def test_the_lamps_vary_within_their_bounds() -> None:
    lamps = FlickeringLamps(2, seed=0)
    t = np.arange(0.0, 600.0, 1 / 30)
    gains = np.array([lamps.gains(s) for s in t])
    assert gains.min() >= GAIN_RANGE[0] and gains.max() <= GAIN_RANGE[1]
    steady, failing = gains[:, 0], gains[:, 1]
    # The first lamp only drifts: slowly, by a few percent.
    assert 0.9 < steady.min() < 0.97 and 1.03 < steady.max() < 1.1
    assert np.abs(np.diff(steady)).max() < 0.005
    # The failing one flickers: frame to frame jumps, darker than 85 % for a few percent of the time.
    assert 0.02 < (failing < 0.85).mean() < 0.3
    assert (np.abs(np.diff(failing)) > 0.15).sum() > 50
    assert np.array_equal(gains[:100], np.array([FlickeringLamps(2, seed=0).gains(s) for s in t[:100]]))
    assert not np.array_equal(gains[:3000], np.array([FlickeringLamps(2, seed=1).gains(s) for s in t[:3000]]))


def test_relighting_dims_the_frame_within_the_gains(realistic: RoomRenderer) -> None:
    pose = camera_pose(*VIEWS[0])
    lit, depth = realistic.render(pose)
    same, same_depth = realistic.render(pose, (1.0, 1.0))
    assert np.array_equal(lit, same) and np.array_equal(depth, same_depth)
    dim, _ = realistic.render(pose, (0.5, 0.5))
    bright = (lit > 40) & (lit < 250)
    ratio = dim[bright].astype(np.float64) / lit[bright]
    # Both lamps at half: every point between half and all of its light (ambient light stays).
    assert ratio.min() >= 0.5 - 1.0 / 40 and ratio.max() <= 1.0 + 1e-9 and 0.6 < float(np.median(ratio)) < 0.9
    one, _ = realistic.render(pose, (1.0, 0.5))
    assert float(one.mean()) > float(dim.mean()) and not np.array_equal(one, lit)
    with pytest.raises(ValueError, match=r"^expected one gain per lamp \(2\), got \[1\.0\]$"):
        realistic.render(pose, (1.0,))


# ---- motion blur ---------------------------------------------------------------------------------

def test_a_still_camera_is_not_blurred() -> None:
    rgb = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    assert add_motion_blur(rgb, (0.0, 0.0)) is rgb
    assert add_motion_blur(rgb, (0.3, -0.3)) is rgb
    still = camera_pose(2.0, 2.0, 0.3)
    assert image_motion(still, still, np.full((48, 64), 2.0, np.float32), FR1) == pytest.approx((0.0, 0.0), abs=1e-9)


def test_blur_smears_along_the_motion_only() -> None:
    dot = np.zeros((41, 41, 3), np.uint8)
    dot[20, 20] = 255
    smeared = add_motion_blur(dot, (10.0, 0.0))[..., 0]
    rows, cols = np.nonzero(smeared)
    assert set(rows.tolist()) == {20} and cols.min() >= 14 and cols.max() <= 26 and cols.max() - cols.min() >= 9
    diagonal = add_motion_blur(dot, (6.0, 6.0))[..., 0]
    rows, cols = np.nonzero(diagonal)
    assert np.all(np.abs(rows - cols) <= 1)  # along the diagonal
    noise = np.random.default_rng(1).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    blurred = add_motion_blur(noise, (8.0, 0.0)).astype(np.float64)
    across = np.abs(np.diff(blurred, axis=1)).mean() / np.abs(np.diff(noise.astype(np.float64), axis=1)).mean()
    down = np.abs(np.diff(blurred, axis=0)).mean() / np.abs(np.diff(noise.astype(np.float64), axis=0)).mean()
    assert across < 0.3 and down > 2 * across


def test_turning_moves_the_image_sideways_by_the_turn() -> None:
    robot, w, exposure = (3.0, 3.0, 0.4), 1.0, 0.02
    opened = camera_pose(*arc_pose(*robot, 0.0, w, -exposure / 2))
    closed = camera_pose(*arc_pose(*robot, 0.0, w, exposure / 2))
    du, dv = image_motion(opened, closed, np.full((FR1.height, FR1.width), 2.5, np.float32), FR1)
    # Turning left (counter-clockwise) sweeps the scene right across the image by f * w * T pixels
    # at the centre, (1 + x^2) times that at normalised x off it: the mean over the 5 x 5 grid.
    x = (np.linspace(0.1, 0.9, 5) * (FR1.width - 1) - FR1.cx) / FR1.fx
    assert du == pytest.approx(FR1.fx * w * exposure * float(np.mean(1 + x * x)), rel=0.02) and abs(dv) < 0.1


def test_the_live_camera_blurs_fast_turns_and_not_a_still_robot(realistic: RoomRenderer) -> None:
    camera = LiveCamera(DEFAULT_WORLD, FR1, seed=0, look="realistic")
    assert camera.lamps is not None
    robot, dt = VIEWS[0], 1 / 30
    still = image_array(camera.capture(robot, 100.0)[0]).astype(np.float64)
    turning = image_array(camera.capture(robot, 100.0 + dt, velocity=(0.0, 1.0))[0]).astype(np.float64)
    pose = camera_pose(*robot)

    def distance(image: np.ndarray, t: float, motion: tuple[float, float]) -> float:
        """How far a captured image is from the clean render at lamp time ``t`` blurred by ``motion``
        (after averaging 9 rows, which leaves horizontal detail and cuts the sensor's noise)."""
        clean, _ = camera.renderer.render(pose, camera.lamps.gains(t) if camera.lamps else None)
        difference = image - add_motion_blur(clean, motion)
        return float(np.abs(cv2.blur(difference, (1, 9))).mean())

    # A still robot: the sharp frame plus the sensor's noise; a turning one: the frame blurred sideways.
    turn = (FR1.fx * 0.02, 0.0)
    assert distance(still, 0.0, (0.0, 0.0)) < 0.6 * distance(still, 0.0, turn)
    assert distance(turning, dt, turn) < 0.6 * distance(turning, dt, (0.0, 0.0))


# ---- odometry in it ------------------------------------------------------------------------------

def test_odometry_follows_the_patrols_turn_on_the_spot_within_a_centimetre_and_a_degree() -> None:
    # The hardest motion of the patrol: at the second waypoint it turns on the spot at 1 rad/s for
    # two seconds, in front of the tiled east wall, through the live camera's blur, flicker and noise.
    # Bound: ATE RMSE under 1.2 cm (it is 0.7; the odometry before the low-contrast threshold of 4
    # and the motion model made 1.6), heading never more than 1.5 degrees off, no frame lost.
    trace = simulate_mission(duration=19.5, rate=30.0)
    camera = LiveCamera(DEFAULT_WORLD, FR1, seed=0, look="realistic")
    odometry: VisualOdometry | None = None
    stamps, truth, estimate, heading_errors = [], [], [], []
    for i in range(round(16.8 * 30), len(trace.stamps) - 1):
        robot, after = trace.poses[i], trace.poses[i + 1]
        velocity = (float(np.hypot(*(after[:2] - robot[:2]))) * 30,
                    math.remainder(float(after[2] - robot[2]), math.tau) * 30)
        color, depth, t_wc = camera.capture(tuple(robot), float(trace.stamps[i]), velocity=velocity)
        odometry = odometry or VisualOdometry(FR1, t_wc)
        pose = odometry.track(image_array(color), depth_metres(image_array(depth)), float(trace.stamps[i]))
        stamps.append(float(trace.stamps[i]))
        truth.append(t_wc[:3, 3])
        estimate.append(pose[:3, 3])
        heading_errors.append(abs(math.remainder(robot_pose(pose)[2] - float(robot[2]), math.tau)))
    turned = math.remainder(float(trace.poses[-1][2] - trace.poses[round(16.8 * 30)][2]), math.tau)
    assert turned > 1.5  # the turn is in the segment (the mission has not changed under the test)
    assert odometry is not None and odometry.failures == 0
    assert max(heading_errors) < math.radians(1.5)
    ate = evaluate_ate(np.array(stamps), np.array(truth), np.array(stamps), np.array(estimate))
    assert ate.rmse < 0.012


# ---- rendering -----------------------------------------------------------------------------------

@pytest.mark.slow  # paints the room and renders frames along the patrol at full size
def test_the_realistic_room_renders_at_640_by_480(realistic: RoomRenderer) -> None:
    lamps = FlickeringLamps(2, seed=0)
    for i, robot in enumerate(VIEWS):
        rgb, depth = realistic.render(camera_pose(*robot), lamps.gains(i * 3.1))
        assert rgb.shape == (480, 640, 3) and rgb.dtype == np.uint8
        assert depth.shape == (480, 640) and depth.dtype == np.float32 and depth.min() > 0
        assert 40 < float(rgb.mean()) < 220 and float(rgb.std()) > 10


# ---- choosing the world --------------------------------------------------------------------------

def test_worlds_are_named_and_an_unknown_name_is_refused() -> None:
    assert WORLDS == ("easy", "realistic")
    assert world_look("easy").paint is build_atlas and world_look("easy").exposure == 0.0
    assert world_look("realistic").flickering_lamps and world_look("realistic").exposure == 0.02
    with pytest.raises(UnknownWorldError, match=r"^unknown world 'hard'; expected one of easy, realistic$"):
        world_look("hard")
    with pytest.raises(UnknownWorldError):
        LiveCamera(DEFAULT_WORLD, look="hard")
    parser = _parser()  # tinman generate --world: every world, and no other
    assert [parser.parse_args(["generate", "dir", "--world", name]).world for name in WORLDS] == list(WORLDS)
    with pytest.raises(SystemExit):
        parser.parse_args(["generate", "dir", "--world", "hard"])


def test_the_world_option_reaches_the_camera(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(ENVIRONMENT_VARIABLE, "")  # restored after the test: prepare exports its own
    app = TinMan()
    parser = argparse.ArgumentParser()
    app.add_arguments(parser)
    assert parser.parse_args([]).world is None  # not given: the default, realistic
    app.prepare(parser.parse_args(["--out", str(tmp_path)]), lambda line: None)
    settings = current()
    assert settings.world == "realistic"
    film = _Film(settings)
    assert film.live is not None and film.live.look.name == "realistic" and film.live.lamps is not None
    assert film.record()["world"] == "realistic"
    atlas_lighting = film.live.renderer._atlas.lighting
    assert atlas_lighting is not None and atlas_lighting.ambient == 0.4
    app.prepare(parser.parse_args(["--world", "easy", "--out", str(tmp_path)]), lambda line: None)
    easy = _Film(current())
    assert easy.live is not None and easy.live.look.name == "easy" and easy.live.lamps is None
    for world in ("easy", "realistic"):  # either, given with --dataset, has nothing to choose
        with pytest.raises(TinManError, match=rf"^--world {world} with --dataset: a recording is played back"):
            app.prepare(parser.parse_args(["--world", world, "--dataset", str(tmp_path)]), lambda line: None)
    current.cache_clear()


@pytest.mark.slow  # renders a second of the patrol in the realistic world and writes it
def test_a_realistic_sequence_is_generated(tmp_path: Path) -> None:
    from tinman.dataset import TumSequence
    from tinman.sequences import generate

    directory = generate(tmp_path / "real", duration=1.0, look="realistic", workers=1)
    metadata = json.loads((directory / "tinman.json").read_text())
    assert metadata["look"] == "realistic" and metadata["motion_blur"] is True
    sequence = TumSequence.open(directory)
    assert len(sequence) == 30 and sequence.rgb(10).shape == (480, 640, 3)
