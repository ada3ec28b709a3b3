"""The runner of ``Zenoh``: the groups of this host as processes, joined to the rest by Zenoh.

A network runner (:mod:`.netrunner`): each group's process opens one Zenoh session (peer
or client mode, the endpoints of its host), declares its liveliness token, a publisher
and a subscriber per channel it has with another group, and reports ready only once
every peer has appeared (the start barrier,
:meth:`anodize._transport.zenoh.links.ZenohLinks.wait_for_peers`). Groups placed on
other hosts are started there, by ``anodize run ... --host``; the supervisors of the
run's hosts speak on a Zenoh session of their own (:class:`~.zenohlink.ZenohHostLink`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

from .._transport.zenoh import ZenohSettings, session_config
from .._transport.zenoh.binding import Session, ZError, close, open_session, reason
from .._transport.zenoh.settings import loopback_endpoint, run_token, supervisor_settings, tls_hint
from ..errors import AnodizeError
from .hostview import LOST_AFTER
from .netrunner import NetworkRunner
from .plan import RunPlan
from .zenohlink import ZenohHostLink

__all__ = ["ZenohRunner"]


class ZenohRunner(NetworkRunner):
    """Starts this host's groups; see the module docstring.

    Args:
        plan: the run; its groups are every group of the system.
        settings: the run's Zenoh settings (``host`` is this host).
        elsewhere: the groups of the system that run on other hosts, by name -> host.
        hosts: per host, its own (mode, connect, listen) where it differs from ``settings``.
        liveness: seconds a local group may send no heartbeat before it is failed.
    """

    transport = "zenoh"

    def __init__(self, plan: RunPlan, settings: ZenohSettings, elsewhere: Mapping[str, str],
                 hosts: Mapping[str, tuple[str, tuple[str, ...], tuple[str, ...]]] | None = None,
                 liveness: float = 2.0) -> None:
        super().__init__(plan, elsewhere, liveness, settings.wait)
        self.settings = replace(settings, token=run_token(several_hosts=bool(elsewhere)))
        self.hosts = dict(hosts or {})
        # The supervisors of the other hosts, on a session of this supervisor's own: policies that
        # reach beyond a group act there too.
        self.session: Session | None = None
        self.meeting = ""  # the loopback endpoint where this host's peers meet, if this runner opened one
        link = None
        s = self.settings
        if not elsewhere and s.mode == "peer" and not s.connect and not s.listen and not self.hosts:
            # Every group is here and nothing says where peers meet: they meet on a loopback
            # endpoint this supervisor listens on (and by scouting, if on), so a run on one
            # machine needs no multicast.
            self.meeting = loopback_endpoint()
            self.session = self._open(replace(s, listen=(self.meeting,), scouting=False))
            self.settings = replace(s, connect=(self.meeting,))
        if elsewhere:
            here = self._for_host(self.settings.host)
            self.session = self._open(supervisor_settings(here))
            link = ZenohHostLink(self.session, here.prefix, f"{here.run_id}/{here.token}", here.host,
                                 set(here.host_of.values()))
        # A supervisor unheard through an outage the transport rides through is not lost either.
        self.connect(link, max(LOST_AFTER, self.settings.lease + self.settings.outage))

    @staticmethod
    def _open(settings: ZenohSettings) -> Session:
        try:
            return open_session(session_config(settings))
        except ZError as error:
            raise AnodizeError(f"the supervisor of host {settings.host} cannot open a Zenoh session in "
                               f"{settings.mode} mode (connect {', '.join(settings.connect) or 'none'}; listen "
                               f"{', '.join(settings.listen) or 'none'}): {reason(error)}{tls_hint(settings)}"
                               ) from None

    def _for_host(self, host: str) -> ZenohSettings:
        settings = replace(self.settings, host=host)
        if host in self.hosts:
            mode, connect, listen = self.hosts[host]
            settings = replace(settings, mode=mode, connect=connect, listen=listen)
        return settings

    def settings_for(self, group: str) -> ZenohSettings:
        return self._for_host(self.settings.host_of.get(group, self.settings.host))

    def host_of(self) -> Mapping[str, str]:
        return self.settings.host_of

    def notes(self) -> list[str]:
        notes = super().notes()
        s = self.settings
        notes.append(f"Zenoh {s.mode} mode (connect {', '.join(s.connect) or 'none'}; listen "
                     f"{', '.join(s.listen) or 'default'}; scouting {'on' if s.scouting else 'off'}), run "
                     f"{s.run_id}, host {s.host}; lease {s.lease:g} s, outage ridden through up to "
                     f"{s.outage:g} s more; start barrier waits {s.wait:g} s")
        if s.tls is not None:
            notes.append(f"Zenoh TLS on every link: root CA {s.tls.root_ca or 'none given'}, certificate "
                         f"{s.tls.certificate or 'none given'}, mutual {'yes' if s.tls.mutual else 'no'}")
        if self.meeting:
            notes.append(f"Zenoh peers of this host meet on {self.meeting}, where its supervisor listens")
        for host, (mode, connect, listen) in sorted(self.hosts.items()):
            notes.append(f"host {host}: Zenoh {mode} mode, connect {', '.join(connect) or 'none'}, "
                         f"listen {', '.join(listen) or 'default'}")
        if s.ros is not None:  # published as rmw_zenoh does (anodize/_transport/zenoh/ros_topics.py)
            notes.append(f"ROS 2 topics in rmw_zenoh's format on ROS_DOMAIN_ID {s.ros.domain}: " + (", ".join(
                f"{topic.name} ({sender}->{receiver}: {label}, {topic.type_name})"
                for (sender, receiver, label), topic in sorted(s.ros.topics.items())) or "none"))
            if s.ros.external:
                notes.append("external roles, played by ROS 2 nodes on rmw_zenoh: " + ", ".join(sorted(s.ros.external)))
        if not s.token:
            notes.append("no ANODIZE_ZENOH_TOKEN: the run's keys and claims rest on its run id alone, which "
                         "every key shows, so a program on the network can claim a group before it starts and "
                         "speak as a supervisor of the run (stop it, restart it); give every host the same "
                         "secret in ANODIZE_ZENOH_TOKEN")
        notes.extend(self.elsewhere_notes())
        return notes

    def close(self) -> None:
        try:
            super().close()
        finally:
            if self.link is not None:
                self.link.close()
            if self.session is not None:
                close(self.session)
