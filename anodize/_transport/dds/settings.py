"""What a group's process needs to join its run on DDS, and the names and configuration derived from it."""

from __future__ import annotations

import os
import re
import secrets
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import ClassVar

from ...errors import ConfigurationError
from ..links import SplitBrainError, StartBarrierError
from ..ros_lanes import RosSettings

__all__ = ["DdsSettings", "DOMAIN_ENV", "TOKEN_ENV", "StartBarrierError", "SplitBrainError", "topic_name",
           "participant_config", "run_token"]

DOMAIN_ENV = "ANODIZE_DDS_DOMAIN"  # overrides the system file's domain
TOKEN_ENV = "ANODIZE_DDS_TOKEN"  # a run's secret token, the same on every host of the run
_TOKEN = re.compile(r"[A-Za-z0-9_.-]{8,128}")


@dataclass(frozen=True)
class DdsSettings:
    """What a group's process needs to join its run on DDS (picklable, in the group's spec).

    Attributes:
        domain: the DDS domain id.
        run_id: keeps two runs of the same system apart (part of every topic name).
        host: the host this group runs on (for messages and identities).
        group_of: role -> group, for every role of the system.
        host_of: group -> host, for every group of the system.
        lease: seconds of liveliness lease (a silent peer is failed after about this).
        wait: seconds the start barrier waits for every peer.
        ros: the channels' labels that are ROS 2 topics, and the roles ROS 2 nodes play.
        token: a secret of this run, fresh each run ("" for a run over several hosts, whose
            supervisors share only the run id): part of the run's partition and of every
            identity, so that an endpoint there before the run started can neither meet the
            run's endpoints nor claim its groups (see :attr:`partition`).
    """

    domain: int
    run_id: str
    host: str
    group_of: Mapping[str, str]
    host_of: Mapping[str, str]
    lease: float = 1.0
    wait: float = 30.0
    extra_config: str = field(default="")
    ros: RosSettings | None = None
    token: str = field(default="", repr=False)
    LINKS: ClassVar[str] = "anodize._transport.dds.links:DdsLinks"  # its links (the group spec's seam)

    @property
    def claim_run(self) -> str:
        """The run as identities name it: the run id, and the token if there is one (run ids have no ``/``)."""
        return f"{self.run_id}/{self.token}" if self.token else self.run_id

    @property
    def partition(self) -> str:
        """The DDS partition of every anodize endpoint of the run (not of its ROS topics, which
        ROS 2 tools find in the default partition). DDS matches a writer and a reader only if
        they share a partition, so the endpoints of other runs, and programs in the default
        partition, never match ours: they can neither feed a channel nor hold it back."""
        return f"anodize/{self.claim_run}"

    def where(self, role: str) -> str:
        """Where ``role`` runs, for messages."""
        if self.is_external(role):
            return f"external role {role} (a ROS 2 node)"
        group = self.group_of[role]
        return f"group {group} on host {self.host_of.get(group, '?')}"

    def is_external(self, role: str) -> bool:
        """Whether ``role`` is played by a ROS 2 node, not by anodize."""
        return self.ros is not None and role in self.ros.external


def topic_name(run_id: str, sender: str, receiver: str) -> str:
    """The channel's topic: DDS names allow letters, digits, ``_`` and ``/``."""
    return "anodize/" + "/".join(_safe(part) for part in (run_id, sender, receiver))


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]", lambda m: f"_{ord(m.group()):x}_", text)


def participant_config(lease: float) -> str:
    """Cyclone configuration for a group: a discovery lease of ``lease`` seconds, so a vanished
    participant (process killed, host cut off) is dropped, and its endpoints unmatched, that fast."""
    return (f"<CycloneDDS><Domain id=\"any\"><Discovery><LeaseDuration>{lease:g}s</LeaseDuration>"
            "</Discovery></Domain></CycloneDDS>")


def run_token(several_hosts: bool) -> str:
    """The run's token (:attr:`DdsSettings.token`): ``$ANODIZE_DDS_TOKEN`` if set; else a fresh
    random one when this host runs every group, and none ("") for a run over several hosts
    (their supervisors share nothing secret unless the user gives them the same token).

    Raises:
        ConfigurationError: the variable is set to something that is not a token.
    """
    given = os.environ.get(TOKEN_ENV, "")
    if given:
        if not _TOKEN.fullmatch(given):  # the value is a secret: say what is wrong, not what it is
            raise ConfigurationError(f"{TOKEN_ENV}: expected 8 to 128 letters, digits, '_', '.' or '-', got "
                                     f"{len(given)} characters" + ("" if given.isprintable() else
                                                                   ", some not printable"))
        return given
    return "" if several_hosts else secrets.token_hex(8)
