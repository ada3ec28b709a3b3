"""Render RGB-D frames of a :class:`~tinman.world.World` by warping each face's texture.

A sibling of the ray caster :class:`tinman.render.RoomRenderer` for rendering live:
the same constructor, the same ``render``, the same textures and intrinsics. The
room is made of planar rectangles (walls, floor, ceiling, box faces), so instead
of intersecting every pixel's ray with the scene, each face that faces the
camera is

1. clipped against the near plane in camera space (a face reaching behind the
   camera must not fold over) and rasterised: each image row gets the span of
   pixel centres inside the face, from the face's edge planes through the camera
   centre, in float64;
2. depth tested: its inverse depth is affine in the pixel coordinates (for the
   plane ``n . X = s`` in camera coordinates, ``1 / z = n . K^-1 [u, v, 1] / s``), so
   the nearest face per pixel is kept in a float64 buffer, and the depth is its
   reciprocal rounded once to float32: exact at the pixel centre, not interpolated;
3. textured with ``cv2.warpPerspective``: the homography from image pixels to the
   face's texels in the atlas of :mod:`tinman.textures`, one warp per mip level
   the face needs, blended per pixel as the ray caster blends its two samples
   (the same level formula and bias, the same atlas, so the same baked-in lighting).

What differs from the ray caster: pixels on the borders between faces are not
supersampled (each shows the face its centre sees, so silhouettes are aliased);
surfaces nearer than ``NEAR_PLANE`` (a micrometre) are not drawn (depth 0, black);
and depth is exact to float32 rounding, where the ray caster's float32 arithmetic
strays by up to a few 1e-6 relative at grazing angles. Elsewhere colours agree
within a level and depths within 1e-6.

Speed: both renderers spend most of a frame sampling textures (two bilinear
taps and a blend per pixel), which warping does not make cheaper; it saves the
per-pixel ray arithmetic and the border supersampling (``bench/render.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .geometry import FR1, Intrinsics
from .render import (
    _LEVEL_BIAS,  # the ray caster's mip bias: both renderers must pick the same levels
    painted_surfaces,
)
from .textures import MAX_SURFACES, MIP_LEVELS, Atlas, Surface
from .world import World

__all__ = ["NEAR_PLANE", "WarpRenderer", "clip_to_near_plane"]

NEAR_PLANE = 1e-6  # metres along the optical axis
# Pixels: edges are widened by this much, so faces that share an edge leave no gap between
# them; where they overlap either is right (along a shared edge both have the same depth).
_EDGE_SLACK = 1e-6
# The in-plane axes (h, v) of a surface on each axis, as in tinman.textures.
_IN_PLANE = ((1, 2), (0, 2), (0, 1))
_ROOM_FACES = 6  # surfaces 0-5 are the walls, the floor and the ceiling (tinman.textures.room_surfaces)


@dataclass(frozen=True, eq=False)
class _Face:
    """A textured rectangle and what its warps need that does not depend on the pose."""

    id: int
    in_room: bool               # a wall, the floor or the ceiling: seen from inside, they never overlap
    axis: int
    value: float
    normal: int
    corners: np.ndarray         # (4, 3) world points, counter-clockwise seen from the visible side
    plane_to_texels: np.ndarray  # 3x3: in-plane (h, v, 1) -> level-0 atlas texel (col, row, 1)
    log2_inv_texel: float


class WarpRenderer:
    """Renders colour and depth images of a world from camera poses, one warp per face and mip level.

    Interchangeable with :class:`tinman.render.RoomRenderer`: the same arguments, the same
    textures (painted once from ``seed``), the same images up to the differences listed in
    the module's docstring.

    Args:
        world: the room and its boxes (at most 50 boxes).
        intrinsics: the pinhole camera, image size included.
        seed: the seed of the procedural textures.

    Raises:
        ValueError: the world has more boxes than the renderer supports.
    """

    def __init__(self, world: World, intrinsics: Intrinsics = FR1, seed: int = 0) -> None:
        self.world = world
        self.intrinsics = intrinsics
        self.seed = seed
        self.surfaces, self._atlas = painted_surfaces(world, seed)
        self._faces = [_face(i, s, self._atlas) for i, s in enumerate(self.surfaces)]
        k = intrinsics
        self._k_inverse = np.array([[1 / k.fx, 0.0, -k.cx / k.fx], [0.0, 1 / k.fy, -k.cy / k.fy], [0.0, 0.0, 1.0]])
        self._columns = np.arange(k.width, dtype=np.float64)
        # Row f + 1 of these tables is "column >= f" and "column <= f" (f from -1 to the width): a
        # face's mask is one row per image row taken from each, which is much faster than comparing.
        bounds = np.arange(-1, k.width + 1)[:, None]
        self._from_column = self._columns[None, :] >= bounds
        self._to_column = self._columns[None, :] <= bounds
        ray_x = ((np.arange(k.width) - k.cx) / k.fx)[None, :]
        ray_y = ((np.arange(k.height) - k.cy) / k.fy)[:, None]
        # log2(|ray|^2 / focal), as the ray caster's footprint of a pixel.
        self._log2_stretch = np.log2((ray_x ** 2 + ray_y ** 2 + 1) / math.sqrt(k.fx * k.fy)).astype(np.float32)
        # Level k of level-0 texel coordinates: scaled by 2^-k and moved to where level k is in the atlas.
        # (The offsets are the ones Atlas.sample uses, so both renderers sample the same texels.)
        column_offset, row_offset = self._atlas._column_offset, self._atlas._row_offset
        self._level_maps = [np.array([[2.0 ** -level, 0.0, column_offset[level]],
                                      [0.0, 2.0 ** -level, row_offset[level]], [0.0, 0.0, 1.0]])
                            for level in range(MIP_LEVELS)]

    def render(self, t_wc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The colour and depth images seen by a camera.

        Args:
            t_wc: 4x4 camera-to-world pose (optical frame: x right, y down, z forward);
                the camera must be inside the room and outside every box.

        Returns:
            ``(rgb, depth)``: ``uint8 (H, W, 3)`` in RGB order, and ``float32 (H, W)``
            metres along the optical axis (0 only where no surface is at least
            ``NEAR_PLANE`` ahead, which a camera inside the room never has).
        """
        pose = np.asarray(t_wc, dtype=np.float64)
        rotation, origin = pose[:3, :3], pose[:3, 3]
        k = self.intrinsics
        inverse_depth = np.zeros((k.height, k.width))
        labels = np.zeros((k.height, k.width), np.uint8)
        drawn = []
        for face in self._faces:
            window = self._rasterise(face, rotation, origin, inverse_depth, labels)
            if window is not None:
                drawn.append((face, window))
        depth, holes = _reciprocal(inverse_depth)
        rgba = self._texture(drawn, rotation, origin, depth, labels)
        if holes is not None:
            rgba[holes] = 0
        return cv2.cvtColor(rgba, cv2.COLOR_RGBA2RGB), depth

    # -- visibility ---------------------------------------------------------------------------

    def _rasterise(self, face: _Face, rotation: np.ndarray, origin: np.ndarray, inverse_depth: np.ndarray,
                   labels: np.ndarray) -> tuple[slice, slice] | None:
        """Depth-test ``face`` into ``inverse_depth`` and ``labels``; the window it covers, if any."""
        distance = face.value - origin[face.axis]  # to the face's plane, signed along its axis
        if distance * face.normal >= 0:  # the camera is behind the face, or in its plane
            return None
        polygon = clip_to_near_plane((face.corners - origin) @ rotation, NEAR_PLANE)
        if len(polygon) < 3:
            return None
        spans = _row_spans(polygon, self._k_inverse, self.intrinsics)
        if spans is None:
            return None
        first_row, first, last = spans
        rows = slice(first_row, first_row + len(first))
        columns = slice(int(first.min()), int(last.max()) + 1)
        a, b, c = rotation[face.axis] @ self._k_inverse / distance
        inverse = np.add.outer(b * np.arange(rows.start, rows.stop, dtype=np.float64) + c,
                               a * self._columns[columns])
        nearer = np.take(self._from_column[:, columns], first + 1, axis=0)
        nearer &= np.take(self._to_column[:, columns], last + 1, axis=0)
        target = inverse_depth[rows, columns]
        if not face.in_room:  # the room's faces come first and tile the view: no test among them
            nearer &= inverse > target
        cv2.copyTo(inverse, nearer.view(np.uint8), target)
        cv2.copyTo(np.full(nearer.shape, face.id, np.uint8), nearer.view(np.uint8), labels[rows, columns])
        return rows, columns

    # -- colour -------------------------------------------------------------------------------

    def _texture(self, drawn: list[tuple[_Face, tuple[slice, slice]]], rotation: np.ndarray, origin: np.ndarray,
                 depth: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """The RGBA image: each face's pixels warped from its texture, trilinear between mip levels."""
        level = self._levels(depth, labels, origin)
        low = level.astype(np.uint8)  # floor: levels are >= 0
        fraction = level - low
        keep = np.float32(1.0) - fraction
        rgba = np.zeros((*labels.shape, 4), np.uint8)
        for face, window in drawn:
            mine = labels[window] == face.id
            low_window = low[window]
            finest, coarsest, _, _ = cv2.minMaxLoc(low_window, mine.view(np.uint8))
            image_to_plane = self._image_to_plane(face, rotation, origin)
            for lower in range(int(finest), int(coarsest) + 1):
                band = mine if finest == coarsest else mine & (low_window == lower)
                box = _bounding_box(band)
                if box is None:  # no pixel of the face needs this level
                    continue
                target = (slice(window[0].start + box[0].start, window[0].start + box[0].stop),
                          slice(window[1].start + box[1].start, window[1].start + box[1].stop))
                colour = self._warp(face, image_to_plane, lower, target)
                if lower < MIP_LEVELS - 1:
                    coarser = self._warp(face, image_to_plane, lower + 1, target)
                    colour = cv2.blendLinear(colour, coarser, keep[target], fraction[target])
                cv2.copyTo(colour, band[box].view(np.uint8), rgba[target])
        return rgba

    def _levels(self, depth: np.ndarray, labels: np.ndarray, origin: np.ndarray) -> np.ndarray:
        """The ray caster's mip level per pixel, in ``[0, MIP_LEVELS - 1]`` (float32).

        The ray caster's level is log2(z / |ray's normal component| * |ray|^2 / focal / texel)
        plus a bias; on a plane at signed distance ``s`` along its axis the normal component
        is ``|s| / z``, so the level is ``2 log2 z + log2 stretch + (log2(1 / texel) - log2 |s| + bias)``.
        """
        constant = np.zeros(MAX_SURFACES, np.float32)
        for face in self._faces:
            distance = max(abs(face.value - float(origin[face.axis])), 1e-12)
            constant[face.id] = face.log2_inv_texel - math.log2(distance) + _LEVEL_BIAS
        with np.errstate(divide="ignore"):
            level: np.ndarray = np.log2(depth)
        level *= np.float32(2.0)
        level += self._log2_stretch
        level += cv2.LUT(labels, constant).reshape(labels.shape)
        np.clip(level, 0.0, MIP_LEVELS - 1, out=level)
        return level

    def _image_to_plane(self, face: _Face, rotation: np.ndarray, origin: np.ndarray) -> np.ndarray:
        """The homography from pixels to the in-plane coordinates ``(h, v)`` of the face's plane.

        The ray ``D = R K^-1 [u, v, 1]`` meets the plane ``X[axis] = value`` at
        ``origin + s D / D[axis]`` (``s = value - origin[axis]``), so in homogeneous coordinates
        ``(h, v, 1) ~ (s D[h] + origin[h] D[axis], s D[v] + origin[v] D[axis], D[axis])``.
        """
        h_axis, v_axis = _IN_PLANE[face.axis]
        distance = face.value - origin[face.axis]
        to_plane = np.zeros((3, 3))
        to_plane[0, h_axis] = to_plane[1, v_axis] = distance
        to_plane[0, face.axis] = origin[h_axis]
        to_plane[1, face.axis] = origin[v_axis]
        to_plane[2, face.axis] = 1.0
        result: np.ndarray = to_plane @ rotation @ self._k_inverse
        return result

    def _warp(self, face: _Face, image_to_plane: np.ndarray, level: int,
              target: tuple[slice, slice]) -> np.ndarray:
        """The face's texture at mip ``level`` over the image rectangle ``target`` (uint8 RGBA)."""
        shift = np.array([[1.0, 0.0, target[1].start], [0.0, 1.0, target[0].start], [0.0, 0.0, 1.0]])
        image_to_texels = self._level_maps[level] @ face.plane_to_texels @ image_to_plane @ shift
        size = (target[1].stop - target[1].start, target[0].stop - target[0].start)
        return cv2.warpPerspective(self._atlas.image, image_to_texels, size,
                                   flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)


def clip_to_near_plane(polygon: np.ndarray, near: float) -> np.ndarray:
    """The part of a convex polygon with ``z >= near`` (Sutherland-Hodgman), in the same order.

    Args:
        polygon: ``(n, 3)`` camera-space vertices, in order around the polygon.
        near: the near plane's depth.

    Returns:
        ``(m, 3)`` vertices, ``m`` from 0 (all behind) to ``n + 1``.
    """
    ahead = polygon[:, 2] >= near
    if ahead.all():
        return polygon
    kept = []
    for i, start in enumerate(polygon):
        end = polygon[(i + 1) % len(polygon)]
        if ahead[i]:
            kept.append(start)
        if ahead[i] != ahead[(i + 1) % len(polygon)]:
            crossing = start + (near - start[2]) / (end[2] - start[2]) * (end - start)
            crossing[2] = near
            kept.append(crossing)
    return np.array(kept, dtype=np.float64).reshape(-1, 3)


def _row_spans(polygon: np.ndarray, k_inverse: np.ndarray,
               k: Intrinsics) -> tuple[int, np.ndarray, np.ndarray] | None:
    """The pixels whose centres see a convex polygon in front of the camera, row by row.

    Each edge and the camera centre span a plane; a pixel's ray passes through the
    polygon when it is on the inner side of every such plane, a half-plane of the image,
    ``alpha u + beta v + gamma >= 0``. (The polygon must be counter-clockwise seen from the camera.)

    Returns:
        ``(first_row, first, last)``: the first row with pixels inside and, for it and every
        row after it that has any, the first and last columns (int32 arrays); None if no pixel.
    """
    image_rows = k.fy * polygon[:, 1] / polygon[:, 2] + k.cy
    top = max(0, math.ceil(float(image_rows.min()) - _EDGE_SLACK))
    bottom = min(k.height - 1, math.floor(float(image_rows.max()) + _EDGE_SLACK))
    if top > bottom:
        return None
    v = np.arange(top, bottom + 1, dtype=np.float64)
    lines = _edge_lines(polygon, k_inverse)
    alpha = lines[:, :1]
    offset = np.multiply.outer(lines[:, 1], v) + (lines[:, 2:] + _EDGE_SLACK)  # inside: alpha u + offset >= 0
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = offset / -alpha
    lower = np.where(alpha > 0, bound, 0.0).max(axis=0)
    upper = np.where(alpha < 0, bound, k.width - 1.0).min(axis=0)
    upper[((alpha == 0) & (offset < 0)).any(axis=0)] = -1.0  # outside a horizontal edge: the whole row
    first = np.ceil(np.clip(lower, -1, k.width)).astype(np.int32)
    last = np.floor(np.clip(upper, -1, k.width)).astype(np.int32)
    rows = np.flatnonzero(first <= last)
    if rows.size == 0:
        return None
    keep = slice(int(rows[0]), int(rows[-1]) + 1)
    return top + keep.start, first[keep], last[keep]


def _edge_lines(polygon: np.ndarray, k_inverse: np.ndarray) -> np.ndarray:
    """Per edge, ``(alpha, beta, gamma)``: ``alpha u + beta v + gamma`` is the signed distance in
    pixels of ``(u, v)`` from the edge's image line, positive inside (repeated vertices give none)."""
    start, end = polygon, np.roll(polygon, -1, axis=0)
    normals = np.empty_like(polygon)  # end x start: a normal of the plane through the camera and the edge
    normals[:, 0] = end[:, 1] * start[:, 2] - end[:, 2] * start[:, 1]
    normals[:, 1] = end[:, 2] * start[:, 0] - end[:, 0] * start[:, 2]
    normals[:, 2] = end[:, 0] * start[:, 1] - end[:, 1] * start[:, 0]
    lines = normals @ k_inverse
    size = np.hypot(lines[:, 0], lines[:, 1])
    present = size > 0
    result: np.ndarray = lines[present] / size[present, None]
    return result


def _reciprocal(inverse_depth: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Depth from inverse depth, rounded once to float32, and where nothing was drawn (None:
    nowhere); the depth is 0 there."""
    depth = np.empty(inverse_depth.shape, np.float32)
    with np.errstate(divide="ignore"):
        np.divide(1.0, inverse_depth, out=depth, casting="unsafe")
    if inverse_depth.all():
        return depth, None
    holes = inverse_depth == 0
    depth[holes] = 0.0
    return depth, holes


def _bounding_box(mask: np.ndarray) -> tuple[slice, slice] | None:
    """The smallest rectangle holding every true pixel of ``mask``; None if there is none."""
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    columns = np.flatnonzero(mask.any(axis=0))
    return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(columns[0]), int(columns[-1]) + 1)


def _face(index: int, surface: Surface, atlas: Atlas) -> _Face:
    """The face of ``surface`` (id ``index``): corners in counter-clockwise order and texel map."""
    h_axis, v_axis = _IN_PLANE[surface.axis]
    corners = np.zeros((4, 3))
    corners[:, surface.axis] = surface.value
    (h0, h1), (v0, v1) = surface.h_range, surface.v_range
    corners[:, h_axis] = (h0, h1, h1, h0)
    corners[:, v_axis] = (v0, v0, v1, v1)
    visible_side = np.zeros(3)
    visible_side[surface.axis] = surface.normal
    if np.cross(corners[1] - corners[0], corners[2] - corners[1]) @ visible_side < 0:
        corners = corners[::-1].copy()
    plane_to_texels = np.array([[atlas.scale_h[index], 0.0, atlas.offset_h[index]],
                                [0.0, atlas.scale_v[index], atlas.offset_v[index]], [0.0, 0.0, 1.0]])
    return _Face(index, index < _ROOM_FACES, surface.axis, surface.value, surface.normal, corners, plane_to_texels,
                 float(atlas.log2_inv_texel[index]))
