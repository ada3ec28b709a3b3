"""The runner of ``Dds``: the groups of this host as processes, joined to the rest by DDS.

It is a network runner (:mod:`.netrunner`: the process runner without pipes, this
host's groups only): each group's process joins the
run's DDS domain, opens a topic per channel it has with another group, and
reports ready only once every peer has appeared (the start barrier,
:meth:`anodize._transport.dds.links.DdsLinks.wait_for_peers`). Groups placed on other
hosts are started there, by ``anodize run ... --host``; this host's report names
them as running elsewhere.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

from .._session.logs import LogEntry
from .._transport.dds import DdsSettings
from .._transport.dds.rosout import RosoutWriter
from .._transport.dds.settings import run_token
from .hostlink import HostLink
from .netrunner import NetworkRunner
from .plan import RunPlan

__all__ = ["DdsRunner"]


class DdsRunner(NetworkRunner):
    """Starts this host's groups; see the module docstring.

    Args:
        plan: the run; its groups are every group of the system.
        settings: the run's DDS settings (``host`` is this host).
        elsewhere: the groups of the system that run on other hosts, by name -> host.
        liveness: seconds a local group may send no heartbeat before it is failed.
    """

    transport = "dds"

    def __init__(self, plan: RunPlan, settings: DdsSettings, elsewhere: Mapping[str, str],
                 liveness: float = 2.0) -> None:
        super().__init__(plan, elsewhere, liveness, settings.wait)
        # A secret of the run keeps endpoints that were there before it started out of its
        # partition and its claims (DdsSettings.token): fresh when every group is ours, else
        # the one the user gave every host (none: the run id alone).
        settings = replace(settings, token=run_token(several_hosts=bool(elsewhere)))
        self.settings = settings
        # The supervisors of the other hosts: policies that reach beyond a group act there too.
        self.connect(HostLink(settings, set(settings.host_of.values())) if elsewhere else None)
        self.rosout: RosoutWriter | None = None  # the roles' log records on ROS 2's /rosout (see log)

    def settings_for(self, group: str) -> DdsSettings:
        return replace(self.settings, host=self.settings.host_of.get(group, self.settings.host))

    def host_of(self) -> Mapping[str, str]:
        return self.settings.host_of

    def log(self, entries: Sequence[LogEntry]) -> None:
        """The roles' log records: published on ROS 2's ``/rosout`` (the writer made at the first)."""
        if self.rosout is None:
            ros = self.settings.ros
            self.rosout = RosoutWriter(ros.domain if ros is not None else self.settings.domain,
                                       (ros.distro or None) if ros is not None else None)
        self.rosout.log(entries)

    def notes(self) -> list[str]:
        notes = super().notes()
        settings = self.settings
        notes.append(f"DDS domain {settings.domain}, run {settings.run_id}, host {settings.host}; "
                     f"liveliness lease {settings.lease:g} s; start barrier waits {settings.wait:g} s")
        if settings.ros is not None:
            ros = settings.ros
            notes.append(f"ROS 2 topics on domain {ros.domain}: " + (", ".join(
                f"{topic.name} ({sender}->{receiver}: {label}, {topic.type_name})"
                for (sender, receiver, label), topic in sorted(ros.topics.items())) or "none"))
            if ros.external:
                notes.append("external roles, played by ROS 2 nodes: " + ", ".join(sorted(ros.external)))
        if not settings.token:
            notes.append("no ANODIZE_DDS_TOKEN: the run's DDS partition and claims rest on its run id alone, so "
                         "a program on the domain that knows the run id can claim a group before it starts")
        notes.extend(self.elsewhere_notes())
        if self.rosout is not None:
            rosout = self.rosout
            notes.append(f"{rosout.written} log records published on /rosout (DDS domain "
                         f"{settings.ros.domain if settings.ros is not None else settings.domain})"
                         + (f"; {rosout.failed} could not be written" if rosout.failed else ""))
        return notes

    def close(self) -> None:
        try:
            super().close()
        finally:
            if self.link is not None:
                self.link.close()
            if self.rosout is not None:
                self.rosout.close()
