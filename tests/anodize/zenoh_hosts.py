"""Zenoh test helpers: free loopback endpoints, in-process routers, and a two-host system file."""

from __future__ import annotations

import json
import socket
from pathlib import Path
from typing import Any

import dds_roles

HERE = Path(__file__).resolve().parent


def free_endpoint() -> str:
    """A loopback TCP endpoint no other test is using (the port of a socket bound to 0)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{probe.getsockname()[1]}"


def open_router(endpoint: str) -> Any:
    """A Zenoh router in this process, listening on ``endpoint`` (scouting off); its session."""
    import zenoh

    return zenoh.open(zenoh.Config.from_json5(json.dumps(
        {"mode": "router", "listen": {"endpoints": [endpoint]}, "scouting": {"multicast": {"enabled": False}}})))


SYSTEM_FILE = """\
protocol = "stream.proto"
global = "Stream"
timeout = 120
pythonpath = ["{here}"]

[transport]
kind = "zenoh"
run_id = "{run_id}"
lease = 1.0

[zenoh]
mode = "client"
connect = ["{router}"]
scouting = false

[groups.producing]
host = "A"
roles = {{ P = "dds_roles:{producer}" }}

[groups.consuming]
host = "B"
roles = {{ C = "dds_roles:{consumer}" }}
"""


def write_system(directory: Path, router: str, producer: str, run_id: str, consumer: str = "consumer") -> Path:
    """A system file of P (host A) and C (host B), both clients of ``router``."""
    (directory / "stream.proto").write_text(dds_roles.STREAM + "\n")
    path = directory / "system.toml"
    path.write_text(SYSTEM_FILE.format(run_id=run_id, here=HERE, router=router, producer=producer,
                                       consumer=consumer))
    return path


POLICY_HEADER = """\
protocol = "system.proto"
global = "{name}"
timeout = 120
pythonpath = ["{here}"]

[transport]
kind = "zenoh"
run_id = "{run_id}"

[zenoh]
mode = "client"
connect = ["{router}"]
scouting = false
"""


def write_policy_system(directory: Path, router: str, protocol: str, name: str, run_id: str, groups: str) -> Path:
    """A system file of ``groups`` over Zenoh, every host a client of ``router``."""
    (directory / "system.proto").write_text(protocol + "\n")
    path = directory / "system.toml"
    path.write_text(POLICY_HEADER.format(name=name, run_id=run_id, here=HERE, router=router) + groups)
    return path


