"""The mission's outcome, apart from the system's: what the robot did in the room.

The run report says how the *system* ended (``stopped, no failures``: every group ran
until the timeout and none failed). Whether the robot did its job is another question,
answered here from the roles' records: which patrol waypoints it reached and when (on
its true path, the Gazebo record), where it bumped into the room, how often the safety
layer stopped it and how often odometry recovered after losing track. A bump is a
mission failure: the safety layer is there so that no pose estimate, however wrong,
drives the robot into a wall.

The picture marks what this module finds (:func:`mission_marks`), so the map and the
report cannot disagree.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .mission import WAYPOINT_TOLERANCE
from .world import DEFAULT_WORLD

__all__ = ["WaypointReached", "Contact", "MissionMarks", "mission_marks", "mission_outcome", "mission_line",
           "counted", "CONTACT_GAP"]

CONTACT_GAP = 0.5  # seconds: bumps closer in time than this are one contact (the robot pressing on a wall)


@dataclass(frozen=True)
class WaypointReached:
    """The robot came within tolerance of a patrol waypoint.

    Attributes:
        number: the waypoint's number in the patrol, from 1.
        lap: 1 on the first round of the patrol, 2 on the second, ...
        t: seconds since the simulator started.
        x, y: where the robot was then (metres).
    """

    number: int
    lap: int
    t: float
    x: float
    y: float


@dataclass(frozen=True)
class Contact:
    """Where the robot bumped into the room: consecutive refused steps at one place.

    Attributes:
        t: seconds since the simulator started, at the first refused step.
        x, y: where the robot was (metres).
        bumps: the steps refused there.
    """

    t: float
    x: float
    y: float
    bumps: int


@dataclass(frozen=True)
class MissionMarks:
    """What the picture marks on the map: reached waypoints and contacts."""

    waypoints: tuple[WaypointReached, ...]
    contacts: tuple[Contact, ...]


def mission_marks(records: Mapping[str, Mapping[str, Any]],
                  waypoints: Sequence[tuple[float, float]] = DEFAULT_WORLD.waypoints,
                  tolerance: float = WAYPOINT_TOLERANCE) -> MissionMarks:
    """The waypoints the robot reached, in patrol order, and where it bumped, from the Gazebo record."""
    gazebo = records.get("Gazebo", {})
    return MissionMarks(_reached(_rows(gazebo), waypoints, tolerance), _contacts(gazebo.get("bump_events") or []))


def mission_outcome(records: Mapping[str, Mapping[str, Any]],
                    waypoints: Sequence[tuple[float, float]] = DEFAULT_WORLD.waypoints) -> dict[str, Any]:
    """``report.json``'s ``mission``: ``outcome`` (``"ok"`` or ``"FAILED"``) and ``failures`` (why),
    ``waypoints_reached`` (each with its number, lap, time and place), ``patrol_completed`` (every
    waypoint reached, the last one being by the dock), ``bumps``, ``contacts``, ``safety_stops``
    and ``recoveries`` (None where no role counted them)."""
    marks = mission_marks(records, waypoints)
    gazebo = records.get("Gazebo", {})
    bumps = gazebo.get("bumps")
    failures = []
    if bumps:
        failures.append(f"the robot bumped into the room ({counted(bumps, 'bump')} in "
                        f"{counted(len(marks.contacts) or 1, 'contact')}): the safety layer did not stop it")
    return {
        "outcome": "FAILED" if failures else "ok",
        "failures": failures,
        "patrol_waypoints": len(waypoints),
        "waypoints_reached": [{"number": w.number, "lap": w.lap, "t_s": w.t, "x": w.x, "y": w.y}
                              for w in marks.waypoints],
        "patrol_completed": len(marks.waypoints) >= len(waypoints),
        "bumps": bumps,
        "contacts": [{"t_s": c.t, "x": c.x, "y": c.y, "bumps": c.bumps} for c in marks.contacts],
        "safety_stops": records.get("Move", {}).get("safety_stops"),
        "recoveries": records.get("VisOdom", {}).get("recoveries"),
    }


def mission_line(mission: Mapping[str, Any]) -> str:
    """``mission: ok: 2 of 5 waypoints reached (1 at 6.1 s, 2 at 12.8 s), 0 bumps, 1 safety stop``."""
    reached = mission["waypoints_reached"]
    when = ", ".join(f"{w['number']} at {w['t_s']:.1f} s" for w in reached)
    parts = [f"{len(reached)} of {counted(mission['patrol_waypoints'], 'waypoint')} reached"
             + (f" ({when})" if when else "") + (", patrol completed" if mission["patrol_completed"] else "")]
    if mission["bumps"] is not None:
        parts.append(counted(mission["bumps"], "bump"))
    if mission["safety_stops"] is not None:
        parts.append(counted(mission["safety_stops"], "safety stop"))
    if mission["recoveries"] is not None:
        parts.append(counted(mission["recoveries"], "recovery", "recoveries"))
    verdict = mission["outcome"] + (f" ({'; '.join(mission['failures'])})" if mission["failures"] else "")
    return f"mission: {verdict}: {', '.join(parts)}"


def counted(number: int, noun: str, plural: str | None = None) -> str:
    """``1 bump``, ``2 bumps``, ``0 bumps`` (``plural`` where adding an s is wrong)."""
    return f"{number} {noun if number == 1 else plural or noun + 's'}"


def _rows(gazebo: Mapping[str, Any]) -> list[tuple[float, float, float]]:
    """``(t, x, y)`` of the robot's true path (the record's ``columns`` say where each is)."""
    columns = list(gazebo.get("columns") or ["t", "x", "y"])
    try:
        it, ix, iy = columns.index("t"), columns.index("x"), columns.index("y")
        rows = [(float(row[it]), float(row[ix]), float(row[iy])) for row in gazebo.get("trajectory") or []]
    except (ValueError, IndexError, TypeError):
        return []
    return [row for row in rows if all(math.isfinite(v) for v in row)]


def _reached(rows: list[tuple[float, float, float]], waypoints: Sequence[tuple[float, float]],
             tolerance: float) -> tuple[WaypointReached, ...]:
    """The waypoints the robot passed in patrol order (as the Planner's ``Patrol`` moves on)."""
    found: list[WaypointReached] = []
    if not waypoints:
        return ()
    for t, x, y in rows:
        index = len(found) % len(waypoints)
        wx, wy = waypoints[index]
        if math.hypot(x - wx, y - wy) <= tolerance:
            found.append(WaypointReached(index + 1, len(found) // len(waypoints) + 1, round(t, 3), x, y))
    return tuple(found)


def _contacts(events: Sequence[Sequence[float]]) -> tuple[Contact, ...]:
    """Bump events ``[t, x, y]`` grouped into contacts (one per run of bumps less than CONTACT_GAP apart)."""
    contacts: list[Contact] = []
    last = -math.inf
    for event in events:
        try:
            t, x, y = (float(v) for v in event[:3])
        except (TypeError, ValueError):
            continue
        if contacts and t - last < CONTACT_GAP:
            head = contacts[-1]
            contacts[-1] = Contact(head.t, head.x, head.y, head.bumps + 1)
        else:
            contacts.append(Contact(round(t, 3), x, y, 1))
        last = t
    return tuple(contacts)
