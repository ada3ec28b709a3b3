"""Texture lighting: the lamps' irradiance stays finite wherever a lamp is."""

from __future__ import annotations

import numpy as np

from tinman.textures import _MARGIN, Surface, _light


def test_a_lamp_touching_a_surface_lights_it_without_dividing_zero_by_zero() -> None:
    texel = 0.01
    top = Surface("box top", "top", 2, 1.0, +1, (0.0, 1.0), (0.0, 1.0))
    picture = np.full((128, 128, 3), 100, np.uint8)
    # A lamp exactly on the first point of the coarse grid the irradiance is computed on.
    lamp = np.array([[(0.5 - _MARGIN) * texel, (0.5 - _MARGIN) * texel, 1.0]])
    with np.errstate(divide="raise", invalid="raise"):
        lit = _light(picture, top, texel, lamp)
    # Light grazing along the surface adds nothing: the ambient light alone, everywhere.
    assert lit.shape == picture.shape
    assert (lit == 55).all()
