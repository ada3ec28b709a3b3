"""Which matched endpoint is the peer a channel expects (the one that claims its group of our run and
incarnation), and who the others are, for a report that names them."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from .binding import userdata_of
from .identity import instance_handle, parse_identity
from .qos import Endpoints
from .settings import SplitBrainError

__all__ = ["find_peer", "describe"]


def find_peer(endpoints: Endpoints, role: str, channel: str, handles: Iterable[int],
              data_of: Callable[[int], Any]) -> tuple[int | None, str]:
    """The handle and GUID of the one matched endpoint that says it is ``role``'s group of
    our run and incarnation, or (None, "") while there is none.

    Raises:
        SplitBrainError: several claim it (never guess which one is genuine).
    """
    settings = endpoints.settings
    expected = settings.group_of[role]
    claims = []
    for handle in handles:
        data = data_of(handle)
        identity = parse_identity(userdata_of(data.qos)) if data is not None else None
        # A restart starts its batch of groups as one incarnation: an endpoint of an older
        # one is the session we left, not a peer of this one. The run's token (claim_run) is
        # known only to the run's own processes: an endpoint that was there before the run
        # started cannot claim a group of it, wherever it sits (even subscribed to "*").
        if identity is not None and identity[:3] == (settings.claim_run, expected, endpoints.incarnation):
            claims.append((instance_handle(handle), str(data.key), identity))
    if len(claims) > 1:
        raise SplitBrainError(
            f"{len(claims)} DDS endpoints on {channel} claim to be {settings.where(role)}: "
            + ", ".join(f"{guid} (pid {identity[4]} on {identity[3]})" for _, guid, identity in claims)
            + "; is the same run started twice, or is someone forging it?")
    if claims:
        handle, guid, _ = claims[0]
        return handle, guid
    return None, ""


def describe(handle: int, data: Any) -> str:
    """A matched endpoint for a report: its GUID and the identity it claims."""
    guid = str(data.key) if data is not None else f"handle {instance_handle(handle)}"
    claimed = userdata_of(data.qos).decode(errors="replace") if data is not None else ""
    return f"{guid} (it claims {claimed or 'nothing'!r})"
