"""Path planning on the occupancy grid: RRT-Connect with shortcut smoothing, or A*.

Both planners work on ``World.occupancy``, whose obstacles are already grown by the
robot's radius plus a margin, so a path is a polyline of floor points whose every
segment crosses free cells only (``OccupancyGrid.segment_free``) and the robot's
centre may follow it.

- ``plan_rrt_connect``: bidirectional RRT-Connect (Kuffner & LaValle, ICRA 2000): two
  trees, one from each end, take turns extending toward a random sample and greedily
  connecting to each other. ``shortcut`` then smooths the jagged result by random
  shortcuts, as OpenRR's gear does.
- ``plan_astar``: A* (networkx) over the 8-connected free cells with a euclidean
  heuristic; deterministic. ``simplify`` then drops the points a straight line can skip.

``Planner`` ties either to a ``World`` and ``Patrol`` walks the world's waypoints.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import networkx as nx
import numpy as np

from .world import CLEARANCE, OccupancyGrid, World

__all__ = ["NoPathError", "Point", "plan_rrt_connect", "shortcut", "simplify", "free_cell_graph",
           "plan_astar", "Planner", "Patrol"]

Point = tuple[float, float]

# A robot pressed against a wall sits inside the grid's safety margin; the planner
# starts it from the nearest free cell, if one is this close.
MAX_START_SNAP = 0.5  # metres


class NoPathError(Exception):
    """Raised when no path joins ``start`` and ``goal``; ``reason`` says why."""

    def __init__(self, start: Sequence[float], goal: Sequence[float], reason: str) -> None:
        super().__init__(start, goal, reason)
        self.start = (float(start[0]), float(start[1]))
        self.goal = (float(goal[0]), float(goal[1]))
        self.reason = reason

    def __str__(self) -> str:
        return (f"no path from ({self.start[0]:.2f}, {self.start[1]:.2f}) "
                f"to ({self.goal[0]:.2f}, {self.goal[1]:.2f}): {self.reason}")


def _check_ends(grid: OccupancyGrid, start: Point, goal: Point) -> None:
    if not grid.free(*start):
        raise NoPathError(start, goal, "the start is not free")
    if not grid.free(*goal):
        raise NoPathError(start, goal, "the goal is not free")


class _Tree:
    """An RRT: points and parent indices in growable arrays, nearest neighbour by brute force."""

    def __init__(self, root: Point) -> None:
        self.points = np.empty((256, 2))
        self.parents = np.empty(256, dtype=np.int64)
        self.points[0] = root
        self.parents[0] = -1
        self.size = 1

    def nearest(self, q: np.ndarray) -> int:
        offsets = self.points[:self.size] - q
        return int(np.argmin(np.einsum("ij,ij->i", offsets, offsets)))

    def add(self, q: np.ndarray, parent: int) -> int:
        if self.size == len(self.points):
            self.points = np.concatenate([self.points, np.empty_like(self.points)])
            self.parents = np.concatenate([self.parents, np.empty_like(self.parents)])
        self.points[self.size] = q
        self.parents[self.size] = parent
        self.size += 1
        return self.size - 1

    def branch(self, index: int) -> list[Point]:
        """The points from node ``index`` back to the root."""
        points = []
        while index >= 0:
            points.append((float(self.points[index, 0]), float(self.points[index, 1])))
            index = int(self.parents[index])
        return points


_TRAPPED, _ADVANCED, _REACHED = 0, 1, 2


def _extend(grid: OccupancyGrid, tree: _Tree, q: np.ndarray, step: float) -> tuple[int, int]:
    """One RRT step from the tree's nearest point toward ``q``: ``(status, new node or -1)``."""
    near = tree.nearest(q)
    origin = tree.points[near]
    offset = q - origin
    distance = float(math.hypot(offset[0], offset[1]))
    if distance <= step:
        new, status = q, _REACHED
    else:
        new, status = origin + offset * (step / distance), _ADVANCED
    if not grid.segment_free((origin[0], origin[1]), (new[0], new[1])):
        return _TRAPPED, -1
    return status, tree.add(new, near)


def _connect(grid: OccupancyGrid, tree: _Tree, q: np.ndarray, step: float) -> tuple[int, int]:
    """Extend the tree toward ``q`` until it reaches ``q`` or is blocked."""
    status, node = _extend(grid, tree, q, step)
    while status == _ADVANCED:
        status, next_node = _extend(grid, tree, q, step)
        if status != _TRAPPED:
            node = next_node
    return (_REACHED if status == _REACHED else _TRAPPED), node


def plan_rrt_connect(grid: OccupancyGrid, start: Point, goal: Point, rng: np.random.Generator,
                     step: float = 0.4, max_iterations: int = 3000) -> list[Point]:
    """A collision-free path by RRT-Connect (not smoothed: see ``shortcut``).

    Args:
        grid: the inflated occupancy grid.
        start, goal: floor points ``(x, y)`` in free cells.
        rng: the source of the random samples (the result depends only on its state).
        step: the longest edge a tree grows in one extension (metres).
        max_iterations: samples to try before giving up.

    Returns:
        Points from ``start`` to ``goal`` (both included), every segment free.

    Raises:
        NoPathError: an end is not free, or the trees did not meet in ``max_iterations``.
    """
    start = (float(start[0]), float(start[1]))
    goal = (float(goal[0]), float(goal[1]))
    _check_ends(grid, start, goal)
    if grid.segment_free(start, goal):
        return [start, goal]
    rows, cols = grid.shape
    extent = np.array([cols * grid.resolution, rows * grid.resolution])
    from_start, from_goal = _Tree(start), _Tree(goal)
    grow, other = from_start, from_goal
    for _ in range(max_iterations):
        sample = rng.random(2) * extent
        if not grid.free(sample[0], sample[1]):
            continue
        status, new = _extend(grid, grow, sample, step)
        if status != _TRAPPED:
            status, met = _connect(grid, other, grow.points[new], step)
            if status == _REACHED:
                start_node, goal_node = (new, met) if grow is from_start else (met, new)
                return from_start.branch(start_node)[::-1] + from_goal.branch(goal_node)[1:]
        grow, other = other, grow
    raise NoPathError(start, goal, f"RRT-Connect found none in {max_iterations} iterations")


def _path_lengths(path: Sequence[Point]) -> np.ndarray:
    """Cumulative arc length at each point of the path (first 0)."""
    points = np.asarray(path, dtype=float)
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])


def _point_at(path: Sequence[Point], lengths: np.ndarray, s: float) -> tuple[int, Point]:
    """The segment index ``i`` (from ``path[i]`` to ``path[i + 1]``) and the point at arc length ``s``."""
    i = int(np.clip(np.searchsorted(lengths, s, side="right") - 1, 0, len(path) - 2))
    span = lengths[i + 1] - lengths[i]
    t = 0.0 if span <= 0 else (s - lengths[i]) / span
    (ax, ay), (bx, by) = path[i], path[i + 1]
    return i, (ax + (bx - ax) * t, ay + (by - ay) * t)


def shortcut(grid: OccupancyGrid, path: Sequence[Point], rng: np.random.Generator,
             iterations: int = 100) -> list[Point]:
    """Random shortcut smoothing: join two random points of the path when the line between is free.

    Args:
        grid: the inflated occupancy grid.
        path: a path whose segments are free.
        rng: picks the points.
        iterations: shortcuts to try.

    Returns:
        A path with the same ends, never longer, every segment still free.
    """
    path = [(float(x), float(y)) for x, y in path]
    for _ in range(iterations):
        if len(path) < 3:
            break
        lengths = _path_lengths(path)
        s1, s2 = np.sort(rng.random(2) * lengths[-1])
        i, a = _point_at(path, lengths, float(s1))
        j, b = _point_at(path, lengths, float(s2))
        if j <= i:
            continue  # both on one segment: nothing to cut
        # The pieces left of the old segments are checked too: segment_free samples a
        # line at fixed spacing, so a piece of a free segment is not free by implication.
        if grid.segment_free(a, b) and grid.segment_free(path[i], a) and grid.segment_free(b, path[j + 1]):
            path = [*path[:i + 1], a, b, *path[j + 1:]]
    return _drop_repeats(path)


def _drop_repeats(path: list[Point]) -> list[Point]:
    kept = [path[0]]
    for point in path[1:-1]:
        if math.hypot(point[0] - kept[-1][0], point[1] - kept[-1][1]) > 1e-9:
            kept.append(point)
    if len(path) > 1:
        kept.append(path[-1])
    return kept


def simplify(grid: OccupancyGrid, path: Sequence[Point]) -> list[Point]:
    """Line-of-sight simplification: from each kept point, skip to the farthest point in view.

    Args:
        grid: the inflated occupancy grid.
        path: a path whose segments are free.

    Returns:
        A subsequence of ``path`` with the same ends whose segments are all free.
    """
    path = [(float(x), float(y)) for x, y in path]
    if len(path) <= 2:
        return path
    kept = [path[0]]
    anchor = 0
    while anchor < len(path) - 1:
        # Look from the far end back: the first point in view is the farthest.
        for target in range(len(path) - 1, anchor, -1):
            if target == anchor + 1 or grid.segment_free(path[anchor], path[target]):
                break
        kept.append(path[target])
        anchor = target
    return kept


_DIAGONAL = math.sqrt(2.0)


def free_cell_graph(grid: OccupancyGrid) -> nx.Graph[tuple[int, int]]:
    """The 8-connected graph of free cells ``(row, col)``, edge weights in cells.

    A diagonal edge needs both cells beside it free as well, so a path never cuts the
    corner of an occupied cell.
    """
    free = ~grid.occupied
    graph: nx.Graph[tuple[int, int]] = nx.Graph()
    free_rows, free_cols = np.nonzero(free)
    graph.add_nodes_from(zip(free_rows.tolist(), free_cols.tolist(), strict=True))

    def add(mask: np.ndarray, first: tuple[int, int], second: tuple[int, int], weight: float) -> None:
        """An edge between the cells at offsets ``first`` and ``second`` from each cell set in ``mask``."""
        rows, cols = np.nonzero(mask)
        graph.add_weighted_edges_from(((r + first[0], c + first[1]), (r + second[0], c + second[1]), weight)
                                      for r, c in zip(rows.tolist(), cols.tolist(), strict=True))

    add(free[:, :-1] & free[:, 1:], (0, 0), (0, 1), 1.0)
    add(free[:-1, :] & free[1:, :], (0, 0), (1, 0), 1.0)
    square = free[:-1, :-1] & free[1:, 1:] & free[:-1, 1:] & free[1:, :-1]
    add(square, (0, 0), (1, 1), _DIAGONAL)
    add(square, (0, 1), (1, 0), _DIAGONAL)
    return graph


def _cell_distance(a: tuple[int, int], b: tuple[int, int]) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


def plan_astar(grid: OccupancyGrid, start: Point, goal: Point,
               graph: nx.Graph[tuple[int, int]] | None = None) -> list[Point]:
    """The shortest 8-connected cell path by A*, simplified by line of sight.

    Args:
        grid: the inflated occupancy grid.
        start, goal: floor points ``(x, y)`` in free cells.
        graph: ``free_cell_graph(grid)``, when the caller keeps one (building it is the slow part).

    Returns:
        Points from ``start`` to ``goal`` (both included), every segment free; the same
        for the same arguments.

    Raises:
        NoPathError: an end is not free, or no cell path joins them.
    """
    start = (float(start[0]), float(start[1]))
    goal = (float(goal[0]), float(goal[1]))
    _check_ends(grid, start, goal)
    first, last = grid.cell(*start), grid.cell(*goal)
    if first == last:
        return [start, goal]
    if graph is None:
        graph = free_cell_graph(grid)
    try:
        cells = nx.astar_path(graph, first, last, heuristic=_cell_distance, weight="weight")
    except nx.NetworkXNoPath:
        raise NoPathError(start, goal, "the goal is unreachable") from None
    path = [start] + [grid.centre(row, col) for row, col in cells[1:-1]] + [goal]
    return simplify(grid, path)


class Planner:
    """Plans paths in a ``World`` with one method and one random stream.

    Attributes:
        grid: the occupancy grid the paths avoid.
        method: ``"rrt"`` (RRT-Connect, shortcut, simplify) or ``"astar"``.
    """

    def __init__(self, world: World, method: str = "rrt", seed: int = 0, resolution: float = 0.05,
                 inflate: float = CLEARANCE) -> None:
        """A planner for ``world``.

        Args:
            world: the room.
            method: ``"rrt"`` or ``"astar"``.
            seed: seeds the RRT's random samples; a planner given the same queries in
                the same order returns the same paths.
            resolution: the grid's cell size (metres).
            inflate: how far obstacles are grown (metres); at least the robot's radius.

        Raises:
            ValueError: an unknown method.
        """
        if method not in ("rrt", "astar"):
            raise ValueError(f"unknown planning method {method!r}; expected 'rrt' or 'astar'")
        self.world = world
        self.method = method
        self.grid = world.occupancy(resolution, inflate)
        self._rng = np.random.default_rng(seed)
        free = ~self.grid.occupied
        # Cells joined through free cells share a label; 4-connected, as the planners move.
        _, self._regions = cv2.connectedComponents(free.astype(np.uint8), connectivity=4)
        rows, cols = np.nonzero(free)
        self._free_centres = np.column_stack([(cols + 0.5) * resolution, (rows + 0.5) * resolution])
        self._graph: nx.Graph[tuple[int, int]] | None = None

    def _region(self, point: Point) -> int:
        row, col = self.grid.cell(*point)
        return int(self._regions[row, col])

    def _snap(self, start: Point, goal: Point) -> Point:
        """The start, or the nearest free cell centre if the start lies in the safety margin."""
        if self.grid.free(*start):
            return start
        offsets = self._free_centres - start
        distances = np.hypot(offsets[:, 0], offsets[:, 1])
        nearest = int(np.argmin(distances)) if len(distances) else -1
        if nearest < 0 or distances[nearest] > MAX_START_SNAP:
            raise NoPathError(start, goal, "the start is not free")
        return float(self._free_centres[nearest, 0]), float(self._free_centres[nearest, 1])

    def plan(self, start_xy: Sequence[float], goal_xy: Sequence[float]) -> list[Point]:
        """A collision-free path from ``start_xy`` to ``goal_xy``.

        Args:
            start_xy: where the robot is. Inside the grid's safety margin (a robot
                hugging a wall) the path first goes to the nearest free cell.
            goal_xy: where it should go.

        Returns:
            Points ``(x, y)``: the first is the start, the last the goal.

        Raises:
            NoPathError: the goal is not free, the start is not free and no free cell
                is near, or the goal is unreachable.
        """
        start = (float(start_xy[0]), float(start_xy[1]))
        goal = (float(goal_xy[0]), float(goal_xy[1]))
        if not self.grid.free(*goal):
            raise NoPathError(start, goal, "the goal is not free")
        origin = self._snap(start, goal)
        if self._region(origin) != self._region(goal):
            raise NoPathError(start, goal, "the goal is unreachable")
        if self.method == "rrt":
            raw = plan_rrt_connect(self.grid, origin, goal, self._rng)
            path = simplify(self.grid, shortcut(self.grid, raw, self._rng))
        else:
            if self._graph is None:
                self._graph = free_cell_graph(self.grid)
            path = plan_astar(self.grid, origin, goal, self._graph)
        return path if origin == start else [start, *path]


class Patrol:
    """The world's waypoints in order: the goal is the current one until the robot is near it.

    Looping (no ``dock``), the patrol starts again from the first waypoint after the last.
    Once (a ``dock`` given), the goal after the last waypoint is the dock, and the patrol
    is ``done`` when the robot is within ``dock_tolerance`` of it: the whole patrol.

    Attributes:
        index: the current waypoint's position in ``world.waypoints``.
        reached: how many waypoints the robot has reached so far.
        dock: where a patrol done once ends (None: it loops).
        done: the patrol was done once and the robot is back at the dock.
    """

    def __init__(self, world: World, tolerance: float = 0.3, dock: Point | None = None,
                 dock_tolerance: float = 0.3) -> None:
        """A patrol starting at the world's first waypoint.

        Raises:
            ValueError: the world has no waypoints.
        """
        if not world.waypoints:
            raise ValueError("the world has no waypoints to patrol")
        self.waypoints = tuple((float(x), float(y)) for x, y in world.waypoints)
        self.tolerance = tolerance
        self.dock = None if dock is None else (float(dock[0]), float(dock[1]))
        self.dock_tolerance = dock_tolerance
        self.index = 0
        self.reached = 0
        self.done = False

    @property
    def docking(self) -> bool:
        """Every waypoint is reached and the goal is the dock (a patrol done once)."""
        return self.dock is not None and self.reached >= len(self.waypoints)

    @property
    def goal(self) -> Point:
        """The current waypoint, or the dock once every waypoint of a patrol done once is reached."""
        if self.dock is not None and self.docking:
            return self.dock
        return self.waypoints[self.index]

    def goal_for(self, x: float, y: float) -> Point:
        """The goal for a robot at ``(x, y)``: the next one once it is within tolerance of this one."""
        gx, gy = self.goal
        distance = math.hypot(x - gx, y - gy)
        if self.docking:
            self.done = self.done or distance <= self.dock_tolerance
        elif distance <= self.tolerance:
            self.index = (self.index + 1) % len(self.waypoints)
            self.reached += 1
        return self.goal
