"""Procedural textures for the rendered room, packed in one mip-mapped atlas.

Each surface (a wall, the floor, the ceiling, a box face) gets its own picture,
painted once from the seed: a base colour with multi-scale value noise, a
"dead leaves" layer of overlapping shapes whose sizes span every octave from half
a metre down to a few centimetres, printed text, hard-edged speckles and fine
grain. Nothing in it repeats, and it has corners at every scale, so ORB finds
plenty of distinct features whether the camera is 30 cm or 8 m away. Lighting
(two ceiling lamps, Lambertian, plus ambient) is baked in.

The atlas holds every surface's picture with a 64-texel margin of the same
picture around it, and its mip levels side by side (level 0 on the left, the
halved levels stacked on its right), so one ``cv2.remap`` per level samples all
surfaces at once without bleeding between them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .world import World

__all__ = ["MAX_SURFACES", "MIP_LEVELS", "TEXEL", "Surface", "Atlas", "Lighting", "room_surfaces", "room_lighting",
           "build_atlas", "pack_atlas", "picture_shape", "picture_coordinates", "light_picture"]

MIP_LEVELS = 7
MAX_SURFACES = 256  # surface ids are uint8
_MARGIN = 2 ** (MIP_LEVELS - 1)  # texels around each picture: one texel at the coarsest level
_ATLAS_WIDTH = 4096

# Texel sizes (metres): fine where the camera can come close, coarse where it never does.
TEXEL = {"wall": 0.004, "box": 0.004, "top": 0.004, "floor": 0.006, "ceiling": 0.010}
_TEXEL = TEXEL
# Smallest dead-leaves shape (metres) per kind.
_SMALLEST_SHAPE = {"wall": 0.03, "box": 0.03, "top": 0.04, "floor": 0.05, "ceiling": 0.12}
_TEXT_CHARS = "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789#&%?"


@dataclass(frozen=True)
class Surface:
    """A textured rectangle in the plane ``axis = value`` (axis 0 x, 1 y, 2 z).

    In-plane coordinates: axis 0 -> ``(h, v) = (y, z)``, axis 1 -> ``(x, z)``,
    axis 2 -> ``(x, y)``; the rectangle is ``h_range x v_range``; ``normal`` (+1 or -1)
    is the direction along ``axis`` the visible side faces.
    """

    name: str
    kind: str
    axis: int
    value: float
    normal: int
    h_range: tuple[float, float]
    v_range: tuple[float, float]


def room_surfaces(world: World) -> list[Surface]:
    """The surfaces of a world, in the renderer's id order.

    Ids 0-5: the walls at x = 0, x = width, y = 0, y = depth, the floor, the ceiling
    (id ``2 * axis + (ray direction > 0)``); then five per box: its faces at
    x0, x1, y0, y1 and its top (id ``6 + 5 * box + face``).
    """
    w, d, h = world.width, world.depth, world.wall_height
    surfaces = [
        Surface("west wall", "wall", 0, 0.0, +1, (0.0, d), (0.0, h)),
        Surface("east wall", "wall", 0, w, -1, (0.0, d), (0.0, h)),
        Surface("south wall", "wall", 1, 0.0, +1, (0.0, w), (0.0, h)),
        Surface("north wall", "wall", 1, d, -1, (0.0, w), (0.0, h)),
        Surface("floor", "floor", 2, 0.0, +1, (0.0, w), (0.0, d)),
        Surface("ceiling", "ceiling", 2, h, -1, (0.0, w), (0.0, d)),
    ]
    for i, box in enumerate(world.boxes):
        name = f"box {i}"
        surfaces += [
            Surface(f"{name} x0", "box", 0, box.x0, -1, (box.y0, box.y1), (0.0, box.height)),
            Surface(f"{name} x1", "box", 0, box.x1, +1, (box.y0, box.y1), (0.0, box.height)),
            Surface(f"{name} y0", "box", 1, box.y0, -1, (box.x0, box.x1), (0.0, box.height)),
            Surface(f"{name} y1", "box", 1, box.y1, +1, (box.x0, box.x1), (0.0, box.height)),
            Surface(f"{name} top", "top", 2, box.height, +1, (box.x0, box.x1), (box.y0, box.y1)),
        ]
    return surfaces


@dataclass(frozen=True)
class Lighting:
    """The lamps the textures are lit by: Lambertian point lamps plus ambient light.

    The irradiance of a surface point is ``ambient + sum_i gain_i * strength * cos_i *
    min(1, reach / d_i^2)``, ``cos_i`` the cosine of the angle between the surface normal
    and the direction to lamp ``i`` (0 behind the surface), ``d_i`` the distance to it
    (metres). The textures are lit with every gain 1; a renderer can relight a frame
    with other gains (lamps that dim or flicker) by the ratio of the two irradiances.

    Attributes:
        lamps: lamp positions ``(x, y, z)`` in metres.
        ambient, strength: the irradiance of ambient light and a lamp's at full reach.
        reach: square metres: a lamp is at full strength up to ``sqrt(reach)`` metres away.
    """

    lamps: tuple[tuple[float, float, float], ...]
    ambient: float = 0.55
    strength: float = 0.45
    reach: float = 4.0

    def irradiance(self, point: np.ndarray, normal: np.ndarray, gains: np.ndarray | None = None) -> np.ndarray:
        """The irradiance at surface points.

        Args:
            point: ``(3, ...)`` world coordinates of the points.
            normal: ``(3,)`` the unit normal of them all, or ``(3, ...)`` one per point.
            gains: each lamp's brightness (1 when omitted).

        Returns:
            The irradiance, shape ``point.shape[1:]``, in ``point``'s float type.
        """
        total = np.full(point.shape[1:], self.ambient, point.dtype)
        for i, term in enumerate(self.lamp_terms(point, normal)):
            total += term if gains is None else point.dtype.type(gains[i]) * term
        return total

    def relit(self, point: np.ndarray, normal: np.ndarray, gains: np.ndarray) -> np.ndarray:
        """How much brighter (> 1) or darker surface points are with the lamps at ``gains`` than
        as the textures were lit: the ratio of the two irradiances (arguments as :meth:`irradiance`)."""
        dtype = point.dtype.type
        lit = np.full(point.shape[1:], self.ambient, point.dtype)
        nominal = lit.copy()
        for i, term in enumerate(self.lamp_terms(point, normal)):
            nominal += term
            lit += dtype(gains[i]) * term
        ratio: np.ndarray = lit / nominal
        return ratio

    def lamp_terms(self, point: np.ndarray, normal: np.ndarray) -> list[np.ndarray]:
        """Each lamp's irradiance at full brightness (arguments as :meth:`irradiance`)."""
        dtype = point.dtype.type
        shape = (3, *([1] * (point.ndim - 1)))
        normal = normal.reshape(shape) if normal.ndim == 1 else normal
        terms = []
        for lamp in self.lamps:
            to_lamp = np.asarray(lamp, point.dtype).reshape(shape) - point
            distance = np.sqrt((to_lamp ** 2).sum(axis=0))
            # A point right at a lamp (a box top touching it) would divide 0 by 0.
            distance = np.maximum(distance, dtype(1e-3))
            cosine = np.clip((normal * to_lamp).sum(axis=0) / distance, dtype(0.0), dtype(1.0))
            terms.append(dtype(self.strength) * cosine * np.minimum(dtype(1.0), dtype(self.reach) / distance ** 2))
        return terms


@dataclass
class Atlas:
    """The packed, mip-mapped pictures and, per surface id, the map from in-plane
    coordinates to level-0 atlas texels: ``col = h * scale_h + offset_h``, likewise rows.

    The per-surface tables have ``MAX_SURFACES`` entries, for :meth:`lookup`.
    ``lighting`` is the lighting baked into the pictures (None: unknown, so a renderer
    cannot relight them).
    """

    image: np.ndarray          # uint8 (rows, 1.5 * width, 4), RGBA (A unused)
    level0_shape: tuple[int, int]
    scale_h: np.ndarray        # float32 per surface id
    offset_h: np.ndarray
    scale_v: np.ndarray
    offset_v: np.ndarray
    log2_inv_texel: np.ndarray
    lighting: Lighting | None = None

    @staticmethod
    def lookup(ids: np.ndarray, table: np.ndarray) -> np.ndarray:
        """``table[ids]`` for uint8 ids (``cv2.LUT``, several times faster than indexing)."""
        if ids.ndim == 2:
            return cv2.LUT(ids, table)
        return cv2.LUT(ids.reshape(-1, 1), table).reshape(ids.shape)

    def sample(self, col: np.ndarray, row: np.ndarray, level: np.ndarray) -> np.ndarray:
        """Trilinear samples at level-0 texel coordinates: uint8 ``(*col.shape, 4)``.

        Args:
            col, row: pixel-centred level-0 texel coordinates (float32, same shape).
            level: the mip level of each sample (float32), in ``[0, MIP_LEVELS - 1]``.
        """
        shape = col.shape
        if col.ndim == 1:
            col, row, level = col.reshape(-1, 1), row.reshape(-1, 1), level.reshape(-1, 1)
        low = level.astype(np.uint8)  # floor, since levels are >= 0
        fraction = level - low
        high = np.minimum(low + np.uint8(1), np.uint8(MIP_LEVELS - 1))
        samples = []
        for k in (low, high):
            scale = cv2.LUT(k, _LEVEL_SCALE)
            x = col * scale + cv2.LUT(k, self._column_offset)
            y = row * scale + cv2.LUT(k, self._row_offset)
            samples.append(cv2.remap(self.image, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE))
        blended = cv2.blendLinear(samples[0], samples[1], np.float32(1.0) - fraction, fraction)
        return blended.reshape(*shape, 4)

    def __post_init__(self) -> None:
        rows0, cols0 = self.level0_shape
        # Level k of pixel-centred coordinate c is (c + 0.5) * 2^-k - 0.5, plus where level k
        # starts in the atlas: c * scale + offset.
        self._column_offset = np.full(MAX_SURFACES, cols0, np.float32)
        self._column_offset[0] = 0.0
        self._row_offset = np.zeros(MAX_SURFACES, np.float32)
        self._row_offset[:MIP_LEVELS] = _LEVEL_ROW * rows0
        for offset in (self._column_offset, self._row_offset):
            offset += 0.5 * _LEVEL_SCALE - 0.5


_LEVEL_SCALE = np.zeros(MAX_SURFACES, np.float32)
_LEVEL_SCALE[:MIP_LEVELS] = [2.0 ** -k for k in range(MIP_LEVELS)]
# Level k >= 1 sits right of level 0, from row (1 - 2^(1-k)) * rows0.
_LEVEL_ROW = np.array([0.0] + [1.0 - 2.0 ** (1 - k) for k in range(1, MIP_LEVELS)], dtype=np.float32)


def room_lighting(world: World, ambient: float = 0.55, strength: float = 0.45) -> Lighting:
    """Two lamps 20 cm under the ceiling, a third of the room's length from each end."""
    z = world.wall_height - 0.2
    return Lighting(((world.width / 3, world.depth / 2, z), (2 * world.width / 3, world.depth / 2, z)),
                    ambient, strength)


def build_atlas(world: World, surfaces: list[Surface], seed: int) -> Atlas:
    """Paint every surface of ``world`` (deterministically from ``seed``) and pack the atlas."""
    lighting = room_lighting(world)
    lamps = np.array(lighting.lamps)
    pictures = []
    for index, surface in enumerate(surfaces):
        rng = np.random.default_rng([seed, index])
        pictures.append(_picture(surface, rng, lamps))
    return pack_atlas(surfaces, pictures, lighting)


def picture_shape(surface: Surface) -> tuple[int, int]:
    """``(rows, cols)`` of a surface's picture in the atlas, its margin included."""
    texel = TEXEL[surface.kind]
    extent_h = surface.h_range[1] - surface.h_range[0]
    extent_v = surface.v_range[1] - surface.v_range[0]
    return (_round_up(math.ceil(extent_v / texel) + 2 * _MARGIN, _MARGIN),
            _round_up(math.ceil(extent_h / texel) + 2 * _MARGIN, _MARGIN))


def picture_coordinates(surface: Surface) -> tuple[np.ndarray, np.ndarray]:
    """The in-plane coordinates (metres; see :class:`Surface`) of the texel centres of a surface's
    picture: ``h`` per column and ``v`` per row, margins included (beyond the surface there).

    Pictures read upright and unmirrored from the visible side, so on a wall ``v`` (height)
    falls down the rows, and an image pasted over a block of rows and columns in its own
    order appears upright to a viewer in the room.
    """
    rows, cols = picture_shape(surface)
    texel = TEXEL[surface.kind]
    sign_h, sign_v = _orientation(surface)
    ref_h = surface.h_range[0] if sign_h > 0 else surface.h_range[1]
    ref_v = surface.v_range[0] if sign_v > 0 else surface.v_range[1]
    return (ref_h + sign_h * (np.arange(cols) + 0.5 - _MARGIN) * texel,
            ref_v + sign_v * (np.arange(rows) + 0.5 - _MARGIN) * texel)


def light_picture(picture: np.ndarray, surface: Surface, lighting: Lighting) -> np.ndarray:
    """An unlit picture of a surface (albedo, 0-255, float or uint8) lit by ``lighting``: uint8."""
    return _light(picture, surface, TEXEL[surface.kind], lighting)


def pack_atlas(surfaces: list[Surface], pictures: list[np.ndarray], lighting: Lighting | None = None) -> Atlas:
    """Pack lit pictures (uint8 RGB of :func:`picture_shape` each, in surface id order, upright as
    seen from the visible side) into a mip-mapped atlas.

    Raises:
        ValueError: a picture does not have its surface's shape.
    """
    for surface, picture in zip(surfaces, pictures, strict=True):
        if picture.shape != (*picture_shape(surface), 3) or picture.dtype != np.uint8:
            raise ValueError(f"the picture of {surface.name} is {picture.dtype} {picture.shape}; "
                             f"expected uint8 {(*picture_shape(surface), 3)}")
    # Shelf packing: tallest first; every cell starts at a multiple of the margin so
    # each halving keeps cells on whole texels.
    order = sorted(range(len(surfaces)), key=lambda i: -pictures[i].shape[0])
    places: dict[int, tuple[int, int]] = {}
    x = y = shelf = 0
    for i in order:
        rows, cols = pictures[i].shape[:2]
        if x + cols > _ATLAS_WIDTH:
            x, y, shelf = 0, y + shelf, 0
        places[i] = (y, x)
        x += cols
        shelf = max(shelf, rows)
    rows0 = _round_up(y + shelf, _MARGIN)
    level0 = np.zeros((rows0, _ATLAS_WIDTH, 3), np.uint8)
    for i, (r, c) in places.items():
        rows, cols = pictures[i].shape[:2]
        level0[r:r + rows, c:c + cols] = pictures[i]
    image = np.zeros((rows0, _ATLAS_WIDTH + _ATLAS_WIDTH // 2, 4), np.uint8)
    image[:, :_ATLAS_WIDTH, :3] = level0
    level: np.ndarray = level0
    for k in range(1, MIP_LEVELS):
        level = cv2.resize(level, (level.shape[1] // 2, level.shape[0] // 2), interpolation=cv2.INTER_AREA)
        top = round(_LEVEL_ROW[k] * rows0)
        image[top:top + level.shape[0], _ATLAS_WIDTH:_ATLAS_WIDTH + level.shape[1], :3] = level
    scale_h, offset_h, scale_v, offset_v, log2_inv = (np.zeros(MAX_SURFACES, np.float32) for _ in range(5))
    for i, surface in enumerate(surfaces):
        texel = _TEXEL[surface.kind]
        sign_h, sign_v = _orientation(surface)
        ref_h = surface.h_range[0] if sign_h > 0 else surface.h_range[1]
        ref_v = surface.v_range[0] if sign_v > 0 else surface.v_range[1]
        r, c = places[i]
        scale_h[i] = sign_h / texel
        offset_h[i] = c + _MARGIN - 0.5 - sign_h * ref_h / texel
        scale_v[i] = sign_v / texel
        offset_v[i] = r + _MARGIN - 0.5 - sign_v * ref_v / texel
        log2_inv[i] = -math.log2(texel)
    return Atlas(image, (rows0, _ATLAS_WIDTH), scale_h, offset_h, scale_v, offset_v, log2_inv, lighting)


def _round_up(n: int, multiple: int) -> int:
    return -(-n // multiple) * multiple


def _orientation(surface: Surface) -> tuple[int, int]:
    """Directions of picture columns and rows along h and v, so that pictures on the
    walls and boxes read upright and unmirrored from the side they face."""
    if surface.axis == 2:
        return 1, 1
    # Looking at the face (against its normal) with z up, "right" is forward x up.
    forward = np.zeros(3)
    forward[surface.axis] = -surface.normal
    right = np.cross(forward, [0.0, 0.0, 1.0])
    h_axis = 1 if surface.axis == 0 else 0
    return (1 if right[h_axis] > 0 else -1), -1


def _picture(surface: Surface, rng: np.random.Generator, lamps: np.ndarray) -> np.ndarray:
    """The painted, lit picture of one surface with its margin: uint8 (rows, cols, 3)."""
    texel = _TEXEL[surface.kind]
    rows, cols = picture_shape(surface)
    picture = _paint(rng, rows, cols, texel, surface.kind)
    return _light(picture, surface, texel, lamps)


def _noise(rng: np.random.Generator, rows: int, cols: int, wavelength: float) -> np.ndarray:
    """Smooth value noise with unit standard deviation; ``wavelength`` in texels.

    Long wavelengths are made on a grid eight times coarser and then enlarged
    linearly (they are smooth at that scale already), which is much faster.
    """
    if wavelength < 1.5:
        return rng.standard_normal((rows, cols), dtype=np.float32)
    if wavelength >= 32:
        coarse = _noise(rng, rows // 8 + 2, cols // 8 + 2, wavelength / 8)
        return cv2.resize(coarse, (coarse.shape[1] * 8, coarse.shape[0] * 8),
                          interpolation=cv2.INTER_LINEAR)[4:4 + rows, 4:4 + cols]
    grid = rng.standard_normal((int(rows / wavelength) + 4, int(cols / wavelength) + 4), dtype=np.float32)
    size = (math.ceil(grid.shape[1] * wavelength), math.ceil(grid.shape[0] * wavelength))
    smooth = cv2.resize(grid, size, interpolation=cv2.INTER_CUBIC)
    offset = int(wavelength)
    smooth = smooth[offset:offset + rows, offset:offset + cols]
    return smooth / max(float(smooth[::7, ::7].std()), 1e-6)


def _palette(rng: np.random.Generator, count: int) -> np.ndarray:
    """``count`` random RGB colours around a random hue, with a wide spread of brightness."""
    hue = rng.uniform(0, 180) + rng.normal(0, 25, count)
    hsv = np.stack([np.mod(hue, 180), rng.uniform(40, 200, count), rng.uniform(25, 245, count)], axis=1)
    rgb: np.ndarray = cv2.cvtColor(hsv.astype(np.uint8)[None], cv2.COLOR_HSV2RGB)[0]
    return rgb.astype(np.float64)


def _paint(rng: np.random.Generator, rows: int, cols: int, texel: float, kind: str) -> np.ndarray:
    """Base colour, noise at every octave, dead-leaves shapes, text, speckles and grain."""
    base = _palette(rng, 1)[0] * 0.6 + 60
    luminance = np.zeros((rows, cols), np.float32)
    for wavelength, amplitude in ((0.6, 0.10), (0.25, 0.08), (0.1, 0.07), (0.04, 0.06), (0.016, 0.05)):
        if wavelength / texel >= 2:
            luminance += amplitude * _noise(rng, rows, cols, wavelength / texel)
    luminance += 1.0
    image = np.stack([luminance * np.float32(base[c]) for c in range(3)], axis=-1)
    canvas = np.clip(image, 0, 255).astype(np.uint8)
    _dead_leaves(rng, canvas, texel, _SMALLEST_SHAPE[kind], 0.6 if kind != "ceiling" else 1.0)
    if kind in ("wall", "box"):
        _text(rng, canvas, texel, density=3.0)
    image = canvas.astype(np.float32)
    # Hard-edged speckles: small irregular blobs give corners at close range.
    if kind != "ceiling":
        speckle_wavelength = 0.012 if kind in ("wall", "box", "top") else 0.02
        for shade in (35.0, 225.0):
            field = _noise(rng, rows, cols, speckle_wavelength / texel)
            alpha = np.clip((field - np.float32(1.3)) * np.float32(2.0), 0.0, 0.7)[..., None]
            image += (np.float32(shade) - image) * alpha
    image *= (np.float32(1.0) + np.float32(0.05) * _noise(rng, rows, cols, 1.0))[..., None]
    return image


def _dead_leaves(rng: np.random.Generator, canvas: np.ndarray, texel: float, smallest: float,
                 largest: float) -> None:
    """Overlapping random shapes, big ones first, sizes in octaves down to ``smallest`` metres.

    Shapes of one octave are drawn in batches of one colour (one OpenCV call per
    colour); where shapes of a batch overlap, the fill rule cuts holes, which only
    adds corners.
    """
    rows, cols = canvas.shape[:2]
    area = rows * cols * texel * texel
    unit = 16  # 4 bits of sub-texel precision
    size = largest
    while size >= smallest * 0.99:
        coverage = 0.45 if size > 0.1 else 0.3
        count = max(1, int(coverage * area / (0.5 * size * size)))
        palette = _palette(rng, 24)
        for corners, jitter in ((3, 0.4), (4, 0.25), (6, 0.6), (20, 0.0)):
            n = max(1, count // 4)
            centre = rng.uniform([0, 0], [cols, rows], size=(n, 1, 2))
            radius = rng.uniform(0.25, 0.5, (n, 1)) * size / texel
            angle = (rng.uniform(0, 2 * np.pi, (n, 1)) + np.arange(corners) * (2 * np.pi / corners)
                     + rng.uniform(-jitter, jitter, (n, corners)))
            stretch = rng.uniform(0.5, 1.0, (n, 1)) if corners == 20 else rng.uniform(0.6, 1.0, (n, corners))
            offsets = np.stack([np.cos(angle) * radius, np.sin(angle) * radius * stretch], axis=-1)
            points = ((centre + offsets) * unit).astype(np.int32)
            colour_of = rng.integers(0, len(palette), n)
            outline = rng.random(n) < 0.2
            for c, colour in enumerate(palette):
                rgb = tuple(float(v) for v in colour)
                filled = list(points[(colour_of == c) & ~outline])
                if filled:
                    cv2.fillPoly(canvas, filled, rgb, cv2.LINE_AA, 4)
                rings = list(points[(colour_of == c) & outline])
                if rings:
                    thickness = max(1, int(size / texel * 0.06))
                    cv2.polylines(canvas, rings, True, rgb, thickness, cv2.LINE_AA, 4)
        size /= 2


def _text(rng: np.random.Generator, canvas: np.ndarray, texel: float, density: float) -> None:
    """Random labels, ``density`` per square metre, 2 to 12 cm tall."""
    rows, cols = canvas.shape[:2]
    count = int(density * rows * cols * texel * texel)
    for _ in range(count):
        height = rng.uniform(0.02, 0.12) / texel
        scale = height / 22.0  # FONT_HERSHEY_SIMPLEX is about 22 px tall at scale 1
        label = "".join(rng.choice(list(_TEXT_CHARS), int(rng.integers(2, 7))))
        origin = (int(rng.uniform(0, cols)), int(rng.uniform(0, rows)))
        colour = tuple(float(v) for v in (rng.uniform(0, 60, 3) if rng.random() < 0.6 else rng.uniform(200, 255, 3)))
        cv2.putText(canvas, label, origin, cv2.FONT_HERSHEY_SIMPLEX, scale, colour,
                    max(1, round(scale * 2.5)), cv2.LINE_AA)


def _light(picture: np.ndarray, surface: Surface, texel: float, lamps: np.ndarray | Lighting) -> np.ndarray:
    """Multiply by the irradiance of the lamps and ambient light (Lambertian); ``lamps`` positions
    (an ``(N, 3)`` array: the default room's lamp model) or a whole :class:`Lighting`."""
    if isinstance(lamps, Lighting):
        lighting = lamps
    else:
        lighting = Lighting(tuple((float(x), float(y), float(z)) for x, y, z in lamps))
    rows, cols = picture.shape[:2]
    step = 16  # irradiance is smooth: compute it on a coarse grid and interpolate
    sign_h, sign_v = _orientation(surface)
    ref_h = surface.h_range[0] if sign_h > 0 else surface.h_range[1]
    ref_v = surface.v_range[0] if sign_v > 0 else surface.v_range[1]
    j = np.arange(0, cols + step, step, dtype=np.float64)
    i = np.arange(0, rows + step, step, dtype=np.float64)
    h = ref_h + sign_h * (j + 0.5 - _MARGIN) * texel
    v = ref_v + sign_v * (i + 0.5 - _MARGIN) * texel
    hh, vv = np.meshgrid(h, v)
    point = np.zeros((3, *hh.shape))
    in_plane = {0: (1, 2), 1: (0, 2), 2: (0, 1)}[surface.axis]
    point[surface.axis] = surface.value
    point[in_plane[0]] = hh
    point[in_plane[1]] = vv
    normal = np.zeros(3)
    normal[surface.axis] = surface.normal
    irradiance = lighting.irradiance(point, normal)
    factor = cv2.resize(irradiance.astype(np.float32), (hh.shape[1] * step, hh.shape[0] * step),
                        interpolation=cv2.INTER_LINEAR)[:rows, :cols]
    return np.clip(picture * factor[..., None], 0, 255).astype(np.uint8)
