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
from typing import ClassVar, Protocol, runtime_checkable

from .._session.channel import Channel
from ..errors import AnodizeError
from .codec import Codec

__all__ = ["Links", "LinkNetwork", "FailureWriter", "WritingEnd", "PayloadError", "NetworkSettings",
           "StartBarrierError", "SplitBrainError"]


class PayloadError(AnodizeError):
    """A payload that cannot cross to another group's process (nothing was sent)."""


class StartBarrierError(AnodizeError):
    """Peers of a group did not appear on the network (the DDS domain, Zenoh) in time."""


class SplitBrainError(StartBarrierError):
    """Several endpoints claim to be one peer group of the run at a start barrier (the run started
    twice, or forged): the supervisor stops the whole run, whatever the group's policy, by this
    class's name."""


@runtime_checkable
class FailureWriter(Protocol):
    """The sending end of a channel to another process: it can say, from any thread, that its role failed."""

    def put_failure(self, cause: str) -> None: ...


class WritingEnd:
    """The read side of a link's sending end, which every transport's sender shares: nothing
    arrives there (the receiving process holds the other end), so a read is a mistake, named."""

    sender: str
    receiver: str
    read_where: ClassVar[str] = "in the receiver's group"  # where the channel is read, for the error

    def get(self, *, timeout: float | None = None) -> object:
        """Never used: this is the writing end.

        Raises:
            AnodizeError: always.
        """
        where = self.read_where.replace("the receiver's", f"{self.receiver}'s")
        raise AnodizeError(f"the channel {self.sender}->{self.receiver} is read {where}")

    def get_nowait(self) -> object:
        """Never used: as :meth:`get`."""
        return self.get()

    def empty(self) -> bool:
        """True: nothing arrives at the writing end."""
        return True


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


class NetworkSettings(Protocol):
    """What a group's process needs to join its run on a network transport (DDS, Zenoh): the
    one seam of a group's spec. ``LINKS`` names (``module:Class``) its :class:`Links`, made as
    ``Class(settings, group, incarnation, report)``, whose ``wait_for_peers()`` is the start
    barrier; the group's process imports it, so only a run on that transport loads its binding."""

    LINKS: ClassVar[str]
