"""The planning group (priority 30, memory bound): Planner."""

from __future__ import annotations

import time

from anodize import Endpoint

from ..faults import start_faults
from ..geometry import robot_pose
from ..messages import Header, Path, PoseStamped, path_through, pose_matrix, seconds
from ..mission import DOCK, DOCKING_TOLERANCE, WAYPOINT_TOLERANCE
from ..planning import NoPathError, Patrol, Planner
from ..records import save_record
from ..settings import current
from ..world import DEFAULT_WORLD

__all__ = ["planner"]


def planner(ep: Endpoint) -> None:
    """Plans from VisOdom's pose to the patrol's next waypoint; Move gets the latest path.

    A Path goes back for every Pose (the protocol's loop); a new plan is made at
    most every ``replan_period`` seconds, and the latest one is sent in between.

    Time is the poses' own (their stamps, as a ROS node follows message time), never
    this process's clock: what the Planner sends depends on what it received and
    nothing else, so ``anodize replay`` of a recorded run reproduces it message for
    message. (The planning time measured for the record is not sent.)

    With ``--patrol`` (``settings.patrol``) the patrol is done once: the five waypoints,
    then back to the dock. Once the robot is there by its pose, the Planner sends empty
    paths (Move stays still) and writes the ``Patrol`` record, by which the launcher
    stops the run (:func:`tinman.app.patrol_done`).
    """
    settings = current()
    start_faults("Planner")
    planning = Planner(DEFAULT_WORLD, method=settings.planner, seed=settings.seed)
    patrol = Patrol(DEFAULT_WORLD, tolerance=WAYPOINT_TOLERANCE, dock=DOCK if settings.patrol else None,
                    dock_tolerance=DOCKING_TOLERANCE)
    path: Path | None = None
    docked = False
    planned_at = -float("inf")  # the stamp of the pose the last plan started from
    plans: list[dict[str, object]] = []
    failures: list[str] = []
    plan_ms: list[float] = []
    heading_to: tuple[float, float] | None = None  # the goal of the last plan logged at INFO
    while True:
        pose: PoseStamped = ep.recv("VisOdom").payload
        now = seconds(pose.header.stamp)
        if path is None:  # no plan yet: an empty path, and Move stays idle
            path = Path(header=Header(stamp=pose.header.stamp, frame_id="map"), poses=[])
        if now - planned_at >= settings.replan_period:
            planned_at = now
            x, y, _ = robot_pose(pose_matrix(pose.pose))
            goal = patrol.goal_for(x, y)
            if patrol.done:  # back at the dock: the robot stays, and the launcher ends the run
                if not docked:
                    docked = True
                    ep.logger.info("patrol done: docked at (%.2f, %.2f) after %d waypoints", x, y, patrol.reached)
                    path = Path(header=Header(stamp=pose.header.stamp, frame_id="map"), poses=[])
                    save_record("Patrol", {"completed_stamp": now, "x": round(x, 3), "y": round(y, 3),
                                           "waypoints": patrol.reached})
                ep.send("Move", "Path", path)
                continue
            began = time.perf_counter()
            try:
                points = planning.plan((x, y), goal)
            except NoPathError as error:  # keep following the last plan; say why in the record
                failures.append(str(error))
                ep.logger.warning("no path to (%.2f, %.2f): %s; following the last plan", *goal, error)
            else:
                plan_ms.append((time.perf_counter() - began) * 1000.0)
                if goal != heading_to:
                    heading_to = goal
                    ep.logger.info("new goal (%.2f, %.2f): a plan of %d points", *goal, len(points))
                ep.logger.debug("plan of %d points to (%.2f, %.2f) in %.1f ms", len(points), *goal, plan_ms[-1])
                header = Header(stamp=pose.header.stamp, frame_id="map")
                path = path_through(points, header)
                plans.append({"stamp": seconds(pose.header.stamp), "goal": list(goal),
                              "points": [[round(px, 3), round(py, 3)] for px, py in points]})
            # Written at every plan: a planner stopped by its memory bound leaves its record.
            save_record("Planner", {"method": settings.planner, "plans": len(plans),
                                    "failures": failures[-5:], "failure_count": len(failures),
                                    "plan_ms": plan_ms[-200:], "recent_plans": plans[-12:]})
        ep.send("Move", "Path", path)
