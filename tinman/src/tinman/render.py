"""Ray-cast RGB-D frames of a :class:`~tinman.world.World` with numpy.

The room is a closed box (floor, ceiling, four walls) with the world's boxes
standing in it. Every pixel's ray is intersected with the room's planes and with
each box (slab test), all pixels at once; the nearest hit gives the depth (exact
at the pixel centre, along the optical axis) and the surface. Colour comes from
one texture atlas (:mod:`tinman.textures`) sampled with ``cv2.remap``: trilinear
between mip levels chosen from each pixel's footprint on its surface, so far and
grazing surfaces do not shimmer; pixels where two surfaces meet are supersampled,
so silhouettes do not crawl either. Lighting is baked into the textures
(Lambertian: it depends only on the surface point), so a point looks the same
from every viewpoint, as visual odometry assumes; ``render(..., lamp_gains=...)``
relights a frame for lamps that are dimmer or brighter than the textures were lit
with (the ratio of the two irradiances at each pixel's surface point).

Speed notes: ray directions are sums of a row and a column vector (no per-pixel
matrix product), per-surface constants are gathered with ``cv2.LUT`` from the
8-bit surface id, selections are arithmetic rather than ``np.where``, and the
atlas has four channels because ``cv2.remap`` is much faster on those.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import cv2
import numpy as np

from .geometry import FR1, Intrinsics
from .textures import MAX_SURFACES, MIP_LEVELS, Atlas, Surface, build_atlas, room_surfaces
from .world import World

__all__ = ["RoomRenderer", "painted_surfaces"]

# Sub-pixel offsets for supersampling the pixels on surface borders (a rotated grid).
_SUBSAMPLES = np.array([[-0.375, -0.125], [0.125, -0.375], [0.375, 0.125], [-0.125, 0.375]],
                       dtype=np.float32)
_F = np.float32
# Mip level offset: -0.75 makes frames closest to 16-times supersampled ones (mean
# error 4.3 levels against 9.2 at 0 and 15 without mip-mapping, measured over four views
# of a test room); -1 is as close but starts to alias, and shimmer would hurt tracking.
_LEVEL_BIAS = -0.75


def painted_surfaces(world: World, seed: int, paint: Callable[[World, list[Surface], int], Atlas] = build_atlas,
                     ) -> tuple[list[Surface], Atlas]:
    """The room's surfaces and their textures, painted once from ``seed``: what every renderer
    samples.

    Raises:
        ValueError: the world has more boxes than the renderers support.
    """
    surfaces = room_surfaces(world)
    if len(surfaces) > MAX_SURFACES:
        raise ValueError(f"the renderer supports at most {(MAX_SURFACES - 6) // 5} boxes, got {len(world.boxes)}")
    return surfaces, paint(world, surfaces, seed)


class RoomRenderer:
    """Renders colour and depth images of a world from camera poses.

    The textures are painted once, from ``seed``, when the renderer is built (a
    second or two for the default room); rendering is then deterministic: the same
    pose always gives the same images.

    Args:
        world: the room and its boxes (at most 50 boxes).
        intrinsics: the pinhole camera, image size included.
        seed: the seed of the procedural textures.
        paint: paints the textures: :func:`tinman.textures.build_atlas` (the easy room's
            procedural ones, the default) or another function with its signature (e.g.
            :func:`tinman.realistic.build_realistic_atlas`).

    Raises:
        ValueError: the world has more boxes than the renderer supports.
    """

    def __init__(self, world: World, intrinsics: Intrinsics = FR1, seed: int = 0, *,
                 paint: Callable[[World, list[Surface], int], Atlas] = build_atlas) -> None:
        self.world = world
        self.intrinsics = intrinsics
        self.seed = seed
        self.surfaces, self._atlas = painted_surfaces(world, seed, paint)
        self._normal_sign = np.zeros(MAX_SURFACES, np.float32)
        self._normal_sign[:len(self.surfaces)] = [surface.normal for surface in self.surfaces]
        k = intrinsics
        self._focal = math.sqrt(k.fx * k.fy)
        # Camera-frame ray (x, y, 1) of each pixel centre: x varies along rows, y down columns.
        self._ray_x = ((np.arange(k.width) - k.cx) / k.fx).astype(_F)[None, :]
        self._ray_y = ((np.arange(k.height) - k.cy) / k.fy).astype(_F)[:, None]
        self._log2_stretch = np.log2((self._ray_x ** 2 + self._ray_y ** 2 + 1) / self._focal).astype(_F)
        self._box_lo = np.array([[b.x0, b.y0, 0.0] for b in world.boxes]).reshape(-1, 3)
        self._box_hi = np.array([[b.x1, b.y1, b.height] for b in world.boxes]).reshape(-1, 3)
        self._room_hi = np.array([world.width, world.depth, world.wall_height])

    def render(self, t_wc: np.ndarray, lamp_gains: Sequence[float] | np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
        """The colour and depth images seen by a camera.

        Args:
            t_wc: 4x4 camera-to-world pose (optical frame: x right, y down, z forward);
                the camera must be inside the room and outside every box.
            lamp_gains: each lamp's brightness now, one per lamp of the textures' lighting
                (1: as the textures were lit). None (the default) or all ones: the frame as lit.

        Returns:
            ``(rgb, depth)``: ``uint8 (H, W, 3)`` in RGB order, and ``float32 (H, W)``
            metres along the optical axis (every pixel sees a surface: no zeros).

        Raises:
            ValueError: ``lamp_gains`` has not one gain per lamp, or the textures record no lighting.
        """
        pose = np.asarray(t_wc, dtype=np.float64)
        rotation, origin = pose[:3, :3], pose[:3, 3]
        dirs = [(_F(rotation[a, 0]) * self._ray_x + _F(rotation[a, 2])) + _F(rotation[a, 1]) * self._ray_y
                for a in range(3)]
        depth, ids, axis = self._cast(origin, dirs, pose)
        rgba = self._shade(origin, dirs, depth, ids, axis, self._log2_stretch)
        self._antialias_borders(rgba, origin, rotation, ids)
        rgb = cv2.cvtColor(rgba, cv2.COLOR_RGBA2RGB)
        if lamp_gains is not None:
            rgb = self._relight(rgb, origin, dirs, depth, ids, axis, np.asarray(lamp_gains, dtype=np.float64))
        return rgb, depth

    def _relight(self, rgb: np.ndarray, origin: np.ndarray, dirs: list[np.ndarray], t: np.ndarray,
                 ids: np.ndarray, axis: np.ndarray, gains: np.ndarray) -> np.ndarray:
        """The frame with the lamps at ``gains``: each pixel times the ratio of its surface point's
        irradiance then to the one baked into the textures."""
        lighting = self._atlas.lighting
        if lighting is None:
            raise ValueError("these textures record no lighting, so lamp_gains cannot relight them")
        if gains.shape != (len(lighting.lamps),):
            raise ValueError(f"expected one gain per lamp ({len(lighting.lamps)}), got {gains.tolist()}")
        if np.all(gains == 1.0):
            return rgb
        point = np.stack([_F(origin[a]) + t * dirs[a] for a in range(3)])
        sign = self._atlas.lookup(ids, self._normal_sign)
        normal = np.stack([sign * (axis == a) for a in range(3)])
        ratio = lighting.relit(point, normal, gains)
        lit: np.ndarray = cv2.multiply(rgb, cv2.merge([ratio, ratio, ratio]), dtype=cv2.CV_8U)
        return lit

    # -- ray casting --------------------------------------------------------------------------

    def _cast(self, origin: np.ndarray, dirs: list[np.ndarray],
              pose: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest hits of the rays ``origin + t * dirs``.

        Returns ``t`` (float32; it is the optical-axis depth, as every ray has camera
        z = 1), the surface id and the axis of the plane hit (both uint8). With a
        ``pose`` the rays are the full image and each box is only tested on the pixels
        inside its projected bounding rectangle.
        """
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            inverse = [np.reciprocal(d) for d in dirs]
            # Inside the room, the ray leaves through one of the planes ahead of it on each
            # axis: the far plane gives t > 0 and the near one t < 0, so take the larger.
            t_axis = [np.maximum(_F(self._room_hi[a] - origin[a]) * inverse[a], _F(-origin[a]) * inverse[a])
                      for a in range(3)]
            positive = [(d > 0).view(np.uint8) for d in dirs]
            first = (t_axis[1] < t_axis[0]).view(np.uint8)
            t = np.minimum(t_axis[0], t_axis[1])
            side = positive[0] ^ (first & (positive[0] ^ positive[1]))
            second = (t_axis[2] < t).view(np.uint8)
            np.minimum(t, t_axis[2], out=t)
            side ^= second & (side ^ positive[2])
            axis = first + second * (np.uint8(2) - first)
            ids = axis * np.uint8(2) + side
            for b in range(len(self._box_lo)):
                window = self._box_window(b, pose) if pose is not None else (slice(None),)
                if window is not None:
                    self._cast_box(b, origin, inverse, t, ids, axis, window)
        return t, ids, axis

    def _cast_box(self, b: int, origin: np.ndarray, inverse: list[np.ndarray], t: np.ndarray,
                  ids: np.ndarray, axis: np.ndarray, window: tuple[slice, ...]) -> None:
        """Slab test of box ``b`` on the rays in ``window``; updates the hits in place."""
        lo = self._box_lo[b] - origin
        hi = self._box_hi[b] - origin
        slabs = []
        for a in range(3):
            inv = inverse[a][window]
            t_lo = _F(lo[a]) * inv
            t_hi = _F(hi[a]) * inv
            slabs.append((np.minimum(t_lo, t_hi), np.maximum(t_lo, t_hi), (inv < 0).view(np.uint8)))
        near, far, going_back = slabs[0]
        enter_axis = np.zeros(near.shape, np.uint8)
        for a in (1, 2):
            t_in, t_out, backwards = slabs[a]
            later = (t_in > near).view(np.uint8)
            np.maximum(near, t_in, out=near)
            np.minimum(far, t_out, out=far)
            enter_axis += later * (np.uint8(a) - enter_axis)
            # Which of the two faces: x0 or x1, y0 or y1; along z only the top is entered.
            # (uint8 arithmetic wraps, so "+= later * (new - old)" selects exactly.)
            going_back += later * ((backwards if a == 1 else np.uint8(0)) - going_back)
        t_window = t[window]
        hit = (near <= far) & (near > 0) & (near < t_window)
        if not hit.any():
            return
        np.copyto(t_window, near, where=hit)
        # Face ids 6 + 5 b + (0 x0, 1 x1, 2 y0, 3 y1, 4 top); a ray going -x enters at x1.
        face = np.uint8(6 + 5 * b) + enter_axis * np.uint8(2) + going_back
        np.copyto(ids[window], face, where=hit)
        np.copyto(axis[window], enter_axis, where=hit)

    def _box_window(self, b: int, pose: np.ndarray) -> tuple[slice, slice] | None:
        """The image rectangle that can show box ``b`` (None when it is out of view)."""
        lo, hi = self._box_lo[b], self._box_hi[b]
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        camera = (corners - pose[:3, 3]) @ pose[:3, :3]  # world -> camera coordinates
        near_plane = 1e-3
        points = [c for c in camera if c[2] >= near_plane]
        # Clip the box's edges at the near plane, so corners behind the camera still bound it.
        for i in range(8):
            for j in range(i + 1, 8):
                if np.count_nonzero(corners[i] != corners[j]) == 1:
                    zi, zj = camera[i][2], camera[j][2]
                    if (zi - near_plane) * (zj - near_plane) < 0:
                        s = (near_plane - zi) / (zj - zi)
                        points.append(camera[i] + s * (camera[j] - camera[i]))
        if not points:
            return None
        p = np.array(points)
        k = self.intrinsics
        u = k.fx * p[:, 0] / p[:, 2] + k.cx
        v = k.fy * p[:, 1] / p[:, 2] + k.cy
        c0, c1 = max(0, math.floor(u.min()) - 1), min(k.width, math.ceil(u.max()) + 2)
        r0, r1 = max(0, math.floor(v.min()) - 1), min(k.height, math.ceil(v.max()) + 2)
        if c0 >= c1 or r0 >= r1:
            return None
        return slice(r0, r1), slice(c0, c1)

    # -- colour ------------------------------------------------------------------------------

    def _shade(self, origin: np.ndarray, dirs: list[np.ndarray], t: np.ndarray, ids: np.ndarray,
               axis: np.ndarray, log2_stretch: np.ndarray) -> np.ndarray:
        """Texture colour at the hits: uint8 RGBA, shape of ``t`` plus 4.

        ``log2_stretch`` is log2(|ray|^2 / focal) per ray, so that the footprint of a
        pixel on its surface, distance / (focal * cos(incidence)), is
        ``t * 2^log2_stretch / |normal component of the ray|``.
        """
        atlas = self._atlas
        on_x = (axis == 0).view(np.uint8).astype(_F)
        on_z = (axis == 2).view(np.uint8).astype(_F)
        dx, dy, dz = dirs
        # In-plane coordinates: axis 0 -> (h, v) = (y, z), axis 1 -> (x, z), axis 2 -> (x, y).
        h = (_F(origin[0]) + on_x * _F(origin[1] - origin[0])) + t * (dx + on_x * (dy - dx))
        v = (_F(origin[2]) + on_z * _F(origin[1] - origin[2])) + t * (dz + on_z * (dy - dz))
        col = h * atlas.lookup(ids, atlas.scale_h) + atlas.lookup(ids, atlas.offset_h)
        row = v * atlas.lookup(ids, atlas.scale_v) + atlas.lookup(ids, atlas.offset_v)
        normal_component = np.abs(dy + on_x * (dx - dy) + on_z * (dz - dy))
        np.maximum(normal_component, _F(1e-6), out=normal_component)
        level = (np.log2(t) - np.log2(normal_component) + log2_stretch
                 + atlas.lookup(ids, atlas.log2_inv_texel) + _F(_LEVEL_BIAS))
        np.clip(level, 0.0, MIP_LEVELS - 1, out=level)
        return atlas.sample(col, row, level)

    def _antialias_borders(self, rgba: np.ndarray, origin: np.ndarray, rotation: np.ndarray,
                           ids: np.ndarray) -> None:
        """Replace the pixels where surfaces meet by the mean of four sub-pixel rays."""
        border = np.zeros(ids.shape, dtype=bool)
        across = ids[:, 1:] != ids[:, :-1]
        border[:, 1:] |= across
        border[:, :-1] |= across
        down = ids[1:, :] != ids[:-1, :]
        border[1:, :] |= down
        border[:-1, :] |= down
        rows, cols = np.nonzero(border)
        if rows.size == 0:
            return
        k = self.intrinsics
        ray_x = ((cols.astype(_F)[:, None] + _SUBSAMPLES[:, 0] - _F(k.cx)) / _F(k.fx)).ravel()
        ray_y = ((rows.astype(_F)[:, None] + _SUBSAMPLES[:, 1] - _F(k.cy)) / _F(k.fy)).ravel()
        dirs = [_F(rotation[a, 0]) * ray_x + _F(rotation[a, 1]) * ray_y + _F(rotation[a, 2]) for a in range(3)]
        t, sub_ids, axis = self._cast(origin, dirs, None)
        # Half the pixel spacing: one mip level finer (log2 0.5 = -1).
        stretch = np.log2((ray_x ** 2 + ray_y ** 2 + 1) / self._focal) - _F(1.0)
        colour = self._shade(origin, dirs, t, sub_ids, axis, stretch)
        mean = colour.reshape(-1, len(_SUBSAMPLES), 4).astype(_F).mean(axis=1)
        rgba[rows, cols] = (mean + _F(0.5)).astype(np.uint8)
