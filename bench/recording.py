"""What recording costs TinMan, and how fast ``anodize verify`` reads a recording.

Runs ``anodize run tinman`` in turn not recording, recording every channel (``--record``,
the default: inside groups too) and recording the channels between groups only
(``--record --record-between``), so that all three see the same machine load,
``--runs`` times each, and compares the control loop's period (p50, p99) and the frames
visual odometry tracked: medians, and the spread (lowest..highest) over the runs. Each
recording of every channel is then verified with ``anodize verify``'s code; its speed is
compared with the rate the run wrote the recording at (the target: verified faster than
it was recorded).

    .venv/bin/python bench/recording.py [--runs 3] [--duration 10] [--hogs 2]

``--hogs N``: N processes spin at normal priority through every run (the machine a user
shares), as bench/criticality.py's ``hogs`` scenario.

Prints a table and writes bench/results/recording.json.
"""

from __future__ import annotations

import argparse
import contextlib
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

from runs import LoadWatch, hogs, print_table, write_results  # noqa: E402

ROOT = HERE.parent


MODES = {"none": [], "everything": ["--record"], "between": ["--record", "--record-between"]}
SHOWN = {"none": "not recording", "everything": "--record (every channel)",
         "between": "--record --record-between"}


def run_tinman(out: Path, duration: float, mode: str) -> dict[str, Any]:
    """One TinMan run: its report, and when it records, the recording's size (and, recording every
    channel, verify's speed)."""
    command = [sys.executable, "-m", "anodize._tools.cli", "run", "tinman", "--quiet", "--world", "easy",
               "--duration", str(duration), "--out", str(out), *MODES[mode]]
    record = mode != "none"
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=duration * 10 + 120)
    report_file = out / "report.json"
    if not report_file.exists():
        raise RuntimeError(f"tinman wrote no report:\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
    report = json.loads(report_file.read_text(encoding="utf-8"))
    result = {"p50_ms": report["control_period_ms"]["p50"], "p99_ms": report["control_period_ms"]["p99"],
              "frames_tracked": report["frames_processed"], "duration_s": report["duration_s"],
              "outcome": report["outcome"], "ok": bool(report["ok"]), "problems": report.get("problems", [])[:3]}
    if record:
        path = out / "run.mcap"
        result["recording_mib"] = path.stat().st_size / 2**20
        result["lost"] = sum(1 for note in report.get("notes", []) if "not recorded" in note)
        if mode == "everything":
            result.update(verify_speed(path, report["duration_s"]))
        path.unlink()
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
    parser.add_argument("--hogs", type=int, default=0, metavar="N",
                        help="N CPU hogs at normal priority through every run (default none)")
    parser.add_argument("--json", default=str(HERE / "results" / "recording.json"))
    args = parser.parse_args(argv)
    started = time.monotonic()
    watch = LoadWatch()
    runs: dict[str, list[dict[str, Any]]] = {mode: [] for mode in MODES}
    busy = hogs(args.hogs) if args.hogs else contextlib.nullcontext()
    with tempfile.TemporaryDirectory(prefix="anodize-bench-rec-") as folder, busy:
        for number in range(args.runs):
            for mode, into in runs.items():
                out = Path(folder) / f"{mode}{number}"
                into.append(run_tinman(out, args.duration, mode))
                watch.sample()
                print(f"run {number + 1}/{args.runs} {SHOWN[mode]}: {into[-1]['outcome']} in "
                      f"{into[-1]['duration_s']:.1f} s, p99 {into[-1]['p99_ms']:.2f} ms, "
                      f"{into[-1]['frames_tracked']} frames", flush=True)

    def values(mode: str, key: str) -> list[float]:
        return [float(r[key]) for r in runs[mode]]

    def cell(mode: str, key: str) -> str:
        found = values(mode, key)
        return f"{statistics.median(found):.2f} ({min(found):.2f}..{max(found):.2f})"

    rows = [["measure: median (lowest..highest)", SHOWN["none"], SHOWN["everything"], SHOWN["between"],
             "ratio every channel / none", "ratio between / none"]]
    for key, name in (("p50_ms", "control period p50 (ms)"), ("p99_ms", "control period p99 (ms)"),
                      ("frames_tracked", "frames tracked by VO")):
        base = statistics.median(values("none", key))
        ratios = [f"{statistics.median(values(mode, key)) / base:.3f}x" if base else "-"
                  for mode in ("everything", "between")]  # no frames tracked: a run too short for VO
        rows.append([name, cell("none", key), cell("everything", key), cell("between", key), *ratios])
    rows.append(["runs that failed (counted above too)", *(str(sum(not r["ok"] for r in runs[m])) for m in MODES),
                 "", ""])
    rows.append(["recording size (MiB)", "", cell("everything", "recording_mib"), cell("between", "recording_mib"),
                 "", ""])
    rows.append(["runs whose recording lost messages", "", str(sum(r["lost"] > 0 for r in runs["everything"])),
                 str(sum(r["lost"] > 0 for r in runs["between"])), "", ""])
    verify_rate = statistics.median(values("everything", "verify_mib_per_s"))
    record_rate = statistics.median(values("everything", "recorded_mib_per_s"))
    rows.append(["recording written (MiB/s)", "", f"{record_rate:.1f}", "", "", ""])
    rows.append(["verify read and checked (MiB/s)", "", f"{verify_rate:.1f}", "",
                 f"{verify_rate / record_rate:.0f}x the recording rate", ""])
    rows.append(["verify (messages/s)", "", f"{statistics.median(values('everything', 'verify_messages_per_s')):.0f}",
                 "", "", ""])
    print()
    print_table(rows, text_columns=(0,))
    how = (f"anodize run tinman --world easy for {args.duration:g} s, {args.runs} runs each not recording, recording "
           f"every channel and recording between groups only, in turn; medians (lowest..highest); "
           f"{os.cpu_count()} CPUs" + (f", {args.hogs} CPU hogs at nice 0 throughout" if args.hogs else ""))
    write_results(Path(args.json), {"runs": args.runs, "duration_s": args.duration, "hogs": args.hogs, "table": rows,
                                    **{f"runs_{mode}": found for mode, found in runs.items()}}, started,
                  title="What recording costs TinMan", how=how, watch=watch)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
