"""The room TinMan lives in: walls, box obstacles, and the occupancy map planners use.

One ``World`` feeds the renderer (what the camera sees), the simulator (what the
robot bumps into) and the planner (the occupancy grid), so all three agree.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Box", "World", "OccupancyGrid", "DEFAULT_WORLD", "ROBOT_RADIUS", "CLEARANCE"]

ROBOT_RADIUS = 0.18  # metres: a TurtleBot-sized disc
# How far the planner keeps the robot's centre from walls and boxes (metres): its radius, plus
# room for the odometry's error (a few centimetres) and pure pursuit cutting corners.
CLEARANCE = ROBOT_RADIUS + 0.2


@dataclass(frozen=True)
class Box:
    """An axis-aligned obstacle standing on the floor: ``x0 < x1``, ``y0 < y1`` (metres)."""

    x0: float
    y0: float
    x1: float
    y1: float
    height: float

    def contains(self, x: np.ndarray | float, y: np.ndarray | float, margin: float = 0.0) -> np.ndarray | bool:
        """Whether floor points lie inside the box grown by ``margin`` (a bool for one point given as floats)."""
        return ((x >= self.x0 - margin) & (x <= self.x1 + margin)
                & (y >= self.y0 - margin) & (y <= self.y1 + margin))


@dataclass(frozen=True)
class OccupancyGrid:
    """Cells of ``resolution`` metres; ``occupied[row, col]`` covers the square with corner
    ``(col * resolution, row * resolution)``. Obstacles are already grown by the robot's radius."""

    occupied: np.ndarray
    resolution: float

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupied.shape

    def cell(self, x: float, y: float) -> tuple[int, int]:
        """The ``(row, col)`` of a floor point (may lie outside the grid)."""
        return int(np.floor(y / self.resolution)), int(np.floor(x / self.resolution))

    def centre(self, row: int, col: int) -> tuple[float, float]:
        """The floor point ``(x, y)`` at the centre of a cell."""
        return (col + 0.5) * self.resolution, (row + 0.5) * self.resolution

    def free(self, x: float, y: float) -> bool:
        """Whether a floor point is inside the grid and not occupied."""
        row, col = self.cell(x, y)
        rows, cols = self.occupied.shape
        return 0 <= row < rows and 0 <= col < cols and not self.occupied[row, col]

    def segment_free(self, a: tuple[float, float], b: tuple[float, float]) -> bool:
        """Whether the straight segment a-b crosses only free cells (sampled at half a cell)."""
        length = float(np.hypot(b[0] - a[0], b[1] - a[1]))
        steps = max(1, int(np.ceil(length / (self.resolution * 0.5))))
        t = np.linspace(0.0, 1.0, steps + 1)
        xs = a[0] + (b[0] - a[0]) * t
        ys = a[1] + (b[1] - a[1]) * t
        rows = np.floor(ys / self.resolution).astype(int)
        cols = np.floor(xs / self.resolution).astype(int)
        h, w = self.occupied.shape
        if rows.min() < 0 or cols.min() < 0 or rows.max() >= h or cols.max() >= w:
            return False
        return not bool(self.occupied[rows, cols].any())


@dataclass(frozen=True)
class World:
    """A rectangular room ``[0, width] x [0, depth]`` with walls ``wall_height`` high.

    Attributes:
        boxes: obstacles on the floor.
        start: where the robot starts, ``(x, y, theta)``.
        waypoints: the patrol the planner follows, in order, then again from the first.
    """

    width: float = 8.0
    depth: float = 6.0
    wall_height: float = 2.5
    boxes: tuple[Box, ...] = ()
    start: tuple[float, float, float] = (1.0, 1.0, 0.0)
    waypoints: tuple[tuple[float, float], ...] = field(default_factory=tuple)

    def collides(self, x: float, y: float, radius: float = ROBOT_RADIUS) -> bool:
        """Whether a disc of ``radius`` at ``(x, y)`` overlaps a wall or a box."""
        if x < radius or y < radius or x > self.width - radius or y > self.depth - radius:
            return True
        for box in self.boxes:
            nearest_x = min(max(x, box.x0), box.x1)
            nearest_y = min(max(y, box.y0), box.y1)
            if (x - nearest_x) ** 2 + (y - nearest_y) ** 2 < radius * radius:
                return True
        return False

    def occupancy(self, resolution: float = 0.05, inflate: float = CLEARANCE) -> OccupancyGrid:
        """The occupancy grid, obstacles and walls grown by ``inflate`` metres."""
        cols = round(self.width / resolution)
        rows = round(self.depth / resolution)
        xs = (np.arange(cols) + 0.5) * resolution
        ys = (np.arange(rows) + 0.5) * resolution
        x, y = np.meshgrid(xs, ys)
        occupied = (x < inflate) | (y < inflate) | (x > self.width - inflate) | (y > self.depth - inflate)
        for box in self.boxes:
            occupied |= box.contains(x, y, inflate)
        return OccupancyGrid(occupied, resolution)


DEFAULT_WORLD = World(
    boxes=(
        Box(2.6, 2.2, 3.4, 3.8, 1.0),   # a cabinet in the middle of the room
        Box(5.2, 0.0, 5.8, 1.8, 0.8),   # a desk against the south wall
        Box(5.0, 3.8, 6.2, 4.4, 1.2),   # a shelf
    ),
    start=(1.0, 1.0, 0.0),
    waypoints=((4.3, 1.1), (6.9, 2.9), (4.2, 5.1), (1.2, 4.6), (1.3, 1.2)),
)
