"""The simulator's camera: where Gazebo's RGB-D images come from.

On a real TinMan, Gazebo's camera plugin renders what the camera on the simulated
robot sees. :class:`LiveCamera` does that: it renders the room from the robot's
true pose (through the camera's mount, :func:`tinman.geometry.camera_pose`) and adds
the sensor's noise (Kinect-like depth noise and dropouts, image noise). Odometry
then tracks the robot that is really driving, so its error is the robot's. In the
realistic world (:mod:`tinman.worlds`) the lamps flicker and the image blurs along
the camera's motion during the exposure.
:class:`RecordedCamera` plays a recorded TUM RGB-D sequence back instead
(``anodize run tinman --dataset DIR``): the images then belong to that recording's
path, not to the simulated robot.
"""

from __future__ import annotations

import numpy as np

from .geometry import FR1, Intrinsics, camera_pose
from .messages import Header, Image, image_of, stamp_from_seconds
from .sim import arc_pose
from .world import World
from .worlds import world_look

__all__ = ["LiveCamera", "RecordedCamera", "OPTICAL_FRAME", "frame_images"]

OPTICAL_FRAME = "camera_optical"  # the images' frame_id: depth is registered to colour, as TUM's is


def frame_images(rgb: np.ndarray, depth_raw: np.ndarray, color_stamp: float, depth_stamp: float) -> tuple[Image, Image]:
    """A colour (``rgb8``) and a depth (``16UC1``, 5000 units per metre) ``sensor_msgs/Image``."""
    color = image_of(rgb, "rgb8", Header(stamp=stamp_from_seconds(color_stamp), frame_id=OPTICAL_FRAME))
    depth = image_of(depth_raw, "16UC1", Header(stamp=stamp_from_seconds(depth_stamp), frame_id=OPTICAL_FRAME))
    return color, depth


class LiveCamera:
    """Renders the camera's view of ``world`` from a robot pose, with the sensor's noise.

    Args:
        world: the room.
        intrinsics: the camera (freiburg1's by default, as the recorded sequences).
        seed: the textures' seed and the noise's (and the lamps' flicker's).
        look: the named world (:data:`tinman.worlds.WORLDS`): its textures, lamps and exposure.

    Raises:
        tinman.worlds.UnknownWorldError: ``look`` names no world.
        tinman.photos.PhotoMissingError: the realistic world's photographs are not installed.
    """

    def __init__(self, world: World, intrinsics: Intrinsics = FR1, seed: int = 0, *,
                 look: str = "easy") -> None:
        from .lamps import FlickeringLamps
        from .render import RoomRenderer
        from .render_warp import WarpRenderer

        self.intrinsics = intrinsics
        self.look = world_look(look)
        # The textures are painted here: a second or two.
        self.renderer: RoomRenderer | WarpRenderer
        if self.look.name == "easy":
            # The per-surface warp renderer: the ray caster's images (exact depth, the same textures),
            # in two thirds of its time (bench/render.py).
            self.renderer = WarpRenderer(world, intrinsics, seed)
        else:
            # The warp renderer paints only the easy room's textures and cannot relight a frame for
            # flickering lamps: other worlds are ray-cast.
            self.renderer = RoomRenderer(world, intrinsics, seed, paint=self.look.paint)
        lighting = self.renderer._atlas.lighting
        self.lamps = (FlickeringLamps(len(lighting.lamps), seed)
                      if self.look.flickering_lamps and lighting is not None else None)
        self._rng = np.random.default_rng([seed, 2])
        self._first_stamp: float | None = None

    def capture(self, robot: tuple[float, float, float], stamp: float, blind: bool = False,
                velocity: tuple[float, float] = (0.0, 0.0)) -> tuple[Image, Image, np.ndarray]:
        """The images the camera takes at ``stamp`` (seconds) on a robot at ``(x, y, theta)``,
        and the camera's true pose ``T_wc`` then; ``blind``: a covered lens (black, no depth).

        ``velocity`` is the robot's ``(v, w)`` (m/s, rad/s): in a world whose camera has an
        exposure time, the image is blurred by the motion during it (centred on ``stamp``).
        The lamps' clock starts at the first frame's stamp.
        """
        from .synthetic import simulate_frame

        t_wc = camera_pose(*robot)
        if self._first_stamp is None:
            self._first_stamp = stamp
        if blind:
            k = self.intrinsics
            color, depth_image = frame_images(np.zeros((k.height, k.width, 3), np.uint8),
                                              np.zeros((k.height, k.width), np.uint16), stamp, stamp)
            return color, depth_image, t_wc
        gains = self.lamps.gains(stamp - self._first_stamp) if self.lamps is not None else None
        shutter = None
        exposure = self.look.exposure
        if exposure > 0 and velocity != (0.0, 0.0):
            shutter = (camera_pose(*arc_pose(*robot, *velocity, -exposure / 2)),
                       camera_pose(*arc_pose(*robot, *velocity, exposure / 2)))
        rgb, depth_raw = simulate_frame(self.renderer, t_wc, self._rng, gains, shutter)
        color, depth_image = frame_images(rgb, depth_raw, stamp, stamp)
        return color, depth_image, t_wc


class RecordedCamera:
    """Plays a TUM RGB-D sequence back, frame by frame, with the stamps it was recorded with."""

    def __init__(self, directory: str) -> None:
        from .dataset import TumSequence

        self.sequence = TumSequence.open(directory)
        self.intrinsics = self.sequence.intrinsics
        self.frame_rate = self.sequence.frame_rate

    def __len__(self) -> int:
        return len(self.sequence)

    def offset(self, index: int) -> float:
        """Seconds from the first frame to frame ``index``."""
        stamps = self.sequence.stamps
        return float(stamps[index]) - float(stamps[0])

    def frame(self, index: int) -> tuple[Image, Image]:
        """Frame ``index``: its colour and depth images."""
        sequence = self.sequence
        return frame_images(sequence.rgb(index), sequence.depth_raw(index), float(sequence.stamps[index]),
                            float(sequence.depth_stamps[index]))

