"""On DDS the roles' log records reach ROS 2's ``/rosout``: read here by an independent reader
(Cyclone DDS's Python binding, with its own declaration of ``rcl_interfaces/msg/Log``, as a
ROS 2 node's middleware would declare it), during ``anodize run``."""

# No ``from __future__ import annotations``: Cyclone's IdlStruct reads the field annotations as types.
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import int32, uint8, uint32
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from dds_hosts import domain

from anodize._tools.cli import main

pytestmark = pytest.mark.slow
REPO = Path(__file__).resolve().parents[3]


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Log(IdlStruct, typename="rcl_interfaces::msg::dds_::Log_"):
    stamp: Time
    level: uint8
    name: str
    msg: str
    file: str
    function: str
    line: uint32


def test_a_ros_reader_of_rosout_gets_the_roles_records(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    number = domain()
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    participant = DomainParticipant(number)
    reader: DataReader[Log] = DataReader(participant, Topic(participant, "rt/rosout", Log), qos=Qos(
        Policy.Reliability.Reliable(0), Policy.History.KeepAll, Policy.Durability.TransientLocal,
        Policy.DataRepresentation(use_cdrv0_representation=True)))
    system = tmp_path / "system.toml"
    system.write_text(f'protocol = "{REPO / "protocols" / "stream.proto"}"\nglobal = "Stream"\n'
                      f'transport = "dds"\ndomain = {number}\nrun_id = "rosout-{time.time_ns()}"\n'
                      f'pythonpath = ["{REPO / "tests" / "anodize"}"]\ntimeout = 60\n'
                      '[groups.a]\nroles = { P = "logging_roles:producer" }\n'
                      '[groups.b]\nroles = { C = "logging_roles:consumer" }\n', encoding="utf-8")
    assert main(["run", str(system), "--quiet"]) == 0
    out = capsys.readouterr().out
    logs: list[Log] = []
    deadline = time.monotonic() + 10.0  # written reliably before the run returned; taken here
    while len([x for x in logs if x.name == "P"]) < 5 and time.monotonic() < deadline:
        logs.extend(reader.take(N=100))
        time.sleep(0.05)
    own = [(x.level, x.name, x.msg) for x in logs if x.name == "P"]
    assert own == [(10, "P", "debug from P"), (20, "P", "planning 2 items"), (30, "P", "battery low"),
                   (40, "P", "lidar lost"), (50, "P", "safety stop")], out
    assert all(x.stamp.sec > 1_700_000_000 and x.file.endswith("logging_roles.py") for x in logs)
    assert f"6 log records published on /rosout (DDS domain {number})" in out
