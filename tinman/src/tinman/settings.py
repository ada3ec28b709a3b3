"""How one TinMan run is configured, shared with every group process.

Role functions take only their endpoint, and group processes are spawned fresh,
so the run's settings travel in one environment variable (JSON) that the
launcher sets before the groups start and every role reads back.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache
from pathlib import Path

__all__ = ["Settings", "ENVIRONMENT_VARIABLE", "current", "export", "launched", "FAULTS"]

ENVIRONMENT_VARIABLE = "TINMAN_SETTINGS"
FAULTS = ("memory-hog", "blind-camera", "lying-pose", "overspeed", "stalled-pose")  # what --inject can put into a group


@dataclass(frozen=True)
class Settings:
    """One run's choices.

    Attributes:
        out: the folder for the report, the picture and each role's records.
        dataset: a TUM RGB-D sequence the camera plays back ("": the simulated camera renders the
            room from the simulated robot's true pose, live).
        world: how the room looks to the simulated camera (:data:`tinman.worlds.WORLDS`):
            ``"realistic"`` (photographs, plain walls, repeated patterns, flickering lamps, motion
            blur; :data:`tinman.worlds.DEFAULT_LOOK`) or ``"easy"`` (procedural textures made for ORB).
        duration: seconds the run lasts (with ``patrol``, its time limit).
        patrol: the whole patrol once (every waypoint, then back to the dock), the run ending
            when the Planner is back at the dock; else the patrol loops until ``duration``.
        paper: whether the run follows Fig. 16's single loop (``TinMan``).
        teleop: keyboard driving from the terminal instead of the scripted joystick.
        inject: group -> fault to inject (one of :data:`FAULTS`).
        groups: role -> the group that runs it (so a role knows whether a fault is its own).
        planner: ``"rrt"`` (RRT-Connect with shortcut smoothing) or ``"astar"``.
        control_rate: Hz of the joystick, hence of the whole control loop.
        camera_rate: Hz of the simulated camera (a recorded sequence plays at its own rate).
        replan_period: seconds between two plans.
        seed: for the planner's random samples.
    """

    out: str = "out/tinman"
    dataset: str = ""
    world: str = "realistic"
    duration: float = 20.0
    patrol: bool = False
    paper: bool = False
    teleop: bool = False
    inject: dict[str, str] = field(default_factory=dict)
    groups: dict[str, str] = field(default_factory=dict)
    planner: str = "rrt"
    control_rate: float = 50.0
    camera_rate: float = 30.0
    replan_period: float = 0.5
    seed: int = 0

    @property
    def records(self) -> Path:
        """Where roles leave what they measured (one JSON file per role)."""
        return Path(self.out) / "records"

    def fault_for(self, role: str) -> str | None:
        """The fault injected into ``role``'s group, if any."""
        group = self.groups.get(role)
        return self.inject.get(group) if group is not None else None

    def with_changes(self, **changes: object) -> Settings:
        return replace(self, **changes)  # type: ignore[arg-type]


def export(settings: Settings) -> None:
    """Make ``settings`` what :func:`current` returns here and in processes started after."""
    os.environ[ENVIRONMENT_VARIABLE] = json.dumps(asdict(settings))
    current.cache_clear()


def launched() -> bool:
    """Whether a launcher exported this run's settings (``anodize run tinman`` does; a role
    function called on its own, as ``anodize replay`` calls it, has none)."""
    return bool(os.environ.get(ENVIRONMENT_VARIABLE))


@lru_cache(maxsize=1)
def current() -> Settings:
    """The run's settings (the defaults when none were exported)."""
    text = os.environ.get(ENVIRONMENT_VARIABLE)
    return Settings(**json.loads(text)) if text else Settings()
