"""Transports as values: what carries a run's messages, with its own settings.

``System(g, transport=Processes(liveness=5.0))``. Each value is frozen, checks its
fields when it is made (a :class:`~anodize.ConfigurationError` naming what was
expected and what it got), and builds its :class:`~.supervisor.Runner` from a
run's :class:`~.plan.RunPlan`; the supervision core is the same for all of them.
"""

from __future__ import annotations

import os
import re
import socket
from dataclasses import dataclass
from typing import ClassVar

from .._extras import import_extra
from ..errors import ConfigurationError
from .plan import RunPlan
from .supervisor import Runner

__all__ = ["Inproc", "Processes", "Dds", "Transport", "KINDS"]


def _seconds(owner: str, name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
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

        host = self.host
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
        # Two runs of one system under two ROS namespaces are two runs: the namespace is in the default run id.
        namespace = plan.ros.namespace.strip("/").replace("/", ".") if plan.ros is not None else ""
        run_id = self.run_id or (f"{plan.protocol}.{namespace}"[:64] if namespace else plan.protocol)
        settings = DdsSettings(domain=domain, run_id=run_id, host=here,
                               group_of=dict(plan.group_of), host_of=host_of, wait=self.wait, ros=ros)
        elsewhere = {name: host_of[name] for name, g in plan.groups.items() if host is not None and g.host != host}
        return DdsRunner(plan, settings, elsewhere, self.liveness)


Transport = Inproc | Processes | Dds
"""A transport value: :class:`Inproc`, :class:`Processes` or :class:`Dds`."""

KINDS: dict[str, type[Inproc] | type[Processes] | type[Dds]] = {t.kind: t for t in (Inproc, Processes, Dds)}
"""Each transport value's class by its kind (the ``transport`` strings of the deprecated forms)."""
