"""TinMan's whole patrol, run after run, quiet and under load: ``bench/tinman.py --patrol``.

Each run is ``anodize run tinman --patrol`` as a user types it (a subprocess, this checkout's
anodize and TinMan), read back from its ``report.json``. The loads alternate run by run
(quiet, hogs, quiet, hogs, ...) so that both see the same drift in the machine's other work:

  quiet  nothing else of ours runs (the machine's other work is recorded: bench/runs.LoadWatch)
  hogs   two processes spinning at normal priority (``python -c "while True: pass"``, nice 0),
         killed after the run

Per load: patrol completed (runs), time to complete (median and range, of the completed),
waypoints reached, bumps (the issue's target: 0 in every run), safety stops, recoveries,
the longest time to recover, VO-only and fused ATE (as % of the path; medians and range) and
the control period's p99.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

# Beside runs.py, however this is loaded; appended, not put first, as bench/tinman.py does: that
# script must not hide the tinman package from whatever imports it later in this interpreter.
if str(Path(__file__).resolve().parent) not in sys.path:
    sys.path.append(str(Path(__file__).resolve().parent))
from runs import hogs

__all__ = ["LOADS", "run_patrol", "summarise", "table"]

REPO = Path(__file__).resolve().parents[1]
LOADS = ("quiet", "hogs")
LOAD_NAMES = {"quiet": "quiet", "hogs": "two CPU hogs (nice 0)"}

def _dig(report: dict[str, Any], keys: Sequence[str]) -> Any:
    value: Any = report
    for key in keys:
        if not isinstance(value, dict):
            return None
        value = value.get(key)
    return value


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None


def read_run(report: dict[str, Any], exit_status: int) -> dict[str, Any]:
    """One run's numbers from its report.json (None where the report does not have them)."""
    mission = report.get("mission") or {}
    return {
        "exit": exit_status,
        "completed": bool(mission.get("patrol_completed")),
        "ended_by": mission.get("ended_by"),
        "time_s": _number(mission.get("completed_in_s")),
        "waypoints": len(mission.get("waypoints_reached") or []),
        "bumps": _number(mission.get("bumps")),
        "safety_stops": _number(mission.get("safety_stops")),
        "recoveries": _number(mission.get("recoveries")),
        "vo_ate_percent": _number(report.get("vo_ate_percent")),
        "fused_ate_percent": _number(report.get("fused_ate_percent")),
        "recover_max_s": _number(_dig(report, ("recovery", "time_to_recover_s", "max"))),
        "control_p99_ms": _number((report.get("control_period_ms") or {}).get("p99")),
        "duration_s": _number(report.get("duration_s")),
        "problems": list(report.get("problems") or []),
    }


def run_patrol(limit: float, world: str, load: str, keep: Path | None = None) -> dict[str, Any]:
    """One whole patrol under ``load``; its numbers, or ``error`` when it wrote no report."""
    out = Path(tempfile.mkdtemp(prefix="anodize-patrol-"))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "tinman" / "src")])}
    command = [sys.executable, "-m", "anodize._tools.cli", "run", "tinman", "--patrol", "--quiet",
               "--world", world, "--duration", f"{limit:g}", "--out", str(out)]
    try:
        with hogs() if load == "hogs" else contextlib.nullcontext():
            done = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True,
                                  timeout=limit * 3 + 180)
        report_file = out / "report.json"
        if not report_file.exists():
            return {"load": load, "error": f"no report (exit {done.returncode}): {(done.stdout + done.stderr)[-600:]}"}
        result = {"load": load, **read_run(json.loads(report_file.read_text(encoding="utf-8")), done.returncode)}
        if keep is not None:  # the picture of each run, to look at afterwards
            keep.mkdir(parents=True, exist_ok=True)
            shutil.copy(out / "trajectory.png", keep / f"patrol-{load}-{len(list(keep.glob(f'patrol-{load}-*')))}.png")
        return result
    except subprocess.TimeoutExpired:
        return {"load": load, "error": f"the run did not end within {limit * 3 + 180:g} s"}
    finally:
        shutil.rmtree(out, ignore_errors=True)


def _values(runs: list[dict[str, Any]], key: str) -> list[float]:
    return [r[key] for r in runs if r.get(key) is not None]


def _spread(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"median": None, "min": None, "max": None}
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Per load: counts, and the median, min and max of each measure."""
    good = [r for r in runs if "error" not in r]
    return {
        "runs": len(runs), "errors": len(runs) - len(good),
        "completed": sum(r["completed"] for r in good),
        "time_s": _spread(_values([r for r in good if r["completed"]], "time_s")),
        "waypoints": _spread(_values(good, "waypoints")),
        "bumps_total": sum(_values(good, "bumps")) if _values(good, "bumps") else None,
        "runs_with_bumps": sum(1 for v in _values(good, "bumps") if v > 0),
        **{key: _spread(_values(good, key)) for key in ("bumps", "safety_stops", "recoveries", "recover_max_s",
                                                         "vo_ate_percent", "fused_ate_percent", "control_p99_ms")},
    }


def _cell(spread: dict[str, float | None], form: Callable[[float], str]) -> str:
    median, low, high = spread["median"], spread["min"], spread["max"]
    if median is None or low is None or high is None:
        return "-"
    return form(median) if low == high else f"{form(median)} ({form(low)} to {form(high)})"


def table(summary: dict[str, dict[str, Any]]) -> list[list[str]]:
    """One row per load: medians with their range."""
    rows = [["load", "runs", "patrol completed", "time to complete, s", "waypoints reached", "bumps (runs with any)",
             "safety stops", "recoveries", "longest recovery, s", "VO ATE / path", "fused ATE / path",
             "control period p99, ms"]]
    for load, s in summary.items():
        bumps = "-" if s["bumps_total"] is None else f"{s['bumps_total']:.0f} ({s['runs_with_bumps']})"
        rows.append([
            LOAD_NAMES.get(load, load), str(s["runs"]) + (f" ({s['errors']} no report)" if s["errors"] else ""),
            f"{s['completed']} of {s['runs'] - s['errors']}",
            _cell(s["time_s"], lambda v: f"{v:.1f}"),
            _cell(s["waypoints"], lambda v: f"{v:g}"),
            bumps,
            _cell(s["safety_stops"], lambda v: f"{v:g}"),
            _cell(s["recoveries"], lambda v: f"{v:g}"),
            _cell(s["recover_max_s"], lambda v: f"{v:.2f}"),
            _cell(s["vo_ate_percent"], lambda v: f"{v:.2f}%"),
            _cell(s["fused_ate_percent"], lambda v: f"{v:.2f}%"),
            _cell(s["control_p99_ms"], lambda v: f"{v:.1f}"),
        ])
    return rows
