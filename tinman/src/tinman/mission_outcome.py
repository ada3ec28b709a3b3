"""The mission's outcome, apart from the system's: what the robot did in the room.

The run report says how the *system* ended (``stopped, no failures``: every group ran
until the timeout and none failed). Whether the robot did its job is another question,
answered here from the roles' records: which patrol waypoints it reached and when (on
its true path, the Gazebo record), where it bumped into the room, how often the safety
layer stopped it and how often odometry recovered after losing track. A bump is a
mission failure: the safety layer is there so that no pose estimate, however wrong,
drives the robot into a wall.

With ``--patrol`` the patrol is done once: every waypoint, then back to the dock, and the
run ends when the Planner, by its pose, is back there (its ``Patrol`` record) or at the time
limit. The outcome then says which (``patrol completed in N s`` or ``time limit``), judged on
the true path: a patrol the Planner believed done but the robot did not truly drive fails.

The picture marks what this module finds (:func:`mission_marks`), so the map and the
report cannot disagree.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .mission import DOCK_TOLERANCE, WAYPOINT_TOLERANCE
from .world import DEFAULT_WORLD

__all__ = ["WaypointReached", "Contact", "DockReached", "MissionMarks", "mission_marks", "mission_outcome",
           "mission_line", "counted", "CONTACT_GAP"]

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
class DockReached:
    """Back at the dock after every waypoint of a patrol done once (``t``: seconds since the
    simulator started; ``x, y``: where the robot was then)."""

    t: float
    x: float
    y: float


@dataclass(frozen=True)
class MissionMarks:
    """What the picture marks on the map: reached waypoints, contacts, and the dock once back at it."""

    waypoints: tuple[WaypointReached, ...]
    contacts: tuple[Contact, ...]
    dock: DockReached | None = None


Point = tuple[float, float]


def mission_marks(records: Mapping[str, Mapping[str, Any]],
                  waypoints: Sequence[Point] = DEFAULT_WORLD.waypoints,
                  tolerance: float = WAYPOINT_TOLERANCE, dock: Point | None = None,
                  dock_tolerance: float = DOCK_TOLERANCE) -> MissionMarks:
    """The waypoints the robot reached, in patrol order, where it bumped, and (a patrol done once,
    ``dock`` given) when it was back at the dock after the last waypoint, from the Gazebo record."""
    gazebo = records.get("Gazebo", {})
    rows = _rows(gazebo)
    reached = _reached(rows, waypoints, tolerance)
    docked = _docked(rows, reached, len(waypoints), dock, dock_tolerance) if dock is not None else None
    return MissionMarks(reached, _contacts(gazebo.get("bump_events") or []), docked)


def mission_outcome(records: Mapping[str, Mapping[str, Any]],
                    waypoints: Sequence[Point] = DEFAULT_WORLD.waypoints, *,
                    dock: Point | None = None, time_limit: float | None = None,
                    failed_at: float | None = None) -> dict[str, Any]:
    """``report.json``'s ``mission``: ``outcome`` (``"ok"`` or ``"FAILED"``) and ``failures`` (why),
    ``waypoints_reached`` (each with its number, lap, time and place), ``patrol_completed``,
    ``bumps``, ``contacts``, ``safety_stops`` and ``recoveries`` (None where no role counted them).

    Looping (no ``dock``), ``patrol_completed`` is every waypoint reached once. The whole patrol
    (``dock``, with ``--patrol``): ``mode`` is ``"patrol"``, ``patrol_completed`` means every
    waypoint in order and then the dock on the true path, ``completed_in_s`` when it got back,
    ``ended_by`` is ``"patrol completed"`` (the Planner's ``Patrol`` record: back at the dock by
    its pose), ``"run failed"`` (the system failed at ``failed_at`` seconds, before the time limit)
    or ``"time limit"``, and a patrol not completed fails the mission."""
    marks = mission_marks(records, waypoints, dock=dock)
    gazebo = records.get("Gazebo", {})
    bumps = gazebo.get("bumps")
    failures = []
    if bumps:
        failures.append(f"the robot bumped into the room ({counted(bumps, 'bump')} in "
                        f"{counted(len(marks.contacts) or 1, 'contact')}): the safety layer did not stop it")
    every = len(marks.waypoints) >= len(waypoints)
    patrol: dict[str, Any] = {"mode": "loop", "ended_by": "duration", "time_limit_s": time_limit}
    if dock is not None:
        ended_by = ("patrol completed" if "Patrol" in records
                    else "run failed" if failed_at is not None else "time limit")
        completed = every and marks.dock is not None
        patrol = {"mode": "patrol", "ended_by": ended_by, "time_limit_s": time_limit, "failed_at_s": failed_at,
                  "dock": {"x": dock[0], "y": dock[1], "t_s": marks.dock.t if marks.dock else None,
                           "final_distance_m": _final_distance(gazebo, dock)},
                  "completed_in_s": marks.dock.t if completed and marks.dock else None}
        if not completed:
            failures.append(_not_completed(ended_by, marks, len(waypoints), patrol["dock"]["final_distance_m"],
                                           failed_at))
    return {
        "outcome": "FAILED" if failures else "ok",
        "failures": failures,
        **patrol,
        "patrol_waypoints": len(waypoints),
        "waypoints_reached": [{"number": w.number, "lap": w.lap, "t_s": w.t, "x": w.x, "y": w.y}
                              for w in marks.waypoints],
        "patrol_completed": every if dock is None else patrol["completed_in_s"] is not None,
        "bumps": bumps,
        "contacts": [{"t_s": c.t, "x": c.x, "y": c.y, "bumps": c.bumps} for c in marks.contacts],
        "safety_stops": records.get("Move", {}).get("safety_stops"),
        "recoveries": records.get("VisOdom", {}).get("recoveries"),
    }


def _not_completed(ended_by: str, marks: MissionMarks, waypoints: int, distance: float | None,
                   failed_at: float | None) -> str:
    """Why a patrol done once is not completed, on the true path."""
    where = f" ({distance:.2f} m from it at the end)" if distance is not None else ""
    missed = (f"reached {len(marks.waypoints)} of {counted(waypoints, 'waypoint')}"
              if len(marks.waypoints) < waypoints else f"did not get back to the dock{where}")
    if ended_by == "patrol completed":
        return f"the Planner, by its pose, was back at the dock, but the robot truly {missed}"
    if ended_by == "run failed":
        return f"the patrol was cut short when the run failed at {failed_at:.1f} s: the robot {missed}"
    return f"the patrol was not completed in the time limit: the robot {missed}"


def mission_line(mission: Mapping[str, Any]) -> str:
    """``mission: ok: 2 of 5 waypoints reached (1 at 6.1 s, 2 at 12.8 s), 0 bumps, 1 safety stop``;
    the whole patrol's begins ``patrol completed in 45.3 s:`` or ``time limit (180 s):``."""
    reached = mission["waypoints_reached"]
    when = ", ".join(f"{w['number']} at {w['t_s']:.1f} s" for w in reached)
    whole = mission.get("mode") == "patrol"
    parts = [f"{len(reached)} of {counted(mission['patrol_waypoints'], 'waypoint')} reached"
             + (f" ({when})" if when else "")
             + (", patrol completed" if mission["patrol_completed"] and not whole else "")]
    dock = mission.get("dock") or {}
    if whole and dock.get("t_s") is not None:
        parts.append(f"back at the dock at {dock['t_s']:.1f} s")
    elif whole and dock.get("final_distance_m") is not None:
        parts.append(f"{dock['final_distance_m']:.2f} m from the dock at the end")
    if mission["bumps"] is not None:
        parts.append(counted(mission["bumps"], "bump"))
    if mission["safety_stops"] is not None:
        parts.append(counted(mission["safety_stops"], "safety stop"))
    if mission["recoveries"] is not None:
        parts.append(counted(mission["recoveries"], "recovery", "recoveries"))
    verdict = mission["outcome"] + (f" ({'; '.join(mission['failures'])})" if mission["failures"] else "")
    head = ""
    if whole and mission.get("completed_in_s") is not None:
        head = f"patrol completed in {mission['completed_in_s']:.1f} s: "
    elif whole and mission.get("ended_by") == "run failed":
        head = f"run failed at {mission['failed_at_s']:.1f} s: "
    elif whole and mission.get("ended_by") == "time limit":
        limit = mission.get("time_limit_s")
        head = "time limit" + (f" ({limit:g} s)" if limit is not None else "") + ": "
    elif whole:
        head = "patrol ended by the Planner: "
    return f"mission: {verdict}: {head}{', '.join(parts)}"


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


def _docked(rows: list[tuple[float, float, float]], reached: Sequence[WaypointReached], waypoints: int,
            dock: Point, tolerance: float) -> DockReached | None:
    """The first moment, after the patrol's last waypoint, the robot was within ``tolerance`` of the dock."""
    if len(reached) < waypoints or not waypoints:
        return None
    after = reached[waypoints - 1].t
    for t, x, y in rows:
        if t >= after and math.hypot(x - dock[0], y - dock[1]) <= tolerance:
            return DockReached(round(t, 3), x, y)
    return None


def _final_distance(gazebo: Mapping[str, Any], dock: Point) -> float | None:
    """How far the robot truly was from the dock at the end (None: no true path)."""
    rows = _rows(gazebo)
    if not rows:
        return None
    _, x, y = rows[-1]
    return round(math.hypot(x - dock[0], y - dock[1]), 3)


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
