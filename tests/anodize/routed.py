"""Three network namespaces — robot, router, base — for tests of Zenoh across a router (test helpers).

Two veth pairs join them: robot <-> router (``10.81.T.1`` <-> ``10.81.T.2``) and router <-> base
(``10.82.T.1`` <-> ``10.82.T.2``). The router namespace forwards no IP packets (``ip_forward`` is 0,
and robot and base have no route to each other's subnet): whatever crosses from robot to base is routed
by the Zenoh router running in the router namespace, to which robot and base connect as clients.
nftables can drop a share of the packets on the robot's link, at random, and counts what it dropped.

Every :class:`Routed` has names of its own (pid and a counter), tracks the processes it starts and kills
them (by pid) and deletes its namespaces when closed, whatever happened. :func:`unavailable` says why a
machine cannot run these tests (they are skipped with that reason).

Run as a script, this module is a raw Zenoh publisher or subscriber (no anodize), so the harness is
proven on its own: ``python routed.py pub ENDPOINT KEY COUNT SIZE DONE`` and
``python routed.py sub ENDPOINT KEY COUNT OUT``; ``python routed.py replay ENDPOINT KEY PROBE OUT ACCEPTED`` puts
an old incarnation's samples again once a new one speaks (:func:`replay_old_writer`).
"""

from __future__ import annotations

import contextlib
import importlib.util
import itertools
import json
import os
import re
import signal
import subprocess
import sys
import time
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

PORT = 7447
_made = itertools.count()


def unavailable() -> str | None:
    """Why this machine cannot run a three-namespace test (root, namespaces, nftables, zenoh), or None."""
    from dds_hosts import namespaces_unavailable  # here: the raw scripts below need not import anodize

    reason = namespaces_unavailable(needs_nft=True)
    if reason is None and importlib.util.find_spec("zenoh") is None:
        reason = "the zenoh extra (eclipse-zenoh) is not installed"
    return reason


def sh(*argv: str) -> str:
    """Run a command (bounded); fail with its output if it fails."""
    done = subprocess.run(argv, capture_output=True, text=True, timeout=30)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed ({done.returncode}): {done.stdout}{done.stderr}")
    return done.stdout


# A Zenoh router, for as long as its process lives (SIGTERM or SIGINT end it). Used where the `anodize
# router` command (anodize/_tools/router.py) is not in this tree.
ROUTER_SCRIPT = """\
import signal, sys, threading, zenoh
config = zenoh.Config()
config.insert_json5("mode", '"router"')
config.insert_json5("listen/endpoints", '["' + sys.argv[1] + '"]')
config.insert_json5("scouting/multicast/enabled", "false")
stop = threading.Event()
for number in (signal.SIGTERM, signal.SIGINT):
    signal.signal(number, lambda *_: stop.set())
with zenoh.open(config):
    stop.wait()
"""


REACH_SCRIPT = """\
import socket, sys
for attempt in range(3):  # a lossy link may drop a SYN and its answer
    try:
        socket.create_connection((sys.argv[1], 9), timeout=2).close()
    except ConnectionRefusedError:
        sys.exit(0)
    except OSError:
        continue
    sys.exit(0)
sys.exit(1)
"""


def router_command(listen: str) -> list[str]:
    """The command that runs a Zenoh router listening on ``listen`` until SIGTERM: ``anodize router``
    where this tree has it, else :data:`ROUTER_SCRIPT`."""
    if importlib.util.find_spec("anodize._tools.router") is not None:
        return [sys.executable, "-m", "anodize._tools.cli", "router", "--listen", listen]
    return [sys.executable, "-c", ROUTER_SCRIPT, listen]


class Routed:
    """The three namespaces, their links, the router's process and whatever else runs in them."""

    def __init__(self) -> None:
        number = next(_made)
        tag = f"{os.getpid()}-{number}"
        self.robot, self.router, self.base = (f"anz-{name}-{tag}" for name in ("robot", "router", "base"))
        # Interfaces live in their namespaces only (never in the host's), so short fixed names do not collide.
        self.robot_dev, self.router_robot_dev, self.router_base_dev, self.base_dev = "r0", "r1", "b1", "b0"
        subnet = (os.getpid() + number) % 250
        self.robot_ip, self.router_robot_ip = f"10.81.{subnet}.1", f"10.81.{subnet}.2"
        self.router_base_ip, self.base_ip = f"10.82.{subnet}.1", f"10.82.{subnet}.2"
        self.processes: list[subprocess.Popen[str]] = []
        self.router_process: subprocess.Popen[str] | None = None
        self.created: list[str] = []

    # -- the namespaces and their links

    def create(self) -> None:
        for ns in (self.robot, self.router, self.base):
            sh("ip", "netns", "add", ns)
            self.created.append(ns)
            sh("ip", "-n", ns, "link", "set", "lo", "up")
        sh("ip", "netns", "exec", self.router, "sysctl", "-qw", "net.ipv4.ip_forward=0")
        robot_side = ((self.robot, self.robot_dev, self.robot_ip),
                      (self.router, self.router_robot_dev, self.router_robot_ip))
        base_side = (self.router, self.router_base_dev, self.router_base_ip), (self.base, self.base_dev, self.base_ip)
        for (a, dev_a, ip_a), (b, dev_b, ip_b) in (robot_side, base_side):
            sh("ip", "link", "add", dev_a, "netns", a, "type", "veth", "peer", "name", dev_b, "netns", b)
            for ns, dev, ip in ((a, dev_a, ip_a), (b, dev_b, ip_b)):
                sh("ip", "-n", ns, "addr", "add", f"{ip}/24", "dev", dev)
                sh("ip", "-n", ns, "link", "set", dev, "up")

    def endpoint(self, host: str) -> str:
        """The router's Zenoh endpoint as ``host`` ("robot" or "base") reaches it."""
        return f"tcp/{self.router_robot_ip if host == 'robot' else self.router_base_ip}:{PORT}"

    def namespace(self, host: str) -> str:
        return {"robot": self.robot, "router": self.router, "base": self.base}[host]

    def drop(self, percent: int) -> None:
        """Drop ``percent`` % of the packets crossing the robot's link, each way, at random (counted)."""
        for ns, dev in ((self.robot, self.robot_dev), (self.router, self.router_robot_dev)):
            for command in ("add table inet lossy",
                            "add chain inet lossy out { type filter hook output priority 0; }",
                            f'add rule inet lossy out oifname "{dev}" numgen random mod 100 < {percent} counter drop'):
                sh("ip", "netns", "exec", ns, "nft", command)

    def dropped(self) -> int:
        """Packets the loss rules dropped so far, both ways."""
        total = 0
        for ns in (self.robot, self.router):
            listing = subprocess.run(["ip", "netns", "exec", ns, "nft", "list", "table", "inet", "lossy"],
                                     capture_output=True, text=True, timeout=30).stdout
            total += sum(int(n) for n in re.findall(r"counter packets (\d+)", listing))
        return total

    def cut(self, host: str) -> None:
        """Take ``host``'s link to the router down: nothing crosses it any more."""
        sh("ip", "-n", self.namespace(host), "link", "set", self.link(host), "down")

    def mend(self, host: str) -> None:
        """Bring ``host``'s link up again."""
        sh("ip", "-n", self.namespace(host), "link", "set", self.link(host), "up")

    def link(self, host: str) -> str:
        """The device of ``host``'s ("robot" or "base") link to the router, in its namespace."""
        return self.robot_dev if host == "robot" else self.base_dev

    def can_reach(self, host: str, address: str) -> bool:
        """Whether a TCP connection from ``host`` to ``address`` (port 9, where nothing listens) is answered
        at all (accepted or refused) in one of three tries of 2 s: there is a route and the packets cross."""
        probe = ["ip", "netns", "exec", self.namespace(host), sys.executable, "-c", REACH_SCRIPT, address]
        return subprocess.run(probe, capture_output=True, timeout=30).returncode == 0

    # -- processes

    def start(self, host: str, argv: Sequence[str], env: dict[str, str] | None = None) -> subprocess.Popen[str]:
        """``argv`` in ``host``'s namespace (``ip netns exec`` execs it in place: same pid), output captured."""
        process = subprocess.Popen(["ip", "netns", "exec", self.namespace(host), *argv],
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                   env={**os.environ, **(env or {})})
        self.processes.append(process)
        return process

    def start_router(self, seconds: float = 30) -> subprocess.Popen[str]:
        """The Zenoh router in the router namespace, once it listens (bounded)."""
        process = self.start("router", router_command(f"tcp/0.0.0.0:{PORT}"))
        self.router_process = process
        deadline = time.monotonic() + seconds
        while not listening(process.pid, PORT):
            if process.poll() is not None or time.monotonic() > deadline:
                out = process.communicate()[0] if process.poll() is not None else "(still running)"
                raise AssertionError(f"the router did not listen on port {PORT} within {seconds} s:\n{out}")
            time.sleep(0.05)
        return process

    def kill_router(self) -> None:
        """SIGKILL the router's process (what it held is lost)."""
        assert self.router_process is not None, "no router was started"
        kill_tree(self.router_process.pid)
        self.router_process.wait(timeout=30)

    def end_processes(self, first: int = 0) -> None:
        """Kill the processes started here from the ``first``-th on (their trees, by pid), but the router."""
        for process in self.processes[first:]:
            if process is not self.router_process and process.poll() is None:
                kill_tree(process.pid)
            if process is not self.router_process:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    process.communicate(timeout=30)

    def close(self) -> None:
        """Kill every process started here (their trees, by pid) and whatever else runs in the namespaces,
        then delete the namespaces."""
        self.end_processes()
        if self.router_process is not None and self.router_process.poll() is None:
            kill_tree(self.router_process.pid)
        for ns in self.created:
            left = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True, timeout=30).stdout
            for pid in left.split():
                with contextlib.suppress(ProcessLookupError):
                    os.kill(int(pid), signal.SIGKILL)
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30)
        self.created.clear()


def children(pid: int) -> list[int]:
    """The direct children of ``pid`` (all its threads')."""
    found: list[int] = []
    with contextlib.suppress(FileNotFoundError, ProcessLookupError):
        for task in Path(f"/proc/{pid}/task").iterdir():
            with contextlib.suppress(FileNotFoundError, ProcessLookupError):
                found += [int(child) for child in (task / "children").read_text().split()]
    return found


def kill_tree(pid: int) -> None:
    """SIGKILL ``pid`` and its descendants (stopped first, so none is left to respawn or reparent)."""
    tree, todo = [], [pid]
    while todo:
        current = todo.pop()
        with contextlib.suppress(ProcessLookupError):
            os.kill(current, signal.SIGSTOP)
            tree.append(current)
            todo += children(current)
    for member in tree:
        with contextlib.suppress(ProcessLookupError):
            os.kill(member, signal.SIGKILL)


def listening(pid: int, port: int) -> bool:
    """Whether a TCP socket listens on ``port`` in the network namespace of process ``pid``."""
    try:
        table = Path(f"/proc/{pid}/net/tcp").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return False
    return any(fields[1].endswith(f":{port:04X}") and fields[3] == "0A"
               for fields in (line.split() for line in table.splitlines()[1:]))


def wait_for(path: Path, processes: list[subprocess.Popen[str]], seconds: float = 90) -> None:
    """Until the file ``path`` exists (bounded; a process that ends first fails the test)."""
    deadline = time.monotonic() + seconds
    while not path.exists():
        ended = [p for p in processes if p.poll() is not None]
        if ended or time.monotonic() > deadline:
            out = "".join(finish(p, 30) for p in ended)
            raise AssertionError(f"{path.name} did not appear within {seconds} s:\n{out}")
        time.sleep(0.05)


def finish(process: subprocess.Popen[str], seconds: float) -> str:
    """The output of ``process`` once it ends (bounded: a hang fails here, its process killed)."""
    try:
        out, _ = process.communicate(timeout=seconds)
    except subprocess.TimeoutExpired:
        kill_tree(process.pid)
        out, _ = process.communicate()
        raise AssertionError(f"still running after {seconds} s:\n{out}") from None
    return out


# -- raw Zenoh: a publisher and a subscriber of numbered, checksummed samples (the harness's own proof)

def _client(endpoint: str) -> object:
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def sample(number: int, size: int) -> bytes:
    """``size`` bytes (at least 12): the number (8 bytes), filler, a CRC-32 of what precedes it (4 bytes)."""
    body = number.to_bytes(8, "little") + bytes((number + i) % 251 for i in range(max(size, 12) - 12))
    return body + zlib.crc32(body).to_bytes(4, "little")


def publish(endpoint: str, key: str, count: int, size: int, done: Path) -> None:
    """Publish ``count`` samples reliably (congestion control Block) once a subscriber matches; stay
    connected until the file ``done`` exists (the subscriber made it), so nothing is cut off in flight."""
    import zenoh

    with _client(endpoint) as session:  # type: ignore[attr-defined]
        publisher = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK,
                                              reliability=zenoh.Reliability.RELIABLE)
        deadline = time.monotonic() + 60
        while not publisher.matching_status.matching:
            if time.monotonic() > deadline:
                raise SystemExit("no subscriber matched within 60 s")
            time.sleep(0.05)
        filler = sample(0, size)[8:-4]
        for number in range(count):
            body = number.to_bytes(8, "little") + filler
            publisher.put(body + zlib.crc32(body).to_bytes(4, "little"))
        deadline = time.monotonic() + 600
        while not done.exists() and time.monotonic() < deadline:
            time.sleep(0.05)


def subscribe(endpoint: str, key: str, count: int, out: Path) -> None:
    """Receive samples until ``count`` have come (or 600 s); write what came to ``out`` (JSON: received,
    in_order, damaged, first_out_of_order) and make ``out`` + ".done"."""
    import queue

    arrived: queue.Queue[bytes] = queue.Queue()
    with _client(endpoint) as session:  # type: ignore[attr-defined]
        session.declare_subscriber(key, lambda s: arrived.put(s.payload.to_bytes()))
        (out.parent / (out.name + ".ready")).touch()
        received = in_order = damaged = 0
        first_out_of_order: int | None = None
        deadline = time.monotonic() + 600
        while received < count and time.monotonic() < deadline:
            try:
                payload = arrived.get(timeout=1)
            except queue.Empty:
                continue
            number = int.from_bytes(payload[:8], "little")
            if zlib.crc32(payload[:-4]) != int.from_bytes(payload[-4:], "little"):
                damaged += 1
            if number == in_order:
                in_order += 1
            elif first_out_of_order is None:
                first_out_of_order = number
            received += 1
    out.write_text(json.dumps({"received": received, "in_order": in_order, "damaged": damaged,
                               "first_out_of_order": first_out_of_order}))
    (out.parent / (out.name + ".done")).touch()


def replay_old_writer(endpoint: str, key: str, probe: str, out: Path, accepted: Path) -> None:
    """Record the samples (payload and attachment) that anodize writers of incarnation 0 put on ``key``
    (a key expression, wildcards allowed); once a writer of a later incarnation speaks there and the file
    ``accepted`` exists (the new reader took that writer's samples: it rejects others from then on, where
    before it drops them unreported), put the recorded ones again on their keys, as they were, and write
    to ``out`` (JSON) how many and the claims (old and new). A writer's claim comes on its sample 0 only
    (:mod:`anodize._transport.zenoh.identity`): the replayer must be listening before a writer starts.

    Files beside ``out``, for a test to wait on (each bounded there): ``.ready`` once the router routes
    ``key`` to this subscriber (proven: samples put on ``probe``, a key ``key`` matches, by a second
    session, came back through the router); ``.held``, the count of distinct numbers recorded from
    incarnation 0's writers so far (the old incarnation may end once it holds what it sent); ``.seen``,
    the claims heard so far (for a message should the test wait in vain). ``out`` is written once what
    was put is past the router (a marker put after it came back through the router to the second
    session): a sender that ends after that cannot overtake it. Gives up after 300 s; any failure ends
    the process (its sessions closed, bounded), with a traceback."""
    import queue
    import threading

    import zenoh

    from anodize._transport.zenoh.identity import claim_of, parse_attachment

    arrived: queue.Queue[tuple[str, bytes, bytes]] = queue.Queue()
    probed, marked = threading.Event(), threading.Event()
    back = f"{probe}/back"  # the marker's key: not matched by ``key``, only by the second session

    def on_sample(s: Any) -> None:
        if str(s.key_expr) == probe:
            probed.set()
        else:
            attachment = s.attachment.to_bytes() if s.attachment is not None else b""
            arrived.put((str(s.key_expr), s.payload.to_bytes(), attachment))

    session: Any = _client(endpoint)
    second: Any = _client(endpoint)
    try:
        subscriber = session.declare_subscriber(key, on_sample)
        second.declare_subscriber(back, lambda _: marked.set())
        _until(probed, lambda: second.put(probe, b""), f"the probe on {probe} did not come back")
        (out.parent / (out.name + ".ready")).touch()
        claims: dict[bytes, str] = {}  # writer id -> its claim (from its sample 0)
        recorded: list[tuple[int, str, bytes, bytes]] = []  # number, key, payload, attachment
        new_claim: str | None = None
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and not (new_claim is not None and accepted.exists()):
            try:
                sample_key, payload, attachment = arrived.get(timeout=0.05)
            except queue.Empty:
                continue
            parsed = parse_attachment(attachment)
            if parsed is None:
                continue
            number, writer = parsed
            if writer not in claims and claim_of(attachment):
                claims[writer] = claim_of(attachment)
                _write(out.parent / (out.name + ".seen"), json.dumps(sorted(claims.values())))
            fields = claims.get(writer, "").split(";")  # anodize1;<run>;<group>;<incarnation>;<host>;<pid>;<id>
            if len(fields) < 4:
                continue  # a writer whose sample 0 we did not hear: its incarnation is unknown
            if fields[3] == "0":
                recorded.append((number, sample_key, payload, attachment))
                _write(out.parent / (out.name + ".held"), str(len({n for n, *_ in recorded})))
            elif new_claim is None:
                new_claim = claims[writer]
        if new_claim is None or not accepted.exists():
            raise SystemExit(f"no new writer accepted within 300 s; heard {sorted(claims.values())}")
        recorded.sort(key=lambda r: r[0])  # sample 0 (with the old writer's claim) first: the report names it
        for _, sample_key, payload, attachment in recorded:
            session.put(sample_key, payload, attachment=attachment, congestion_control=zenoh.CongestionControl.BLOCK)
        # Puts of one session cross the router in order: the marker back means the replay has crossed.
        _until(marked, lambda: session.put(back, b"", congestion_control=zenoh.CongestionControl.BLOCK),
               "the marker after the replay did not come back")
        old = sorted({claims[parse_attachment(a)[1]] for *_, a in recorded})  # type: ignore[index]
        _write(out, json.dumps({"replayed": len(recorded), "claims": old, "new_claim": new_claim}))
        subscriber.undeclare()
    finally:
        for each in (session, second):
            closing = threading.Thread(target=each.close, daemon=True)
            closing.start()
            closing.join(5)  # bounded: the test has what it needs


def _until(event: Any, act: Any, failure: str, seconds: float = 60) -> None:
    """``act()`` every 50 ms until ``event`` is set (bounded: SystemExit with ``failure``)."""
    deadline = time.monotonic() + seconds
    while not event.is_set():
        if time.monotonic() > deadline:
            raise SystemExit(f"{failure} within {seconds} s")
        act()
        event.wait(0.05)


def _write(path: Path, text: str) -> None:
    """``text`` to ``path`` at once (a reader never sees it half written)."""
    path.with_name(path.name + ".tmp").write_text(text)
    path.with_name(path.name + ".tmp").replace(path)


if __name__ == "__main__":
    if sys.argv[1] == "pub":
        publish(sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5]), Path(sys.argv[6]))
    elif sys.argv[1] == "sub":
        subscribe(sys.argv[2], sys.argv[3], int(sys.argv[4]), Path(sys.argv[5]))
    else:
        replay_old_writer(sys.argv[2], sys.argv[3], sys.argv[4], Path(sys.argv[5]), Path(sys.argv[6]))
