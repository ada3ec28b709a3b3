"""Logging end to end through ``anodize run``: the terminal, the report (text and JSON), a flood."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from anodize._tools.cli import main

REPO = Path(__file__).resolve().parents[3]
TESTS = REPO / "tests" / "anodize"


def system_file(tmp_path: Path, transport: str, producer: str = "producer") -> Path:
    path = tmp_path / "system.toml"
    path.write_text(f'protocol = "{REPO / "protocols" / "stream.proto"}"\nglobal = "Stream"\n'
                    f'transport = "{transport}"\npythonpath = ["{TESTS}"]\ntimeout = 60\n'
                    f'[groups.a]\nroles = {{ P = "logging_roles:{producer}" }}\n'
                    f'[groups.b]\nroles = {{ C = "logging_roles:consumer" }}\n', encoding="utf-8")
    return path


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    status = main(list(argv))
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return status, out, err


@pytest.mark.parametrize("transport", ["inproc", "process"])
def test_run_prints_each_severity_with_role_and_reports_counts(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, transport: str) -> None:
    report = tmp_path / "run.json"
    status, out, err = run(capsys, "run", str(system_file(tmp_path, transport)), "--json", str(report))
    assert (status, err) == (0, "")
    logged = [line for line in out.splitlines() if line.startswith("[")]
    shown = [(line.split("] ")[0] + "]", line.split("] [")[2]) for line in logged]
    expected = [("[DEBUG]", "P]: debug from P"), ("[INFO]", "P]: planning 2 items"), ("[WARN]", "P]: battery low"),
                ("[ERROR]", "P]: lidar lost"), ("[FATAL]", "P]: safety stop")]
    assert [s for s in shown if s[1].startswith("P]")] == expected
    # the consumer's module logger (INFO) is the role's record only in a group's own process,
    # whose root level anodize sets; in-process the root level stays the caller's (WARNING)
    assert (("[INFO]", "C]: consumer done") in shown) == (transport == "process")
    assert "  logs: 1 DEBUG, " in out and "  [FATAL] [P]: safety stop" in out
    data = json.loads(report.read_text(encoding="utf-8"))["logs"]
    assert data["counts"] == {"DEBUG": 1, "INFO": 1 + (transport == "process"), "WARN": 1, "ERROR": 1, "FATAL": 1}
    assert data["dropped"] == dict.fromkeys(data["dropped"], 0)
    assert [(e["severity"], e["role"], e["group"], e["message"]) for e in data["last"]] == [
        ("WARN", "P", "a", "battery low"), ("ERROR", "P", "a", "lidar lost"), ("FATAL", "P", "a", "safety stop")]
    assert all(e["where"].endswith(".py:" + e["where"].rsplit(":", 1)[1]) for e in data["last"])


def test_run_quiet_prints_only_warnings_and_above(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    status, out, err = run(capsys, "run", str(system_file(tmp_path, "process")), "--quiet")
    assert (status, err) == (0, "")
    assert [line.split("] ")[0] for line in out.splitlines() if line.startswith("[")] == ["[WARN", "[ERROR", "[FATAL"]


@pytest.mark.parametrize("transport", ["inproc", "process"])
def test_a_flood_of_records_finishes_and_the_report_counts_the_dropped(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, transport: str) -> None:
    report = tmp_path / "run.json"
    status, out, err = run(capsys, "run", str(system_file(tmp_path, transport, "flooder")), "--quiet",
                           "--json", str(report))
    assert (status, err) == (0, "")
    data = json.loads(report.read_text(encoding="utf-8"))["logs"]
    delivered, dropped = data["counts"]["INFO"], data["dropped"]["INFO"]
    consumer = transport == "process"  # its "consumer done" (see the first test)
    assert delivered + dropped == 100_000 + consumer and dropped > 0  # every record delivered or counted
    assert " dropped (" in out


@pytest.mark.parametrize("transport", ["inproc", "process"])
def test_a_recording_holds_the_records_on_rosout_and_verify_passes_over_them(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, transport: str) -> None:
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    status, out, _ = run(capsys, "run", str(system_file(tmp_path, transport)), "--quiet",
                         "--record", str(tmp_path / "bag"))
    consumer = transport == "process"  # its module logger's INFO (see the first test)
    assert status == 0 and f"recording: {5 + consumer} log records on /rosout" in out
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(tmp_path / "bag") as bag:
        rosout = [c for c in bag.connections if c.topic == "/rosout"]
        assert [c.msgtype for c in rosout] == ["rcl_interfaces/msg/Log"]
        logs = [store.deserialize_cdr(data, "rcl_interfaces/msg/Log") for _, _, data in bag.messages(rosout)]
    own = [(log.level, log.name, log.msg) for log in logs if log.name == "P"]
    assert own == [(10, "P", "debug from P"), (20, "P", "planning 2 items"), (30, "P", "battery low"),
                   (40, "P", "lidar lost"), (50, "P", "safety stop")]
    assert all(log.stamp.sec > 1_700_000_000 and log.file.endswith("logging_roles.py") and log.line > 0
               for log in logs)
    status, out, _ = run(capsys, "verify", str(tmp_path / "bag"))
    assert status == 0 and "/rosout" not in out, out


def test_a_replayed_role_shows_what_it_logs_and_nothing_reaches_stderr(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert run(capsys, "run", str(system_file(tmp_path, "process")), "--quiet",
               "--record", str(tmp_path / "run.mcap"))[0] == 0
    status, out, err = run(capsys, "replay", str(tmp_path / "run.mcap"), "--role", "P",
                           "--function", "logging_roles:producer", "--pythonpath", str(TESTS))
    assert (status, err) == (0, "")
    shown = [line.split("] [")[0] + " " + line.split("]: ")[1] for line in out.splitlines() if line.startswith("[")]
    assert shown == ["[DEBUG debug from P", "[INFO planning 2 items", "[WARN battery low", "[ERROR lidar lost",
                     "[FATAL safety stop"]
