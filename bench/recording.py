"""What recording costs TinMan, and how fast ``anodize verify`` reads a recording.

Runs ``anodize run tinman`` alternately without and with ``--record`` (so both see the
same machine load), ``--runs`` times each, and compares the medians of the control
loop's period (p50, p99) and of the frames visual odometry tracked. Each recording is
then verified with ``anodize verify``'s code; its speed is compared with the rate the
run wrote the recording at (the issue's target: verified faster than it was recorded).

    .venv/bin/python bench/recording.py [--runs 3] [--duration 10]

Prints a table and writes bench/results/recording.json.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from runs import LoadWatch, print_table, write_results  # noqa: E402

ROOT = HERE.parent


def run_tinman(out: Path, duration: float, record: bool) -> dict[str, Any]:
    """One TinMan run: its report, and with ``record`` the recording's size and verify's speed."""
    command = [sys.executable, "-m", "anodize._tools.cli", "run", "tinman", "--quiet", "--world", "easy",
               "--duration", str(duration), "--out", str(out)]
    if record:
        command.append("--record")
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=duration * 10 + 120)
    report_file = out / "report.json"
    if not report_file.exists():
        raise RuntimeError(f"tinman wrote no report:\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
    report = json.loads(report_file.read_text(encoding="utf-8"))
    result = {"p50_ms": report["control_period_ms"]["p50"], "p99_ms": report["control_period_ms"]["p99"],
              "frames_tracked": report["frames_processed"], "duration_s": report["duration_s"]}
    if record:
        result.update(verify_speed(out / "run.mcap", report["duration_s"]))
        (out / "run.mcap").unlink()
    return result


def verify_speed(path: Path, recorded_in: float) -> dict[str, Any]:
    from anodize._recording.reader import open_recording
    from anodize._recording.verify import verify
    from anodize._tools.recordings import protocol_of

    with open_recording(path) as recording:
        global_type = protocol_of(recording, None, None)
        began = time.perf_counter()
        report = verify(recording, global_type, import_classes=False)  # the recording's protocol, as the CLI reads it
        seconds = time.perf_counter() - began
    if not report.conforms:
        raise RuntimeError(f"a TinMan recording does not verify:\n{report.text()}")
    size = path.stat().st_size
    return {"recording_mib": size / 2**20, "messages": report.messages, "verify_s": seconds,
            "verify_mib_per_s": size / 2**20 / seconds, "recorded_mib_per_s": size / 2**20 / recorded_in,
            "verify_messages_per_s": report.messages / seconds}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--json", default=str(HERE / "results" / "recording.json"))
    args = parser.parse_args(argv)
    started = time.monotonic()
    watch = LoadWatch()
    plain: list[dict[str, Any]] = []
    recorded: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="anodize-bench-rec-") as folder:
        for number in range(args.runs):
            for record, into in ((False, plain), (True, recorded)):
                out = Path(folder) / f"{'rec' if record else 'plain'}{number}"
                into.append(run_tinman(out, args.duration, record))
                print(f"run {number + 1}/{args.runs} {'with' if record else 'without'} --record: "
                      f"p99 {into[-1]['p99_ms']:.2f} ms, {into[-1]['frames_tracked']} frames", flush=True)

    def median(runs: list[dict[str, Any]], key: str) -> float:
        return float(statistics.median(r[key] for r in runs))

    rows = [["measure (median of runs)", "without --record", "with --record", "ratio"]]
    for key, name in (("p50_ms", "control period p50 (ms)"), ("p99_ms", "control period p99 (ms)"),
                      ("frames_tracked", "frames tracked by VO")):
        a, b = median(plain, key), median(recorded, key)
        rows.append([name, f"{a:.2f}", f"{b:.2f}", f"{b / a:.3f}x"])
    verify_rate, record_rate = median(recorded, "verify_mib_per_s"), median(recorded, "recorded_mib_per_s")
    rows.append(["recording written (MiB/s)", "", f"{record_rate:.1f}", ""])
    rows.append(["verify read and checked (MiB/s)", "", f"{verify_rate:.1f}",
                 f"{verify_rate / record_rate:.0f}x the recording rate"])
    rows.append(["verify (messages/s)", "", f"{median(recorded, 'verify_messages_per_s'):.0f}", ""])
    print()
    print_table(rows, text_columns=(0,))
    how = (f"anodize run tinman for {args.duration:g} s, {args.runs} runs each without and with --record, "
           f"alternating; medians; {os.cpu_count()} CPUs")
    write_results(Path(args.json), {"runs": args.runs, "duration_s": args.duration, "table": rows,
                                    "without_record": plain, "with_record": recorded}, started,
                  title="What recording costs TinMan", how=how, watch=watch)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
