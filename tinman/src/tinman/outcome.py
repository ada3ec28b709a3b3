"""TinMan's report of a run: what the robot system achieved, from the run report and the records."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from anodize import ProtocolViolationError, RunReport

from .ate import evaluate_ate
from .contract import contract_report
from .mission import DOCK
from .mission_outcome import mission_outcome
from .records import load_records
from .settings import Settings
from .tum import read_trajectory

__all__ = ["build_report", "violations_in", "truth_path", "CAMERA_TRUTH", "VO_ESTIMATE", "FUSED_ESTIMATE",
           "world_clock", "world_clock_line"]

CAMERA_TRUTH = "camera_truth.txt"  # in the records: the simulated camera's true path, TUM format
VO_ESTIMATE = "vo_estimate.txt"  # in the records: the camera's odometry's path, TUM format
FUSED_ESTIMATE = "fused_estimate.txt"  # in the records: the fused pose's path (camera poses), TUM format


def violations_in(report: RunReport) -> list[str]:
    """Every protocol violation the monitors raised, as ``role: message``."""
    found = [f"{name}: {role.error}" for name, role in report.roles.items()
             if isinstance(role.error, ProtocolViolationError)]
    found += [f"group {name}: {group.error}" for name, group in report.groups.items()
              if isinstance(group.error, ProtocolViolationError)]
    return found


def build_report(report: RunReport, settings: Settings) -> dict[str, Any]:
    """``report.json``'s content (see the README's TinMan section for each key)."""
    records = load_records(settings.records)
    vo = records.get("VisOdom", {})
    camera = records.get("Camera", {})
    move = records.get("Move", {})
    gazebo = records.get("Gazebo", {})
    planner = records.get("Planner", {})
    ate = _ate(settings)  # the camera's odometry alone (ate_*, also vo_ate_percent)
    fused = _ate(settings, FUSED_ESTIMATE)  # the one pose the robot steers by
    violations = violations_in(report)
    run = report.to_dict()
    mission = mission_outcome(records, dock=DOCK if settings.patrol else None, time_limit=settings.duration,
                              failed_at=report.duration if report.failed else None)
    return {
        "system": "tinman",
        "global": report.protocol,
        "transport": report.transport,
        "outcome": report.outcome,  # the system's: how the groups ended (the robot's is "mission")
        "mission": mission,
        "duration_s": round(report.duration, 3),
        "requested_duration_s": settings.duration,  # with --patrol, the time limit
        "patrol": settings.patrol,
        "dataset": settings.dataset,
        "world": settings.world if not settings.dataset else None,
        "injected": dict(settings.inject),
        **ate,
        "vo_ate_percent": ate["ate_percent"],
        "fused_ate_percent": fused["ate_percent"],
        "fused": {key: fused[key] for key in ("ate_rmse_m", "trajectory_length_m", "ate_percent", "ate_pairs",
                                               "final_position_error_m", "drift_per_m")},
        "frames_processed": vo.get("frames_processed"),
        "frames_dropped": _sum(vo.get("frames_dropped"), gazebo.get("camera_frames_skipped")),
        "frames_published": camera.get("frames_published"),
        "camera": gazebo.get("camera"),
        "world_clock": world_clock(gazebo),
        "vo_track_ms": {key: vo.get("track_ms", {}).get(key) for key in ("p50", "p99")},
        "violations": len(violations),
        "violation_messages": violations,
        "contract": contract_report(records, report),  # each time and value constraint, as the monitors saw it
        "messages": dict(report.messages),
        "high_water": dict(report.high_water),  # per channel, the most messages that waited at once
        "boosts": run["boosts"],  # priority inheritance: per waiter->target pair, episodes and seconds
        "logs": run["logs"],  # the roles' log records: per severity, dropped, the last warnings and errors
        "groups": {name: {key: group[key] for key in (
            "status", "scheduling", "peak_memory", "memory_bound", "memory_note", "notes", "error", "restarts",
            "messages", "rate_hz", "rate_min_hz")} for name, group in run["groups"].items()},
        "roles": {name: {"group": role["group"], "status": role["status"], "error": role["error"]}
                  for name, role in run["roles"].items()},
        "control_period_ms": move.get("period_ms", {"p50": None, "p99": None}),
        "control": {"commands": move.get("commands"), "sources": move.get("sources"),
                    "paths_received": move.get("paths_received"),
                    "planner_lost": move.get("planner_lost"),
                    "teleop_commands_after_planner_lost": move.get("teleop_commands_after_planner_lost"),
                    "estimates": move.get("estimates"),
                    "stops_for_lost_tracking": move.get("stops_for_lost_tracking"),
                    "path_commands_after_a_stop": move.get("path_commands_after_a_stop"),
                    "recovering_commands": move.get("recovering_commands"),
                    "path_commands_after_recovering": move.get("path_commands_after_recovering"),
                    "held_back_near_obstacles": move.get("held_back"),
                    "safety_stops": move.get("safety_stops"), "safety_slowed": move.get("safety_slowed"),
                    "safety_blind": move.get("safety_blind"), "scanner_lost": move.get("scanner_lost"),
                    "estimate_timeouts": move.get("estimate_timeouts"), "scan_timeouts": move.get("scan_timeouts")},
        "vo_lost_frames": vo.get("lost_frames"),
        "recovery": {"recoveries": vo.get("recoveries"), "time_to_recover_s": vo.get("recovery_s"),
                     "lost_at_the_end": vo.get("lost_at_the_end")},
        "fusion": {"fused": vo.get("fused"), "wheel_readings": vo.get("wheel_readings"),
                   "updates": vo.get("fused_updates"), "refused": vo.get("fused_refused"),
                   "scan_matches": vo.get("scan_matches"), "scan_matches_gated": vo.get("scan_matches_gated"),
                   "scans_unmatched": vo.get("scans_unmatched"), "relocated_on_the_map": vo.get("relocated_on_the_map"),
                   "scan_match_ms_p50": (vo.get("scan_match_ms") or {}).get("p50")},
        "robot": {"distance_m": _round(gazebo.get("odometer_m")), "bumps": gazebo.get("bumps"),
                  "waypoints_reached": len(mission["waypoints_reached"])},
        "planner": {"method": planner.get("method"), "plans": planner.get("plans"),
                    "failures": planner.get("failure_count"),
                    "plan_ms_p50": _round(float(np.median(planner["plan_ms"])) if planner.get("plan_ms") else None)},
        "notes": list(report.notes),
    }


def world_clock(gazebo: dict[str, Any]) -> dict[str, Any]:
    """How well the simulated world kept real time (it runs at nice -10 so that no load on the
    robot's groups starves it: decision 0030): the seconds its physics stepped (one control
    period per command) against the wall seconds from its first step to its last (plus a
    period), and the camera frames it rendered
    against those that fell due. A factor well below 1 means the run measured the harness's
    starvation as much as the robot."""
    simulated, wall = _number(gazebo.get("simulated_s")), _number(gazebo.get("wall_s"))
    factor = simulated / wall if simulated is not None and wall is not None and wall > 0 else None
    return {"simulated_s": _round(simulated), "wall_s": _round(wall), "real_time_factor": _round(factor),
            "camera_frames_rendered": gazebo.get("camera_frames"), "camera_frames_due": gazebo.get("camera_frames_due")}


def _number(value: Any) -> float | None:
    """A record's number (records are read as untrusted input: anything else is None)."""
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def world_clock_line(world: dict[str, Any]) -> str | None:
    """The printed line of :func:`world_clock` (None when the world left no record)."""
    if world.get("real_time_factor") is None:
        return None
    line = (f"world (real time): real-time factor {world['real_time_factor']:.2f} "
            f"({world['simulated_s']:.2f} s simulated in {world['wall_s']:.2f} s)")
    rendered, due = world.get("camera_frames_rendered"), world.get("camera_frames_due")
    if rendered is not None and due is not None:
        line += f"; camera rendered {rendered} of {due} frames due"
    return line


def _ate(settings: Settings, estimate: str = VO_ESTIMATE) -> dict[str, Any]:
    empty = {"ate_rmse_m": None, "trajectory_length_m": None, "ate_percent": None, "ate_pairs": 0,
             "final_position_error_m": None, "drift_per_m": None}
    estimate_file = settings.records / estimate
    truth_file = truth_path(settings)
    if not estimate_file.exists() or not truth_file.exists():
        return empty
    try:
        truth_stamps, truth_poses = read_trajectory(truth_file)
        stamps, poses = read_trajectory(estimate_file)
        result = evaluate_ate(truth_stamps, truth_poses[:, :3, 3], stamps, poses[:, :3, 3])
    except (OSError, ValueError) as error:
        return {**empty, "ate_error": str(error)}
    # Unaligned, in the map frame the odometry starts in (the robot's dock): where the robot
    # believes it ended, against where it did.
    nearest = int(np.argmin(np.abs(truth_stamps - stamps[-1])))
    final = float(np.linalg.norm(poses[-1][:3, 3] - truth_poses[nearest][:3, 3]))
    return {"ate_rmse_m": round(result.rmse, 5), "trajectory_length_m": round(result.length, 4),
            "ate_percent": round(result.percent, 4), "ate_pairs": result.pairs,
            "final_position_error_m": round(final, 4),
            "drift_per_m": round(final / result.length, 5) if result.length > 0 else None}


def truth_path(settings: Settings) -> Path:
    """The camera's true path: the simulated camera's (live), or the recording's ground truth."""
    if settings.dataset:
        return Path(settings.dataset) / "groundtruth.txt"
    return settings.records / CAMERA_TRUTH


def _sum(*values: Any) -> int | None:
    present = [int(v) for v in values if v is not None]
    return sum(present) if present else None


def _round(value: float | None, digits: int = 3) -> float | None:
    return None if value is None else round(float(value), digits)
