"""Transports as values: what carries a run's messages, with its own settings.

``System(g, transport=Processes(liveness=5.0))``. Each value is frozen, checks its
fields when it is made (a :class:`~anodize.ConfigurationError` naming what was
expected and what it got), and builds its :class:`~.runner.Runner` from a
run's :class:`~.plan.RunPlan`; the supervision core is the same for all of them.
"""

from __future__ import annotations

import math
import os
import re
import socket
from dataclasses import dataclass
from typing import ClassVar

from .._extras import import_extra
from .._transport.zenoh.settings import SECURE_PROTOCOLS, ZenohTls
from ..errors import ConfigurationError
from .plan import RunPlan
from .runner import Runner

__all__ = ["Inproc", "Processes", "Dds", "Zenoh", "Transport", "KINDS"]


def _seconds(owner: str, name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value < math.inf:  # nan too
        raise ConfigurationError(f"{owner} {name}: expected a number of seconds > 0, got {value!r}")


@dataclass(frozen=True)
class Inproc:
    """Every role is a thread of this process (the groups share one interpreter)."""

    kind: ClassVar[str] = "inproc"

    def runner(self, plan: RunPlan) -> Runner:
        """Threads, one per role, on in-process channels."""
        from .threads import ThreadRunner

        return ThreadRunner(plan)


@dataclass(frozen=True)
class Processes:
    """Each group is its own OS process (its roles are threads in it); channels between groups are pipes.

    Args:
        liveness: seconds a group may send no heartbeat (frozen, stopped, or in a call that
            holds the GIL) before it is failed and its policy applies.
    """

    liveness: float = 2.0
    kind: ClassVar[str] = "process"

    def __post_init__(self) -> None:
        _seconds("Processes", "liveness", self.liveness)

    def runner(self, plan: RunPlan) -> Runner:
        """One process per group, supervised from this one."""
        from .processes import ProcessRunner

        return ProcessRunner(plan, self.liveness)


_RUN_ID = re.compile(r"[A-Za-z0-9_.-]{1,64}")


@dataclass(frozen=True)
class Dds:
    """As :class:`Processes`, but channels between groups are DDS topics (Cyclone DDS), so groups may
    run on several hosts. Needs the ``dds`` extra.

    Args:
        domain: the DDS domain id (the environment variable ``ANODIZE_DDS_DOMAIN`` overrides it;
            with a :class:`~anodize.RosBridge` the run lives on the ROS domain instead).
        run_id: keeps two runs of the same system on one domain apart; every host of a run
            must use the same one ("" = the global type's name, followed by the ROS namespace
            as ``TinManParallel.r1`` when the system has one). Over several hosts, give
            every host the same secret in ``ANODIZE_DDS_TOKEN`` too (one host makes its own).
        host: run only the groups placed on this host (``group(..., host=...)``); the others
            are started on theirs, with the same run id and domain. None runs every group here.
        wait: seconds the groups wait for all their peers to appear on the domain before the
            roles start; a group whose peers do not all appear fails, naming them.
        liveness: as for :class:`Processes`, for the groups of this host.
    """

    domain: int = 0
    run_id: str = ""
    host: str | None = None
    wait: float = 30.0
    liveness: float = 2.0
    kind: ClassVar[str] = "dds"

    def __post_init__(self) -> None:
        if isinstance(self.domain, bool) or not isinstance(self.domain, int) or not 0 <= self.domain <= 232:
            raise ConfigurationError(f"Dds domain: expected a DDS domain id 0..232, got {self.domain!r}")
        if not isinstance(self.run_id, str) or (self.run_id and not _RUN_ID.fullmatch(self.run_id)):
            raise ConfigurationError(f"Dds run_id: expected up to 64 letters, digits, '_', '.' or '-', "
                                     f"got {self.run_id!r}")
        if self.host is not None and (not isinstance(self.host, str) or not self.host.isidentifier()):
            raise ConfigurationError(f"Dds host: expected a name such as robot or base_1, got {self.host!r}")
        _seconds("Dds", "wait", self.wait)
        _seconds("Dds", "liveness", self.liveness)

    def runner(self, plan: RunPlan) -> Runner:
        """This host's groups as processes, joined to the rest of the run by DDS.

        Raises:
            ConfigurationError: ``host`` runs no group, or some group has no host to run on.
        """
        import_extra("cyclonedds", "dds", "the DDS transport")  # fails here, naming the extra, when it is missing
        from .._transport.dds import DOMAIN_ENV, DdsSettings  # only a DDS run loads Cyclone DDS
        from .ddsrunner import DdsRunner

        here, host_of, elsewhere = _placement(plan, self.host)
        domain = self.domain
        if os.environ.get(DOMAIN_ENV):
            try:
                domain = int(os.environ[DOMAIN_ENV])
                if not 0 <= domain <= 232:
                    raise ValueError
            except ValueError:
                raise ConfigurationError(f"{DOMAIN_ENV}={os.environ[DOMAIN_ENV]!r}: expected a DDS domain id") from None
        ros = None
        if plan.ros is not None and (plan.ros.topics or plan.ros.external):
            ros = plan.ros.settings(plan.machines, plan.channels)
            domain = ros.domain  # ROS 2 nodes meet on their domain; anodize's own topics are there too
        settings = DdsSettings(domain=domain, run_id=_run_id(plan, self.run_id), host=here,
                               group_of=dict(plan.group_of), host_of=host_of, wait=self.wait, ros=ros)
        return DdsRunner(plan, settings, elsewhere, self.liveness)


def _placement(plan: RunPlan, host: str | None) -> tuple[str, dict[str, str], dict[str, str]]:
    """This host's name, every group's host, and the groups that run elsewhere (by name -> host).

    Raises:
        ConfigurationError: ``host`` runs no group, or some group has no host to run on.
    """
    hosts = {g.host for g in plan.groups.values() if g.host is not None}
    if host is not None and host not in hosts:
        raise ConfigurationError(f"no group runs on host {host!r}; the system's hosts are "
                                 f"{', '.join(sorted(hosts)) or 'none (give groups a host)'}")
    unplaced = sorted(name for name, g in plan.groups.items() if g.host is None)
    if host is not None and unplaced:  # no host would run them
        raise ConfigurationError(f"--host {host}: groups {', '.join(unplaced)} have no host; give every "
                                 "group a host, or run without --host")
    here = socket.gethostname() if host is None else host
    host_of = {name: g.host or here for name, g in plan.groups.items()}
    elsewhere = {name: host_of[name] for name, g in plan.groups.items() if host is not None and g.host != host}
    return here, host_of, elsewhere


def _run_id(plan: RunPlan, given: str) -> str:
    """The run id: the given one, else the global type's name (and the ROS namespace, if any:
    two runs of one system under two ROS namespaces are two runs)."""
    namespace = plan.ros.namespace.strip("/").replace("/", ".") if plan.ros is not None else ""
    return given or (f"{plan.protocol}.{namespace}"[:64] if namespace else plan.protocol)


def _endpoints(owner: str, name: str, value: object) -> None:
    if not isinstance(value, tuple) or not all(isinstance(e, str) and _ENDPOINT.fullmatch(e) for e in value):
        raise ConfigurationError(f"{owner} {name}: expected Zenoh endpoints such as \"tcp/10.0.0.1:7447\", "
                                 f"got {value!r}")


_ENDPOINT = re.compile(r"[a-z0-9]+/[^\s#?]+(#[^\s]*)?")


@dataclass(frozen=True)
class Zenoh:
    """As :class:`Processes`, but channels between groups go over Eclipse Zenoh, so groups may run
    on several hosts, behind routers (NAT, a cellular link) or as peers on a LAN. Needs the
    ``zenoh`` extra.

    Args:
        mode: ``"peer"`` (groups find each other by multicast scouting on the LAN, or through
            ``connect``) or ``"client"`` (groups talk through the Zenoh routers of ``connect``).
        connect: Zenoh endpoints to connect to, such as ``"tcp/10.0.0.1:7447"`` (a router, or a peer).
        listen: Zenoh endpoints the groups listen on (a peer others connect to).
        run_id: keeps two runs of the same system apart; every host of a run must use the same
            one ("" = the global type's name). Over several hosts, give every host the same secret
            in ``ANODIZE_ZENOH_TOKEN`` too (one host makes its own).
        host: run only the groups placed on this host (``group(..., host=...)``); None runs every group here.
        wait: seconds the groups wait for all their peers (and a client for its router) before the
            roles start; a group whose peers do not all appear fails, naming them.
        liveness: as for :class:`Processes`, for the groups of this host.
        lease: seconds of Zenoh's link lease: a peer whose process dies or whose host is cut off
            is noticed within about a lease, and failed after a lease more (plus ``outage``).
        outage: seconds more a peer may stay unseen before it is failed, so that a router restarting
            is ridden through (what was in flight is sent again); 0 fails it after a lease.
        scouting: whether peers look for each other by multicast on the LAN (turn it off when
            the endpoints are given, so that runs cannot meet by accident).
        hosts: per host, ``{"mode": ..., "connect": [...], "listen": [...]}`` for the groups of that
            host (a run may place groups behind different routers).
        tls: TLS on every link (:class:`ZenohTls`); every endpoint must then be ``tls/...``, and
            a session listens only on the endpoints given (none: nowhere).
    """

    mode: str = "peer"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    run_id: str = ""
    host: str | None = None
    wait: float = 30.0
    liveness: float = 2.0
    lease: float = 1.0
    outage: float = 0.0
    scouting: bool = True
    hosts: tuple[tuple[str, str, tuple[str, ...], tuple[str, ...]], ...] = ()
    tls: ZenohTls | None = None
    kind: ClassVar[str] = "zenoh"

    def __post_init__(self) -> None:
        for name in ("connect", "listen"):
            if isinstance(getattr(self, name), list):
                object.__setattr__(self, name, tuple(getattr(self, name)))
        if self.mode not in ("peer", "client"):
            raise ConfigurationError(f"Zenoh mode: expected \"peer\" or \"client\", got {self.mode!r}")
        _endpoints("Zenoh", "connect", self.connect)
        _endpoints("Zenoh", "listen", self.listen)
        if self.mode == "client" and not self.connect:
            raise ConfigurationError("Zenoh mode \"client\": expected the endpoints of one or more routers in "
                                     "connect, got none")
        if not isinstance(self.run_id, str) or (self.run_id and not _RUN_ID.fullmatch(self.run_id)):
            raise ConfigurationError(f"Zenoh run_id: expected up to 64 letters, digits, '_', '.' or '-', "
                                     f"got {self.run_id!r}")
        if self.host is not None and (not isinstance(self.host, str) or not self.host.isidentifier()):
            raise ConfigurationError(f"Zenoh host: expected a name such as robot or base_1, got {self.host!r}")
        for name in ("wait", "liveness", "lease"):
            _seconds("Zenoh", name, getattr(self, name))
        if isinstance(self.outage, bool) or not isinstance(self.outage, int | float) or not 0 <= self.outage < math.inf:
            raise ConfigurationError(f"Zenoh outage: expected a number of seconds >= 0, got {self.outage!r}")
        if not isinstance(self.scouting, bool):
            raise ConfigurationError(f"Zenoh scouting: expected true or false, got {self.scouting!r}")
        for entry in self.hosts:
            host, mode, connect, listen = entry
            if mode not in ("peer", "client"):
                raise ConfigurationError(f"Zenoh hosts {host}: mode: expected \"peer\" or \"client\", got {mode!r}")
            _endpoints(f"Zenoh hosts {host}", "connect", connect)
            _endpoints(f"Zenoh hosts {host}", "listen", listen)
        if self.tls is not None:
            self._check_tls(self.tls)

    def _check_tls(self, tls: object) -> None:
        """With TLS, nothing of the run travels in the clear: every endpoint is ``tls/`` (or
        ``quic/``, which is TLS too); a host that listens has a certificate, and a peer (which
        also connects to the peers it hears of) the authority to check theirs."""
        if not isinstance(tls, ZenohTls):
            raise ConfigurationError(f"Zenoh tls: expected anodize.ZenohTls(...), got {tls!r}")
        places = [("", self.mode, self.connect, self.listen)] + [
            (f" hosts {host}", mode, connect, listen) for host, mode, connect, listen in self.hosts]
        for where, mode, connect, listen in places:
            clear = [e for e in (*connect, *listen) if not e.startswith(SECURE_PROTOCOLS)]
            if clear:
                raise ConfigurationError(f"Zenoh{where}: with tls, every endpoint must be tls/ADDRESS:PORT (or "
                                         f"quic/), got {clear[0]!r} (it would not be encrypted)")
            if listen and not tls.certificate:
                raise ConfigurationError(f"Zenoh{where} tls: it listens ({listen[0]}), so it needs certificate "
                                         "and private_key")
            if mode == "peer" and not tls.root_ca:
                raise ConfigurationError(f"Zenoh{where} tls: a peer connects to the peers it hears of, so it "
                                         "needs root_ca, the authority that signs their certificates")

    def runner(self, plan: RunPlan) -> Runner:
        """This host's groups as processes, joined to the rest of the run by Zenoh.

        Raises:
            ConfigurationError: ``host`` runs no group, or some group has no host to run on.
        """
        import_extra("zenoh", "zenoh", "the Zenoh transport")  # fails here, naming the extra, when it is missing
        from .._transport.zenoh import ZenohSettings
        from .zenohrunner import ZenohRunner

        problem = self.tls.missing() if self.tls is not None else None
        if problem is not None:
            raise ConfigurationError(problem)

        here, host_of, elsewhere = _placement(plan, self.host)
        ros = None
        if plan.ros is not None and (plan.ros.topics or plan.ros.external):
            ros = plan.ros.settings(plan.machines, plan.channels)
        settings = ZenohSettings(mode=self.mode, run_id=_run_id(plan, self.run_id), host=here,
                                 group_of=dict(plan.group_of), host_of=host_of, connect=self.connect,
                                 listen=self.listen, lease=self.lease, outage=self.outage, wait=self.wait,
                                 scouting=self.scouting, ros=ros, tls=self.tls)
        hosts = {host: (mode, connect, listen) for host, mode, connect, listen in self.hosts}
        return ZenohRunner(plan, settings, elsewhere, hosts, self.liveness)


Transport = Inproc | Processes | Dds | Zenoh
"""A transport value: :class:`Inproc`, :class:`Processes`, :class:`Dds` or :class:`Zenoh`."""

KINDS: dict[str, type[Inproc] | type[Processes] | type[Dds] | type[Zenoh]] = {
    t.kind: t for t in (Inproc, Processes, Dds, Zenoh)}
"""Each transport value's class by its kind (the ``transport`` strings of the deprecated forms)."""
