"""Roles of the inversion benchmark (module level: group processes import them)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from anodize import Endpoint

ENV = "ANODIZE_BENCH_INVERSION"


def _settings() -> dict[str, object]:
    return json.loads(os.environ[ENV])  # type: ignore[no-any-return]


def high(ep: Endpoint) -> None:
    """H: asks L ``asks`` times, 10 ms apart, and writes each response time (seconds)."""
    settings = _settings()
    times = []
    for _ in range(int(settings["asks"])):  # type: ignore[call-overload]
        start = time.perf_counter()
        ep.send("L", "ask")
        ep.recv("L", timeout=30)
        times.append(time.perf_counter() - start)
        ep.sleep(0.01)
    ep.send("L", "stop")
    Path(str(settings["out"]), "high.json").write_text(json.dumps(times), encoding="utf-8")


def low(ep: Endpoint) -> None:
    """L: 2 ms of CPU work per request, then the reply (bounded: it always ends)."""
    while ep.recv("H", timeout=60).label == "ask":
        end = time.perf_counter() + 0.002
        while time.perf_counter() < end:
            pass
        ep.send("H", "answer")
