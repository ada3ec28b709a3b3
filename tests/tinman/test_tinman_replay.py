"""``anodize replay`` of a recorded TinMan run (plain ``--record``, which records every channel,
those inside a group too): every role's replay but the simulator's matches its
recording message for message (the roles read time through their endpoints, which a recording
records and a replay gives back; Move's and VisOdom's threads go through their recorded order);
the Visualizer, which only receives, compares nothing and says so (exit 1); no replay writes
into the recorded run's folder; and the run's report gives the world's real-time factor."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import sessiontypes
from anodize._recording.reader import open_recording
from anodize._tools import cli
from anodize._tools.config import load_config
from sessiontypes.graph import communication_graph
from tinman.app import SYSTEM_FILE
from tinman.settings import ENVIRONMENT_VARIABLE

pytestmark = pytest.mark.slow  # runs the whole system in processes for seconds, then replays in a fresh process

ROOT = Path(__file__).resolve().parents[2]


BAG = "run.mcap"  # the recording plain --record writes in the run's folder


@pytest.fixture(scope="module")
def recorded(tinman_recorded: Any) -> Path:
    """The session's recorded 6 s run (tests/conftest.py) in ``<tmp>/out/tinman``: the folder the
    default settings name, seen from ``<tmp>``."""
    out: Path = tinman_recorded.out
    report = json.loads((out / "report.json").read_text())
    assert report["messages"].get("VisOdom->Planner", 0) >= 2, report["messages"]
    return out


def _folder(out: Path) -> dict[str, tuple[int, bytes]]:
    return {str(path.relative_to(out)): (path.stat().st_mtime_ns, path.read_bytes())
            for path in sorted(out.rglob("*")) if path.is_file() and path.suffix != ".mcap"}


def _replay(recorded: Path, role: str, function: str) -> tuple[int, str]:
    """``anodize replay`` as a user runs it: a fresh process, in the folder above ``out/tinman``."""
    environment = {key: value for key, value in os.environ.items() if key != ENVIRONMENT_VARIABLE}
    environment["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "tinman" / "src")])
    done = subprocess.run([sys.executable, "-m", "anodize._tools.cli", "replay", str(recorded / BAG),
                           "--role", role, "--function", function, "--timeout", "60"],
                          cwd=recorded.parent.parent, env=environment, capture_output=True, text=True, timeout=180)
    assert done.stderr == "", done.stderr
    return done.returncode, done.stdout


ROLES = {"Joy": "control:joy", "Control": "control:control", "Move": "control:move",
         "Camera": "perception:camera", "VisOdom": "perception:visodom", "Planner": "planner:planner"}


# Joy's period and Move's timeouts (tinman.proto's contract) replay too: the replay's clock keeps
# its origin past the recorded readings, and a wait that expired in the run expires in the replay.
@pytest.mark.parametrize("role", sorted(ROLES))
def test_each_role_but_the_simulator_s_replays_equal_and_writes_nothing_into_the_run(recorded: Path,
                                                                                     role: str) -> None:
    before = _folder(recorded)
    assert f"records/{role}.json" in before or role in ("Joy", "Control")  # they keep no record
    status, out = _replay(recorded, role, f"tinman.roles.{ROLES[role]}")
    lines = out.splitlines()
    assert lines[0].endswith("global TinManParallel: matches the recording and follows the protocol"), out
    sent = [line for line in lines if line.startswith(f"  sent on {role}->")]
    assert sent, out
    for line in sent:  # every recorded message of each channel out of the role, compared
        compared, _, recorded_count = line.split(": ", 1)[1].partition(" compared of ")
        assert int(compared) >= 2 and recorded_count == f"{compared} recorded", out
    assert not any(line.startswith(("note: threads:", "note: clock:")) for line in lines), out
    assert status == 0
    assert _folder(recorded) == before  # not a file of the recorded run written again


def test_plain_record_holds_every_channel_of_tinman(recorded: Path) -> None:
    """Every channel of TinManParallel, those inside a group (Joy->Control, Camera->VisOdom, ...) too."""
    config = load_config(SYSTEM_FILE)
    channels = communication_graph(sessiontypes.load(str(config.protocol)).globals["TinManParallel"]).edges
    with open_recording(recorded / BAG) as recording:
        listed = set(recording.info["recorded_channels"].split())
        topics = {(t.metadata.get("anodize.sender"), t.metadata.get("anodize.receiver")) for t in recording.topics}
    assert listed == {f"{s}->{r}" for s, r in channels}
    assert {("Joy", "Control"), ("Control", "Move"), ("Camera", "VisOdom"), ("Gazebo", "Camera")} <= topics


def test_the_visualizer_only_receives_so_its_replay_compares_nothing_and_fails(recorded: Path) -> None:
    before = _folder(recorded)
    status, out = _replay(recorded, "Visualizer", "tinman.roles.simulation:visualizer")
    assert out.splitlines()[0].endswith("COMPARED NOTHING: the role sent no message on a recorded channel, so the "
                                        "replay shows nothing (not a pass)"), out
    assert status == 1
    assert _folder(recorded) == before


def test_the_report_gives_the_world_s_real_time_factor(recorded: Path) -> None:
    world = json.loads((recorded / "report.json").read_text())["world_clock"]
    assert world["simulated_s"] > 0 and world["wall_s"] > 0
    assert abs(world["real_time_factor"] - world["simulated_s"] / world["wall_s"]) < 0.01
    assert 0 < world["camera_frames_rendered"] <= world["camera_frames_due"]


def test_the_recorded_run_s_contract_held_and_verify_lists_its_constraints(
        recorded: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The report's contract section and ``anodize verify`` of the recording agree: every constraint
    held; verify judges the period, the deadlines and the velocity limits on the recorded times and
    payloads, and says why it leaves the deadlines with ``else timeout`` unjudged."""
    report = json.loads((recorded / "report.json").read_text())
    assert report["contract"] and all(entry["held"] and entry["checked"] > 0 for entry in report["contract"])
    capsys.readouterr()
    assert cli.main(["verify", str(recorded / BAG)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"{recorded / BAG} conforms to TinManParallel"), lines
    assert not any(line.startswith(("not recorded", "missing", "gap")) for line in lines), lines
    held = [line for line in lines if line.startswith("constraint: ") and ": held on " in line]
    for start in ("Joy->Control Joy every 20ms +- 15ms", "Control->Move Twist within 100ms",
                  "Move->Gazebo Twist within 500ms", "Move->Gazebo Twist {abs(linear.x) <= 0.5",
                  "Control->Move Twist {abs(linear.x) <= 0.5"):
        assert any(line.startswith(f"constraint: {start}") for line in held), (start, lines)
    assert "constraint: VisOdom->Move Pose within 500ms else timeout: not judged" in "\n".join(lines)
