"""The named worlds ``--world`` chooses from: how the room looks to the camera.

Both share the default room's geometry (walls, boxes, dock, patrol), so the
planner, the simulator and the mission are the same and only what the camera
sees differs:

- ``easy``: procedural textures made for ORB (:func:`tinman.textures.build_atlas`),
  steady lamps, a still shutter; what the library's renderers, cameras and sequence
  generator paint unless told otherwise;
- ``realistic`` (``anodize run tinman``'s default): photographs, plain paint and repeated patterns
  (:func:`tinman.realistic.build_realistic_atlas`), lamps that drift and a failing
  one that flickers (:class:`tinman.lamps.FlickeringLamps`), and a 20 ms exposure
  that blurs the image when the robot moves or turns fast
  (:func:`tinman.synthetic.add_motion_blur`).

Both add the same sensor noise (depth noise and dropouts, image noise).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .realistic import build_realistic_atlas
from .textures import Atlas, Surface, build_atlas
from .world import World

__all__ = ["WORLDS", "DEFAULT_LOOK", "WorldLook", "UnknownWorldError", "world_look"]


@dataclass(frozen=True)
class WorldLook:
    """What makes a named world look the way it does.

    Attributes:
        name: the world's name (``--world NAME``).
        paint: paints the room's textures (the signature of :func:`tinman.textures.build_atlas`).
        flickering_lamps: whether the lamps' brightness varies over time.
        exposure: seconds the shutter is open: the camera blurs what moves during it (0: never).
    """

    name: str
    paint: Callable[[World, list[Surface], int], Atlas]
    flickering_lamps: bool
    exposure: float


_LOOKS = {
    "easy": WorldLook("easy", build_atlas, flickering_lamps=False, exposure=0.0),
    "realistic": WorldLook("realistic", build_realistic_atlas, flickering_lamps=True, exposure=0.02),
}
WORLDS = tuple(_LOOKS)
DEFAULT_LOOK = "realistic"  # what `anodize run tinman` films unless --world says otherwise


class UnknownWorldError(ValueError):
    """Raised when a world is asked for by a name that is not one of :data:`WORLDS`."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.name = name
        self.expected = WORLDS

    def __str__(self) -> str:
        return f"unknown world {self.name!r}; expected one of {', '.join(self.expected)}"


def world_look(name: str) -> WorldLook:
    """The named world's look.

    Raises:
        UnknownWorldError: ``name`` is not one of :data:`WORLDS`.
    """
    try:
        return _LOOKS[name]
    except KeyError:
        raise UnknownWorldError(name) from None
