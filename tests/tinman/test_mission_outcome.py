"""The mission's outcome apart from the system's: waypoints reached (which, when), bumps, the
printed ``mission:`` line and the exit status, plurals, and the marks on the map."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import PathCollection

from anodize import RoleReport, RunReport
from anodize._supervision.report import RoleStatus
from tinman.app import _judge, _lines
from tinman.mission_outcome import Contact, counted, mission_line, mission_marks, mission_outcome
from tinman.outcome import build_report
from tinman.picture import run_figure
from tinman.settings import Settings
from tinman.world import DEFAULT_WORLD

FIRST, SECOND = DEFAULT_WORLD.waypoints[0], DEFAULT_WORLD.waypoints[1]
START = DEFAULT_WORLD.start


def _gazebo(*, bumps: list[list[float]] | None = None, through_second: bool = False) -> dict[str, Any]:
    """The robot drives from the dock to the first waypoint (there at t = 2.0 s), and on to the
    second (there at t = 4.0 s) if asked; ``bumps`` are ``[t, x, y]`` of refused steps."""
    stops = [(0.0, START[0], START[1]), (2.0, *FIRST)] + ([(4.0, *SECOND)] if through_second else [])
    rows = [[t, x, y, 0.0, 0.3, 0.0] for t, x, y in stops]
    return {"trajectory": rows, "columns": ["t", "x", "y", "theta", "v", "w"], "odometer_m": 3.5,
            "bumps": len(bumps or []), "bump_events": bumps or []}


def _write(records: Path, gazebo: dict[str, Any], move: dict[str, Any] | None = None) -> None:
    records.mkdir(parents=True, exist_ok=True)
    (records / "Gazebo.json").write_text(json.dumps(gazebo))
    (records / "Move.json").write_text(json.dumps(move or {"period_ms": {"p50": 20.0, "p99": 25.0}, "commands": 1}))
    (records / "VisOdom.json").write_text(json.dumps({"frames_processed": 1, "frames_dropped": 1, "lost_frames": 1}))


def _run_report() -> RunReport:
    """A run stopped by its timeout, no role failed."""
    move = RoleReport(name="Move", group="control", status=RoleStatus.STOPPED)
    return RunReport(protocol="TinManParallel", roles={"Move": move}, groups={}, duration=20.0, transport="process")


def test_which_waypoints_were_reached_and_when() -> None:
    marks = mission_marks({"Gazebo": _gazebo(through_second=True)})
    assert [(w.number, w.lap, w.t) for w in marks.waypoints] == [(1, 1, 2.0), (2, 1, 4.0)]
    mission = mission_outcome({"Gazebo": _gazebo(through_second=True)})
    assert mission["outcome"] == "ok" and not mission["patrol_completed"]
    assert [(w["number"], w["t_s"]) for w in mission["waypoints_reached"]] == [(1, 2.0), (2, 4.0)]


def test_bumps_are_grouped_into_contacts_where_they_happened() -> None:
    events = [[5.0, 2.0, 0.3], [5.02, 2.0, 0.3], [5.04, 2.0, 0.3], [9.0, 7.5, 4.0]]
    marks = mission_marks({"Gazebo": _gazebo(bumps=events)})
    assert marks.contacts == (Contact(5.0, 2.0, 0.3, 3), Contact(9.0, 7.5, 4.0, 1))


def test_a_run_that_bumped_failed_its_mission_whatever_the_system_outcome(tmp_path: Path) -> None:
    settings = Settings(out=str(tmp_path))
    _write(settings.records, _gazebo(bumps=[[5.0, 2.0, 0.3], [5.02, 2.0, 0.3]]))
    data = build_report(_run_report(), settings)
    assert data["outcome"] == "stopped, no failures"  # the system's: every group ran to the timeout
    assert data["mission"]["outcome"] == "FAILED" and data["mission"]["bumps"] == 2
    ok, problems = _judge(data, settings)
    assert not ok  # hence exit status 1
    assert any(problem.startswith("mission failed: the robot bumped into the room (2 bumps in 1 contact)")
               for problem in problems), problems
    lines = _lines(data, problems)
    assert lines[0].startswith("mission: FAILED (the robot bumped into the room (2 bumps in 1 contact)"), lines[0]
    assert lines[0].endswith(": 1 of 5 waypoints reached (1 at 2.0 s), 2 bumps"), lines[0]


def test_a_run_without_bumps_says_its_mission_is_ok(tmp_path: Path) -> None:
    settings = Settings(out=str(tmp_path))
    _write(settings.records, _gazebo(through_second=True),
           move={"period_ms": {"p50": 20.0, "p99": 25.0}, "commands": 2, "safety_stops": 1})
    data = build_report(_run_report(), settings)
    ok, problems = _judge(data, settings)
    assert ok, problems
    assert _lines(data, problems)[0] == ("mission: ok: 2 of 5 waypoints reached (1 at 2.0 s, 2 at 4.0 s), 0 bumps, "
                                         "1 safety stop")


def test_a_patrol_is_cut_short_by_a_failed_run_and_ended_by_its_time_limit_when_only_stopped(tmp_path: Path) -> None:
    settings = Settings(out=str(tmp_path), patrol=True, duration=150.0)
    _write(settings.records, _gazebo(through_second=True))
    stopped = build_report(_run_report(), settings)["mission"]  # the timeout stopped every role
    assert stopped["ended_by"] == "time limit" and stopped["failed_at_s"] is None
    failed = _run_report()
    failed.roles["Move"] = RoleReport(name="Move", group="control", status=RoleStatus.FAILED)
    mission = build_report(failed, settings)["mission"]
    assert mission["ended_by"] == "run failed" and mission["failed_at_s"] == 20.0
    assert mission["failures"][0].startswith("the patrol was cut short when the run failed at 20.0 s: ")


def test_plurals_are_right_in_the_printed_report(tmp_path: Path) -> None:
    assert [counted(n, "bump") for n in (0, 1, 2)] == ["0 bumps", "1 bump", "2 bumps"]
    assert [counted(n, "recovery", "recoveries") for n in (1, 3)] == ["1 recovery", "3 recoveries"]
    settings = Settings(out=str(tmp_path))
    _write(settings.records, _gazebo(bumps=[[5.0, 2.0, 0.3]]))
    data = build_report(_run_report(), settings)
    data.update(final_position_error_m=0.1, drift_per_m=0.03)  # as if visual odometry had been evaluated
    text = "\n".join(_lines(data, []))
    assert "drove 3.50 m, 1 waypoint reached, 1 bump;" in text, text
    assert "over 1 command\n" in text and "odometry lost track on 1 frame:" in text, text
    assert "1 waypoints" not in text and "1 bumps" not in text and "1 commands" not in text, text
    assert mission_line(data["mission"]).endswith("1 of 5 waypoints reached (1 at 2.0 s), 1 bump")


def _room(settings: Settings) -> Axes:
    return next(axes for axes in run_figure(settings).axes if axes.get_label() == "room")


def test_the_map_marks_the_waypoints_reached_and_the_bumps(tmp_path: Path) -> None:
    settings = Settings(out=str(tmp_path))
    _write(settings.records, _gazebo(bumps=[[5.0, 2.0, 0.3], [5.02, 2.0, 0.3], [9.0, 7.5, 4.0]],
                                     through_second=True))
    collections = {str(c.get_label()): c for c in _room(settings).collections if isinstance(c, PathCollection)}
    reached = next(c for label, c in collections.items() if label.startswith("waypoints reached (2)"))
    assert np.asarray(reached.get_offsets()).tolist() == [list(FIRST), list(SECOND)]
    bumps = next(c for label, c in collections.items() if label.startswith("bumps: 3 bumps in 2 contacts"))
    assert np.asarray(bumps.get_offsets()).tolist() == [[2.0, 0.3], [7.5, 4.0]]


def test_a_run_without_bumps_has_no_bump_mark(tmp_path: Path) -> None:
    settings = Settings(out=str(tmp_path))
    _write(settings.records, _gazebo())
    labels = [str(c.get_label()) for c in _room(settings).collections]
    assert not any(label.startswith("bumps") for label in labels)
    assert any(label.startswith("waypoints reached (1)") for label in labels)
