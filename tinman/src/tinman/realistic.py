"""The realistic room's textures: photographs, plain paint, tiles and a repeated poster.

The easy room (:func:`tinman.textures.build_atlas`) is painted for ORB: nothing
repeats and there are corners at every scale. This one is painted like a room:

- walls of plain paint (off-white, a percent or two of unevenness: the lamps'
  shading is most of what varies across them), with a skirting board;
- real photographs from scikit-image's bundled samples (:mod:`tinman.photos`): a
  brick feature wall (``brick``), terrazzo floor tiles (``gravel``), a turf mat
  (``grass``), framed prints (``camera``, ``coffee``, ``astronaut``, ``chelsea``);
- repeated patterns: the same ``rocket`` poster three times in a row, 50 cm floor
  tiles that are all the same tile, 15 cm wall tiles, a ceiling grid, radiator fins,
  cabinet drawers;
- an over-exposed window (it saturates the camera) and a plain door.

The room's geometry is the world's (the default room's boxes are dressed as a
cabinet, a desk and a shelf; any further box is plain grey); placements are in
world metres, so they stay put whatever the texture resolution. Lighting is the
textures' Lambertian model with more contrast than the easy room's (darker
ambient light, brighter lamps), and is recorded in the atlas so a renderer can
relight frames when the lamps flicker (:mod:`tinman.lamps`).
"""

from __future__ import annotations

import cv2
import numpy as np

from .photos import photo
from .textures import (
    TEXEL,
    Atlas,
    Lighting,
    Surface,
    _noise,  # the easy room's smooth value noise: the same paint unevenness generator
    light_picture,
    pack_atlas,
    picture_coordinates,
    picture_shape,
    room_lighting,
)
from .world import World

__all__ = ["build_realistic_atlas", "paint_surface", "realistic_lighting", "FLOOR_TILE", "POSTER"]

FLOOR_TILE = 0.504      # metres: a 50 cm terrazzo tile and its grout, 84 floor texels (tiles repeat exactly)
WALL_TILE = 0.152       # metres: 15 cm wall tiles and grout, 38 wall texels
POSTER = "rocket"       # the poster hung three times on the south wall
POSTER_CENTRES = (1.3, 2.5, 3.7)  # x of the south wall's posters (metres)
_F = np.float32

# Albedos (0-255 per channel; above 255 only for what shines: the window).
_PAINT = (212.0, 208.0, 198.0)
_SKIRTING = (228.0, 226.0, 220.0)
_FRAME = (28.0, 26.0, 24.0)
_MAT = (238.0, 236.0, 230.0)


def realistic_lighting(world: World) -> Lighting:
    """The realistic room's lamps: the easy room's two, with darker ambient light and brighter lamps."""
    return room_lighting(world, ambient=0.4, strength=0.6)


def build_realistic_atlas(world: World, surfaces: list[Surface], seed: int) -> Atlas:
    """Paint every surface of the realistic room (deterministic from ``seed``), light and pack them.

    A drop-in for :func:`tinman.textures.build_atlas` (``RoomRenderer(..., paint=build_realistic_atlas)``).

    Raises:
        tinman.photos.PhotoMissingError: a photograph is not in the installed scikit-image.
    """
    lighting = realistic_lighting(world)
    pictures = [light_picture(paint_surface(surface, np.random.default_rng([seed, 7, index])), surface, lighting)
                for index, surface in enumerate(surfaces)]
    return pack_atlas(surfaces, pictures, lighting)


def paint_surface(surface: Surface, rng: np.random.Generator) -> np.ndarray:
    """The unlit picture (albedo) of one surface: float32 ``(rows, cols, 3)`` of
    :func:`tinman.textures.picture_shape`, upright as seen from its visible side."""
    canvas = _Canvas(surface)
    painter = _PAINTERS.get(surface.name)
    if painter is not None:
        painter(canvas, rng)
    elif surface.kind == "box":
        canvas.paint((150.0, 150.0, 152.0), rng)
    elif surface.kind == "top":
        canvas.paint((170.0, 170.0, 172.0), rng)
    return canvas.image


class _Canvas:
    """A surface's picture and the in-plane coordinates of its texels (see :class:`Surface`)."""

    def __init__(self, surface: Surface) -> None:
        self.surface = surface
        self.texel = TEXEL[surface.kind]
        self.h, self.v = picture_coordinates(surface)
        self.image = np.zeros((*picture_shape(surface), 3), np.float32)

    def block(self, h0: float, h1: float, v0: float, v1: float) -> tuple[slice, slice] | None:
        """The rows and columns of the texels whose centres lie in ``[h0, h1) x [v0, v1)`` (None: none)."""
        cols = np.flatnonzero((self.h >= h0) & (self.h < h1))
        rows = np.flatnonzero((self.v >= v0) & (self.v < v1))
        if cols.size == 0 or rows.size == 0:
            return None
        return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1)

    def paint(self, colour: tuple[float, float, float], rng: np.random.Generator, unevenness: float = 0.012) -> None:
        """Cover everything with plain paint: ``colour`` times one plus a little large-scale unevenness."""
        rows, cols = self.image.shape[:2]
        shade = np.ones((rows, cols), np.float32)
        for wavelength, amplitude in ((1.2, unevenness), (0.3, unevenness / 2)):
            if wavelength / self.texel >= 2:
                shade += _F(amplitude) * _noise(rng, rows, cols, wavelength / self.texel)
        self.image[:] = shade[..., None] * np.array(colour, np.float32)

    def fill(self, h0: float, h1: float, v0: float, v1: float, colour: tuple[float, float, float]) -> None:
        """A plain rectangle."""
        where = self.block(h0, h1, v0, v1)
        if where is not None:
            self.image[where] = colour

    def paste(self, image: np.ndarray, h0: float, h1: float, v0: float, v1: float) -> None:
        """``image`` (float or uint8 RGB) resized to cover ``[h0, h1) x [v0, v1)``, upright."""
        where = self.block(h0, h1, v0, v1)
        if where is None:
            return
        rows, cols = where[0].stop - where[0].start, where[1].stop - where[1].start
        interpolation = cv2.INTER_AREA if image.shape[0] > rows else cv2.INTER_LINEAR
        self.image[where] = cv2.resize(image.astype(np.float32), (cols, rows), interpolation=interpolation)

    def tile(self, unit: np.ndarray, h0: float, h1: float, v0: float, v1: float) -> None:
        """Repeat ``unit`` (its texels as they are) over the rectangle, from its top-left corner:
        every copy is the same texels."""
        where = self.block(h0, h1, v0, v1)
        if where is None:
            return
        rows, cols = where[0].stop - where[0].start, where[1].stop - where[1].start
        reps = (-(-rows // unit.shape[0]), -(-cols // unit.shape[1]), 1)
        self.image[where] = np.tile(unit.astype(np.float32), reps)[:rows, :cols]

    def texels(self, metres: float) -> int:
        """A length in whole texels (at least one)."""
        return max(1, round(metres / self.texel))


# ---- pictures -----------------------------------------------------------------------------------

def _grey(name: str) -> np.ndarray:
    """A grey sample image as float32 ``(rows, cols)`` scaled to a mean of 1."""
    grey = photo(name)[..., 0].astype(np.float32)
    return grey / max(float(grey.mean()), 1.0)


def _tinted(grey: np.ndarray, colour: tuple[float, float, float], contrast: float = 1.0) -> np.ndarray:
    """A grey picture (mean 1) coloured: ``colour * (1 + contrast * (grey - 1))``."""
    shade = 1.0 + _F(contrast) * (grey - 1.0)
    return shade[..., None] * np.array(colour, np.float32)


def _framed(canvas: _Canvas, name: str, h_centre: float, bottom: float, width: float,
            mat: float = 0.04, frame: float = 0.025) -> None:
    """A photograph ``width`` metres wide (its aspect kept) in a white mat and a black frame."""
    image = photo(name)
    height = width * image.shape[0] / image.shape[1]
    h0, h1 = h_centre - width / 2, h_centre + width / 2
    v0, v1 = bottom + mat + frame, bottom + mat + frame + height
    canvas.fill(h0 - mat - frame, h1 + mat + frame, v0 - mat - frame, v1 + mat + frame, _FRAME)
    canvas.fill(h0 - mat, h1 + mat, v0 - mat, v1 + mat, _MAT)
    canvas.paste(image, h0, h1, v0, v1)


def _wall(canvas: _Canvas, rng: np.random.Generator) -> None:
    """Plain paint and a skirting board 8 cm high, with the shadow line along its top."""
    canvas.paint(_PAINT, rng)
    h0, h1 = canvas.surface.h_range
    canvas.fill(h0 - 1, h1 + 1, -1.0, 0.08, _SKIRTING)
    canvas.fill(h0 - 1, h1 + 1, 0.08, 0.085, (150.0, 148.0, 142.0))


def _west_wall(canvas: _Canvas, rng: np.random.Generator) -> None:
    """A window (over-exposed: it shines), a radiator under it with fins every 5 cm, and a door."""
    _wall(canvas, rng)
    canvas.fill(1.15, 2.65, 0.85, 2.15, (235.0, 235.0, 232.0))   # the window's frame
    canvas.fill(1.2, 2.6, 0.9, 2.1, (330.0, 335.0, 345.0))       # sky, brighter than paint can be
    canvas.fill(1.88, 1.92, 0.9, 2.1, (235.0, 235.0, 232.0))     # mullion
    canvas.fill(1.2, 2.6, 1.48, 1.52, (235.0, 235.0, 232.0))     # transom
    fin = np.empty((1, canvas.texels(0.05), 3), np.float32)
    fin[:] = (232.0, 232.0, 228.0)
    fin[:, : canvas.texels(0.012)] = (175.0, 175.0, 172.0)
    canvas.tile(fin, 1.3, 2.5, 0.15, 0.75)                       # the radiator
    canvas.fill(3.55, 4.55, 0.0, 2.1, (205.0, 203.0, 196.0))     # the door's frame
    canvas.fill(3.6, 4.5, 0.0, 2.05, (150.0, 112.0, 78.0))       # the door
    canvas.fill(4.36, 4.46, 1.0, 1.03, (60.0, 60.0, 62.0))       # its handle


def _north_wall(canvas: _Canvas, rng: np.random.Generator) -> None:
    """A brick feature wall 2.5 m wide (the brick sample, 5 mm a pixel: large bricks) and two framed prints."""
    _wall(canvas, rng)
    bricks = _tinted(np.rot90(_grey("brick")), (168.0, 96.0, 72.0), contrast=1.0)  # courses horizontal
    canvas.paste(bricks, 0.6, 3.1, 0.0, 2.5)
    _framed(canvas, "astronaut", 4.5, 1.0, 0.5)
    _framed(canvas, "camera", 7.0, 1.0, 0.45)


def _east_wall(canvas: _Canvas, rng: np.random.Generator) -> None:
    """Wall tiles to 1.2 m over three metres (15 cm, all alike), and a framed print."""
    _wall(canvas, rng)
    tile = np.empty((canvas.texels(WALL_TILE), canvas.texels(WALL_TILE), 3), np.float32)
    tile[:] = (150.0, 150.0, 146.0)  # grout
    grout = canvas.texels(0.004)
    tile[grout:, grout:] = (234.0, 234.0, 228.0)
    canvas.tile(tile, 0.4, 3.4, 0.08, 1.2)
    canvas.fill(0.4, 3.4, 1.2, 1.22, (205.0, 205.0, 200.0))  # the tiles' top trim
    _framed(canvas, "coffee", 4.7, 1.1, 0.6)


def _south_wall(canvas: _Canvas, rng: np.random.Generator) -> None:
    """The same poster three times in a row, a framed print, a light switch and a socket."""
    _wall(canvas, rng)
    for centre in POSTER_CENTRES:
        _framed(canvas, POSTER, centre, 1.0, 0.55, mat=0.0, frame=0.012)
    _framed(canvas, "chelsea", 7.0, 1.05, 0.45)
    canvas.fill(0.55, 0.63, 1.05, 1.13, (238.0, 238.0, 234.0))  # light switch
    canvas.fill(2.0, 2.08, 0.3, 0.38, (238.0, 238.0, 234.0))    # socket


def _floor(canvas: _Canvas, rng: np.random.Generator) -> None:
    """Terrazzo tiles (the gravel sample, low contrast), every one the same; a turf mat (grass)."""
    size = canvas.texels(FLOOR_TILE)
    grout = 2
    stone = cv2.resize(_grey("gravel"), (size - grout, size - grout), interpolation=cv2.INTER_AREA)
    tile = np.empty((size, size, 3), np.float32)
    tile[:] = (118.0, 116.0, 110.0)
    tile[grout:, grout:] = _tinted(stone, (176.0, 170.0, 158.0), contrast=0.35)
    canvas.tile(tile, -1.0, 99.0, -1.0, 99.0)
    canvas.fill(0.78, 2.02, 2.88, 3.72, (40.0, 62.0, 32.0))  # the mat's border
    canvas.paste(_tinted(_grey("grass"), (80.0, 122.0, 54.0), contrast=0.8), 0.8, 2.0, 2.9, 3.7)


def _ceiling(canvas: _Canvas, rng: np.random.Generator) -> None:
    """White acoustic panels in a 60 cm grid."""
    canvas.paint((236.0, 236.0, 232.0), rng, unevenness=0.006)
    size = canvas.texels(0.6)
    cell = np.ones((size, size, 3), np.float32)
    cell[: canvas.texels(0.015)] = 0.86
    cell[:, : canvas.texels(0.015)] = 0.86
    repeated = np.tile(cell, (-(-canvas.image.shape[0] // size), -(-canvas.image.shape[1] // size), 1))
    canvas.image *= repeated[: canvas.image.shape[0], : canvas.image.shape[1]]


def _cabinet_front(canvas: _Canvas, rng: np.random.Generator) -> None:
    """Grey metal with four drawers alike: split lines and handles."""
    canvas.paint((148.0, 153.0, 158.0), rng, unevenness=0.02)
    h0, h1 = canvas.surface.h_range
    middle = (h0 + h1) / 2
    height = canvas.surface.v_range[1]
    for k in range(4):
        top = height * (1.0 - 0.25 * k)
        canvas.fill(h0 - 1, h1 + 1, top - 0.004, top, (70.0, 72.0, 75.0))
        canvas.fill(middle - 0.06, middle + 0.06, top - 0.07, top - 0.055, (45.0, 45.0, 48.0))


def _cabinet_side(canvas: _Canvas, rng: np.random.Generator) -> None:
    canvas.paint((148.0, 153.0, 158.0), rng, unevenness=0.02)


def _desk(canvas: _Canvas, rng: np.random.Generator) -> None:
    canvas.paint((200.0, 184.0, 158.0), rng, unevenness=0.01)


def _desk_top(canvas: _Canvas, rng: np.random.Generator) -> None:
    """Laminate, with a print of the camera sample lying on it."""
    canvas.paint((200.0, 184.0, 158.0), rng, unevenness=0.01)
    canvas.paste(photo("camera"), 5.3, 5.65, 0.8, 1.15)


def _shelf(canvas: _Canvas, rng: np.random.Generator) -> None:
    canvas.paint((224.0, 221.0, 214.0), rng, unevenness=0.008)


def _shelf_front(canvas: _Canvas, rng: np.random.Generator) -> None:
    """White boards, and a calendar (chelsea) pinned on."""
    _shelf(canvas, rng)
    _framed(canvas, "chelsea", 5.6, 0.55, 0.4, mat=0.0, frame=0.0)


_PAINTERS = {
    "west wall": _west_wall, "east wall": _east_wall, "south wall": _south_wall, "north wall": _north_wall,
    "floor": _floor, "ceiling": _ceiling,
    # The default room's boxes: 0 a cabinet (drawers face west and east), 1 a desk, 2 a shelf.
    "box 0 x0": _cabinet_front, "box 0 x1": _cabinet_front, "box 0 y0": _cabinet_side, "box 0 y1": _cabinet_side,
    "box 0 top": _cabinet_side,
    "box 1 x0": _desk, "box 1 x1": _desk, "box 1 y0": _desk, "box 1 y1": _desk, "box 1 top": _desk_top,
    "box 2 x0": _shelf, "box 2 x1": _shelf, "box 2 y0": _shelf_front, "box 2 y1": _shelf, "box 2 top": _shelf,
}
