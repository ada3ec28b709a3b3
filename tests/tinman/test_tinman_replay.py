"""``anodize replay`` of a recorded TinMan run: the Planner's replay matches its recording message
for message, and no replay writes into the recorded run's folder."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from anodize._tools import cli
from tinman.settings import ENVIRONMENT_VARIABLE

pytestmark = pytest.mark.slow  # runs the whole system in processes for seconds, then replays in a fresh process

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recorded 6 s run in ``<tmp>/out/tinman``: the folder the default settings name, seen from ``<tmp>``."""
    root = tmp_path_factory.mktemp("replayed")
    out = root / "out" / "tinman"
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(ENVIRONMENT_VARIABLE, "")  # restored after the run: the run exports its own
        status = cli.main(["run", "tinman", "--quiet", "--duration", "6", "--record", "--out", str(out)])
    report = json.loads((out / "report.json").read_text())
    assert status == (0 if report["ok"] else 1)
    assert report["messages"].get("VisOdom->Planner", 0) >= 2, report["messages"]
    return out


def _folder(out: Path) -> dict[str, tuple[int, bytes]]:
    return {str(path.relative_to(out)): (path.stat().st_mtime_ns, path.read_bytes())
            for path in sorted(out.rglob("*")) if path.is_file() and path.suffix != ".mcap"}


def _replay(recorded: Path, role: str, function: str) -> tuple[int, str]:
    """``anodize replay`` as a user runs it: a fresh process, in the folder above ``out/tinman``."""
    environment = {key: value for key, value in os.environ.items() if key != ENVIRONMENT_VARIABLE}
    environment["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "tinman" / "src")])
    done = subprocess.run([sys.executable, "-m", "anodize._tools.cli", "replay", str(recorded / "run.mcap"),
                           "--role", role, "--function", function, "--timeout", "60"],
                          cwd=recorded.parent.parent, env=environment, capture_output=True, text=True, timeout=180)
    assert done.stderr == "", done.stderr
    return done.returncode, done.stdout


def test_the_planners_replay_matches_its_recording_and_writes_nothing_into_the_run(recorded: Path) -> None:
    before = _folder(recorded)
    assert "records/Planner.json" in before
    status, out = _replay(recorded, "Planner", "tinman.roles.planner:planner")
    first = out.splitlines()[0]
    assert first.endswith("global TinManParallel: matches the recording and follows the protocol"), out
    sent = next(line for line in out.splitlines() if line.startswith("  sent on Planner->Move: "))
    compared, _, recorded_count = sent.removeprefix("  sent on Planner->Move: ").partition(" compared of ")
    assert int(compared) >= 2 and recorded_count == f"{compared} recorded", out
    assert status == 0
    assert _folder(recorded) == before  # not a file of the recorded run written again
