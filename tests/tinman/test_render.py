"""The renderer: exact depth (checked against an independent ray caster and by
back-projection), textures that ORB can track, no aliasing, determinism."""

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
from tinman.world import DEFAULT_WORLD, Box, World

# A quarter-size FR1 keeps the tests fast; the geometry is the same.
SMALL = Intrinsics(fx=FR1.fx / 4, fy=FR1.fy / 4, cx=(FR1.cx + 0.5) / 4 - 0.5, cy=(FR1.cy + 0.5) / 4 - 0.5,
                   width=160, height=120)
ROOM = World(width=4.0, depth=3.0, wall_height=2.5, boxes=(Box(2.0, 1.0, 2.6, 1.8, 0.8),),
             start=(1.0, 1.0, 0.0))


@pytest.fixture(scope="module")
def small() -> RoomRenderer:
    return RoomRenderer(ROOM, SMALL, seed=3)


@pytest.fixture(scope="module")
def full() -> RoomRenderer:
    return RoomRenderer(DEFAULT_WORLD, FR1, seed=0)


def reference_depth(world: World, k: Intrinsics, t_wc: np.ndarray) -> np.ndarray:
    """Optical-axis depth by intersecting every rectangle of the scene (float64)."""
    u, v = np.meshgrid(np.arange(k.width, dtype=float), np.arange(k.height, dtype=float))
    rays = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones_like(u)])
    d = np.einsum("ij,jhw->ihw", t_wc[:3, :3], rays)
    o = t_wc[:3, 3]
    w, dp, h = world.width, world.depth, world.wall_height
    # (axis, value, bounds of the other two axes in order)
    rects = [(0, 0.0, (0, dp), (0, h)), (0, w, (0, dp), (0, h)), (1, 0.0, (0, w), (0, h)),
             (1, dp, (0, w), (0, h)), (2, 0.0, (0, w), (0, dp)), (2, h, (0, w), (0, dp))]
    for b in world.boxes:
        rects += [(0, b.x0, (b.y0, b.y1), (0, b.height)), (0, b.x1, (b.y0, b.y1), (0, b.height)),
                  (1, b.y0, (b.x0, b.x1), (0, b.height)), (1, b.y1, (b.x0, b.x1), (0, b.height)),
                  (2, b.height, (b.x0, b.x1), (b.y0, b.y1))]
    best = np.full(u.shape, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis, value, first, second in rects:
            t = (value - o[axis]) / d[axis]
            others = [a for a in range(3) if a != axis]
            p0 = o[others[0]] + t * d[others[0]]
            p1 = o[others[1]] + t * d[others[1]]
            inside = ((t > 0) & (p0 >= first[0] - 1e-9) & (p0 <= first[1] + 1e-9)
                      & (p1 >= second[0] - 1e-9) & (p1 <= second[1] + 1e-9))
            best = np.where(inside & (t < best), t, best)
    return best


free_poses = st.tuples(st.floats(0.3, 3.7), st.floats(0.3, 2.7), st.floats(-math.pi, math.pi),
                       st.floats(-0.3, 0.3), st.floats(-0.2, 0.2)).filter(
    lambda p: not ROOM.collides(p[0], p[1], 0.2))


def tilted(x: float, y: float, theta: float, pitch: float, roll: float) -> np.ndarray:
    """A camera pose with some pitch (about camera x) and roll (about camera z)."""
    pose = camera_pose(x, y, theta)
    cp, sp, cr, sr = math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
    about_x = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    about_z = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    pose[:3, :3] = pose[:3, :3] @ about_x @ about_z
    return pose


@settings(max_examples=examples(25), deadline=None)
@given(free_poses)
def test_depth_equals_an_independent_ray_cast(small: RoomRenderer, p: tuple[float, ...]) -> None:
    pose = tilted(*p)
    rgb, depth = small.render(pose)
    expected = reference_depth(ROOM, SMALL, pose)
    assert rgb.shape == (SMALL.height, SMALL.width, 3) and rgb.dtype == np.uint8
    assert depth.shape == (SMALL.height, SMALL.width) and depth.dtype == np.float32
    close = np.isclose(depth, expected, rtol=1e-5, atol=1e-5)
    # Only rays that graze an edge within float32 rounding may pick the other surface.
    assert close.mean() > 0.998, np.argwhere(~close)[:5]


def test_centre_depth_is_the_distance_to_the_wall_ahead(small: RoomRenderer) -> None:
    _, depth = small.render(camera_pose(0.7, 2.5, 0.0))  # looking +x along y = 2.5, past the box
    assert depth[SMALL.height // 2, SMALL.width // 2] == pytest.approx(4.0 - 0.7, abs=1e-5)
    # The wall is perpendicular to the optical axis: every pixel on it has that depth.
    assert np.count_nonzero(np.isclose(depth, 3.3, atol=1e-5)) > 0.3 * depth.size
    _, depth = small.render(camera_pose(2.3, 2.4, -math.pi / 2))  # looking -y at the box face y1
    assert depth[SMALL.height // 2, SMALL.width // 2] == pytest.approx(2.4 - 1.8, abs=1e-5)


def test_floor_pixels_have_the_depth_of_the_floor_plane(small: RoomRenderer) -> None:
    _, depth = small.render(camera_pose(0.5, 2.5, 0.0))  # the box is not in view
    rows = np.arange(SMALL.height)
    below = rows > SMALL.cy + 20  # rows that see the floor ahead, well below the horizon
    expected = 0.5 * SMALL.fy / (rows[below] - SMALL.cy)  # y_camera = height of the camera
    np.testing.assert_allclose(depth[below, SMALL.width // 2], expected, rtol=1e-5)


def back_project(depth: np.ndarray, k: Intrinsics, pose: np.ndarray, u: int, v: int) -> np.ndarray:
    z = float(depth[v, u])
    camera = np.array([(u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z, 1.0])
    return (pose @ camera)[:3]


def project(point: np.ndarray, k: Intrinsics, pose: np.ndarray) -> tuple[float, float]:
    camera = np.linalg.inv(pose) @ np.append(point, 1.0)
    return k.fx * camera[0] / camera[2] + k.cx, k.fy * camera[1] / camera[2] + k.cy


def test_a_point_seen_from_two_poses_lands_on_the_same_surface(small: RoomRenderer) -> None:
    first = camera_pose(0.8, 0.8, 0.4)
    second = camera_pose(1.2, 0.6, 0.7)
    _, depth1 = small.render(first)
    _, depth2 = small.render(second)
    seen_again = in_view = 0
    grid = [(u, v) for u in range(5, SMALL.width, 15) for v in range(5, SMALL.height, 15)]
    for u, v in grid:
        point = back_project(depth1, SMALL, first, u, v)
        # It lies on a surface of the room: a wall, the floor, the ceiling or the box.
        planes = [abs(point[0] - x) for x in (0.0, 4.0, 2.0, 2.6)] + [abs(point[1] - y) for y in (0.0, 3.0, 1.0, 1.8)]
        planes += [abs(point[2] - z) for z in (0.0, 2.5, 0.8)]
        assert min(planes) < 1e-4
        pu, pv = project(point, SMALL, second)
        iu, iv = round(pu), round(pv)
        if not (0 <= iu < SMALL.width and 0 <= iv < SMALL.height):
            continue
        in_view += 1
        # From the second pose, at the nearest pixel centre, either the same point shows up
        # (within a pixel's footprint on a slanted surface) or something nearer hides it.
        again = back_project(depth2, SMALL, second, iu, iv)
        z_second = (np.linalg.inv(second) @ np.append(point, 1.0))[2]
        if np.linalg.norm(again - point) < 4.0 * float(depth2[iv, iu]) / SMALL.fx:
            seen_again += 1
        else:
            assert depth2[iv, iu] < z_second - 0.05
    assert in_view > 30 and seen_again > 0.8 * in_view


def test_the_same_pose_renders_the_same_images_and_seeds_differ(small: RoomRenderer) -> None:
    pose = camera_pose(1.0, 1.0, 0.3)
    rgb1, depth1 = small.render(pose)
    rgb2, depth2 = small.render(pose)
    assert np.array_equal(rgb1, rgb2) and np.array_equal(depth1, depth2)
    other = RoomRenderer(ROOM, SMALL, seed=4)
    rgb3, depth3 = other.render(pose)
    assert np.array_equal(depth1, depth3)
    assert np.abs(rgb1.astype(int) - rgb3.astype(int)).mean() > 20


def test_no_aliasing_frames_match_supersampled_ones(small: RoomRenderer,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    # Rendered at four times the resolution and averaged down, a frame must look like the
    # directly rendered one; aliasing (texture detail finer than the pixels, which
    # shimmers as the camera moves) would make them differ.
    quad = Intrinsics(fx=SMALL.fx * 4, fy=SMALL.fy * 4, cx=(SMALL.cx + 0.5) * 4 - 0.5,
                      cy=(SMALL.cy + 0.5) * 4 - 0.5, width=640, height=480)
    fine_renderer = RoomRenderer(ROOM, quad, seed=3)
    poses = [camera_pose(0.4, 0.4, 0.6), camera_pose(3.5, 2.5, -2.5)]  # far walls, grazing floor
    references = [cv2.resize(fine_renderer.render(p)[0], (SMALL.width, SMALL.height),
                             interpolation=cv2.INTER_AREA).astype(float) for p in poses]

    def error() -> float:
        return float(np.mean([np.abs(small.render(p)[0] - ref).mean()
                              for p, ref in zip(poses, references, strict=True)]))

    mip_mapped = error()
    assert mip_mapped < 6.5
    monkeypatch.setattr("tinman.render.MIP_LEVELS", 1)  # finest level only: aliased
    assert error() > 2.5 * mip_mapped


@pytest.mark.slow  # the full-resolution renderer takes seconds to paint its textures
@pytest.mark.parametrize("pose", [(1.0, 1.0, 0.0), (4.3, 1.1, 1.0), (6.9, 2.9, 2.5), (7.4, 5.4, -2.4),
                                  (2.2, 3.0, 0.2), (4.75, 0.9, 0.0)])
def test_orb_finds_many_well_spread_features(full: RoomRenderer, pose: tuple[float, float, float]) -> None:
    rgb, _ = full.render(camera_pose(*pose))
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    keypoints = cv2.ORB_create(1000).detect(gray, None)
    assert len(keypoints) >= 600
    cells = {(int(k.pt[0] // 160), int(k.pt[1] // 120)) for k in keypoints}
    assert len(cells) >= 12  # of the 4 x 4 grid


@pytest.mark.slow  # the full-resolution renderer, as above
def test_orb_features_match_between_nearby_views_and_give_the_motion(full: RoomRenderer) -> None:
    first, second = camera_pose(1.0, 1.0, 0.2), camera_pose(1.04, 1.01, 0.23)
    rgb1, depth1 = full.render(first)
    rgb2, _ = full.render(second)
    orb = cv2.ORB_create(1000)
    k1, d1 = orb.detectAndCompute(cv2.cvtColor(rgb1, cv2.COLOR_RGB2GRAY), None)
    k2, d2 = orb.detectAndCompute(cv2.cvtColor(rgb2, cv2.COLOR_RGB2GRAY), None)
    matches = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(d1, d2)
    points = np.array([back_project(depth1, FR1, np.eye(4), round(k1[m.queryIdx].pt[0]),
                                    round(k1[m.queryIdx].pt[1])) for m in matches])
    pixels = np.array([k2[m.trainIdx].pt for m in matches])
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(points, pixels, FR1.matrix(), None, reprojectionError=2.0)
    assert ok and len(inliers) > 200
    rotation, _ = cv2.Rodrigues(rvec)
    motion = np.eye(4)
    motion[:3, :3], motion[:3, 3] = rotation, tvec.ravel()
    estimate = first @ np.linalg.inv(motion)
    assert np.linalg.norm(estimate[:3, 3] - second[:3, 3]) < 0.005


def test_a_world_with_too_many_boxes_is_refused() -> None:
    boxes = tuple(Box(0.1 * i, 0.0, 0.1 * i + 0.05, 0.05, 0.5) for i in range(51))
    with pytest.raises(ValueError, match=r"^the renderer supports at most 50 boxes, got 51$"):
        RoomRenderer(World(width=8.0, boxes=boxes), SMALL)
