"""What the benchmarks that run anodize systems share: settings handed to role functions in
group processes, the results those roles write back, tables, and the machine's load."""

from __future__ import annotations

import datetime
import json
import multiprocessing
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["BUSY_PER_CPU", "LoadWatch", "bench_env", "hogs", "print_table", "source_state", "write_results"]


@contextmanager
def bench_env(variable: str, **settings: Any) -> Iterator[tuple[str, Callable[[str], dict[str, Any]]]]:
    """``settings`` and a fresh output folder as JSON in the environment variable ``variable`` (group
    processes inherit it); yields the folder and a reader of ``<folder>/<name>.json``."""
    out = Path(tempfile.mkdtemp(prefix="anodize-bench-"))
    os.environ[variable] = json.dumps({"out": str(out), **settings})

    def result(name: str) -> dict[str, Any]:
        path = out / f"{name}.json"
        if not path.exists():
            raise RuntimeError(f"the run produced no {name}.json")
        return json.loads(path.read_text(encoding="utf-8"))  # type: ignore[no-any-return]

    try:
        yield str(out), result
    finally:
        os.environ.pop(variable, None)
        shutil.rmtree(out, ignore_errors=True)


@contextmanager
def hogs(count: int = 2) -> Iterator[None]:
    """``count`` processes spinning at normal priority (nice 0) while the block runs, killed after."""
    spinning = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(count)]
    try:
        yield
    finally:
        for process in spinning:
            process.kill()
            process.wait(timeout=10)


def print_table(rows: list[list[str]], text_columns: tuple[int, ...]) -> None:
    """``rows`` (the first is the header) as a markdown table: ``text_columns`` left-aligned,
    the others (numbers) right-aligned."""
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    for k, row in enumerate(rows):
        cells = [cell.ljust(w) if i in text_columns else cell.rjust(w)
                 for i, (cell, w) in enumerate(zip(row, widths, strict=True))]
        print("| " + " | ".join(cells) + " |")
        if k == 0:
            print("|" + "|".join(("-" * (w + 1) + ":") if i not in text_columns else "-" * (w + 2)
                                 for i, w in enumerate(widths)) + "|")


def write_results(path: Path, document: dict[str, Any], started: float, *, title: str, how: str,
                  watch: LoadWatch) -> None:
    """Write a benchmark's JSON and say where, with the seconds since ``started`` (monotonic).

    Every result file carries what the documentation's performance page prints of it (the page
    is generated from these files, docs/hooks.py): ``title``, ``how`` (one line: what was run,
    how often, on what), ``table`` (rows of cells, the first the header; ``document`` must hold
    it) and ``load``, what ``watch`` saw of the machine's load (unless ``document`` has it).
    """
    table = document.get("table")
    if not (isinstance(table, list) and table and all(isinstance(row, list) for row in table)):
        raise ValueError(f"{path.name}: expected the table as a list of rows of cells, got {table!r}")
    full = {"title": title, "how": how, **document}
    full.setdefault("date", datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"))
    full.setdefault("load", watch.result())
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(full, indent=2) + "\n", encoding="utf-8")
    print(f"\n{LoadWatch.headline(full['load'])}")
    print(f"wrote {path} ({time.monotonic() - started:.0f} s)")


def source_state(repo: Path, *paths: str) -> dict[str, Any]:
    """The commit measured and the files under ``paths`` that differ from it (uncommitted
    work is measured too), or an error when git cannot say."""
    def git(*command: str) -> str:
        return subprocess.run(["git", "-C", str(repo), *command], capture_output=True, text=True,
                              check=True, timeout=30).stdout

    try:
        return {"commit": git("rev-parse", "HEAD").strip(),
                "uncommitted": [line[3:] for line in git("status", "--porcelain", "--", *paths).splitlines()]}
    except (OSError, subprocess.SubprocessError) as error:
        return {"error": str(error)}


BUSY_PER_CPU = 0.5  # a 1-minute load, or CPU used by other processes, above this per CPU: busy


class LoadWatch:
    """How busy the machine is, before, during and after a benchmark, apart from the benchmark.

    ``os.getloadavg()`` and the CPU count at the start and at the end, and the CPU time that
    processes other than this one and its children used meanwhile: the busy time in
    ``/proc/stat`` (all CPUs) minus this process's own CPU time and that of its children
    (``os.times()``; a child counts once it has been waited for, so take a :meth:`sample`
    between runs, when the children of the last one have ended). The 1-minute load at the end
    counts the benchmark's own processes, so the end is judged by the other processes' share
    of the last :meth:`sample` windows that span a minute. ``busy`` when the load at the start,
    or the others' share over the whole run or its last minute, exceeds ``BUSY_PER_CPU`` per CPU.
    """

    def __init__(self) -> None:
        self.cpus = os.cpu_count() or 1
        self.start_load = os.getloadavg()
        self.windows: list[dict[str, float]] = []
        self._first = self._last = self._now()

    @staticmethod
    def _now() -> tuple[float, float, float]:
        """(monotonic s, CPU-busy s of the whole machine or NaN, CPU s of this process and its children)."""
        busy = float("nan")
        try:
            with open("/proc/stat", encoding="ascii") as stat:
                fields = [int(x) for x in stat.readline().split()[1:]]
            idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
            busy = (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")  # guest time is inside user
        except (OSError, ValueError, IndexError):
            pass
        t = os.times()
        return time.monotonic(), busy, t.user + t.system + t.children_user + t.children_system

    def _share(self, a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
        """CPUs that other processes kept busy between ``a`` and ``b``, per CPU."""
        wall = b[0] - a[0]
        return max(0.0, (b[1] - a[1]) - (b[2] - a[2])) / wall / self.cpus if wall > 0 else 0.0

    def sample(self) -> float:
        """Close a window (call it between runs); the other processes' share of it, per CPU."""
        now = self._now()
        share = self._share(self._last, now)
        self.windows.append({"end_s": now[0] - self._first[0], "seconds": now[0] - self._last[0],
                             "others_per_cpu": share})
        self._last = now
        return share

    def result(self) -> dict[str, Any]:
        """What was seen, and whether the machine was busy (the reasons, if so)."""
        self.sample()
        end = self._last
        last_minute, covered = [], 0.0
        for window in reversed(self.windows):
            last_minute.append(window)
            covered += window["seconds"]
            if covered >= 60:
                break
        tail = (sum(w["others_per_cpu"] * w["seconds"] for w in last_minute) / covered) if covered else 0.0
        whole = self._share(self._first, end)
        reasons = []
        if self.start_load[0] > BUSY_PER_CPU * self.cpus:
            reasons.append(f"1-minute load {self.start_load[0]:.2f} at the start, on {self.cpus} CPUs")
        if whole > BUSY_PER_CPU:
            reasons.append(f"other processes used {whole:.2f} of each CPU during the run")
        if tail > BUSY_PER_CPU:
            reasons.append(f"other processes used {tail:.2f} of each CPU in the run's last minute")
        return {"cpus": self.cpus, "loadavg_start": list(self.start_load), "loadavg_end": list(os.getloadavg()),
                "others_per_cpu": whole, "others_per_cpu_last_minute": tail, "threshold_per_cpu": BUSY_PER_CPU,
                "windows": self.windows, "busy": bool(reasons), "reasons": reasons}

    @staticmethod
    def headline(found: dict[str, Any]) -> str:
        """One line for a table's header: the load, and the busy mark when it was busy."""
        line = (f"load (1/5/15 min) {' '.join(f'{x:.2f}' for x in found['loadavg_start'])} at the start, "
                f"{' '.join(f'{x:.2f}' for x in found['loadavg_end'])} at the end, {found['cpus']} CPUs; "
                f"other processes used {found['others_per_cpu']:.2f} of each CPU during the run")
        if found["busy"]:
            line = f"MACHINE BUSY: do not publish ({'; '.join(found['reasons'])})\n{line}"
        return line


def run_raw(targets: list[tuple[Callable[..., None], tuple[Any, ...]]], timeout: float,
            what: str = "raw process(es)") -> None:
    """Start the peers' processes (spawned), join them within ``timeout`` s, kill what is left;
    RuntimeError naming ``what`` when one failed or timed out."""
    ctx = multiprocessing.get_context("spawn")
    processes = [ctx.Process(target=fn, args=args, daemon=True) for fn, args in targets]
    try:
        for process in processes:
            process.start()
        deadline = time.monotonic() + timeout
        for process in processes:
            process.join(max(0.0, deadline - time.monotonic()))
        failed = [p.exitcode for p in processes if p.exitcode != 0]
    finally:
        for process in processes:
            if process.is_alive():
                process.kill()
                process.join(5)
    if failed:
        raise RuntimeError(f"{what} failed or timed out: exit codes {failed}")
