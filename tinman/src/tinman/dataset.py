"""Reading TUM RGB-D sequences, real or synthetic, frame by frame.

A sequence directory holds ``rgb.txt`` and ``depth.txt`` (``timestamp filename``
lines), the images they name, and usually ``groundtruth.txt``. Colour and depth
frames come at slightly different times, so they are paired with
:func:`tinman.tum.associate` (at most 20 ms apart), as the benchmark's tools do.
The camera is the Kinect of the sequence's "freiburg" number, or the one recorded
in a synthetic sequence's ``tinman.json``.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .geometry import FR1, Intrinsics, depth_metres
from .tum import associate, read_file_list, read_trajectory

__all__ = ["DatasetError", "TumSequence", "FREIBURG_INTRINSICS", "MAX_TIME_DIFFERENCE"]

MAX_TIME_DIFFERENCE = 0.02  # seconds between a colour frame and its depth frame

# The benchmark's calibrated colour cameras (vision.in.tum.de/data/datasets/rgbd-dataset/file_formats).
FREIBURG_INTRINSICS = {
    1: FR1,
    2: Intrinsics(fx=520.9, fy=521.0, cx=325.1, cy=249.7, width=640, height=480),
    3: Intrinsics(fx=535.4, fy=539.2, cx=320.1, cy=247.6, width=640, height=480),
}

_METADATA = "tinman.json"


class DatasetError(Exception):
    """A sequence directory that cannot be read: missing, incomplete or with bad files.

    Attributes:
        path: the file or directory at fault.
        reason: what is wrong with it.
    """

    def __init__(self, path: Path | str, reason: str) -> None:
        super().__init__(path, reason)
        self.path = Path(path)
        self.reason = reason

    def __str__(self) -> str:
        return f"{self.path}: {self.reason}"


@dataclass(frozen=True)
class _Frame:
    stamp: float
    rgb: Path
    depth_stamp: float
    depth: Path


class TumSequence:
    """The associated colour and depth frames of one sequence; open with :meth:`open`.

    Attributes:
        directory: the sequence directory.
        intrinsics: the colour camera.
        stamps: colour timestamps of the associated frames, increasing (float64).
        depth_stamps: the depth timestamp paired with each frame.
        metadata: the contents of ``tinman.json`` (synthetic sequences), else ``{}``.
    """

    def __init__(self, directory: Path, frames: list[_Frame], intrinsics: Intrinsics,
                 metadata: dict[str, object]) -> None:
        self.directory = directory
        self.intrinsics = intrinsics
        self.metadata = metadata
        self._frames = frames
        self.stamps = np.array([f.stamp for f in frames], dtype=float)
        self.depth_stamps = np.array([f.depth_stamp for f in frames], dtype=float)
        self._groundtruth: tuple[np.ndarray, np.ndarray] | None = None
        self._groundtruth_read = False

    @classmethod
    def open(cls, directory: str | Path) -> TumSequence:
        """Read a sequence's file lists and pair its frames (images are read on demand).

        Raises:
            DatasetError: the directory, ``rgb.txt`` or ``depth.txt`` is missing or
                unreadable, a list names no frames, no colour frame has a depth frame
                within 20 ms, or ``tinman.json`` is malformed.
        """
        root = Path(directory)
        if not root.is_dir():
            raise DatasetError(root, "no such sequence directory")
        metadata = _read_metadata(root)
        rgb = _read_list(root / "rgb.txt")
        depth = _read_list(root / "depth.txt")
        pairs = associate(rgb, depth, 0.0, MAX_TIME_DIFFERENCE)
        if not pairs:
            raise DatasetError(root, f"no colour frame has a depth frame within {MAX_TIME_DIFFERENCE} s "
                                     f"({len(rgb)} colour, {len(depth)} depth frames)")
        frames = [_Frame(a, root / rgb[a], b, root / depth[b]) for a, b in pairs]
        return cls(root, frames, _intrinsics(root, metadata), metadata)

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def frame_rate(self) -> float:
        """Frames per second (from the median interval; 0.0 for fewer than two frames)."""
        if len(self.stamps) < 2:
            return 0.0
        return float(1.0 / np.median(np.diff(self.stamps)))

    def rgb(self, index: int) -> np.ndarray:
        """Frame ``index``'s colour image: uint8 (H, W, 3), RGB order.

        Raises:
            IndexError: no such frame.
            DatasetError: the image file is missing or is not an 8-bit colour image.
        """
        path = self._frames[index].rgb
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise DatasetError(path, "missing or unreadable image" if path.exists() else "no such image file")
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4):
            raise DatasetError(path, f"expected an 8-bit colour image, got {image.dtype} {image.shape}")
        code = cv2.COLOR_BGR2RGB if image.shape[2] == 3 else cv2.COLOR_BGRA2RGB
        return cv2.cvtColor(image, code)

    def depth(self, index: int) -> np.ndarray:
        """Frame ``index``'s depth image: float32 (H, W) metres, 0 where there is no reading.

        Raises:
            IndexError: no such frame.
            DatasetError: the image file is missing or is not a 16-bit single-channel PNG.
        """
        return depth_metres(self.depth_raw(index))

    def depth_raw(self, index: int) -> np.ndarray:
        """Frame ``index``'s depth image as stored: uint16 (H, W), ``DEPTH_SCALE`` units per metre.

        Raises:
            IndexError: no such frame.
            DatasetError: the image file is missing or is not a 16-bit single-channel PNG.
        """
        path = self._frames[index].depth
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise DatasetError(path, "missing or unreadable image" if path.exists() else "no such image file")
        if image.dtype != np.uint16 or image.ndim != 2:
            raise DatasetError(path, f"expected a 16-bit depth image, got {image.dtype} {image.shape}")
        return image

    @property
    def groundtruth(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(stamps (N,), poses (N, 4, 4))`` of ``groundtruth.txt``, or None without one.

        Raises:
            DatasetError: the file is malformed.
        """
        if not self._groundtruth_read:
            path = self.directory / "groundtruth.txt"
            if path.exists():
                try:
                    self._groundtruth = read_trajectory(path)
                except (OSError, UnicodeDecodeError, ValueError) as error:
                    raise DatasetError(path, str(error)) from None
            self._groundtruth_read = True
        return self._groundtruth

    def __repr__(self) -> str:
        return f"TumSequence({str(self.directory)!r}, frames={len(self)})"


def _read_list(path: Path) -> dict[float, str]:
    if not path.is_file():
        raise DatasetError(path, "no such file list")
    try:
        entries = read_file_list(path)
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise DatasetError(path, f"unreadable file list: {error}") from None
    if not entries:
        raise DatasetError(path, "the file list names no frames")
    return {stamp: fields[0] for stamp, fields in entries.items()}


def _read_metadata(root: Path) -> dict[str, object]:
    path = root / _METADATA
    if not path.exists():
        return {}
    try:
        metadata = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise DatasetError(path, f"unreadable metadata: {error}") from None
    if not isinstance(metadata, dict):
        raise DatasetError(path, "expected a JSON object")
    return metadata


def _intrinsics(root: Path, metadata: dict[str, object]) -> Intrinsics:
    """The metadata's camera, else the one of ``freiburgN`` in the directory's name, else FR1."""
    recorded = metadata.get("intrinsics")
    if recorded is not None:
        try:
            return Intrinsics(**recorded)  # type: ignore[arg-type]
        except TypeError as error:
            raise DatasetError(root / _METADATA, f"bad intrinsics: {error}") from None
    match = re.search(r"freiburg(\d)", root.resolve().name)
    if match and int(match.group(1)) in FREIBURG_INTRINSICS:
        return FREIBURG_INTRINSICS[int(match.group(1))]
    return FR1
