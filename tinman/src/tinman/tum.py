"""The TUM RGB-D benchmark's text formats: file lists, timestamp association, trajectories.

``rgb.txt``/``depth.txt`` lines are ``timestamp filename``; ``groundtruth.txt`` and
estimated trajectories are ``timestamp tx ty tz qx qy qz qw``; ``#`` starts a
comment line; commas and tabs count as spaces. :func:`associate` matches two lists
exactly as the benchmark's ``associate.py`` does (greedy by smallest difference).
"""

from __future__ import annotations

import stat
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from .geometry import pose_matrix, quaternion_from_matrix

__all__ = ["read_file_list", "associate", "read_trajectory", "write_trajectory", "write_file_list"]

MAX_TEXT_BYTES = 256 * 2**20  # the benchmark's longest lists are a few MB


def read_file_list(path: str | Path) -> dict[float, list[str]]:
    """``timestamp -> the rest of the line's fields``, as ``associate.read_file_list``.

    Raises:
        OSError: the file cannot be read.
        ValueError: not a regular file (a device or a FIFO would be read for ever), larger than
            ``MAX_TEXT_BYTES``, not UTF-8, or a line without a timestamp.
    """
    status = Path(path).stat()
    if not stat.S_ISREG(status.st_mode):
        raise ValueError(f"{path}: not a regular file; expected a TUM text file")
    if status.st_size > MAX_TEXT_BYTES:
        raise ValueError(f"{path}: larger than {MAX_TEXT_BYTES // 2**20} MiB; expected a TUM text file")
    text = Path(path).read_text(encoding="utf-8")
    entries: dict[float, list[str]] = {}
    for number, line in enumerate(text.replace(",", " ").replace("\t", " ").split("\n"), 1):
        if not line or line[0] == "#":
            continue
        fields = [field.strip() for field in line.split(" ") if field.strip()]
        if len(fields) > 1:
            try:
                entries[float(fields[0])] = fields[1:]
            except ValueError:
                raise ValueError(f"{path}:{number}: expected a timestamp, got {fields[0]!r}") from None
    return entries


def associate(first: Iterable[float], second: Iterable[float], offset: float = 0.0,
              max_difference: float = 0.02) -> list[tuple[float, float]]:
    """Pairs ``(a, b)`` with ``|a - (b + offset)| < max_difference``, each stamp used once.

    Candidates are taken in order of increasing difference (ties by ``a``, then ``b``),
    like the benchmark's script, but found with a sorted search instead of all pairs.
    """
    firsts = sorted(set(first))
    seconds = np.array(sorted(set(second)), dtype=float)
    candidates: list[tuple[float, float, float]] = []
    for a in firsts:
        low = np.searchsorted(seconds, a - offset - max_difference, side="left")
        high = np.searchsorted(seconds, a - offset + max_difference, side="right")
        for b in seconds[max(0, low - 1):high + 1]:
            difference = abs(a - (float(b) + offset))
            if difference < max_difference:
                candidates.append((difference, a, float(b)))
    candidates.sort()
    used_first: set[float] = set()
    used_second: set[float] = set()
    matches = []
    for _, a, b in candidates:
        if a not in used_first and b not in used_second:
            used_first.add(a)
            used_second.add(b)
            matches.append((a, b))
    matches.sort()
    return matches


def read_trajectory(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps (N,), poses (N, 4, 4))`` from a ``t tx ty tz qx qy qz qw`` file.

    Raises:
        ValueError: a line without exactly seven numbers after its timestamp, or with a
            quaternion of length 0 (or not finite).
    """
    entries = read_file_list(path)
    stamps = np.array(sorted(entries), dtype=float)
    poses = np.empty((len(stamps), 4, 4))
    for i, stamp in enumerate(stamps):
        fields = entries[float(stamp)]
        try:
            values = [float(v) for v in fields]
        except ValueError:
            values = []
        if len(values) != 7:
            raise ValueError(f"{path}: at {stamp:.6f}: expected 'tx ty tz qx qy qz qw', "
                             f"got {' '.join(fields)!r}")
        try:
            poses[i] = pose_matrix(values[:3], values[3:])
        except ValueError as error:
            raise ValueError(f"{path}: at {stamp:.6f}: {error}") from None
    return stamps, poses


def write_trajectory(path: str | Path, stamps: Iterable[float], poses: Iterable[np.ndarray],
                     comment: str = "") -> None:
    """Write poses in the TUM trajectory format (one ``t tx ty tz qx qy qz qw`` line each)."""
    lines = [f"# {line}" for line in comment.splitlines()]
    lines.append("# timestamp tx ty tz qx qy qz qw")
    for stamp, pose in zip(stamps, poses, strict=True):
        qx, qy, qz, qw = quaternion_from_matrix(pose[:3, :3])
        tx, ty, tz = pose[:3, 3]
        lines.append(f"{stamp:.6f} {tx:.6f} {ty:.6f} {tz:.6f} {qx:.6f} {qy:.6f} {qz:.6f} {qw:.6f}")
    _write(Path(path), "\n".join(lines) + "\n")


def write_file_list(path: str | Path, entries: Mapping[float, str], comment: str = "") -> None:
    """Write ``timestamp filename`` lines (``rgb.txt``, ``depth.txt``)."""
    lines = [f"# {line}" for line in comment.splitlines()]
    lines.append("# timestamp filename")
    lines.extend(f"{stamp:.6f} {name}" for stamp, name in sorted(entries.items()))
    _write(Path(path), "\n".join(lines) + "\n")


def _write(path: Path, text: str) -> None:
    # Write then rename, so a reader never sees half a file.
    partial = path.with_name(path.name + ".partial")
    partial.write_text(text, encoding="utf-8")
    partial.replace(path)
