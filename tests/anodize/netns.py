"""Two simulated hosts on one machine, for tests of the DDS transport across a network.

:func:`two_hosts` makes two network namespaces joined by a veth pair: each has its own
interfaces, addresses and ports, so two Cyclone DDS processes in them discover each other
over a real (virtual) link as they would across two machines, and the link can be made
lossy (:mod:`nftables` ``numgen random``) or cut. Everything is torn down on exit, even
when the body fails, and namespaces that a killed test run left behind are removed by the
next run. Needs root and iproute2 (and nftables for loss and cuts): tests skip with the
reason :func:`netns_unavailable` or :func:`nft_unavailable` gives.

Cyclone finds its peers by multicast on the veth (SPDP to 239.255.0.1): checked here, so
:meth:`TwoHosts.cyclone_env` only chooses the interface. :func:`loopback_cyclone_env`
is for several processes on one host: unicast discovery on 127.0.0.1, which needs no
multicast and no interface but ``lo``.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import json
import os
import re
import shutil
import signal
import subprocess
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["NetnsError", "TwoHosts", "two_hosts", "netns_unavailable", "nft_unavailable", "loopback_cyclone_env"]

PREFIX = "anodize-"  # every namespace made here is "anodize-<pid>-<n>-<a|b>" (or "-trial")
COMMAND_TIMEOUT = 20  # seconds for one ip or nft command: setup never hangs a test run
TABLE = "anodize_link"  # the nftables table (netdev family) on each end of the link
_pairs = itertools.count()


class NetnsError(RuntimeError):
    """An ip or nft command failed: the simulated network is not what the test asked for."""


def _sh(*argv: str, stdin: str | None = None) -> str:
    """Run one ip/nft command and return its output; fail loudly, so setup never half-succeeds."""
    try:
        result = subprocess.run(argv, input=stdin, capture_output=True, text=True, timeout=COMMAND_TIMEOUT,
                                check=False)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise NetnsError(f"{' '.join(argv)}: {error}") from error
    if result.returncode != 0:
        raise NetnsError(f"{' '.join(argv)}: {result.stderr.strip() or f'exit status {result.returncode}'}")
    return result.stdout


def _namespaces() -> list[str]:
    """Names of the existing namespaces (``ip netns list`` adds ``(id: n)`` to some)."""
    return [line.split()[0] for line in _sh("ip", "netns", "list").splitlines() if line.strip()]


def _delete(ns: str) -> None:
    """Kill what still runs in ``ns``, then delete it: a live process would keep it (and its link) alive."""
    with contextlib.suppress(NetnsError):
        for pid in _sh("ip", "netns", "pids", ns).split():
            with contextlib.suppress(ProcessLookupError):
                os.kill(int(pid), signal.SIGKILL)
    with contextlib.suppress(NetnsError):
        _sh("ip", "netns", "del", ns)


@contextlib.contextmanager
def _trial_namespace() -> Iterator[str]:
    """A namespace to try things in, deleted afterwards."""
    ns = f"{PREFIX}{os.getpid()}-trial"
    _sh("ip", "netns", "add", ns)
    try:
        yield ns
    finally:
        _delete(ns)


def _loss_rule(percent: int) -> str:
    """Drop ``percent`` % of the IPv4 packets (all of Cyclone's traffic) at random; ARP passes, so
    the lossy link does not add neighbour-resolution stalls of its own."""
    return f"meta protocol ip numgen random mod 100 < {percent} counter drop"


def _table(device: str) -> str:
    """An nftables table filtering what arrives on ``device``: applied at both ends, it filters both
    directions, with no need for the newer egress hook."""
    return (f"table netdev {TABLE} {{\n  chain ingress {{\n"
            f'    type filter hook ingress device "{device}" priority 0; policy accept;\n  }}\n}}\n')


@functools.cache
def netns_unavailable() -> str | None:
    """Why this machine cannot make the two hosts (to skip with), or None when it can."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2)"
    try:
        with _trial_namespace() as ns:
            _sh("ip", "-n", ns, "link", "add", "trial-a", "type", "veth", "peer", "name", "trial-b")
    except NetnsError as error:
        return f"cannot make a network namespace with a veth pair: {error}"
    return None


@functools.cache
def nft_unavailable() -> str | None:
    """Why this machine cannot make a link lossy or cut it (to skip with), or None when it can."""
    if (reason := netns_unavailable()) is not None:
        return reason
    if shutil.which("nft") is None:
        return "no `nft` command (nftables)"
    try:
        with _trial_namespace() as ns:
            _sh("ip", "-n", ns, "link", "add", "trial-a", "type", "veth", "peer", "name", "trial-b")
            _sh("ip", "netns", "exec", ns, "nft", "-f", "-", stdin=_table("trial-a"))
            _sh("ip", "netns", "exec", ns, "nft", "add", "rule", "netdev", TABLE, "ingress", *_loss_rule(50).split())
    except NetnsError as error:
        return f"nftables cannot drop packets at random on a veth: {error}"
    return None


def cyclone_config(*elements: str) -> dict[str, str]:
    """The environment giving a Cyclone DDS process these ``Domain`` elements; for every domain id, so
    the transport's own configuration (appended after a comma) merges with it."""
    return {"CYCLONEDDS_URI": f'<CycloneDDS><Domain id="any">{"".join(elements)}</Domain></CycloneDDS>'}


def loopback_cyclone_env() -> dict[str, str]:
    """Cyclone configuration for several processes on this host over loopback only: unicast discovery
    to 127.0.0.1 (the participants then take well-known ports by index), so it needs neither multicast
    nor any interface but loopback, and stays off the machine's real network."""
    return cyclone_config('<General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
                          "<AllowMulticast>false</AllowMulticast></General>",
                          '<Discovery><Peers><Peer address="127.0.0.1"/></Peers></Discovery>')


@dataclass
class TwoHosts:
    """Namespaces ``a`` and ``b``, with addresses ``addr_a`` and ``addr_b`` on the veth pair between them."""

    a: str
    b: str
    addr_a: str
    addr_b: str
    _processes: list[subprocess.Popen[Any]] = field(default_factory=list, repr=False)
    _filtered: set[str] = field(default_factory=set, repr=False)  # namespaces that have the nft table

    def _side(self, ns: str) -> str:
        """``"a"`` or ``"b"``; anything else is a test's mistake, caught here rather than by ``ip``."""
        if ns not in (self.a, self.b):
            raise ValueError(f"{ns!r} is neither {self.a!r} nor {self.b!r}")
        return "a" if ns == self.a else "b"

    def device(self, ns: str) -> str:
        """The veth end in ``ns`` (the same names in every pair: each namespace is a world of its own)."""
        return f"veth-{self._side(ns)}"

    def run(self, ns: str, argv: Sequence[str], env: Mapping[str, str] | None = None,
            **popen_kwargs: Any) -> subprocess.Popen[Any]:
        """Start ``argv`` inside ``ns``, with ``env`` added to this process's environment. Whatever still
        runs in either namespace when :func:`two_hosts` exits is killed."""
        self._side(ns)
        process = subprocess.Popen(["ip", "netns", "exec", ns, *argv], env={**os.environ, **(env or {})},
                                   **popen_kwargs)
        self._processes.append(process)
        return process

    def cyclone_env(self, ns: str) -> dict[str, str]:
        """Cyclone configuration for a process in ``ns``: the veth as its only interface. Discovery is
        Cyclone's default, multicast, which crosses the veth; leases and timings are the defaults."""
        return cyclone_config(f'<General><Interfaces><NetworkInterface name="{self.device(ns)}"/>'
                              "</Interfaces></General>")

    def drop(self, ns: str, rule: str) -> None:
        """Add an nftables ``rule`` (e.g. ``counter drop``) for the packets arriving in ``ns``."""
        if ns not in self._filtered:
            self._nft(ns, "-f", "-", stdin=_table(self.device(ns)))
            self._filtered.add(ns)
        self._nft(ns, "insert", "rule", "netdev", TABLE, "ingress", *rule.split())

    def cut(self) -> None:
        """Cut the link: from now on every packet is dropped, silently, in both directions, as when the
        network between two machines fails. The interfaces stay up and keep their addresses, so each
        side learns of the cut only by its peer falling silent (DDS: its lease running out)."""
        for ns in (self.a, self.b):
            self.drop(ns, "counter drop")

    def dropped(self, ns: str) -> int:
        """Packets dropped so far on arriving in ``ns`` (by the random loss and by a cut)."""
        if ns not in self._filtered:
            return 0
        listing = json.loads(self._nft(ns, "-j", "list", "chain", "netdev", TABLE, "ingress"))
        return sum(expr["counter"]["packets"] for item in listing["nftables"] if "rule" in item
                   for expr in item["rule"]["expr"] if "counter" in expr)

    def _nft(self, ns: str, *argv: str, stdin: str | None = None) -> str:
        return _sh("ip", "netns", "exec", ns, "nft", *argv, stdin=stdin)

    def _close(self) -> None:
        """Delete both namespaces (killing what runs there) and reap the processes :meth:`run` started."""
        for ns in (self.a, self.b):
            _delete(ns)
        for process in self._processes:
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(timeout=COMMAND_TIMEOUT)
        if left := {self.a, self.b} & set(_namespaces()):
            raise NetnsError(f"namespaces {sorted(left)} survived their deletion")


def _loss_percent(loss: float) -> int:
    """``loss`` as the whole percentage the nftables rule needs; refuse what it cannot express."""
    percent = round(loss * 100)
    if not 0 <= loss <= 1 or abs(percent - loss * 100) > 1e-6:
        raise ValueError(f"loss must be a whole percentage between 0 and 1, not {loss}")
    return percent


def _reap_stale() -> None:
    """Delete the namespaces of test runs that died without tearing down (killed with SIGKILL)."""
    for ns in _namespaces():
        match = re.fullmatch(rf"{re.escape(PREFIX)}(\d+)-.*", ns)
        if match is None:
            continue
        try:
            os.kill(int(match[1]), 0)
        except ProcessLookupError:
            _delete(ns)
        except PermissionError:
            pass  # alive, someone else's


def _new_pair() -> TwoHosts:
    """Names and addresses for a new pair: the pid keeps parallel test runs apart, the counter pairs
    made one after another (or nested) in one run."""
    pid, n = os.getpid(), next(_pairs)
    net = f"10.213.{pid % 256}.{4 * (n % 64)}"  # a /30 of its own, so addresses tell pairs apart in traces
    prefix, last = net.rsplit(".", 1)
    return TwoHosts(a=f"{PREFIX}{pid}-{n}-a", b=f"{PREFIX}{pid}-{n}-b",
                    addr_a=f"{prefix}.{int(last) + 1}", addr_b=f"{prefix}.{int(last) + 2}")


def _wire(hosts: TwoHosts) -> None:
    """Make the namespaces and the veth pair between them; ``lo`` up too (Cyclone and tests use it)."""
    for ns in (hosts.a, hosts.b):
        _sh("ip", "netns", "add", ns)
    _sh("ip", "link", "add", hosts.device(hosts.a), "netns", hosts.a, "type", "veth",
        "peer", "name", hosts.device(hosts.b), "netns", hosts.b)
    for ns, address in ((hosts.a, hosts.addr_a), (hosts.b, hosts.addr_b)):
        device = hosts.device(ns)
        _sh("ip", "-n", ns, "addr", "add", f"{address}/30", "dev", device)
        _sh("ip", "-n", ns, "link", "set", "lo", "up")
        _sh("ip", "-n", ns, "link", "set", device, "up", "multicast", "on")
        # A multicast route, so programs that do not pick an interface themselves (Cyclone does) work too.
        _sh("ip", "-n", ns, "route", "add", "224.0.0.0/4", "dev", device)


@contextlib.contextmanager
def two_hosts(loss: float = 0.0) -> Iterator[TwoHosts]:
    """Two namespaces joined by a veth pair; with ``loss`` > 0, that fraction of the packets (a whole
    percentage) is dropped at random in each direction. Both namespaces, the link and the nftables
    rules are gone when this exits, however it exits."""
    percent = _loss_percent(loss)
    _reap_stale()
    hosts = _new_pair()
    try:
        _wire(hosts)
        if percent:
            for ns in (hosts.a, hosts.b):
                hosts.drop(ns, _loss_rule(percent))
        yield hosts
    finally:
        hosts._close()
