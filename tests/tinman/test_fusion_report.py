"""The report of the one pose and of relocalisation: raw VO and fused ATE side by side, the
recoveries and their times, the printed lines saying which is which (issue 28, items 2 and 3)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from anodize import RoleReport, RunReport
from anodize._supervision.report import RoleStatus
from tinman.app import _judge, _lines
from tinman.geometry import camera_pose
from tinman.outcome import CAMERA_TRUTH, FUSED_ESTIMATE, VO_ESTIMATE, build_report
from tinman.roles.perception import Recoveries
from tinman.settings import Settings
from tinman.tum import write_trajectory


def _run_report() -> RunReport:
    move = RoleReport(name="Move", group="control", status=RoleStatus.STOPPED)
    return RunReport(protocol="TinManParallel", roles={"Move": move}, groups={}, duration=20.0, transport="process")


def _write_run(records: Path) -> None:
    """4 m straight east; VO zigzags 10 cm either side, the fused pose 2 cm; VO lost track twice."""
    records.mkdir(parents=True, exist_ok=True)
    stamps = np.linspace(100.0, 110.0, 100)
    xs = np.linspace(1.0, 5.0, 100)
    side = np.where(np.arange(100) % 2 == 0, 1.0, -1.0)
    write_trajectory(records / CAMERA_TRUTH, stamps, [camera_pose(x, 1.0, 0.0) for x in xs])
    write_trajectory(records / VO_ESTIMATE, stamps, [camera_pose(x, 1.0 + 0.1 * s, 0.0)
                                                     for x, s in zip(xs, side, strict=True)])
    write_trajectory(records / FUSED_ESTIMATE, stamps, [camera_pose(x, 1.0 + 0.02 * s, 0.0)
                                                        for x, s in zip(xs, side, strict=True)])
    recoveries = Recoveries()
    for stamp, failed in ((1.0, True), (1.1, False), (3.0, True), (4.0, True), (5.0, False), (6.0, False)):
        recoveries.frame(stamp, failed)
    (records / "VisOdom.json").write_text(json.dumps({"frames_processed": 100, "frames_dropped": 0, "lost_frames": 3,
                                                      "fused": True, "wheel_readings": 500, "scan_matches": 98,
                                                      "scan_matches_gated": 1, "scans_unmatched": 1,
                                                      "scan_match_ms": {"p50": 0.8}, **recoveries.record()}))
    (records / "Move.json").write_text(json.dumps({"period_ms": {"p50": 20.0, "p99": 21.0}, "commands": 500,
                                                   "recovering_commands": 40, "stops_for_lost_tracking": 0}))
    (records / "Gazebo.json").write_text(json.dumps({"trajectory": [[0.0, 1.0, 1.0, 0.0, 0.0, 0.0]],
                                                     "columns": ["t", "x", "y", "theta", "v", "w"],
                                                     "odometer_m": 4.0, "bumps": 0, "bump_events": []}))


def test_the_report_gives_raw_vo_and_fused_ate_and_the_time_to_recover(tmp_path: Path) -> None:
    settings = Settings(out=str(tmp_path))
    _write_run(settings.records)
    data = build_report(_run_report(), settings)
    assert abs(data["vo_ate_percent"] - 2.5) < 0.05  # 10 cm over 4 m
    assert abs(data["fused_ate_percent"] - 0.5) < 0.01
    assert data["ate_percent"] == data["vo_ate_percent"]  # the camera's odometry, as before
    assert data["fused"]["trajectory_length_m"] == 4.0 and data["fused"]["ate_pairs"] == 100
    assert data["recovery"] == {"recoveries": 2, "time_to_recover_s": {"p50": 1.05, "max": 2.0},
                                "lost_at_the_end": False}
    assert data["mission"]["recoveries"] == 2
    fusion = data["fusion"]  # the scans matched on the map: taken, refused by the filter's gate, by the matcher
    assert (fusion["scan_matches"], fusion["scan_matches_gated"], fusion["scans_unmatched"]) == (98, 1, 1)
    assert fusion["scan_match_ms_p50"] == 0.8
    ok, problems = _judge(data, settings)
    assert ok, problems
    text = "\n".join(_lines(data, problems))
    assert "visual odometry: ATE RMSE 0.100 m over 4.00 m (2.50%), 100 frames tracked" in text, text
    assert ("fused pose (wheels, VO and the map, what the robot steers by): ATE RMSE 0.020 m over 4.00 m (0.50%); "
            "98 scans matched on the map") in text, text
    assert "robot (steered by the fused pose)" in text, text
    assert ("visual odometry lost track on 3 frames: 2 recoveries, time to recover p50 1.05 s, max 2.00 s; "
            "40 path commands on the wheels alone") in text, text
    assert "2 recoveries" in text.splitlines()[0]  # the mission line counts them


def test_a_run_still_lost_at_its_end_says_so() -> None:
    recoveries = Recoveries()
    recoveries.frame(1.0, True)
    assert recoveries.lost
    assert recoveries.record()["recoveries"] == 0 and recoveries.record()["lost_at_the_end"] is True
