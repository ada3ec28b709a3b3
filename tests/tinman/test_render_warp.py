"""The warp renderer: depth exact to float32 rounding (against an independent float64 ray cast),
near-plane clipping, and the same frames as the ray caster away from face borders."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from budget import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from tinman.geometry import FR1, Intrinsics, camera_pose
from tinman.render import RoomRenderer
from tinman.render_warp import NEAR_PLANE, WarpRenderer, clip_to_near_plane
from tinman.textures import room_surfaces
from tinman.world import DEFAULT_WORLD, Box, World

# A quarter-size FR1 keeps the property tests fast; the geometry is the same.
SMALL = Intrinsics(fx=FR1.fx / 4, fy=FR1.fy / 4, cx=(FR1.cx + 0.5) / 4 - 0.5, cy=(FR1.cy + 0.5) / 4 - 0.5,
                   width=160, height=120)
ROOM = World(width=4.0, depth=3.0, wall_height=2.5, boxes=(Box(2.0, 1.0, 2.6, 1.8, 0.8),),
             start=(1.0, 1.0, 0.0))
BOX_X0, BOX_X1, BOX_Y0, BOX_Y1, BOX_TOP = 6, 7, 8, 9, 10  # surface ids of the box's faces
EAST_WALL, FLOOR = 1, 4
FLOAT32_ROUNDING = 2.0 ** -24  # relative error of rounding a float64 to the nearest float32
_IN_PLANE = ((1, 2), (0, 2), (0, 1))


@pytest.fixture(scope="module")
def warp_full() -> WarpRenderer:
    return WarpRenderer(ROOM, FR1, seed=3)


@pytest.fixture(scope="module")
def warp_small() -> WarpRenderer:
    return WarpRenderer(ROOM, SMALL, seed=3)


@pytest.fixture(scope="module")
def ray_small() -> RoomRenderer:
    return RoomRenderer(ROOM, SMALL, seed=3)


def reference(world: World, k: Intrinsics, t_wc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depth along the optical axis and surface id per pixel, by intersecting every rectangle
    of the scene with every pixel's ray in float64 (-1 and inf where there is none)."""
    u, v = np.meshgrid(np.arange(k.width, dtype=float), np.arange(k.height, dtype=float))
    rays = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones_like(u)])
    d = np.einsum("ij,jhw->ihw", t_wc[:3, :3], rays)
    o = t_wc[:3, 3]
    depth, ids = np.full(u.shape, np.inf), np.full(u.shape, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        for i, surface in enumerate(room_surfaces(world)):
            t = (surface.value - o[surface.axis]) / d[surface.axis]  # rays have camera z = 1
            a, b = _IN_PLANE[surface.axis]
            h, w = o[a] + t * d[a], o[b] + t * d[b]
            hit = ((t > 0) & (h >= surface.h_range[0]) & (h <= surface.h_range[1])
                   & (w >= surface.v_range[0]) & (w <= surface.v_range[1]) & (t < depth))
            depth, ids = np.where(hit, t, depth), np.where(hit, i, ids)
    return depth, ids


def away_from_borders(ids: np.ndarray) -> np.ndarray:
    """Pixels whose 3x3 neighbourhood sees one surface only (the ray caster supersamples the others)."""
    kernel = np.ones((3, 3), np.uint8)
    f = ids.astype(np.float32)
    return np.asarray(cv2.dilate(f, kernel) == cv2.erode(f, kernel))


def assert_depth_exact(depth: np.ndarray, expected: np.ndarray) -> None:
    """Each depth is the float64 value rounded to float32 (or next to it)."""
    assert depth.dtype == np.float32 and np.isfinite(expected).all()
    error = np.abs(depth.astype(np.float64) - expected) / expected
    assert error.max() <= FLOAT32_ROUNDING * (1 + 1e-6), np.unravel_index(error.argmax(), error.shape)


def look_at(eye: tuple[float, float, float], target: tuple[float, float, float]) -> np.ndarray:
    """``T_wc`` of a camera at ``eye`` looking at ``target``, its x axis level (no roll)."""
    forward = np.subtract(target, eye) / np.linalg.norm(np.subtract(target, eye))
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([right, np.cross(forward, right), forward])
    pose[:3, 3] = eye
    return pose


def tilted(x: float, y: float, theta: float, pitch: float, roll: float, height: float = 0.5) -> np.ndarray:
    """A camera pose with some pitch (about camera x) and roll (about camera z)."""
    pose = camera_pose(x, y, theta, height)
    cp, sp, cr, sr = math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
    about_x = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    about_z = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    pose[:3, :3] = pose[:3, :3] @ about_x @ about_z
    return pose


# Anywhere in the room down to a millimetre from the walls and the box, looking anywhere:
# (x, y, heading, pitch, roll, height) for tilted().
poses_in_the_room = st.tuples(st.floats(0.001, 3.999), st.floats(0.001, 2.999), st.floats(-math.pi, math.pi),
                              st.floats(-1.5, 1.5), st.floats(-math.pi, math.pi), st.floats(0.001, 2.499)).filter(
    lambda p: not ROOM.boxes[0].contains(p[0], p[1], 0.001) or p[5] > ROOM.boxes[0].height + 0.001)


# -- near-plane clipping --------------------------------------------------------------------------

def test_a_polygon_crossing_the_near_plane_keeps_its_part_in_front_in_order() -> None:
    square = np.array([[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 3.0], [-1.0, 0.0, 3.0]])
    clipped = clip_to_near_plane(square, 1.0)
    np.testing.assert_array_equal(clipped, [[1.0, 0.0, 1.0], [1.0, 0.0, 3.0], [-1.0, 0.0, 3.0], [-1.0, 0.0, 1.0]])
    triangle_corner_behind = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]])
    clipped = clip_to_near_plane(triangle_corner_behind, 0.5)
    np.testing.assert_allclose(clipped, [[0.75, 0.0, 0.5], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0], [-0.75, 0.0, 0.5]])


def test_a_polygon_wholly_in_front_is_kept_and_one_wholly_behind_is_gone() -> None:
    square = np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 2.0], [1.0, 1.0, 2.0], [0.0, 1.0, 2.0]])
    np.testing.assert_array_equal(clip_to_near_plane(square, 1.0), square)
    assert clip_to_near_plane(square - [0.0, 0.0, 5.0], 1.0).shape == (0, 3)


# -- exact depth ----------------------------------------------------------------------------------

def test_every_pixel_of_a_wall_facing_the_camera_has_its_distance(warp_full: WarpRenderer) -> None:
    pose = camera_pose(2.7, 1.5, 0.0, height=1.25)  # 1.3 m from the east wall, the box behind
    rgb, depth = warp_full.render(pose)
    assert rgb.shape == (FR1.height, FR1.width, 3) and rgb.dtype == np.uint8
    assert depth.shape == (FR1.height, FR1.width) and depth.dtype == np.float32
    assert np.all(depth == np.float32(4.0 - 2.7))
    assert np.all(reference(ROOM, FR1, pose)[1] == EAST_WALL)  # the wall fills the view


def test_depth_is_exact_at_a_box_corner(warp_full: WarpRenderer) -> None:
    pose = look_at((1.5, 0.4, 1.5), (2.0, 1.0, 0.8))  # from above, at the corner of x0, y0 and the top
    _, depth = warp_full.render(pose)
    expected, ids = reference(ROOM, FR1, pose)
    assert_depth_exact(depth, expected)
    around_corner = ids[FR1.height // 2 - 20:FR1.height // 2 + 20, FR1.width // 2 - 20:FR1.width // 2 + 20]
    assert {BOX_X0, BOX_Y0, BOX_TOP} <= set(np.unique(around_corner).tolist())


def test_a_face_crossing_the_near_plane_is_drawn_only_in_front(warp_full: WarpRenderer) -> None:
    # 5 cm from the box's x0 face, looking along it: the face starts behind the camera and runs
    # past it into the view, as do the floor and the walls beside the camera.
    pose = camera_pose(1.95, 1.2, 1.3)
    corner = pose[:3, :3].T @ ([2.0, 1.0, 0.0] - pose[:3, 3])  # in camera coordinates
    assert corner[2] < 0
    _, depth = warp_full.render(pose)
    expected, ids = reference(ROOM, FR1, pose)
    assert_depth_exact(depth, expected)
    assert np.count_nonzero(ids == BOX_X0) > 0.1 * ids.size and np.count_nonzero(ids == FLOOR) > 0
    assert depth.min() > NEAR_PLANE


def test_a_nearer_box_hides_a_farther_one_whatever_their_order() -> None:
    # The farther, taller box comes second, so it is drawn after the nearer one: only the
    # depth test keeps the nearer box in front.
    world = World(width=4.0, depth=3.0, wall_height=2.5,
                  boxes=(Box(1.5, 1.2, 1.9, 1.8, 0.6), Box(3.0, 0.8, 3.5, 2.2, 1.2)))
    pose = camera_pose(0.5, 1.5, 0.0)
    _, depth = WarpRenderer(world, FR1, seed=0).render(pose)
    expected, ids = reference(world, FR1, pose)
    assert_depth_exact(depth, expected)
    near_front, far_front = 6, 11  # the x0 faces of the two boxes (ids 6 + 5 * box + face)
    assert np.count_nonzero(ids == near_front) > 0.05 * ids.size
    assert np.count_nonzero(ids == far_front) > 0.05 * ids.size


def test_a_camera_a_tenth_of_a_millimetre_from_a_corner_sees_it_as_the_ray_caster_does(
        warp_small: WarpRenderer, ray_small: RoomRenderer) -> None:
    pose = tilted(3.9999, 2.9999, 2.0, 0.3, 0.0, height=2.4999)  # by the corner of two walls and the ceiling
    rgb, depth = warp_small.render(pose)
    expected, ids = reference(ROOM, SMALL, pose)
    assert_depth_exact(depth, expected)
    assert expected.min() < 1e-4  # surfaces this near are drawn, and coloured
    assert_frames_agree(ray_small.render(pose), (rgb, depth), expected, ids)


def test_nothing_in_front_of_the_camera_reads_zero_depth_and_black() -> None:
    renderer = WarpRenderer(World(width=2.0, depth=2.0, wall_height=2.0), SMALL, seed=0)
    rgb, depth = renderer.render(camera_pose(-1.0, 1.0, math.pi))  # outside the room, looking away
    assert not depth.any() and not rgb.any()


@settings(max_examples=examples(20), deadline=None)
@given(poses_in_the_room)
def test_depth_equals_a_float64_ray_cast_over_random_poses(warp_small: WarpRenderer,
                                                           p: tuple[float, ...]) -> None:
    pose = tilted(*p)
    _, depth = warp_small.render(pose)
    expected, ids = reference(ROOM, SMALL, pose)
    # Away from borders: a pixel centre within 1e-6 px of an edge may show either side.
    interior = away_from_borders(ids)
    assert_depth_exact(np.where(interior, depth, np.float32(1.0)), np.where(interior, expected, 1.0))


# -- the same frames as the ray caster -------------------------------------------------------------

def assert_frames_agree(ray: tuple[np.ndarray, np.ndarray], warp: tuple[np.ndarray, np.ndarray],
                        expected: np.ndarray, ids: np.ndarray) -> float:
    """Depth and colour agree on the pixels away from face borders; returns the largest
    relative depth difference there.

    Depth: within 1e-6 relative, or else within the ray caster's own error (its float32
    rays and slab arithmetic stray from the float64 value by up to a few 1e-6 at grazing
    angles and close to walls, while the warp renderer's depth is exact to float32 rounding).

    Colour: both sample the same atlas at the same mip levels, but the ray caster computes
    texel coordinates and level weights in float32 while ``cv2.warpPerspective`` works in
    float64, so interpolated values can round differently. Measured with OpenCV 5.0 over
    500 random poses: never more than 1 level. With OpenCV's fixed-point interpolation (1/32
    texel), a coordinate rounding to the neighbouring step moves a value by at most 255/32,
    hence the bound of 8 for every pixel, with all but 0.1% of them within 1 level.
    """
    (rgb_ray, depth_ray), (rgb_warp, depth_warp) = ray, warp
    interior = away_from_borders(ids)
    assert interior.mean() > 0.8
    relative = (np.abs(depth_warp.astype(np.float64) - depth_ray) / depth_ray)[interior]
    ray_error = (np.abs(depth_ray - expected) / expected)[interior]
    assert np.all((relative <= 1e-6) | (relative <= ray_error + 2 * FLOAT32_ROUNDING))
    difference = np.abs(rgb_warp.astype(np.int16) - rgb_ray).max(axis=2)[interior]
    assert difference.max() <= 8 and np.mean(difference > 1) < 1e-3 and difference.mean() < 0.1
    return float(relative.max())


@pytest.mark.slow  # the default room's textures take a second or two to paint, for each renderer
def test_frames_agree_with_the_ray_caster_on_poses_in_the_default_room() -> None:
    ray, warp = RoomRenderer(DEFAULT_WORLD, FR1, seed=0), WarpRenderer(DEFAULT_WORLD, FR1, seed=0)
    poses = [camera_pose(*p) for p in [(1.0, 1.0, 0.0), (4.3, 1.1, 1.0), (6.9, 2.9, 2.5), (7.4, 5.4, -2.4),
                                       (2.2, 3.0, 0.2), (4.75, 0.9, 0.0)]]
    poses += [tilted(1.5, 4.5, -0.8, 0.3, 0.2, height=1.4), tilted(4.4, 2.0, 2.9, -0.2, -0.3, height=0.3)]
    for pose in poses:
        largest = assert_frames_agree(ray.render(pose), warp.render(pose), *reference(DEFAULT_WORLD, FR1, pose))
        assert largest <= 1e-6  # level or mildly tilted views: the ray caster's float32 depth is that good here


@settings(max_examples=examples(20), deadline=None)
@given(poses_in_the_room)
def test_frames_agree_with_the_ray_caster_over_random_poses(ray_small: RoomRenderer, warp_small: WarpRenderer,
                                                            p: tuple[float, ...]) -> None:
    pose = tilted(*p)
    assert_frames_agree(ray_small.render(pose), warp_small.render(pose), *reference(ROOM, SMALL, pose))


# -- the renderer's contract ---------------------------------------------------------------------

def test_the_same_pose_renders_the_same_images(warp_small: WarpRenderer) -> None:
    pose = tilted(1.0, 1.0, 0.3, 0.1, -0.1)
    rgb1, depth1 = warp_small.render(pose)
    rgb2, depth2 = warp_small.render(pose)
    assert np.array_equal(rgb1, rgb2) and np.array_equal(depth1, depth2)


def test_a_world_with_too_many_boxes_is_refused() -> None:
    boxes = tuple(Box(0.1 * i, 0.0, 0.1 * i + 0.05, 0.05, 0.5) for i in range(51))
    with pytest.raises(ValueError, match=r"^the renderer supports at most 50 boxes, got 51$"):
        WarpRenderer(World(width=8.0, boxes=boxes), SMALL)
