"""Issue 29's "Done when", end to end: ONE protocol written as a user writes it (drive_roles.DRIVE:
a period, deadlines, ``else timeout``, value constraints) checks, projects to exact local types,
generates typed modules that pass mypy --strict, runs on inproc, processes and DDS (a conforming run
completes; a late role is blamed at the deadline by the role waiting for it; an out-of-range payload
is refused before it leaves, blaming its sender), and its recording verifies through the CLI; a
recording tampered with (a payload out of range, times stretched) is caught with blame, index, time
and the .proto location.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import drive_roles
import pytest
from dds_hosts import domain
from mcap_rewrite import rewrite

import anodize
import sessiontypes
from anodize import DeadlineMissedError, ProtocolViolationError
from anodize._recording.encoding import codec_for_sort
from anodize._recording.reader import open_recording
from anodize._tools.cli import main

HERE = Path(__file__).resolve().parent
S = 1_000_000_000
REFINEMENT = "drive.proto:3:18"  # where `abs(v) <= 1.5` is written

TRANSPORTS = [pytest.param("inproc", id="inproc"),
              pytest.param("process", id="process", marks=pytest.mark.slow),
              pytest.param("dds", id="dds", marks=pytest.mark.slow)]

SYSTEM_FILE = """\
protocol = "drive.proto"
global = "Drive"
transport = "{kind}"
timeout = 60
pythonpath = ["{here}"]
{dds}
[groups.control]
roles = {{ C = "drive_roles:{control}" }}

[groups.odometry]
roles = {{ O = "drive_roles:{odometer}" }}

[groups.motor]
roles = {{ M = "drive_roles:{motor}" }}
"""


def _proto(directory: Path) -> Path:
    path = directory / "drive.proto"
    path.write_text(drive_roles.DRIVE)
    return path


def _global() -> sessiontypes.GlobalType:
    return sessiontypes.loads(drive_roles.DRIVE, "drive.proto").globals["Drive"]


def _transport(kind: str, run_id: str) -> Any:
    if kind == "dds":
        pytest.importorskip("cyclonedds")
        return anodize.Dds(domain=domain(), run_id=f"{run_id}-{os.getpid()}", wait=30)
    return anodize.Processes() if kind == "process" else anodize.Inproc()


def _run(kind: str, run_id: str, control: str = "control", odometer: str = "odometer", motor: str = "motor",
         record: Path | None = None) -> anodize.RunReport:
    """The three roles in groups of their own (every message crosses groups: all are recorded)."""
    system = anodize.System(_global(), _transport(kind, run_id))
    system.group("control").role("C", getattr(drive_roles, control))
    system.group("odometry").role("O", getattr(drive_roles, odometer))
    system.group("motor").role("M", getattr(drive_roles, motor))
    return system.run(timeout=60, taps=[anodize.Recording(record)] if record is not None else [])


def _cli(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    capsys.readouterr()
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out + out.err


# ---- check, project, generate ------------------------------------------------------------------

def test_the_protocol_checks_and_projects_to_exact_local_types(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    proto = _proto(tmp_path)
    assert _cli(capsys, "check", str(proto)) == (0, f"{proto}: ok (1 global, 0 locals)\n")
    code, out = _cli(capsys, "project", str(proto))
    assert code == 0, out
    assert out.splitlines() == [
        ("C = mu t.+M{cmd(v: float{abs(v) <= 1.5}).!O(go).?M(ack(n: int{n >= 0})) within 300ms else timeout.t, "
         "stop.!O(halt)} every 500ms +- 450ms"),
        "O = mu t.&C{go.!M(pose(x: float)) within 1s.t, halt}",
        ("M = mu t.&C{cmd(v: float{abs(v) <= 1.5}).?O(pose(x: float)) within 1s.!C(ack(n: int{n >= 0})) within 300ms "
         "else timeout.t, stop} every 500ms +- 450ms")]


def test_the_local_types_print_reparse_to_the_same_machines() -> None:
    gt = _global()
    for role in gt.roles:
        local = gt.project(role)
        again = sessiontypes.loads(f"local L at {role} = {local.body}", "again.proto").locals
        (reparsed,) = again.values()
        assert str(reparsed.body) == str(local.body), role
        mine, back = local.fsm(), reparsed.fsm()
        assert all(getattr(mine, f.name) == getattr(back, f.name)
                   for f in dataclasses.fields(mine) if f.name != "protocol"), role


def test_a_generated_send_refuses_a_payload_out_of_range_located_at_the_refinement(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """As the monitor and verify locate it (not at the interaction)."""
    import importlib.util

    out_dir = tmp_path / "gen"
    proto = _proto(tmp_path)
    code, out = _cli(capsys, "project", str(proto), "-o", str(out_dir))
    assert code == 0, out
    spec = importlib.util.spec_from_file_location("drive_c_generated", out_dir / "drive_c.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the class is built
    try:
        spec.loader.exec_module(module)
    finally:
        del sys.modules[spec.name]

    class Unused:  # the refusal comes before the endpoint is touched
        def __getattr__(self, name: str) -> Any:
            raise AssertionError(f"the endpoint was used: {name}")

    with pytest.raises(ProtocolViolationError) as info:
        module.Initial(Unused()).select_cmd(2.0)
    assert (info.value.blame, info.value.location) == ("C", f"{proto}:3:18")
    assert info.value.reason == "refinement {abs(v) <= 1.5} is false for cmd {'v': 2.0}"


@pytest.mark.slow
def test_the_generated_modules_pass_mypy_strict(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                mypy_cache: Path) -> None:
    proto = _proto(tmp_path)
    out_dir = tmp_path / "gen"
    code, out = _cli(capsys, "project", str(proto), "-o", str(out_dir))
    assert code == 0, out
    modules = sorted(out_dir.glob("*.py"))
    assert {m.name for m in modules} >= {"drive_c.py", "drive_o.py", "drive_m.py"}, out
    text = (out_dir / "drive_c.py").read_text()
    assert "every 500ms +- 450ms" in text and "{abs(v) <= 1.5}" in text and "within 300ms else timeout" in text
    result = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", "--follow-imports=silent", "--no-color-output",
         "--cache-dir", str(mypy_cache), *map(str, modules)],
        capture_output=True, text=True, cwd=out_dir, timeout=300, check=False)
    assert result.returncode == 0, result.stdout + result.stderr


# ---- runs on each transport ------------------------------------------------------------------

@pytest.mark.parametrize("kind", TRANSPORTS)
def test_a_conforming_run_completes_and_its_recording_verifies(kind: str, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    _proto(tmp_path)
    dds = f'domain = {domain()}\nrun_id = "drive-{os.getpid()}"\n' if kind == "dds" else ""
    system = tmp_path / "system.toml"
    system.write_text(SYSTEM_FILE.format(kind=kind, here=HERE, dds=dds, control="control", odometer="odometer",
                                         motor="motor"))
    record = tmp_path / "run.mcap"
    code, out = _cli(capsys, "run", "--quiet", str(system), "--record", str(record), "--json",
                     str(tmp_path / "report.json"))
    assert code == 0, out
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["ok"], out
    code, out = _cli(capsys, "verify", str(record))
    assert code == 0, out
    held = [line for line in out.splitlines() if line.startswith("constraint: ")]
    assert [line.split(":", 2)[1].strip() for line in held] == [
        "C->M cmd every 500ms +- 450ms", "C->M cmd {abs(v) <= 1.5}", "C->M stop every 500ms +- 450ms",
        "M->C ack within 300ms else timeout", "M->C ack {n >= 0}", "O->M pose within 1s"], out
    assert "C->M cmd {abs(v) <= 1.5}: held on 3 message(s)" in out, out
    assert "M->C ack {n >= 0}: held on 3 message(s)" in out, out


@pytest.mark.parametrize("kind", TRANSPORTS)
def test_a_late_role_is_blamed_by_the_role_waiting_for_it_at_the_deadline(kind: str) -> None:
    report = _run(kind, "late", odometer="late_odometer")
    waiting = report.roles["M"].error
    assert isinstance(waiting, DeadlineMissedError), report.summary()
    assert (waiting.role, waiting.blame, waiting.kind, waiting.deadline_ns) == ("M", "O", "deadline", 1 * S)
    assert waiting.location == "drive.proto:5:31"  # the clause `within 1s`, as verify points at it
    # M raised when its deadline passed, with nothing there: not when O's pose would have come
    # (LATE_BY after its go; O's own monitor refused that pose, so it never came at all).
    assert waiting.late_ns < (drive_roles.LATE_BY - 1) * S
    own = report.roles["O"].error
    assert isinstance(own, DeadlineMissedError), report.summary()
    assert (own.role, own.blame, own.kind) == ("O", "O", "deadline")


@pytest.mark.parametrize("kind", TRANSPORTS)
def test_an_out_of_range_payload_is_refused_before_it_leaves_blaming_its_sender(kind: str, tmp_path: Path) -> None:
    record = tmp_path / "run.mcap"
    report = _run(kind, "reckless", control="reckless", record=record)
    error = report.roles["C"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert (error.role, error.blame) == ("C", "C")
    assert error.reason == "refinement {abs(v) <= 1.5} is false for cmd {'v': 2.0}"
    assert error.location == REFINEMENT  # the refinement, as verify points at it

    codec = codec_for_sort(None)
    with open_recording(record) as recording:
        cmds = [codec.decode(m.data) for m in recording.messages() if m.topic.metadata.get("anodize.label") == "cmd"]
    assert cmds == [{"v": 0.5}]  # the refused command never left C


@pytest.mark.parametrize("kind", TRANSPORTS[:2])  # the deadline's wait is the endpoint's, whatever carries it
def test_else_timeout_gives_the_waiting_role_a_timeout_and_the_run_goes_on(kind: str) -> None:
    report = _run(kind, "patient", control="patient", motor="slow_motor")
    assert report.ok, report.summary()


# ---- tampered recordings: verify blames with index, time and location --------------------------

def _label(message: list[Any]) -> str:
    label: str = dict(message[0][2]).get("anodize.label", "")  # the channel's metadata; "": a clock channel
    return label


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A conforming inproc run's recording (its protocol text inside)."""
    path = tmp_path_factory.mktemp("drive") / "run.mcap"
    report = _run("inproc", "recorded", record=path)
    assert report.ok, report.summary()
    return path


def _violations(path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, dict[str, Any]]:
    out_json = path.with_suffix(".json")
    code, out = _cli(capsys, "verify", str(path), "--json", str(out_json))
    data = json.loads(out_json.read_text())
    broken = {name: c["violation"] for name, c in data["channels"].items() if c["violation"] is not None}
    return code, out, broken


def test_a_recording_with_a_payload_out_of_range_is_blamed_on_its_sender(
        recorded: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    codec = codec_for_sort(None)
    times: list[int] = []

    def speed_up(messages: list[list[Any]]) -> None:
        second = [m for m in messages if _label(m) == "cmd"][1]
        second[3] = codec.encode({"v": -1.75})
        times.append(second[1])

    rewrite(recorded, tmp_path / "fast.mcap", speed_up)
    code, out, broken = _violations(tmp_path / "fast.mcap", capsys)
    assert code == 1, out
    assert list(broken) == ["C->M"], out
    found = broken["C->M"]
    assert (found["index"], found["blamed"], found["kind"], found["log_time"]) == (1, "C", "refinement", times[0])
    assert found["reason"] == "refinement {abs(v) <= 1.5} is false for cmd {'v': -1.75}"
    assert found["location"] == REFINEMENT, found
    assert "violation: channel C->M, message 1 (log time " in out and "blamed: C; see drive.proto:" in out, out


def test_a_recording_with_its_times_stretched_is_blamed_on_the_late_sender(
        recorded: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    moved: list[int] = []

    def stretch(messages: list[list[Any]]) -> None:
        # From the second pose on, everything happens 1.5 s later: that pose came 1.5 s after
        # O's go (O sent late), and the next cmd 2 s after the previous one (C's period broken too).
        start = [m for m in messages if _label(m) == "pose"][1][1]
        for m in messages:
            if m[1] >= start:
                m[1] += 3 * S // 2
        moved.append(start + 3 * S // 2)

    rewrite(recorded, tmp_path / "slow.mcap", stretch)
    code, out, broken = _violations(tmp_path / "slow.mcap", capsys)
    assert code == 1, out
    pose = broken["O->M"]
    assert (pose["index"], pose["blamed"], pose["kind"], pose["log_time"]) == (1, "O", "deadline", moved[0]), out
    assert pose["location"] == "drive.proto:5:31"
    assert pose["late"] > S // 2 - 1
    period = broken["C->M"]
    assert (period["index"], period["blamed"], period["kind"]) == (2, "C", "period"), out
