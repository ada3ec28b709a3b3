"""Running the halves of a two-host DDS system as separate `anodize run --host` processes (test helpers)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import dds_roles

HERE = Path(__file__).resolve().parent


def namespaces_unavailable(needs_nft: bool = False) -> str | None:
    """Why this machine cannot give a test network namespaces (and, ``needs_nft``, nftables to
    drop packets in them), or None: the reason a namespace test is skipped."""
    if os.geteuid() != 0:
        return "creating network namespaces needs root"
    if shutil.which("ip") is None or (needs_nft and shutil.which("nft") is None):
        return ("no 'ip' (iproute2) or 'nft' (nftables) command (scripts/bootstrap installs them when run as root)"
                if needs_nft else "no 'ip' command (iproute2)")
    probe = f"anz-probe-{os.getpid()}"
    if subprocess.run(["ip", "netns", "add", probe], capture_output=True).returncode != 0:
        return "this machine refuses 'ip netns add' (no CAP_SYS_ADMIN in a container?)"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


def domain() -> int:
    """A domain of this test process: runs of parallel test sessions do not meet."""
    return 1 + os.getpid() % 200


SYSTEM_FILE = """\
protocol = "stream.proto"
global = "Stream"
transport = "dds"
domain = {domain}
run_id = "{run_id}"
timeout = 120
pythonpath = ["{here}"]

[groups.producing]
host = "A"
roles = {{ P = "dds_roles:{producer}" }}

[groups.consuming]
host = "B"
roles = {{ C = "dds_roles:{consumer}" }}
"""


def write_system(directory: Path, producer: str, run_id: str, consumer: str = "consumer") -> Path:
    (directory / "stream.proto").write_text(dds_roles.STREAM + "\n")
    path = directory / "system.toml"
    path.write_text(SYSTEM_FILE.format(domain=domain(), run_id=run_id, here=HERE, producer=producer,
                                       consumer=consumer))
    return path


def start_host(system: Path, host: str, report: Path, env: dict[str, str] | None = None,
               namespace: str | None = None) -> subprocess.Popen[str]:
    """``anodize run SYSTEM --host HOST`` (in network namespace ``namespace``, if given)."""
    prefix = ["ip", "netns", "exec", namespace] if namespace else []
    return subprocess.Popen([*prefix, sys.executable, "-m", "anodize._tools.cli", "run", "--quiet", str(system),
                             "--host", host, "--wait", "30", "--json", str(report)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, **(env or {})})


def wait_for_group(process: subprocess.Popen[str], seconds: float) -> int:
    """The pid of the host's one group process (a spawned child; not multiprocessing's helpers).

    ``process`` may be ``ip netns exec``, which execs the command in place (same pid).
    """
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        for pid in Path(f"/proc/{process.pid}/task/{process.pid}/children").read_text().split():
            if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes():
                return int(pid)
        time.sleep(0.05)
    raise AssertionError("the host's group never started")


def wait_until_flowing(marker: Path, process: subprocess.Popen[str], seconds: float = 90) -> None:
    """Until :func:`dds_roles.slow_producer` has sent its first message (bounded)."""
    deadline = time.monotonic() + seconds
    while not marker.exists():
        if process.poll() is not None or time.monotonic() > deadline:
            out = process.communicate()[0] if process.poll() is not None else "(still running)"
            raise AssertionError(f"the stream never started within {seconds} s:\n{out}")
        time.sleep(0.05)


def finish(process: subprocess.Popen[str], seconds: float) -> str:
    try:
        out, _ = process.communicate(timeout=seconds)
    except subprocess.TimeoutExpired:
        process.kill()
        out, _ = process.communicate()
        raise AssertionError(f"still running after {seconds} s:\n{out}") from None
    return out


def run_hosts(system: Path, directory: Path, env: dict[str, str] | None = None) -> dict[str, Any]:
    """``anodize run --host A`` and ``--host B`` at once; their JSON reports (bounded waits)."""
    hosts = {host: start_host(system, host, directory / f"{host}.json", env) for host in ("A", "B")}
    outputs = {}
    try:
        for host, process in hosts.items():
            outputs[host] = finish(process, 90)  # bounded: a host that hangs fails here
    finally:
        for process in hosts.values():
            process.kill()
            process.wait()
    reports = {}
    for host in hosts:
        path = directory / f"{host}.json"
        assert path.exists(), outputs[host]
        reports[host] = json.loads(path.read_text())
    return reports




def sh(*argv: str) -> None:
    subprocess.run(argv, check=True, capture_output=True, timeout=30)


class Hosts:
    """Namespaces ``a`` and ``b`` joined by a veth pair 10.79.x.1 <-> 10.79.x.2."""

    def __init__(self) -> None:
        tag = os.getpid() % 250
        self.a, self.b = f"anz-a-{os.getpid()}", f"anz-b-{os.getpid()}"
        self.veth_a, self.veth_b = f"anza{tag}", f"anzb{tag}"
        self.subnet = f"10.79.{tag}"

    def create(self) -> None:
        sh("ip", "netns", "add", self.a)
        sh("ip", "netns", "add", self.b)
        sh("ip", "link", "add", self.veth_a, "netns", self.a, "type", "veth", "peer", "name", self.veth_b,
           "netns", self.b)
        for ns, dev, host in ((self.a, self.veth_a, 1), (self.b, self.veth_b, 2)):
            sh("ip", "-n", ns, "addr", "add", f"{self.subnet}.{host}/30", "dev", dev)
            sh("ip", "-n", ns, "link", "set", "lo", "up")
            sh("ip", "-n", ns, "link", "set", dev, "up", "multicast", "on")  # Cyclone discovers by multicast

    def drop(self, percent: int) -> None:
        """Drop ``percent`` % of the packets leaving each namespace, at random."""
        for ns, dev in ((self.a, self.veth_a), (self.b, self.veth_b)):
            for command in ("add table inet lossy",
                            "add chain inet lossy out { type filter hook output priority 0; }",
                            f'add rule inet lossy out oifname "{dev}" numgen random mod 100 < {percent} counter drop'):
                sh("ip", "netns", "exec", ns, "nft", command)

    def dropped(self) -> int:
        """Packets the loss rules dropped so far, in both namespaces."""
        total = 0
        for ns in (self.a, self.b):
            listing = subprocess.run(["ip", "netns", "exec", ns, "nft", "list", "table", "inet", "lossy"],
                                     capture_output=True, text=True, timeout=30).stdout
            total += sum(int(n) for n in re.findall(r"counter packets (\d+)", listing))
        return total

    def cut(self) -> None:
        """Take the link down: nothing crosses any more."""
        sh("ip", "-n", self.a, "link", "set", self.veth_a, "down")

    def restore(self) -> None:
        """Bring the link up again (the partition heals)."""
        sh("ip", "-n", self.a, "link", "set", self.veth_a, "up", "multicast", "on")

    def delete(self) -> None:
        for ns in (self.a, self.b):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30)
