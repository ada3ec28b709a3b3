"""``anodize ps|status|channels|echo|hz``: ask the systems running on this host what they do.

Each command connects to a run's socket (:mod:`anodize._live.runs`; the server is
:mod:`anodize._live.introspection`) and turns its JSON answers into lines, which the CLI
prints: ``ps`` as ``ros2 node list`` with more columns, ``echo`` as ``ros2 topic echo``
(YAML-like, ``---`` between messages), ``hz`` as ``ros2 topic hz``.
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import json
import socket
import statistics
from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from .._live.runs import pid_of, run_dir, running, same_user, socket_path
from ..errors import AnodizeError

__all__ = ["add_commands", "ps_lines", "status_lines", "channels_lines", "echo_lines", "hz_lines", "ask",
           "find_run", "message_lines", "open_introspection", "system_name", "ANSWER_WITHIN"]

ANSWER_WITHIN = 15.0  # seconds a run has to answer (a beat comes every second while watching; a busy host delays it)


def add_commands(commands: Any, run: Callable[[argparse.Namespace], int]) -> None:
    """Register ps, status, channels, echo and hz on the CLI's subparsers; each sets ``lines``."""
    ps = commands.add_parser("ps", help="list the systems running on this host (like 'ros2 node list')")
    ps.set_defaults(run=run, lines=ps_lines)
    for name, help_, lines in (("status", "a running system's groups, roles, states, rates and high-water marks",
                                status_lines),
                               ("channels", "a running system's channels: topic, type, messages so far, rate",
                                channels_lines)):
        parser = commands.add_parser(name, help=help_)
        _add_run_argument(parser)
        parser.set_defaults(run=run, lines=lines)
    echo = commands.add_parser("echo", help="print a channel's messages as they pass (like 'ros2 topic echo')")
    _add_run_argument(echo, channel=True)
    echo.add_argument("-n", "--count", type=int, metavar="N", help="stop after N messages")
    echo.set_defaults(run=run, lines=echo_lines)
    hz = commands.add_parser("hz", help="a channel's rate (like 'ros2 topic hz')")
    _add_run_argument(hz, channel=True)
    hz.add_argument("--window", type=int, default=10000, metavar="N",
                    help="the periods of the last N messages make the statistics (default 10000)")
    hz.add_argument("--count", type=int, metavar="N", help="stop after N reports (one a second)")
    hz.set_defaults(run=run, lines=hz_lines)


def _add_run_argument(parser: argparse.ArgumentParser, channel: bool = False) -> None:
    if channel:
        parser.add_argument("target", nargs="+", metavar="[RUN] CHANNEL",
                            help="the run (its id or pid; omitted when one system runs) and the channel: "
                                 "Sender->Receiver:label, Sender->Receiver, or its topic")
    else:
        parser.add_argument("target", nargs="?", metavar="RUN",
                            help="the run: its id or pid (see 'anodize ps'); omitted when one system runs")


# ---- finding and asking a run --------------------------------------------------------------
def find_run(given: str | None) -> str:
    """The run id ``given`` names (an id or a pid), or the only running one when ``given`` is None.

    Raises:
        AnodizeError: no such run, or none (or several) when ``given`` is None.
    """
    runs = running()
    if given is None:
        if len(runs) == 1:
            return runs[0]
        if not runs:
            raise AnodizeError(f"no system is running on this host (none has a socket in {run_dir()})")
        raise AnodizeError(f"{len(runs)} systems are running: name one ({', '.join(runs)}; see 'anodize ps')")
    for run in runs:
        if given == run or given == str(pid_of(run)):
            return run
    raise AnodizeError(f"no running system {given!r}; expected a run id or pid of 'anodize ps' "
                       f"({', '.join(runs) or 'none is running'})")


def _connect(run: str) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(ANSWER_WITHIN)
    try:
        sock.connect(str(socket_path(run)))
        if not same_user(sock):  # the directory is ours; still, answer only our own user's server
            raise AnodizeError(f"run {run}: its socket is served by another user: refused")
    except BaseException:
        sock.close()
        raise
    return sock


def _answers(sock: socket.socket) -> Iterator[dict[str, Any]]:
    """The run's answer lines, until it closes the connection."""
    buffer = b""
    while True:
        try:
            chunk = sock.recv(1 << 16)
        except TimeoutError:
            raise AnodizeError(f"the run did not answer within {ANSWER_WITHIN:g} s") from None
        if not chunk:
            return
        buffer += chunk
        *lines, buffer = buffer.split(b"\n")
        for line in lines:
            answer = json.loads(line)
            if "error" in answer:
                raise AnodizeError(str(answer["error"]))
            yield answer


def ask(run: str, request: dict[str, Any]) -> Iterator[dict[str, Any]]:
    """Send ``request`` to run ``run``; its answers (one, or a stream for echo and hz)."""
    with _connect(run) as sock:
        sock.sendall((json.dumps(request) + "\n").encode())
        yield from _answers(sock)


def _one(run: str, op: str) -> dict[str, Any]:
    for answer in ask(run, {"op": op}):
        return answer
    raise AnodizeError(f"run {run} ended before it answered")


# ---- ps, status, channels ------------------------------------------------------------------
def ps_lines(args: argparse.Namespace) -> Iterator[str]:
    """One line per running system (nothing when none runs)."""
    rows = []
    for run in running():
        try:
            info = _one(run, "info")
        except (OSError, AnodizeError):  # ending as we asked, or not ours: not listed
            continue
        rows.append([info["run"], str(info["pid"]), info["system"], _since(info["started"]),
                     info["transport"] or "-", info["state"], ",".join(info["groups"]) or "-"])
    if rows:
        yield from _table(["RUN", "PID", "SYSTEM", "STARTED", "TRANSPORT", "STATE", "GROUPS"], rows)


def status_lines(args: argparse.Namespace) -> Iterator[str]:
    """A run's groups, each with its roles and channels."""
    answer = _one(find_run(args.target), "status")
    info = answer["run"]
    yield (f"run {info['run']} (pid {info['pid']}): {info['source'] or info['system']}, protocol "
           f"{info['protocol'] or '-'}, transport {info['transport'] or '-'}, {info['state']} since "
           f"{_since(info['started'])}")
    for name, group in sorted(answer["groups"].items()):
        parts = [f"group {name}", group["state"]]
        if group["pid"]:
            parts.append(f"pid {group['pid']}")
        if group["memory"] is not None:
            parts.append(f"{max(0, group['memory']) / 2**20:.1f} MiB")
        parts.append(f"{group['messages']} sent, {group['received']} received")
        if group["rate_hz"] is not None:
            parts.append(f"{group['rate_hz']:.1f} msg/s")
        if group["restarts"]:
            parts.append(f"{group['restarts']} restarts")
        if group["scheduling"]:
            parts.append(group["scheduling"])
        yield "  ".join(parts)
        for role, state in sorted(group["roles"].items()):
            yield f"  role {role}: {state}"
        for channel, sent in sorted(group["sent"].items()):
            high = group["high_water"].get(channel)
            yield f"  channel {channel}: {sent} sent" + (f", high-water mark {high}" if high is not None else "")
        if group["note"]:
            yield f"  note: {group['note']}"


def channels_lines(args: argparse.Namespace) -> Iterator[str]:
    """A run's channels (every label of each), with topic, type, messages so far and rate."""
    answer = _one(find_run(args.target), "channels")
    rows = [[x["channel"], x["topic"] or "-", x["type"] or "-", str(x["messages"]),
             "-" if x["rate_hz"] is None else f"{x['rate_hz']:.1f}"] for x in answer["channels"]]
    yield from _table(["CHANNEL", "TOPIC", "TYPE", "MESSAGES", "RATE/s"], rows)


# ---- echo and hz ---------------------------------------------------------------------------
def _run_and_channel(target: list[str]) -> tuple[str, str]:
    if len(target) > 2:
        raise AnodizeError(f"expected [RUN] CHANNEL, got {len(target)} arguments: {' '.join(target)}")
    return find_run(target[0] if len(target) == 2 else None), target[-1]


def echo_lines(args: argparse.Namespace) -> Iterator[str]:
    """Each message of the channel as it passes, ``---`` after each; drops said as they happen."""
    if args.count is not None and args.count < 1:
        raise AnodizeError(f"-n {args.count}: expected a number of messages >= 1")
    run, channel = _run_and_channel(args.target)
    shown = dropped = 0
    for answer in ask(run, {"op": "echo", "channel": channel}):
        if "message" in answer or "error" in answer:
            yield f"# {answer['channel']}"
            yield from message_lines(answer.get("message"))
            yield "---"
            shown += 1
            if args.count is not None and shown >= args.count:
                return
        elif "beat" in answer:
            if answer["dropped"] > dropped:
                yield f"# {answer['dropped']} dropped (this reader is slower than the channel: the newest are shown)"
                dropped = answer["dropped"]
            if answer["ended"]:
                break
    if args.count is not None:
        raise AnodizeError(f"run {run} ended after {shown} of {args.count} messages")


def message_lines(value: Any, indent: str = "") -> Iterator[str]:
    """A summarized message (:func:`anodize._live.summary.summarize`) as YAML-like lines."""
    if isinstance(value, dict):
        for key, item in value.items():
            if isinstance(item, dict | list) and item:
                yield f"{indent}{key}:"
                yield from message_lines(item, indent + "  ")
            else:
                yield f"{indent}{key}: {_scalar(item)}"
    elif isinstance(value, list):
        for item in value:
            if isinstance(item, dict | list) and item:
                first, *rest = list(message_lines(item, indent + "  "))
                yield f"{indent}- {first.lstrip()}"
                yield from rest
            else:
                yield f"{indent}- {_scalar(item)}"
    else:
        yield f"{indent}{_scalar(value)}"


def _scalar(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "{}"
    if isinstance(value, list):
        return "[]"
    if isinstance(value, str):
        return value if value and value.strip() == value and value[0] not in "-[{'\"#" else json.dumps(value)
    return str(value)


def hz_lines(args: argparse.Namespace) -> Iterator[str]:
    """Each second, the channel's average rate and its periods' min, max and deviation over the window."""
    if args.window < 2:
        raise AnodizeError(f"--window {args.window}: expected a number of messages >= 2")
    if args.count is not None and args.count < 1:
        raise AnodizeError(f"--count {args.count}: expected a number of reports >= 1")
    run, channel = _run_and_channel(args.target)
    stamps: deque[int] = deque(maxlen=args.window)
    reports = dropped = 0
    fresh = False
    for answer in ask(run, {"op": "hz", "channel": channel}):
        if "stamp" in answer:
            stamps.append(int(answer["stamp"]))
            fresh = True
        elif "beat" in answer:
            if answer["ended"]:
                return
            if not fresh:
                yield "no new messages"
                continue
            fresh = False
            yield from _rate(sorted(stamps))
            if answer["dropped"] > dropped:
                dropped = answer["dropped"]
                yield f"\t{dropped} dropped (the rate is of the messages seen)"
            reports += 1
            if args.count is not None and reports >= args.count:
                return


def _rate(stamps: list[int]) -> Iterator[str]:
    periods = [(b - a) / 1e9 for a, b in itertools.pairwise(stamps)]
    if not periods:
        yield "no new messages"
        return
    mean = statistics.fmean(periods)
    std = statistics.pstdev(periods)
    yield f"average rate: {1.0 / mean:.3f}" if mean > 0 else "average rate: inf"
    yield f"\tmin: {min(periods):.3f}s max: {max(periods):.3f}s std dev: {std:.5f}s window: {len(stamps)}"


# ---- formatting ----------------------------------------------------------------------------
def _since(started: str) -> str:
    try:
        then = datetime.datetime.fromisoformat(started)
    except ValueError:
        return started
    seconds = max(0.0, (datetime.datetime.now(datetime.UTC) - then).total_seconds())
    ago = f"{seconds:.0f}s" if seconds < 120 else f"{seconds / 60:.0f}m" if seconds < 7200 else \
        f"{seconds / 3600:.0f}h"
    return f"{then.strftime('%H:%M:%S')}Z ({ago} ago)"


def _table(header: list[str], rows: list[list[str]]) -> Iterator[str]:
    widths = [max(len(row[i]) for row in [header, *rows]) for i in range(len(header))]
    for row in [header, *rows]:
        yield "  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)).rstrip()


def open_introspection(name: str, source: str) -> tuple[Any, str]:
    """The run's introspection server, or None and why it could not be opened (the run goes on)."""
    from .._live.introspection import Introspection

    try:
        return Introspection(name, source), ""
    except (AnodizeError, OSError) as error:
        return None, str(error)


def system_name(file: str) -> str:
    """A run's name for ``anodize ps``: the system file's stem, or the named system."""
    return Path(file).stem if file.endswith(".toml") else file
