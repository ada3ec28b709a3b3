"""Criticality under load: does the control loop keep its period whatever else the machine does?

Scenarios, side by side in one run (each run of each scenario interleaved with the others',
so that all see the same drift in the machine's load):

  quiet      nothing else of ours runs (the machine's other work, if any, is recorded)
  hogs       two processes spinning at normal priority (nice 0, SCHED_OTHER)
  storm      an allocation storm in a low-priority group: TinMan with
             ``--inject memory-hog=planning`` (priority 30, 256 MiB bound: it allocates
             160 MiB/s until its bound stops it); the minimal system's logging group
             (priority 10) allocating, touching and freeing 32 MiB blocks
  foxglove   ``--foxglove`` with one WebSocket client subscribed to every channel, reading
             as fast as it can (as tests/anodize/test_foxglove.py's client speaks)
  record     ``--record`` onto a throttled disk: a loop device's ext4, mounted ``sync``,
             written through a cgroup v1 blkio limit (--throttle MiB/s); needs root, the
             ``loop`` driver and blkio (else the row says why it was not run)

each on TinMan (``anodize run tinman --world easy``) and on a minimal three-group system
(``bench/criticality_roles.py``: a 50 Hz control loop at priority 90, a sensor at 50, a
logger at 10). Columns: the control period's p99 and max (median over runs of each run's
p99, and the largest max), bumps, waypoints and ATE (TinMan only), false liveness verdicts
(groups failed as unresponsive in runs where nothing was frozen: every such verdict here
is false), priority boosts (episodes of priority inheritance, summed over runs), and what the side work
dropped (live view: not shown; recording: gaps). Ratios are against the quiet row of the
same system measured in the same run. The machine's load is recorded (bench/runs.LoadWatch).

    .venv/bin/python bench/criticality.py [--seconds 20] [--runs 5] [--systems tinman,mini]
        [--scenarios quiet,hogs,storm,foxglove,record] [--throttle 2] [--json PATH]

Prints a table and writes bench/results/criticality.json.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import datetime
import json
import os
import platform
import re
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import criticality_roles  # noqa: E402
from runs import LoadWatch, bench_env, hogs, print_table, source_state, write_results  # noqa: E402

ROOT = HERE.parent
SCENARIOS = ("quiet", "hogs", "storm", "foxglove", "record")
SYSTEMS = ("tinman", "mini")
VERDICT = re.compile(r"heartbeat|unresponsive|frozen", re.IGNORECASE)


# ---- the loads --------------------------------------------------------------------------------
class FoxgloveClient:
    """A WebSocket client subscribed to every channel the server advertises, reading all it gets."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.messages = 0
        self.bytes = 0
        self.error = ""
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            asyncio.run(self._session())
        except Exception as error:  # reported with the run, never raised from a thread
            self.error = f"{type(error).__name__}: {error}"

    async def _session(self) -> None:
        import websockets

        ws = None
        while ws is None and not self.done.is_set():
            try:
                ws = await asyncio.wait_for(websockets.connect(
                    f"ws://127.0.0.1:{self.port}", subprotocols=["foxglove.sdk.v1"], max_size=None), timeout=2.0)
            except (OSError, TimeoutError):
                await asyncio.sleep(0.1)
        if ws is None:
            return
        async with ws:
            subscribed = 0
            with contextlib.suppress(websockets.ConnectionClosed):
                while not self.done.is_set():
                    try:
                        message = await asyncio.wait_for(ws.recv(), timeout=0.5)
                    except TimeoutError:
                        continue
                    if isinstance(message, str):
                        op = json.loads(message)
                        if op.get("op") == "advertise":  # subscribe to everything, as it comes
                            subscriptions = [{"id": subscribed + n + 1, "channelId": c["id"]}
                                             for n, c in enumerate(op["channels"])]
                            subscribed += len(subscriptions)
                            await ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
                    else:
                        self.messages += 1
                        self.bytes += len(message)

    def stop(self) -> dict[str, Any]:
        self.done.set()
        self.thread.join(timeout=10)
        return {"messages": self.messages, "mib": round(self.bytes / 2**20, 1), "error": self.error}


class SlowDisk:
    """A throttled disk: a loop device's ext4 mounted ``sync``, written through a blkio cgroup
    (v1) that allows ``bps`` bytes a second. ``mount`` is None (and ``why`` says why) where it
    cannot be made."""

    def __init__(self, bps: int) -> None:
        self.bps = bps
        self.folder = Path(tempfile.mkdtemp(prefix="anodize-slowdisk-"))
        self.mount: Path | None = None
        self.cgroup = Path(f"/sys/fs/cgroup/blkio/anodize-criticality-{os.getpid()}")
        self.loop = ""
        self.why = ""
        try:
            self._make()
        except (OSError, subprocess.SubprocessError) as error:
            self.why = f"no throttled disk: {error}"
            self.close()

    def _make(self) -> None:
        def run(*command: str) -> str:
            return subprocess.run(command, check=True, capture_output=True, text=True, timeout=60).stdout.strip()

        if os.geteuid() != 0:
            raise OSError("a loop device and a blkio cgroup need root")
        image = self.folder / "disk.img"
        with image.open("wb") as handle:
            handle.truncate(1 << 30)  # sparse
        run("mkfs.ext4", "-q", "-F", str(image))
        self.loop = run("losetup", "-f", "--show", str(image))
        mount = self.folder / "mnt"
        mount.mkdir()
        run("mount", "-o", "sync", self.loop, str(mount))
        self.mount = mount
        device = (Path("/sys/block") / Path(self.loop).name / "dev").read_text(encoding="ascii").strip()
        self.cgroup.mkdir()
        (self.cgroup / "blkio.throttle.write_bps_device").write_text(f"{device} {self.bps}\n", encoding="ascii")

    def enter(self) -> None:
        """Put the calling process (a child, before exec) into the throttled cgroup."""
        (self.cgroup / "cgroup.procs").write_text(str(os.getpid()), encoding="ascii")

    def close(self) -> None:
        if self.mount is not None:
            subprocess.run(["umount", str(self.mount)], capture_output=True, timeout=60)
            self.mount = None
        if self.loop:
            subprocess.run(["losetup", "-d", self.loop], capture_output=True, timeout=60)
            self.loop = ""
        with contextlib.suppress(OSError):
            self.cgroup.rmdir()
        shutil.rmtree(self.folder, ignore_errors=True)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# ---- one run ----------------------------------------------------------------------------------
def run_once(system: str, scenario: str, seconds: float, out: Path, disk: SlowDisk | None) -> dict[str, Any]:
    """One run of ``system`` under ``scenario``: what the table needs, and what went wrong."""
    extra: list[str] = []
    preexec: Callable[[], None] | None = None
    client: FoxgloveClient | None = None
    if scenario == "foxglove":
        port = _free_port()
        extra += ["--foxglove", str(port)]
        client = FoxgloveClient(port)
    if scenario == "record":
        assert disk is not None and disk.mount is not None
        extra += ["--record", str(disk.mount / f"{system}.mcap")]
        preexec = disk.enter
    load = hogs() if scenario == "hogs" else contextlib.nullcontext()
    with load:
        if system == "tinman":
            result = _tinman(seconds, out, extra + (["--inject", "memory-hog=planning"] if scenario == "storm" else []),
                             preexec)
        else:
            result = _mini(seconds, out, extra, preexec, storm=scenario == "storm")
    if client is not None:
        result["client"] = client.stop()
    if disk is not None and disk.mount is not None:
        for leftover in disk.mount.glob("*"):
            shutil.rmtree(leftover, ignore_errors=True) if leftover.is_dir() else leftover.unlink()
    return result


def _run(command: list[str], timeout: float, preexec: Callable[[], None] | None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                          preexec_fn=preexec)  # a cgroup to join before exec


def _tinman(seconds: float, out: Path, extra: list[str], preexec: Callable[[], None] | None) -> dict[str, Any]:
    command = [sys.executable, "-m", "anodize._tools.cli", "run", "tinman", "--quiet", "--world", "easy",
               "--duration", str(seconds), "--out", str(out), *extra]
    done = _run(command, seconds * 6 + 180, preexec)
    report_file = out / "report.json"
    if not report_file.exists():
        return {"error": f"no report (exit {done.returncode}): {(done.stdout + done.stderr)[-600:]}"}
    report = json.loads(report_file.read_text(encoding="utf-8"))
    period = report.get("control_period_ms") or {}
    robot = report.get("robot") or {}
    return {"exit": done.returncode, "p99_ms": period.get("p99"), "max_ms": period.get("max"),
            "bumps": robot.get("bumps"), "waypoints": robot.get("waypoints_reached"),
            "ate_percent": report.get("ate_percent"), "verdicts": _verdicts(report.get("groups") or {}),
            "boosts": _boosts(report), **_side_work(report.get("notes") or [])}


def _mini(seconds: float, out: Path, extra: list[str], preexec: Callable[[], None] | None,
          storm: bool) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    system = criticality_roles.system_file(out)
    with bench_env(criticality_roles.VARIABLE, seconds=seconds, storm=storm) as (_, result):
        command = [sys.executable, "-m", "anodize._tools.cli", "run", str(system), "--quiet", "--json",
                   str(out / "report.json"), "--timeout", str(seconds * 3 + 30), *extra]
        done = _run(command, seconds * 6 + 120, preexec)
        try:
            measured = result("control")
        except RuntimeError as error:
            return {"error": f"{error} (exit {done.returncode}): {(done.stdout + done.stderr)[-600:]}"}
    report = json.loads((out / "report.json").read_text(encoding="utf-8")) if (out / "report.json").exists() else {}
    periods = sorted(measured["periods_ms"])
    late = sum(1 for p in periods if p > measured["nominal_ms"] * criticality_roles.LATE)
    return {"exit": done.returncode, "p99_ms": _percentile(periods, 99), "max_ms": periods[-1] if periods else None,
            "late": late, "bumps": None, "waypoints": None, "ate_percent": None,
            "verdicts": _verdicts(report.get("groups") or {}), "boosts": _boosts(report),
            **_side_work(report.get("notes") or [])}


def _percentile(values: list[float], q: float) -> float | None:
    if not values:
        return None
    return float(statistics.quantiles(values, n=100, method="inclusive")[int(q) - 1]) if len(values) > 1 \
        else values[0]


def _verdicts(groups: dict[str, Any]) -> int:
    """Groups failed as unresponsive (no group in these scenarios is frozen: each is false)."""
    found = 0
    for group in groups.values():
        error = group.get("error") or {}
        text = f"{error.get('type', '')} {error.get('message', '')}" if isinstance(error, dict) else str(error)
        found += bool(VERDICT.search(text))
    return found


def _boosts(report: dict[str, Any]) -> int:
    """Priority-inheritance episodes in one run, over every waiter->target pair."""
    return sum(int(b.get("episodes", 0)) for b in (report.get("boosts") or {}).values())


def _side_work(notes: list[str]) -> dict[str, Any]:
    """What the live view did not show and what a recording could not write, from the notes."""
    gaps = sum(int(m.group(1)) for n in notes if "a gap on" in n
               for m in [re.search(r"(\d+) messages not recorded", n)] if m)
    shown = thinned = dropped = 0
    for note in notes:
        if m := re.search(r"foxglove: showed (\d+) messages", note):
            shown += int(m.group(1))
        if m := re.search(r"(\d+) thinned .* and (\d+) dropped", note):
            thinned, dropped = thinned + int(m.group(1)), dropped + int(m.group(2))
    return {"recording_gap": gaps, "live_shown": shown, "live_thinned": thinned, "live_dropped": dropped,
            "side_work_notes": [n for n in notes if n.startswith(("recording", "foxglove", "recorded"))]}


# ---- the table ----------------------------------------------------------------------------------
def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    good = [r for r in runs if "error" not in r]

    def median(key: str) -> float | None:
        values = [r[key] for r in good if r.get(key) is not None]
        return float(statistics.median(values)) if values else None

    def total(key: str) -> int | None:
        values = [r[key] for r in good if r.get(key) is not None]
        return int(sum(values)) if values else None

    maxima = [r["max_ms"] for r in good if r.get("max_ms") is not None]
    return {"runs": len(runs), "failed_runs": len(runs) - len(good), "p99_ms": median("p99_ms"),
            "max_ms": max(maxima) if maxima else None, "bumps": total("bumps"),
            "bumps_per_run": [r.get("bumps") for r in good], "waypoints": median("waypoints"),
            "waypoints_per_run": [r.get("waypoints") for r in good], "ate_percent": median("ate_percent"),
            "verdicts": total("verdicts"), "boosts": total("boosts"), "late": total("late"),
            "recording_gap": total("recording_gap"),
            "live_shown": total("live_shown"), "live_not_shown": (total("live_thinned") or 0)
            + (total("live_dropped") or 0)}


def table(summary: dict[str, dict[str, dict[str, Any]]]) -> list[list[str]]:
    rows = [["system", "scenario", "runs", "control p99 ms (x quiet)", "max ms (x quiet)", "bumps", "waypoints",
             "ATE %", "false liveness", "boosts", "side work"]]

    def number(value: float | None, digits: int = 2) -> str:
        return "-" if value is None else f"{value:.{digits}f}"

    for system, scenarios in summary.items():
        quiet = scenarios.get("quiet", {})
        for scenario, s in scenarios.items():
            if "skipped" in s:
                rows.append([system, scenario, "0", s["skipped"], "", "", "", "", "", "", ""])
                continue

            def ratio(key: str, s: dict[str, Any] = s, quiet: dict[str, Any] = quiet) -> str:
                base, value = quiet.get(key), s.get(key)
                return f" ({value / base:.2f}x)" if base and value is not None else ""

            side = []
            if s.get("recording_gap"):
                side.append(f"gap {s['recording_gap']} msgs")
            if s.get("live_shown"):
                side.append(f"shown {s['live_shown']}, not {s['live_not_shown']}")
            if system == "mini" and s.get("late") is not None:
                side.append(f"late periods {s['late']}")
            runs = f"{s['runs']}" + (f" ({s['failed_runs']} failed)" if s["failed_runs"] else "")
            rows.append([system, scenario, runs, number(s["p99_ms"]) + ratio("p99_ms"),
                         number(s["max_ms"], 1) + ratio("max_ms"),
                         "n/a" if system == "mini" else str(s["bumps"]),
                         "n/a" if system == "mini" else "/".join(str(w) for w in s["waypoints_per_run"]),
                         "n/a" if system == "mini" else number(s["ate_percent"]),
                         str(s["verdicts"]), str(s.get("boosts", "-")), "; ".join(side)])
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=20.0, help="each run's length (default 20)")
    parser.add_argument("--runs", type=int, default=5, help="runs of each scenario on each system (default 5)")
    parser.add_argument("--systems", default=",".join(SYSTEMS))
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--throttle", type=float, default=2.0, help="the record scenario's disk, MiB/s (default 2)")
    parser.add_argument("--json", default=str(HERE / "results" / "criticality.json"))
    args = parser.parse_args(argv)
    systems = [s for s in args.systems.split(",") if s]
    scenarios = [s for s in args.scenarios.split(",") if s]
    if not set(systems) <= set(SYSTEMS) or not set(scenarios) <= set(SCENARIOS) or "quiet" not in scenarios:
        parser.error(f"expected systems from {SYSTEMS} and scenarios from {SCENARIOS}, quiet among them")
    started = time.monotonic()
    watch = LoadWatch()
    disk = SlowDisk(int(args.throttle * 2**20)) if "record" in scenarios else None
    results: dict[str, dict[str, list[dict[str, Any]]]] = {s: {c: [] for c in scenarios} for s in systems}
    try:
        with tempfile.TemporaryDirectory(prefix="anodize-criticality-") as folder:
            for number in range(args.runs):
                for scenario in scenarios:
                    if scenario == "record" and (disk is None or disk.mount is None):
                        continue
                    for system in systems:
                        out = Path(folder) / f"{system}-{scenario}-{number}"
                        result = run_once(system, scenario, args.seconds, out, disk)
                        result["others_per_cpu"] = watch.sample()
                        results[system][scenario].append(result)
                        shutil.rmtree(out, ignore_errors=True)
                        print(f"run {number + 1}/{args.runs} {system:6} {scenario:8} "
                              + (result["error"][:200] if "error" in result else
                                 f"p99 {result['p99_ms']} ms, max {result['max_ms']} ms, bumps {result['bumps']}, "
                                 f"verdicts {result['verdicts']}"), flush=True)
    finally:
        why = disk.why if disk is not None else ""
        if disk is not None:
            disk.close()
    load = watch.result()
    summary = {system: {scenario: (summarise(runs) if runs else {"skipped": f"not run ({why or 'no disk'})"})
                        for scenario, runs in by_scenario.items()} for system, by_scenario in results.items()}
    rows = table(summary)
    print()
    print(f"criticality: {args.runs} run(s) of {args.seconds:g} s per scenario and system; "
          f"{LoadWatch.headline(load)}")
    print()
    print_table(rows, text_columns=(0, 1, 2, 10))
    document = {
        "benchmark": "criticality",
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                    "python": platform.python_version()},
        "source": source_state(ROOT, "anodize", "tinman", "bench"),
        "options": vars(args), "load": load, "table": rows, "summary": summary, "runs": results,
        "wall_seconds": time.monotonic() - started,
    }
    write_results(Path(args.json), document, started, watch=watch,
                  title="Criticality under load: the control loop beside side work and other load",
                  how=f"{args.runs} run(s) of {args.seconds:g} s per scenario and system, "
                      f"scenarios {', '.join(scenarios)}; median of the runs' p99, largest max")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
