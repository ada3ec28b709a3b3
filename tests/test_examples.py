"""The examples run, and the generated code they use is up to date."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from anodize._tools.cli import main

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(("script", "expected"), [
    ("atm.py", ["C: withdrew 30", "C: withdrawing 500 refused", "C: balance is 70",
                "protocol ATMSession: ok"]),
    ("two_buyer.py", ["B2: bought for 30, delivered 2026-12-01", "S: no sale of 'Ulysses'"]),
])
def test_example_runs_to_a_good_report(script: str, expected: list[str]) -> None:
    done = subprocess.run([sys.executable, str(ROOT / "examples" / script)], capture_output=True,
                          text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 0, done.stdout + done.stderr
    for line in expected:
        assert line in done.stdout
    assert "NOT ok" not in done.stdout


@pytest.mark.parametrize("proto", ["protocols/atm.proto", "protocols/two_buyer.proto"])
def test_generated_example_code_is_up_to_date(proto: str, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(ROOT)
    assert main(["project", proto, "-o", "examples/generated", "--check"]) == 0, capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize("transport", ["process", "dds", "zenoh"])
def test_mixed_criticality_example_stops_the_memory_hog_and_not_the_control_loop(tmp_path: Path,
                                                                                  transport: str) -> None:
    report_path = tmp_path / "report.json"
    done = subprocess.run([str(Path(sys.executable).parent / "anodize"), "run",
                           "examples/mixed_criticality/system.toml", "--transport", transport,
                           "--json", str(report_path)],
                          capture_output=True, text=True, timeout=120, cwd=ROOT,
                          env={**os.environ, "ANODIZE_DDS_DOMAIN": str(1 + os.getpid() % 200)})
    assert done.returncode == 1, done.stdout + done.stderr  # not ok: a group failed, as it should
    report = json.loads(report_path.read_text())
    groups = report["groups"]
    assert groups["planning"]["status"] == "failed"
    assert groups["planning"]["error"]["type"] == "MemoryBoundError"
    assert groups["planning"]["peak_memory"] <= groups["planning"]["memory_bound"] + 2**20
    assert groups["control"]["status"] == "done" and report["messages"]["Control->Motor"] == 601
    assert groups["logging"]["status"] == "done"  # it noticed the planner was gone and ended
    assert "MemoryBoundError: group planning exceeded its memory bound of 96.0 MiB" in done.stdout
    assert "logger: role Logger: peer Planner failed" in done.stdout
