"""The robot's range scanner, as Gazebo's ray sensor simulates it: a ``sensor_msgs/LaserScan``.

TinMan carries a short-range scanner at the centre of its base, as a TurtleBot carries
its 360-degree laser distance sensor (LDS): ``BEAMS`` beams evenly around the robot,
``RANGE_MIN`` to ``RANGE_MAX`` metres, each reading a little noisy. The simulator casts
every beam against the room's walls and boxes from the robot's *true* pose, so the
scan knows nothing of the odometry's estimate: that is what the safety layer
(:mod:`tinman.safety`) needs it for.

The message follows ROS (REP 117): angles counter-clockwise from the robot's forward
axis (``base_scan`` frame), a beam with no return reads ``+inf``.
"""

from __future__ import annotations

import math

import numpy as np

from .messages import Header, LaserScan
from .world import World

__all__ = ["BEAMS", "RANGE_MIN", "RANGE_MAX", "NOISE", "beam_angles", "cast", "ray_ranges", "scan_message",
           "scan_points"]

BEAMS = 36          # one every 10 degrees: at 0.5 m two beams are 9 cm apart, half the robot's radius
RANGE_MIN = 0.12    # metres: the TurtleBot LDS's (nearer than the robot's own radius: never read)
RANGE_MAX = 3.5     # metres: ditto; the safety layer needs well under one
NOISE = 0.005       # metres: one standard deviation of a reading (the LDS's accuracy near range)
FRAME = "base_scan"


def beam_angles(beams: int = BEAMS) -> np.ndarray:
    """The beams' angles (radians, from the robot's forward axis, counter-clockwise): ``-pi`` upwards."""
    return -math.pi + np.arange(beams) * (2.0 * math.pi / beams)


def cast(world: World, pose: tuple[float, float, float], angles: np.ndarray,
         rng: np.random.Generator | None = None) -> np.ndarray:
    """The range each beam reads from a robot at ``pose`` in ``world``.

    Args:
        world: the room (its walls, ``[0, width] x [0, depth]``, and its boxes).
        pose: the robot's true ``(x, y, theta)``.
        angles: the beams' angles from the robot's heading.
        rng: adds Gaussian noise of ``NOISE`` metres to every reading when given.

    Returns:
        float32 ranges; ``+inf`` where nothing lies within ``RANGE_MAX``.
    """
    x, y, theta = pose
    ranges = ray_ranges(world, x, y, theta + angles)
    if rng is not None:
        ranges = ranges + rng.normal(0.0, NOISE, ranges.shape)
    ranges = np.where(ranges > RANGE_MAX, np.inf, np.maximum(ranges, RANGE_MIN))
    return ranges.astype(np.float32)


def ray_ranges(world: World, x: float | np.ndarray, y: float | np.ndarray, heading: np.ndarray) -> np.ndarray:
    """How far each ray from ``(x, y)`` along ``heading`` (radians, in the map) travels before it
    meets a wall or a box of ``world``; the arguments broadcast together (several poses at once),
    and nothing is clipped to the scanner's range."""
    dx, dy = np.cos(heading), np.sin(heading)
    with np.errstate(divide="ignore", invalid="ignore"):
        # The room's walls, seen from inside: each beam leaves through one of them.
        to_x = np.where(dx > 0, (world.width - x) / dx, np.where(dx < 0, -x / dx, np.inf))
        to_y = np.where(dy > 0, (world.depth - y) / dy, np.where(dy < 0, -y / dy, np.inf))
        ranges = np.minimum(to_x, to_y)
        for box in world.boxes:  # the slab method: where the beam is inside both the x and the y slab
            tx0, tx1 = (box.x0 - x) / dx, (box.x1 - x) / dx
            ty0, ty1 = (box.y0 - y) / dy, (box.y1 - y) / dy
            near = np.maximum(np.minimum(tx0, tx1), np.minimum(ty0, ty1))
            far = np.minimum(np.maximum(tx0, tx1), np.maximum(ty0, ty1))
            hit = (near <= far) & (far > 0)
            ranges = np.where(hit, np.minimum(ranges, np.maximum(near, 0.0)), ranges)
    return np.asarray(ranges, dtype=np.float64)


def scan_message(ranges: np.ndarray, header: Header, scan_time: float) -> LaserScan:
    """A ``sensor_msgs/LaserScan`` of ``ranges`` (``beam_angles(len(ranges))``'s beams).

    Args:
        ranges: one reading per beam (metres, ``+inf`` for none).
        header: its stamp (when the scan was taken) and frame (``base_scan``).
        scan_time: seconds between two scans.
    """
    beams = len(ranges)
    increment = 2.0 * math.pi / beams
    return LaserScan(header=header, angle_min=-math.pi, angle_max=-math.pi + (beams - 1) * increment,
                     angle_increment=increment, time_increment=0.0, scan_time=float(scan_time),
                     range_min=RANGE_MIN, range_max=RANGE_MAX,
                     ranges=np.asarray(ranges, dtype=np.float32), intensities=np.zeros(0, dtype=np.float32))


def scan_points(scan: LaserScan) -> tuple[np.ndarray, np.ndarray]:
    """The readings of a scan as ``(x, y)`` in the robot's frame (forward, left), valid ones only
    (within ``[range_min, range_max]``, as REP 117 defines them)."""
    ranges = np.asarray(scan.ranges, dtype=np.float64)
    angles = scan.angle_min + np.arange(len(ranges)) * scan.angle_increment
    valid = np.isfinite(ranges) & (ranges >= scan.range_min) & (ranges <= scan.range_max)
    return ranges[valid] * np.cos(angles[valid]), ranges[valid] * np.sin(angles[valid])
