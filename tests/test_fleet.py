"""The fleet of docs/guide/fleet.md, run from the page's own commands in four network namespaces.

The page's ``commands`` blocks are, in order: the namespaces and links, the router, the base
station, robot 1, robot 2, the clean-up. They run here as the page says, each in its own
shell (a terminal), from a folder laid out as a checkout (``examples/``, ``.venv/bin/anodize``
this checkout's); only the namespaces' names are made this test's own (``fleet-router`` becomes
``fl<pid>-router``), so that a reader's namespaces and a parallel run are left alone. What
they print is checked against the page's transcripts, and what they report against the
example: both robots ran to their stop, the base station monitored both, no violation. The
namespaces are removed by the page's clean-up even when the test fails.
"""

from __future__ import annotations

import json
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import tomllib
from pathlib import Path
from typing import Any, TextIO

import pytest
from test_docs_blocks import Checked, read_page
from test_first_system import shown_matches

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "guide" / "fleet.md"
FLEET = REPO / "examples" / "fleet"
NAMES = re.compile(r"\bfleet-(router|robot1|robot2|base)\b")
LEGS = {"r1": 12, "r2": 8}  # 100 % less 6 % (robot 1) or 9 % (robot 2) a leg: below 30 % after these


def _page() -> tuple[list[Checked], list[Checked]]:
    found, problems = read_page(PAGE.read_text(encoding="utf-8"), "docs/guide/fleet.md")
    assert problems == []
    commands = [c for c in found if c.verb == "commands"]
    transcripts = [c for c in found if c.verb == "transcript"]
    assert len(commands) == 6, "the page's commands: namespaces, router, base, robot 1, robot 2, clean-up"
    return commands, transcripts


def _one_line(code: str) -> str:
    return " ".join(code.replace("\\\n", " ").split())


def test_the_page_shows_the_whole_fleet() -> None:
    (setup, router, base, robot1, robot2, cleanup), transcripts = _page()
    assert "ip netns add" in setup.code and "openssl rand" in setup.code
    assert "anodize router --listen" in router.code
    for run in ("r1", "r2"):
        assert f"robot{run[1]}.toml --host base" in base.code and f"{run}.token" in base.code
    assert "robot1.toml --host robot1" in robot1.code and "robot2.toml --host robot2" in robot2.code
    assert "ip netns del" in cleanup.code and "ip netns pids" in cleanup.code
    # each transcript is the output of a command the page gives
    given = {_one_line(line) for c in (router, base, robot1) for line in c.code.replace("\\\n", " ").splitlines()}
    for transcript in transcripts:
        command = _one_line(transcript.code.splitlines()[0].removeprefix("$ ").removesuffix(" &"))
        assert command in {line.removesuffix(" &") for line in given}, command
    # the files the page shows are the example's
    blocks = read_page(PAGE.read_text(encoding="utf-8"), "p")[0]
    proto = next(c for c in blocks if c.kind == "proto")
    assert proto.code == (FLEET / "fleet.proto").read_text(encoding="utf-8")
    toml = next(c for c in blocks if c.kind == "toml")
    assert tomllib.loads(toml.code) == tomllib.loads((FLEET / "robot1.toml").read_text(encoding="utf-8"))


class Output:
    """A process's output as it comes, read by a thread (a wait for a line is bounded)."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        assert process.stdout is not None
        stream = process.stdout
        self.lines: queue.SimpleQueue[str] = queue.SimpleQueue()
        self.reader = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self.reader.start()

    def _read(self, stream: TextIO) -> None:
        for line in stream:
            self.lines.put(line)

    def next(self, seconds: float) -> str:
        try:
            return self.lines.get(timeout=seconds)
        except queue.Empty:
            raise AssertionError(f"nothing printed for {seconds} s") from None

    def rest(self, seconds: float) -> str:
        self.reader.join(seconds)
        assert not self.reader.is_alive(), f"output still open after {seconds} s"
        return "".join(self.lines.get() for _ in range(self.lines.qsize()))


def _checkout(folder: Path) -> dict[str, str]:
    """``folder`` laid out as the page expects a checkout; the environment its commands run in."""
    (folder / "examples").symlink_to(REPO / "examples")
    tools = folder / ".venv" / "bin"
    tools.mkdir(parents=True)
    (tools / "anodize").write_text(f'#!/bin/sh\nexec {sys.executable} -m anodize._tools.cli "$@"\n', encoding="utf-8")
    (tools / "anodize").chmod(0o755)
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "tinman" / "src")])}


def _ours(prefix: str) -> list[str]:
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, timeout=30).stdout
    return [line.split()[0] for line in listed.splitlines() if line.startswith(f"{prefix}-")]


def _report(path: Path) -> dict[str, Any]:
    report: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return report


@pytest.mark.slow
def test_the_fleet_runs_from_the_page_s_commands(tmp_path: Path) -> None:
    from dds_hosts import namespaces_unavailable

    reason = namespaces_unavailable()
    if reason is not None:
        pytest.skip(reason)
    pytest.importorskip("zenoh", reason="the zenoh extra (eclipse-zenoh) is not installed")
    commands, transcripts = _page()
    prefix = f"fl{os.getpid()}"
    setup, router, base, robot1, robot2, cleanup = (NAMES.sub(rf"{prefix}-\1", c.code) for c in commands)
    checkout = tmp_path / "checkout"
    checkout.mkdir()
    env = _checkout(checkout)

    def start(code: str) -> subprocess.Popen[str]:
        return subprocess.Popen(["bash", "-c", code], cwd=checkout, env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, start_new_session=True)

    started: list[subprocess.Popen[str]] = []
    printed: dict[str, str] = {}
    try:
        done = subprocess.run(["bash", "-e", "-c", setup], cwd=checkout, env=env, capture_output=True, text=True,
                              timeout=60)
        assert done.returncode == 0, done.stderr
        for host, other in (("robot1", "10.78.3.2"), ("robot2", "10.78.1.2"), ("base", "10.78.2.2")):
            route = subprocess.run(["ip", "-n", f"{prefix}-{host}", "route", "get", other], capture_output=True,
                                   text=True, timeout=30)
            assert route.returncode != 0, f"{host} has a route to {other}: {route.stdout}"  # the router alone
        started.append(routing := start(router))
        routed = Output(routing)
        first = routed.next(60)
        assert re.fullmatch(r"router [0-9a-f]+: listening on tcp/10\.78\.1\.1:7447, tcp/10\.78\.2\.1:7447, "
                            r"tcp/10\.78\.3\.1:7447\n", first), first
        hosts = {"base": start(base), "robot1": start(robot1), "robot2": start(robot2)}
        started += hosts.values()
        outputs = {name: Output(process) for name, process in hosts.items()}
        for name, process in hosts.items():
            process.wait(timeout=180)
            printed[name] = outputs[name].rest(30)
            assert process.returncode == 0, f"{name} exited {process.returncode}:\n{printed[name]}"
        os.killpg(routing.pid, signal.SIGINT)  # Ctrl-C in the router's terminal
        routing.wait(timeout=30)
        printed["router"] = first + routed.rest(30)
        assert routing.returncode == 0, printed["router"]
    finally:
        for process in started:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait(timeout=30)
        cleaned = subprocess.run(["bash", "-c", cleanup], cwd=checkout, capture_output=True, text=True, timeout=60)
        left = _ours(prefix)
        for namespace in left:  # the page's clean-up failed: leave nothing behind all the same
            subprocess.run(["ip", "netns", "del", namespace], capture_output=True, timeout=30)
    assert cleaned.returncode == 0 and left == [], f"the page's clean-up left {left}:\n{cleaned.stderr}"

    # What each printed, as the page shows it.
    shown = {t.code.splitlines()[0]: "".join(f"{line}\n" for line in t.code.splitlines()[1:]) for t in transcripts}
    robot_shown = next(text for command, text in shown.items() if "--host robot1" in command)
    assert shown_matches(robot_shown, printed["robot1"]), printed["robot1"]
    as_robot2 = (robot_shown.replace("r1", "r2").replace("robot1", "robot2").replace("12", "8")
                 .replace("10.78.1.1", "10.78.2.1"))  # the page: "the same with r2, leg 8, robot2 and 10.78.2.1"
    assert shown_matches(as_robot2, printed["robot2"]), printed["robot2"]
    for run, legs in LEGS.items():
        assert f"[Monitor]: battery 28% after leg {legs}, below 30%: stop" in printed["base"], printed["base"]
        assert f"wrote out/fleet/base-{run}.json" in printed["base"], printed["base"]
    assert printed["base"].count("protocol Patrol: ok in ") == 2, printed["base"]
    router_shown = next(text for command, text in shown.items() if "anodize router" in command)
    assert router_shown.splitlines()[0].startswith("router ") and printed["router"].endswith(
        "router: stopped (SIGINT)\n"), printed["router"]
    # clients from each host's link, two from the base station's (a run each); a client that
    # reconnects is counted once
    connected = set(re.findall(r"router: client ([0-9a-f]{8}) connected from tcp/(10\.78\.\d)\.2:\d+\n",
                               printed["router"]))
    links = [link for _, link in connected]
    assert set(links) == {"10.78.1", "10.78.2", "10.78.3"} and links.count("10.78.3") >= 2, printed["router"]

    # What each reported: both robots ran to their stop, the base monitored both, no violation.
    for run, legs in LEGS.items():
        for host, group in ((f"robot{run[1]}", "robot"), (f"base-{run}", "monitor")):
            report = _report(checkout / "out" / "fleet" / f"{host}.json")
            assert (report["ok"], report["outcome"], report["transport"]) == (True, "ok", "zenoh"), report
            assert list(report["groups"]) == [group] and report["groups"][group]["status"] == "done", report
            assert report["groups"][group]["messages"] == report["groups"][group]["received"] == legs, report
            assert all(role["error"] is None and role["status"] == "done" for role in report["roles"].values())
