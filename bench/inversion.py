"""Priority inversion, measured: H (SCHED_FIFO 90) asks L (SCHED_FIFO 10, 2 ms of work per
request) and waits for the reply, over the process transport, both pinned to CPU 0, while an
unrelated SCHED_FIFO 50 process on the same CPU spins in bounded bursts (60 ms every 200 ms,
with a hard stop). Three scenarios in one run: nothing spinning; spinning, with priority
inheritance (the default); spinning, with inheritance turned off in L's group. Prints H's
response time p50/p99/max and the ratios against the quiet run, then what inheritance costs
(:mod:`inheritance_cost`: a receive that finds its message waiting, with and without the
hook, and one boost episode), and writes JSON (``bench/results/inversion.json``) through
``runs.write_results``.

    python bench/inversion.py [--asks 150] [--json PATH]

Needs SCHED_FIFO (root or CAP_SYS_NICE) and CPU 0.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

BENCH = Path(__file__).resolve().parent
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))
sys.path.insert(0, str(BENCH.parent))
os.environ["PYTHONPATH"] = os.pathsep.join([str(BENCH), str(BENCH.parent), os.environ.get("PYTHONPATH", "")])

import inheritance_cost  # noqa: E402
import inversion_roles as roles  # noqa: E402
from runs import LoadWatch, bench_env, print_table, source_state, write_results  # noqa: E402

import anodize  # noqa: E402
import sessiontypes  # noqa: E402

DEFAULT_JSON = BENCH / "results" / "inversion.json"
ASK = sessiontypes.loads("global Ask(H, L) = mu t. H -> L : {ask. L -> H : answer. t, stop}",
                         "inversion.proto").globals["Ask"]

# The spinner: SCHED_FIFO 50 on CPU 0, 60 ms of spinning every 200 ms, for at most ``seconds``.
SPINNER = """
import os, sys, time
os.sched_setaffinity(0, {0})
os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
stop = time.monotonic() + float(sys.argv[1])
while time.monotonic() < stop:
    end = time.monotonic() + 0.060
    while time.monotonic() < end:
        pass
    time.sleep(0.140)
"""


def scenario(asks: int, spin: bool, inherit: bool) -> list[float]:
    """H's response times (seconds) in one run."""
    spinner = None
    if spin:  # a hard stop: the spinner ends by itself after 60 s at most, and is killed after the run
        spinner = subprocess.Popen([sys.executable, "-c", SPINNER, "60"])
        time.sleep(0.1)
    try:
        with bench_env(roles.ENV, asks=asks) as (out, _):
            system = anodize.System(ASK, transport=anodize.Processes())
            system.group("high", priority=90, cpus={0}).role("H", "inversion_roles:high")
            system.group("low", priority=10, cpus={0}, priority_inheritance=inherit).role("L", "inversion_roles:low")
            report = system.run(timeout=120)
            if not report.ok:
                raise RuntimeError(report.summary())
            return json.loads(Path(out, "high.json").read_text(encoding="utf-8"))  # type: ignore[no-any-return]
    finally:
        if spinner is not None:
            spinner.kill()
            spinner.wait(10)


def percentiles(times: list[float]) -> dict[str, float]:
    """p50, p99 and max in milliseconds."""
    ordered = sorted(times)
    return {"p50_ms": statistics.median(ordered) * 1000,
            "p99_ms": ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))] * 1000,
            "max_ms": ordered[-1] * 1000}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--asks", type=int, default=150)
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON, help=f"default {DEFAULT_JSON}")
    args = parser.parse_args(argv)
    started = time.monotonic()
    source = source_state(BENCH.parent, "anodize")
    watch = LoadWatch()
    runs = {"nothing spinning": scenario(args.asks, False, True),
            "spinning, inheritance on": scenario(args.asks, True, True),
            "spinning, inheritance off": scenario(args.asks, True, False)}
    results = {name: percentiles(times) for name, times in runs.items()}
    quiet = results["nothing spinning"]
    table = [["scenario", "p50 ms", "p99 ms", "max ms", "p99 / quiet p99"]]
    for name, r in results.items():
        table.append([name, f"{r['p50_ms']:.2f}", f"{r['p99_ms']:.2f}", f"{r['max_ms']:.2f}",
                      f"{r['p99_ms'] / quiet['p99_ms']:.1f}x"])
    print_table(table, (0,))
    cost = inheritance_cost.measure()
    print()
    print_table([["what inheritance costs", "ns"],
                 ["recv of a waiting message, no table", f"{cost['recv_plain_ns']:.0f}"],
                 ["recv of a waiting message, hooked", f"{cost['recv_hooked_ns']:.0f}"],
                 ["one boost episode (lend and take back)", f"{cost['episode_ns']:.0f}"]], (0,))
    how = (f"H (SCHED_FIFO 90) asks L (SCHED_FIFO 10, 2 ms of work) {args.asks} times over Processes, both on "
           "CPU 0; a SCHED_FIFO 50 process spins 60 ms every 200 ms on CPU 0")
    write_results(args.json, {"table": table, "results": results, "cost_ns": cost, "source": source,
                              "asks": args.asks},
                  started, title="Priority inversion and inheritance", how=how, watch=watch)
    return 0


if __name__ == "__main__":
    sys.exit(main())
