"""Real photographs for the realistic room: scikit-image's sample images, as its wheel ships them.

scikit-image bundles a few sample images in its wheel (``skimage/data/*.png``); the
rest of ``skimage.data`` is downloaded on first use. This module reads only the
bundled files, straight from the installed package, and never calls
``skimage.data``'s loaders: those would try to download a missing file (with
pooch installed) where TinMan must fail at once with a clear message instead.
"""

from __future__ import annotations

import importlib.util
from functools import cache
from pathlib import Path

import cv2
import numpy as np

__all__ = ["PHOTOS", "PhotoMissingError", "photo", "photo_path"]

# Name -> file in skimage/data/. Grey textures (brick, gravel, grass: a few millimetres per
# pixel) and colour photographs (camera is grey).
PHOTOS = {
    "brick": "brick.png",
    "gravel": "gravel.png",
    "grass": "grass.png",
    "camera": "camera.png",
    "coffee": "coffee.png",
    "astronaut": "astronaut.png",
    "chelsea": "chelsea.png",
    "rocket": "rocket.jpg",
}


class PhotoMissingError(RuntimeError):
    """Raised when a photograph the realistic room needs is not in the installed scikit-image
    (scikit-image is not installed, or its wheel no longer bundles that image)."""

    def __init__(self, name: str, path: Path | None, reason: str) -> None:
        super().__init__(name, path, reason)
        self.name = name
        self.path = path
        self.reason = reason

    def __str__(self) -> str:
        where = f" ({self.path})" if self.path is not None else ""
        return (f"the realistic world needs scikit-image's bundled sample image {self.name!r}{where}: "
                f"{self.reason}; install scikit-image (pip install 'scikit-image>=0.22'), or use --world easy")


def photo_path(name: str) -> Path:
    """Where the installed scikit-image keeps the sample image ``name`` (one of :data:`PHOTOS`).

    Raises:
        KeyError: ``name`` is not one of :data:`PHOTOS`.
        PhotoMissingError: scikit-image is not installed, or the file is not in it.
    """
    file = PHOTOS[name]
    spec = importlib.util.find_spec("skimage")  # finds the package without importing it
    if spec is None or not spec.submodule_search_locations:
        raise PhotoMissingError(name, None, "scikit-image is not installed")
    path = Path(next(iter(spec.submodule_search_locations))) / "data" / file
    if not path.is_file():
        raise PhotoMissingError(name, path, "the file is not in the installed package")
    return path


@cache
def photo(name: str) -> np.ndarray:
    """The sample image ``name`` as uint8 RGB ``(rows, cols, 3)`` (grey images have three equal
    channels). Read once, then kept; do not modify the array.

    Raises:
        KeyError: ``name`` is not one of :data:`PHOTOS`.
        PhotoMissingError: it is missing or cannot be decoded.
    """
    path = photo_path(name)
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise PhotoMissingError(name, path, "OpenCV cannot decode the file")
    rgb: np.ndarray = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    rgb.setflags(write=False)
    return rgb
