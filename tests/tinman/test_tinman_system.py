"""The whole TinMan system, run the way the README runs it, for a few seconds each."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from machine_stalls import tinman_run

from tinman.app import PATROL_HINT

pytestmark = pytest.mark.slow  # each runs the whole system in processes for seconds


@pytest.fixture
def sequence(tinman_sequence: Path) -> Path:
    """The session's 6 s synthetic sequence (tests/conftest.py): the start of the default patrol
    (runs past its end idle the camera)."""
    return tinman_sequence


def run_tinman(monkeypatch: pytest.MonkeyPatch, out: Path, sequence: Path | None, *options: str) -> dict:
    """Run TinMan; with a ``sequence`` its camera plays that recording back, else it renders live."""
    played = ["--dataset", str(sequence)] if sequence is not None else []
    status, report = tinman_run(monkeypatch, out, *played, *options)
    assert (out / "trajectory.png").stat().st_size > 10_000
    assert status == (0 if report["ok"] else 1)
    return report


def test_tinman_runs_with_every_group_and_no_violation(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path, sequence: Path) -> None:
    report = run_tinman(monkeypatch, tmp_path, sequence, "--duration", "6")
    assert report["ok"], report["problems"]
    assert report["global"] == "TinManParallel" and report["outcome"] == "stopped, no failures"
    assert report["violations"] == 0
    assert set(report["groups"]) == {"control", "perception", "planning", "simulation"}
    assert all(group["status"] == "stopped" for group in report["groups"].values())
    assert report["frames_processed"] > 30
    assert report["ate_rmse_m"] is not None and report["ate_percent"] < 5.0
    assert report["control_period_ms"]["p50"] is not None
    for channel in ("Joy->Control", "Control->Move", "Move->Gazebo", "Camera->VisOdom",
                    "VisOdom->Visualizer", "VisOdom->Planner", "Planner->Move"):
        assert report["messages"][channel] > 0, channel
    # The control loop outpaces the camera loop, which outpaces the planning loop; a camera
    # frame is two messages (its colour and its depth Image).
    frames = report["messages"]["Camera->VisOdom"] / 2
    assert report["messages"]["Move->Gazebo"] > frames > report["messages"]["Planner->Move"]
    assert report["control"]["sources"]["path"] > 0  # the robot followed plans
    assert report["logs"]["counts"]["INFO"] >= 1  # the Planner logged its goal (ep.logger)
    assert report["logs"]["dropped"] == dict.fromkeys(report["logs"]["dropped"], 0)
    assert report["robot"]["distance_m"] > 0.3 and report["robot"]["bumps"] == 0
    assert_the_contract_held(report)


def assert_the_contract_held(report: dict) -> None:
    """Every constraint of the protocol was checked, on both sides where both check, and held."""
    contract = {(entry["interaction"].split(":")[0], entry["side"]): entry for entry in report["contract"]}
    assert {"Joy -> Control", "Control -> Move", "Move -> Gazebo", "VisOdom -> Move", "Gazebo -> Move",
            "Gazebo -> Camera"} == {pair for pair, _ in contract}
    for (pair, side), entry in contract.items():
        assert entry["checked"] > 0 and entry["held"] and entry["violations"] == [], (pair, side, entry)
    joy = contract["Joy -> Control", "sends"]
    assert joy["constraints"] == "every 20ms +- 15ms" and 0 < joy["closest_ms"] <= 15
    assert "abs(linear.x) <= 0.5" in contract["Move -> Gazebo", "sends"]["constraints"]


@pytest.fixture(scope="module")
def two_faults(tmp_path_factory: pytest.TempPathFactory, tinman_sequence: Path) -> dict:
    """One 9 s run with two faults in two groups, each asserted by a test of its own below: a memory
    hog in planning (from 3 s on, the group's bound stops it at about 4.6 s) and a stalled pose in
    perception (VisOdom holds its pose to Move back from 3 s to 5 s). They meet no state in common:
    a lost planner leaves Move its last path, a late pose stops path following (sources "lost"),
    and neither fault blames anyone."""
    with pytest.MonkeyPatch.context() as patch:
        return run_tinman(patch, tmp_path_factory.mktemp("two_faults"), tinman_sequence, "--duration", "9",
                          "--inject", "memory-hog=planning", "--inject", "stalled-pose=perception")


def test_a_leaking_planner_is_stopped_while_control_keeps_driving(two_faults: dict) -> None:
    report = two_faults
    assert report["ok"], report["problems"]
    planning = report["groups"]["planning"]
    assert planning["status"] == "failed" and planning["error"]["type"] == "MemoryBoundError"
    assert report["groups"]["control"]["status"] == "stopped"      # ran until the end
    assert report["groups"]["perception"]["status"] == "stopped"
    assert report["control"]["planner_lost"] is not None
    # The scripted joystick's turn at 6 s came after the planner was gone, and was obeyed.
    assert report["control"]["teleop_commands_after_planner_lost"] > 0
    assert report["violations"] == 0


def test_the_papers_single_loop_also_runs(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, sequence: Path) -> None:
    report = run_tinman(monkeypatch, tmp_path, sequence, "--duration", "4", "--paper")
    assert report["global"] == "TinMan" and report["violations"] == 0
    assert report["ok"], report["problems"]
    # One loop: Move waits for a Path per camera frame, so the robot's commands go at the
    # camera's pace (30 Hz at most) while the joystick's queue up at 50 Hz.
    messages = report["messages"]
    assert abs(messages["Move->Gazebo"] - messages["Planner->Move"]) <= 1
    assert messages["Move->Gazebo"] <= messages["Camera->VisOdom"] / 2  # colour and depth per frame
    assert messages["Move->Gazebo"] < 0.8 * messages["Joy->Control"]


def test_the_camera_sees_the_simulated_robot(tinman_recorded: Any) -> None:
    """No sequence played back: Gazebo renders the camera's view from the robot's true pose, live,
    and the odometry is measured against the path the simulated camera really took. The default run
    (the README's, here shorter), so it also prints how to run the whole patrol, last. It is the
    session's recorded run (tests/conftest.py), which the replay and verify tests read too: the
    recording changes none of what is asserted here."""
    out: Path = tinman_recorded.out
    report = json.loads((out / "report.json").read_text())
    assert (out / "trajectory.png").stat().st_size > 10_000
    assert tinman_recorded.status == (0 if report["ok"] else 1)
    assert not report["patrol"] and report["mission"]["mode"] == "loop"
    assert tinman_recorded.printed.rstrip().splitlines()[-1] == PATROL_HINT
    assert report["ok"], report["problems"]
    assert report["camera"] == "live" and report["dataset"] == "" and report["violations"] == 0
    assert report["frames_processed"] > 60 and report["robot"]["bumps"] == 0
    truth = (out / "records" / "camera_truth.txt").read_text().splitlines()
    assert len([line for line in truth if not line.startswith("#")]) >= report["frames_processed"]
    # ATE against that true path; the robot drove, so the path has a length.
    assert report["ate_pairs"] >= 0.9 * report["frames_processed"] and report["trajectory_length_m"] > 0.5
    assert report["ate_percent"] < 5.0  # the easy room: VO tracks well (issue 14 measures a harder one)


def test_a_lying_pose_estimate_does_not_drive_the_robot_into_a_wall(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """The odometry's map is turned 90 degrees about the dock: steering east by it drives the robot
    south, at the wall 0.8 m away. The safety layer's scan, which does not go through the estimate,
    stops it short."""
    # 10 s: time for the groups to start and the odometry to fix the robot, on a busy machine too.
    report = run_tinman(monkeypatch, tmp_path, None, "--duration", "10", "--world", "easy",
                        "--inject", "lying-pose=perception")
    assert report["violations"] == 0
    assert report["robot"]["bumps"] == 0, report["problems"]
    assert report["control"]["safety_stops"] >= 1
    assert report["ok"], report["problems"]
    # It did drive at the wall (south of the dock), and stopped short of it.
    trajectory = json.loads((tmp_path / "records" / "Gazebo.json").read_text())["trajectory"]
    nearest = min(row[2] for row in trajectory)  # y: the south wall is y = 0
    assert nearest < 0.6
    assert nearest > 0.18  # the robot's radius: never touched


def test_an_overspeeding_control_is_refused_and_blamed_on_control(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path, sequence: Path) -> None:
    """Control commands 2 m/s after 2 s ("overspeed"): the refinement on Control -> Move refuses
    the send (nothing leaves: the robot never drove faster than 0.5 m/s), blames Control, and the
    report's contract and outcome say so."""
    report = run_tinman(monkeypatch, tmp_path, sequence, "--duration", "5", "--inject", "overspeed=control")
    assert not report["ok"] and report["violations"] >= 1
    assert report["roles"]["Control"]["error"]["type"] == "ProtocolViolationError"
    [entry] = [e for e in report["contract"] if e["interaction"].startswith("Control -> Move") and e["side"] == "sends"]
    [violation] = entry["violations"]
    assert not entry["held"] and violation["blame"] == "Control" and violation["raised_at"] == "Control"
    assert "refinement {abs(linear.x) <= 0.5" in violation["message"] and "is false" in violation["message"]
    [received] = [e for e in report["contract"] if e["interaction"].startswith("Control -> Move")
                  and e["side"] == "receives"]
    assert received["held"]  # Move never saw it: nothing left Control
    trajectory = json.loads((tmp_path / "records" / "Gazebo.json").read_text())["trajectory"]
    assert max(abs(row[4]) for row in trajectory) <= 0.5  # no 2 m/s command reached the robot


def test_a_perception_stall_times_move_out_and_path_following_stops(two_faults: dict) -> None:
    """VisOdom holds its pose to Move back for 2 s ("stalled-pose"): Move's estimates thread takes the
    protocol's timeout (500 ms), counts it, and path following stops until the next pose; no bump,
    nobody blamed."""
    report = two_faults
    assert report["ok"], report["problems"]
    control = report["control"]
    assert control["estimate_timeouts"] >= 3  # 2 s of stall is four deadlines of 500 ms
    assert control["stops_for_lost_tracking"] >= 1 and control["sources"]["lost"] > 0
    assert report["robot"]["bumps"] == 0 and report["violations"] == 0
    [entry] = [e for e in report["contract"]
               if e["interaction"].startswith("VisOdom -> Move") and e["side"] == "receives"]
    assert entry["held"] and entry["timeouts"] == control["estimate_timeouts"]
