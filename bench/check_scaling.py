#!/usr/bin/env python3
"""How parse, check and projection scale with protocol size.

Generates protocol TEXT of N interactions (N = number of ``->`` in the text)
for five shapes and times, as separate phases, with the median of --repeat
runs:

  parse        ``sessiontypes.parse.parse_file(text, path)``
  check        ``sessiontypes.check.check_file(source)`` with the projectability
               check switched off (``check._check_projectable`` replaced by a
               no-op in this process only): resolution and the other checks.
  project-all  ``module.globals[name].project(role)`` for every role, on the
               module of that check, so nothing has been projected yet (any
               ``cached_projections`` memo is cleared first): the cold cost.
  check_file   ``check_file`` as shipped (includes projecting every global onto
               every role to prove it projectable).
  project-after-check
               project-all again on the module of the shipped ``check_file``
               (what a user calls after ``sessiontypes.load``; may be cached).

  total        parse + check + project-all (each piece of work counted once).
  pipeline     parse + check_file + project-after-check: what a user waits for
               in ``anodize project`` (printing aside).

Shapes (all texts are linear in N; every generated protocol is well formed):

  sequence  one ``mu t. ... t`` around N interactions between pseudo-random
            distinct roles out of 16.
  choices   a chain of choice blocks over 4 rotating roles:
              p -> q : {stop. q -> o1 : s. q -> o2 : s. t,
                        go.   q -> o1 : g. q -> o2 : g. <next block>}
            (5 interactions a block). o1 and o2 are not told of p's choice and
            must merge ``?q(s)...`` with ``?q(g)...``; the chain continues in
            the ``go`` branch only, so the text stays linear.
  deep-rec  N/4 nested loops over 3 roles:
              mu tK. p -> q : {again. q -> r : again. tK,
                               out.   q -> r : out.   tJ,   (J random in 1..K)
                               down.  q -> r : down.  <level K+1>}
            so variables of outer loops are used deep inside.
  ref-dag   N declarations, each referring twice to the next one:
              global G0(A, B) = A -> B : {l. G1, r. G1}   ...   global GN = end
            Written out, G0 is a tree of 2^N interactions (issue 11).
  ref-chain N declarations, each referring to the next one:
              global G0(A, B) = A -> B : x. G1   ...   global GN = end
            Written out, the N globals hold N^2/2 interactions together.

Each (shape, size) runs in a fresh subprocess (isolation, memory, --timeout);
a failure or timeout is printed in the table instead of stopping the run.

Usage:
  .venv/bin/python bench/check_scaling.py [--sizes 100,1000,10000,100000]
      [--repeat N] [--json PATH] [--shapes sequence,choices,deep-rec,ref-dag,ref-chain]
      [--timeout SECONDS]
  .venv/bin/python bench/check_scaling.py --profile SHAPE[:SIZE] [--top 15]
      cProfile of one parse + check_file + project-all (default size 10000).
"""

from __future__ import annotations

import argparse
import datetime
import gc
import hashlib
import json
import math
import os
import platform
import random
import statistics
import subprocess
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
# --impl DIR (or ANODIZE_BENCH_IMPL) measures the sessiontypes package found in DIR
# instead of the work tree's, e.g. a `git archive` snapshot of another commit.
IMPL = Path(os.environ.get("ANODIZE_BENCH_IMPL") or REPO).resolve()
for _i, _arg in enumerate(sys.argv):
    if _arg == "--impl" and _i + 1 < len(sys.argv):
        IMPL = Path(sys.argv[_i + 1]).resolve()
    elif _arg.startswith("--impl="):
        IMPL = Path(_arg.split("=", 1)[1]).resolve()
if str(IMPL) not in sys.path:
    sys.path.insert(0, str(IMPL))

from runs import LoadWatch, write_results  # noqa: E402  (bench/runs.py, beside this script)

DEFAULT_SIZES = (100, 1_000, 10_000, 100_000)
SHAPES = ("sequence", "choices", "deep-rec", "ref-dag", "ref-chain", "routed")
DEFAULT_JSON = REPO / "bench" / "results" / "check_scaling.json"

# ---------------------------------------------------------------------------
# Protocol generators. Each returns (text, roles); the text has exactly n "->".
# ---------------------------------------------------------------------------

_PAYLOADS = ("int", "str", "float", "bool", "Pose", "Twist", "")
_TYPE_DECLS = ('type Pose = "tinman.messages:Pose"\n'
               'type Twist = "tinman.messages:Twist"\n')


def _msg(rng: random.Random) -> str:
    label = f"m{rng.randrange(8)}"
    payload = rng.choice(_PAYLOADS)
    return f"{label}({payload})"


def gen_sequence(n: int, seed: int = 1, n_roles: int = 16) -> tuple[str, list[str]]:
    """One outer loop around n interactions between random distinct roles."""
    rng = random.Random(seed)
    roles = [f"R{i}" for i in range(n_roles)]
    lines = [_TYPE_DECLS, "global Seq =", "  mu t."]
    for i in range(n):
        if i < n_roles // 2:          # every role occurs, even for tiny n
            a, b = roles[2 * i], roles[2 * i + 1]
        else:
            a, b = rng.sample(roles, 2)
        lines.append(f"    {a} -> {b} : {_msg(rng)}.")
    lines.append("    t")
    return "\n".join(lines) + "\n", roles


def gen_choices(n: int, seed: int = 2) -> tuple[str, list[str]]:
    """Chained choices whose uninformed roles must merge (5 interactions a block)."""
    roles = ["A", "B", "C", "D"]
    per_block = 5
    blocks, rest = divmod(n, per_block)
    out = [_TYPE_DECLS, "global Choices =\n  mu t.\n"]
    closers = 0
    for i in range(blocks):
        p, q, o1, o2 = (roles[(i + k) % 4] for k in range(4))
        exit_to = "end" if i % 3 == 2 else "t"
        out.append(f"  {p} -> {q} : {{stop. {q} -> {o1} : s(int). {q} -> {o2} : s(int). {exit_to},\n"
                   f"    go. {q} -> {o1} : g. {q} -> {o2} : g.\n")
        closers += 1
    for i in range(rest):
        a, b = roles[i % 4], roles[(i + 1) % 4]
        out.append(f"  {a} -> {b} : tail{i}.\n")
    out.append("  t")
    # Close the go branches: one '}' per block (a line of them, wrapped).
    out.extend("\n  " + "}" * min(100, closers - start) for start in range(0, closers, 100))
    out.append("\n")
    return "".join(out), roles


def gen_deep_rec(n: int, seed: int = 3) -> tuple[str, list[str]]:
    """n/4 nested loops; 'out' branches jump to a random enclosing loop."""
    rng = random.Random(seed)
    roles = ["A", "B", "C"]
    per_level = 4
    levels, rest = divmod(n, per_level)
    out = ["global DeepRec =\n"]
    for k in range(1, levels + 1):
        p, q, r = (roles[(k - 1 + i) % 3] for i in range(3))
        j = rng.randint(1, k)
        out.append(f"  mu t{k}. {p} -> {q} : {{again. {q} -> {r} : again. t{k},\n"
                   f"    out. {q} -> {r} : out(int). t{j},\n"
                   f"    down. {q} -> {r} : down.\n")
    for i in range(rest):
        a, b = roles[i % 3], roles[(i + 1) % 3]
        out.append(f"  {a} -> {b} : tail{i}.\n")
    out.append("  t1" if levels else "  end")
    out.extend("\n  " + "}" * min(100, levels - start) for start in range(0, levels, 100))
    out.append("\n")
    return "".join(out), roles


def gen_ref_dag(n: int) -> tuple[str, list[str]]:
    """n declarations, each referring twice to the next: a DAG of declarations."""
    lines = [f"global G{i}(A, B) = A -> B : {{l. G{i + 1}, r. G{i + 1}}}" for i in range(n)]
    lines.append(f"global G{n} = end")
    return "\n".join(lines) + "\n", ["A", "B"]


def gen_ref_chain(n: int) -> tuple[str, list[str]]:
    """n declarations, each referring to the next."""
    lines = [f"global G{i}(A, B) = A -> B : x. G{i + 1}" for i in range(n)]
    lines.append(f"global G{n} = end")
    return "\n".join(lines) + "\n", ["A", "B"]


def gen_routed(n: int) -> tuple[str, list[str]]:
    """The newer constructs chained (5 interactions a block): a choice among receivers that
    the others learn from different peers, named payloads, and a multicast tail."""
    roles = ["A", "B", "C"]
    blocks, rest = divmod(n, 5)
    out = ["global Routed =\n  mu t.\n"]
    out.extend(f"  A -> {{B : stop{i}. B -> C : s(n: int, tag: str). C -> A : ack(ok: bool). t,\n"
               f"    C : go{i}. C -> B : g(n: int, tag: str). B -> A : ack(ok: bool).\n" for i in range(blocks))
    out.extend(f"  A -> B, C : tail{i}(n: int, when: float).\n" for i in range(rest))
    out.append("  t")
    out.extend("\n  " + "}" * min(100, blocks - start) for start in range(0, blocks, 100))
    out.append("\n")
    return "".join(out), roles


GENERATORS: dict[str, Callable[[int], tuple[str, list[str]]]] = {
    "sequence": gen_sequence,
    "choices": gen_choices,
    "deep-rec": gen_deep_rec,
    "ref-dag": gen_ref_dag,
    "ref-chain": gen_ref_chain,
    "routed": gen_routed,
}


def generate(shape: str, n: int) -> str:
    text, _ = GENERATORS[shape](n)
    count = text.count("->")
    if count != n:
        raise AssertionError(f"generator {shape} produced {count} interactions, wanted {n}")
    return text


# ---------------------------------------------------------------------------
# One measurement (runs in a worker subprocess).
# ---------------------------------------------------------------------------

class _PhaseError(Exception):
    def __init__(self, phase: str, message: str) -> None:
        super().__init__(f"{phase}: {message}")
        self.phase = phase


def _describe_error(error: BaseException) -> str:
    text = f"{type(error).__name__}: {error}".splitlines()
    first = text[0] if text else type(error).__name__
    return first[:300]


def _errors_of(diagnostics: list[Any]) -> list[Any]:
    return [d for d in diagnostics if d.severity == "error"]


# Set by --gc-off: the cyclic garbage collector is disabled while a phase runs.
GC_OFF = False
# CPU seconds (all threads of the process) of the phases, parallel to the wall times.
_CPU: dict[str, float] = {}


def _timed(phase: str, function: Callable[..., Any], *args: Any) -> tuple[float, Any]:
    gc.collect()
    if GC_OFF:
        gc.disable()
    cpu = time.process_time()
    start = time.perf_counter()
    try:
        result = function(*args)
    except Exception as error:  # reported, not raised
        raise _PhaseError(phase, _describe_error(error)) from error
    finally:
        wall = time.perf_counter() - start
        _CPU[phase] = time.process_time() - cpu
        if GC_OFF:
            gc.enable()
    return wall, result


def _project_all(module: Any) -> int:
    count = 0
    for global_type in module.globals.values():
        for role in global_type.roles:
            global_type.project(role)
            count += 1
    return count


def _drop_cached_projections(module: Any) -> None:
    """Forget projections a (current or future) implementation may have memoised."""
    for global_type in module.globals.values():
        cache = getattr(global_type, "cached_projections", None)
        if isinstance(cache, dict):
            cache.clear()


def measure_once(text: str, path: str) -> dict[str, float]:
    from sessiontypes import check as check_module
    from sessiontypes.check import check_file
    from sessiontypes.parse import parse_file

    times: dict[str, float] = {}
    times["parse"], source = _timed("parse", parse_file, text, path)

    # check without the projectability pass, then projection onto every role of
    # that (unprojected) module: the two pieces of work separately.
    real = check_module._check_projectable
    check_module._check_projectable = lambda *args, **kwargs: None
    try:
        times["check"], (module, diagnostics) = _timed("check", check_file, source)
    finally:
        check_module._check_projectable = real
    errors = _errors_of(diagnostics)
    if errors:
        raise _PhaseError("check", f"{len(errors)} error(s), first: {str(errors[0]).splitlines()[0]}")
    _drop_cached_projections(module)
    times["project_all"], projected = _timed("project_all", _project_all, module)
    if projected == 0:
        raise _PhaseError("project_all", "no role to project onto")
    del module, diagnostics

    # As shipped: check_file (projects every role to prove projectability),
    # then project-all as a user does after loading (may be served from a cache).
    times["check_file"], (module, diagnostics) = _timed("check_file", check_file, source)
    errors = _errors_of(diagnostics)
    if errors:
        raise _PhaseError("check_file", f"{len(errors)} error(s), first: {str(errors[0]).splitlines()[0]}")
    times["project_after_check"], _ = _timed("project_after_check", _project_all, module)
    del module, diagnostics, source
    gc.collect()
    times["total"] = times["parse"] + times["check"] + times["project_all"]
    times["pipeline"] = times["parse"] + times["check_file"] + times["project_after_check"]
    for phase in ("parse", "check", "project_all", "check_file", "project_after_check"):
        times[f"cpu_{phase}"] = _CPU[phase]
    times["cpu_total"] = times["cpu_parse"] + times["cpu_check"] + times["cpu_project_all"]
    times["cpu_pipeline"] = (times["cpu_parse"] + times["cpu_check_file"]
                             + times["cpu_project_after_check"])
    return times


def _peak_rss_mb() -> float | None:
    """Peak resident memory of this (worker) process, in MiB."""
    try:
        import resource
    except ImportError:  # not on this platform
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1024 * 1024) if sys.platform == "darwin" else peak / 1024


def run_case(shape: str, n: int, repeat: int) -> dict[str, Any]:
    result: dict[str, Any] = {"shape": shape, "size": n, "repeat": repeat, "gc_off": GC_OFF}
    try:
        start = time.perf_counter()
        text = generate(shape, n)
        result["generate_s"] = time.perf_counter() - start
        result["text_bytes"] = len(text.encode())
        result["text_lines"] = text.count("\n")
        _, roles = GENERATORS[shape](min(n, 100))
        result["roles"] = len(roles)
        # Warm-up on a small protocol of the same shape (imports, first-call costs);
        # never larger than the case: an implementation may be exponential in it.
        measure_once(generate(shape, min(50, n)), f"<{shape}-warmup>")
        runs = [measure_once(text, f"<{shape}-{n}>") for _ in range(repeat)]
        result["runs"] = runs
        result["median"] = {phase: statistics.median(r[phase] for r in runs) for phase in runs[0]}
        result["peak_rss_mb"] = _peak_rss_mb()
        result["ok"] = True
    except _PhaseError as failure:
        result["ok"] = False
        result["error"] = str(failure)
    except Exception as error:  # generator or harness bug: still a row
        result["ok"] = False
        result["error"] = "harness: " + _describe_error(error)
        result["traceback"] = traceback.format_exc()
    return result


# ---------------------------------------------------------------------------
# Driver: one subprocess per case.
# ---------------------------------------------------------------------------

def run_in_subprocess(shape: str, n: int, repeat: int, timeout: float,
                      gc_off: bool = False) -> dict[str, Any]:
    command = [sys.executable, str(Path(__file__).resolve()), "--worker", f"{shape}:{n}:{repeat}",
               "--impl", str(IMPL)]
    if gc_off:
        command.append("--gc-off")
    start = time.perf_counter()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout, cwd=REPO)
    except subprocess.TimeoutExpired:
        return {"shape": shape, "size": n, "repeat": repeat, "ok": False,
                "error": f"timeout after {timeout:g} s", "timeout": True}
    wall = time.perf_counter() - start
    for line in reversed(done.stdout.splitlines()):
        if line.startswith("{"):
            try:
                result: dict[str, Any] = json.loads(line)
            except json.JSONDecodeError:
                continue
            result["worker_wall_s"] = wall
            return result
    tail = (done.stderr.strip().splitlines() or [f"exit status {done.returncode}"])[-1]
    return {"shape": shape, "size": n, "repeat": repeat, "ok": False,
            "error": f"worker died (status {done.returncode}): {tail[:300]}"}


def nlogn_ratio(previous: int, current: int) -> float:
    """(n2 log n2) / (n1 log n1); for n2 = 10 n1 that is 10 log(10 n) / log(n)."""
    return (current * math.log(current)) / (previous * math.log(previous))


def _fmt(value: float | None, width: int, digits: int = 4) -> str:
    if value is None:
        return "-".rjust(width)
    if value >= 100:
        return f"{value:.1f}".rjust(width)
    return f"{value:.{digits}f}".rjust(width)


def render_table(results: list[dict[str, Any]], clock: str = "wall") -> str:
    def m_of(r: dict[str, Any]) -> dict[str, float]:
        med = r["median"]
        return med if clock == "wall" else {k[4:]: v for k, v in med.items() if k.startswith("cpu_")}

    header = (f"{'shape':<9} {'size':>7} {'parse s':>9} {'check s':>9} {'project-all s':>13} "
              f"{'total s':>9} {'growth':>7} {'nlogn ref':>9} {'check_file s':>12} {'pipeline s':>10} "
              f"{'peak MB':>8}")
    lines = [header, "-" * len(header)]
    previous: dict[str, dict[str, Any]] = {}
    for r in results:
        shape, n = r["shape"], r["size"]
        if not r.get("ok"):
            lines.append(f"{shape:<9} {n:>7} FAILED: {r.get('error', '?')}")
            previous.pop(shape, None)
            continue
        m = m_of(r)
        prev = previous.get(shape)
        growth = ref = None
        if prev is not None and m_of(prev)["total"] > 0:
            growth = m["total"] / m_of(prev)["total"]
            ref = nlogn_ratio(prev["size"], n)
        peak = f"{r['peak_rss_mb']:.0f}" if r.get("peak_rss_mb") else "-"
        r["growth_total"] = growth
        r["nlogn_ref"] = ref
        lines.append(
            f"{shape:<9} {n:>7} {_fmt(m['parse'], 9)} {_fmt(m['check'], 9)} "
            f"{_fmt(m['project_all'], 13)} {_fmt(m['total'], 9)} "
            f"{(f'{growth:.1f}x' if growth is not None else '-'):>7} "
            f"{(f'{ref:.1f}x' if ref is not None else '-'):>9} "
            f"{_fmt(m['check_file'], 12)} {_fmt(m['pipeline'], 10)} "
            f"{peak:>8}")
        previous[shape] = r
    return "\n".join(lines)


def table_rows(results: list[dict[str, Any]], clock: str = "wall") -> list[list[str]]:
    """The results as table rows (the first the header); call after :func:`render_table`, which adds the growth."""
    rows = [["shape", "interactions", "parse s", "check s", "project all roles s", "total s", "growth vs 10x smaller",
             "n log n reference"]]
    for r in results:
        if not r.get("ok"):
            rows.append([r["shape"], f"{r['size']:,}", "FAILED", "", "", "", "", str(r.get("error", "?"))[:60]])
            continue
        med = r["median"] if clock == "wall" else {k[4:]: v for k, v in r["median"].items() if k.startswith("cpu_")}
        growth, ref = r.get("growth_total"), r.get("nlogn_ref")
        seconds = [f"{med[k]:.3f}" for k in ("parse", "check", "project_all", "total")]
        rows.append([r["shape"], f"{r['size']:,}", *seconds,
                     f"{growth:.1f}x" if growth is not None else "-", f"{ref:.1f}x" if ref is not None else "-"])
    return rows


def render_verdicts(results: list[dict[str, Any]], size: int = 10_000, clock: str = "wall") -> list[str]:
    lines = []
    for r in results:
        if r["size"] != size:
            continue
        if not r.get("ok"):
            lines.append(f"{size:,} interactions, {r['shape']}: NOT measured ({r.get('error')})")
            continue
        m = r["median"] if clock == "wall" else {
            k[4:]: v for k, v in r["median"].items() if k.startswith("cpu_")}
        verdict = "UNDER 1 s" if m["total"] < 1.0 else "NOT under 1 s"
        lines.append(
            f"{size:,} interactions, {r['shape']}: parse+check+project = {m['total']:.3f} s -> {verdict}"
            f" (pipeline parse+check_file+project-after-check: {m['pipeline']:.3f} s -> "
            f"{'under' if m['pipeline'] < 1.0 else 'NOT under'} 1 s)")
    return lines


def _fingerprint() -> dict[str, Any]:
    info: dict[str, Any] = {
        "python": sys.version.split()[0],
        "load_average_at_end": os.getloadavg() if hasattr(os, "getloadavg") else None,
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    try:
        import lark
        info["lark"] = lark.__version__
    except Exception:  # pragma: no cover
        info["lark"] = None
    try:
        info["git_head"] = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True,
                                          text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "sessiontypes"], cwd=REPO,
                               capture_output=True, text=True).stdout.split("\n")
        info["sessiontypes_dirty"] = [line for line in dirty if line.strip()]
    except Exception:
        info["git_head"] = None
    info["impl"] = str(IMPL)
    info["impl_is_work_tree"] = IMPL == REPO  # git_head/dirty describe the work tree
    try:
        import sessiontypes
        info["sessiontypes_file"] = sessiontypes.__file__
    except Exception as error:
        info["sessiontypes_file"] = f"import failed: {error}"
    digest = hashlib.sha256()
    for file in sorted((IMPL / "sessiontypes").glob("*")):
        if file.is_file() and file.suffix in {".py", ".lark"}:
            digest.update(file.name.encode())
            digest.update(file.read_bytes())
    info["sessiontypes_sha256"] = digest.hexdigest()[:16]
    return info


# ---------------------------------------------------------------------------
# Profiling (in-process, on run_deep's helper thread where the work happens).
# ---------------------------------------------------------------------------

def profile_case(shape: str, n: int, top: int) -> str:
    import cProfile
    import io
    import pstats

    from sessiontypes.check import check_file
    from sessiontypes.deep import run_deep
    from sessiontypes.parse import parse_file

    text = generate(shape, n)

    def pipeline() -> None:
        source = parse_file(text, f"<{shape}-{n}>")
        module, diagnostics = check_file(source)
        errors = _errors_of(diagnostics)
        if errors:
            raise RuntimeError(str(errors[0]))
        for global_type in module.globals.values():
            for role in global_type.roles:
                global_type.project(role)

    profiler = cProfile.Profile()
    # check_file/project run their work on a helper thread (sessiontypes.deep);
    # cProfile sees one thread, so run the whole pipeline inside run_deep: the
    # nested run_deep calls then execute inline on the profiled thread.
    start = time.perf_counter()
    run_deep(lambda: profiler.runcall(pipeline))
    wall = time.perf_counter() - start
    out = io.StringIO()
    out.write(f"profile of parse + check_file + project-all, shape={shape}, size={n} "
              f"(wall {wall:.2f} s under cProfile)\n")
    stats = pstats.Stats(profiler, stream=out)
    stats.strip_dirs().sort_stats("cumulative").print_stats(top)
    stats.sort_stats("tottime").print_stats(top)
    return out.getvalue()


# ---------------------------------------------------------------------------

def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default=",".join(str(s) for s in DEFAULT_SIZES),
                        help="comma-separated interaction counts (default %(default)s)")
    parser.add_argument("--repeat", type=int, default=None,
                        help="runs per case, median reported (default 3; 1 for sizes >= 100000)")
    parser.add_argument("--json", default=str(DEFAULT_JSON), help="output JSON (default %(default)s)")
    parser.add_argument("--shapes", default=",".join(SHAPES), help="subset of %(default)s")
    parser.add_argument("--timeout", type=float, default=1800.0,
                        help="seconds per (shape, size) case before it is reported as a timeout")
    parser.add_argument("--profile", metavar="SHAPE[:SIZE]",
                        help="print a cProfile of one case instead of the scaling table")
    parser.add_argument("--top", type=int, default=15, help="rows of the profile (default 15)")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                        help="seconds shown in the table: wall clock (default) or process CPU time "
                             "(less disturbed by other load on the machine)")
    parser.add_argument("--gc-off", action="store_true",
                        help="disable Python's cyclic GC during the timed phases (to see its share)")
    parser.add_argument("--impl", metavar="DIR", default=str(IMPL),
                        help="directory holding the sessiontypes package to measure "
                             "(default: this work tree)")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.worker:
        global GC_OFF
        GC_OFF = args.gc_off
        shape, size, repeat = args.worker.split(":")
        print(json.dumps(run_case(shape, int(size), int(repeat))))
        return 0

    if args.profile:
        shape, _, size = args.profile.partition(":")
        if shape not in GENERATORS:
            parser.error(f"unknown shape {shape!r}; choose from {', '.join(SHAPES)}")
        print(profile_case(shape, int(size or 10_000), args.top))
        return 0

    try:
        sizes = [int(s.replace("_", "")) for s in args.sizes.split(",") if s.strip()]
    except ValueError:
        parser.error(f"--sizes must be integers, got {args.sizes!r}")
    shapes = [s.strip() for s in args.shapes.split(",") if s.strip()]
    for shape in shapes:
        if shape not in GENERATORS:
            parser.error(f"unknown shape {shape!r}; choose from {', '.join(SHAPES)}")
    if any(n < 1 for n in sizes):
        parser.error("sizes must be positive")

    started = time.monotonic()
    watch = LoadWatch()
    results: list[dict[str, Any]] = []
    for shape in shapes:
        gave_up: str | None = None
        for n in sizes:
            repeat = args.repeat if args.repeat is not None else (1 if n >= 100_000 else 3)
            if gave_up:
                result = {"shape": shape, "size": n, "repeat": repeat, "ok": False,
                          "error": f"skipped: {gave_up}"}
            else:
                print(f"... {shape} {n:,} interactions x{repeat}", file=sys.stderr, flush=True)
                result = run_in_subprocess(shape, n, repeat, args.timeout, args.gc_off)
                if result.get("timeout"):
                    gave_up = f"a smaller size timed out ({n:,})"
            results.append(result)

    table = render_table(results, args.clock)
    verdicts = render_verdicts(results, clock=args.clock)
    print(table)
    print()
    if args.gc_off:
        print("(cyclic GC disabled during the timed phases: --gc-off)")
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    if load:
        print(f"load average at the end: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} "
              f"on {os.cpu_count()} CPUs; the table shows {args.clock} seconds "
              "(JSON has both wall and CPU seconds)")
    print("check s = check_file with the projectability pass switched off; project-all s = cold "
          "projection onto every role;\ncheck_file s = as shipped (projects every role); "
          "pipeline s = parse + check_file + project-all after it (as a user runs it).")
    print("total = parse + check + project-all; growth = total / total at the previous size; "
          "nlogn ref = n2 log n2 / (n1 log n1) = 10 log(10n)/log(n) for 10x steps.")
    for line in verdicts:
        print(line)

    payload = {"meta": _fingerprint(), "gc_off": args.gc_off, "clock": args.clock, "sizes": sizes, "shapes": shapes,
               "results": results, "verdicts_10000": verdicts, "text_table": table,
               "table": table_rows(results, args.clock)}
    how = (f"parse, check and project generated protocols, each case in a fresh subprocess; {args.clock} seconds, "
           f"median of 3 (1 at 100,000 interactions) unless --repeat; {os.cpu_count()} CPUs")
    write_results(Path(args.json), payload, started, title="Checking and projection as protocols grow", how=how,
                  watch=watch)
    return 0 if all(r.get("ok") for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
