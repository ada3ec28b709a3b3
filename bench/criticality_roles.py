"""The minimal three-group system of ``bench/criticality.py``: its protocol, system file and roles.

Module level on purpose: anodize's group processes import the roles by name. Settings come
as JSON in ``$ANODIZE_CRITICALITY`` (``bench/runs.bench_env``): ``out`` (the folder results
go to), ``seconds`` (how long the control loop runs) and ``storm`` (whether the logging
group allocates without pause). ``Control`` writes what it measured to ``<out>/control.json``.

- ``control`` (priority 90): the 50 Hz loop. Each period it ticks the sensor, takes its
  reading (64 KiB: a small camera's frame, so the live view and a recording have work),
  and tells the logger; it sleeps to the next period's absolute start. Its period is the
  time between the starts of consecutive loops.
- ``sensing`` (priority 50): answers each tick with a reading.
- ``logging`` (priority 10, 512 MiB bound): takes the statuses; in the storm scenario a
  thread of it allocates and touches 32 MiB blocks, frees them, and does it again.
"""

from __future__ import annotations

import itertools
import json
import os
import threading
import time
from pathlib import Path
from typing import Any

from anodize import Endpoint

VARIABLE = "ANODIZE_CRITICALITY"
PERIOD = 0.02          # seconds: the control loop's 50 Hz
READING = 64 * 2**10   # bytes of a sensor reading
STORM_BLOCK = 32 * 2**20
LATE = 1.5             # a period longer than this many nominal periods is late

PROTOCOL = """
global Mini(Control, Sensor, Logger) =
  mu t. Control -> Sensor : { tick. Sensor -> Control : reading(bytes). Control -> Logger : status(int). t,
                              stop. Control -> Logger : stop }
"""


def system_file(folder: Path) -> Path:
    """Write the protocol and the system file into ``folder``; return the system file."""
    (folder / "mini.proto").write_text(PROTOCOL, encoding="utf-8")
    system = folder / "mini.toml"
    system.write_text(f"""protocol = "mini.proto"
global = "Mini"
pythonpath = [{json.dumps(str(Path(__file__).resolve().parent))}]

[transport]
kind = "process"

[groups.control]
priority = 90
roles = {{ Control = "criticality_roles:control" }}

[groups.sensing]
priority = 50
roles = {{ Sensor = "criticality_roles:sensor" }}

[groups.logging]
priority = 10
memory = "512MiB"
roles = {{ Logger = "criticality_roles:logger" }}
""", encoding="utf-8")
    return system


def _config() -> dict[str, Any]:
    return json.loads(os.environ[VARIABLE])  # type: ignore[no-any-return]


def control(ep: Endpoint) -> None:
    settings = _config()
    loops = int(float(settings["seconds"]) / PERIOD)
    starts: list[float] = []
    next_start = time.monotonic()
    for number in range(loops):
        starts.append(time.monotonic())
        ep.send("Sensor", "tick")
        ep.recv("Sensor")
        ep.send("Logger", "status", number)
        next_start += PERIOD
        ep.sleep(max(0.0, next_start - time.monotonic()))
    ep.send("Sensor", "stop")
    ep.send("Logger", "stop")
    periods = [(b - a) * 1000.0 for a, b in itertools.pairwise(starts)]
    out = Path(settings["out"]) / "control.json"
    out.write_text(json.dumps({"periods_ms": periods, "nominal_ms": PERIOD * 1000.0}), encoding="utf-8")


def sensor(ep: Endpoint) -> None:
    reading = os.urandom(READING)
    while ep.recv("Control")[0] != "stop":
        ep.send("Control", "reading", reading)


def logger(ep: Endpoint) -> None:
    done = threading.Event()
    if _config().get("storm"):
        threading.Thread(target=_storm, args=(done,), name="allocation-storm", daemon=True).start()
    try:
        while ep.recv("Control")[0] != "stop":
            pass
    finally:
        done.set()


def _storm(done: threading.Event) -> None:
    """Allocate, touch and free 32 MiB blocks until ``done`` (a pause of 1 ms between blocks:
    at the group's SCHED_FIFO priority a loop without one would be the RT guard's to demote)."""
    while not done.is_set():
        block = bytearray(STORM_BLOCK)  # zero-filled: every page is touched
        block[::4096] = b"\x01" * len(block[::4096])
        del block
        time.sleep(0.001)
