"""What a transport between group processes provides: the links of one group's channels.

A group's process holds one :class:`~anodize._transport.network.GroupNetwork`: queues
for the channels inside the group, and for each channel to or from another group a
*link* made by the transport's :class:`Links` object (OS pipes:
:class:`~anodize._transport.process.PipeLinks`; DDS topics:
:class:`~anodize._transport.dds.links.DdsLinks`). The network is built from those parts
(composition), so each transport carries only its own machinery. The ends a link makes
see the network only through :class:`LinkNetwork`.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping
from typing import Protocol, runtime_checkable

from .._session.channel import Channel
from ..errors import AnodizeError
from .codec import Codec

__all__ = ["Links", "LinkNetwork", "FailureWriter", "PayloadError"]


class PayloadError(AnodizeError):
    """A payload that cannot cross to another group's process (nothing was sent)."""


@runtime_checkable
class FailureWriter(Protocol):
    """The sending end of a channel to another process: it can say, from any thread, that its role failed."""

    def put_failure(self, cause: str) -> None: ...


class LinkNetwork(Protocol):
    """What the ends of a link see of their group's network."""

    failed: dict[str, str]
    stopping: bool
    capacities: dict[tuple[str, str], int]

    def note_failed(self, role: str, cause: str) -> None:
        """Record why the remote ``role`` failed, and wake its receivers here."""

    def wait_for_cause(self, role: str, default: str) -> str | None:
        """Why ``role`` failed, waiting briefly for word of it (None: the run is stopping)."""


class Links(Protocol):
    """How one transport links a group's channels to other groups' processes."""

    def pairs(self, local_roles: Collection[str], channels: Iterable[tuple[str, str]],
              dead: Mapping[str, str]) -> list[tuple[str, str]]:
        """The channels with one end in this group that this transport links, in order."""

    def writer(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> Channel:
        """The sending end of ``pair`` (its sender is local)."""

    def reader(self, pair: tuple[str, str], codec: Codec, network: LinkNetwork) -> Channel:
        """The receiving end of ``pair`` (its receiver is local); it has a ``frame_size``."""

    def silence(self, pair: tuple[str, str]) -> None:
        """Our receiver of ``pair`` failed: its blocked senders in other processes must notice."""

    def noted_failed(self, role: str) -> None:
        """The remote ``role`` was noted failed: wake the readers waiting on it."""

    def wake(self) -> None:
        """The run is stopping: wake every reader blocked in the transport."""

    def close(self, linger: float) -> None:
        """The process is ending: flush what was written (waiting at most ``linger`` seconds)."""
