"""The start barrier: a group starts only once every channel's other end has appeared on Zenoh.

Until then nothing is put, so nothing goes only to a reader of an incarnation that is
ending (a restart), and nothing is missed by the new one.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from ..started import since_process_start
from .receiver import ZenohReceiver
from .sender import ZenohSender
from .session import GroupSession
from .settings import StartBarrierError

__all__ = ["wait_for_peers"]


def wait_for_peers(group: GroupSession, senders: Sequence[ZenohSender], receivers: Sequence[ZenohReceiver]) -> None:
    """Return once every channel's other end has appeared, or raise when the wait is over.

    Raises:
        StartBarrierError: naming the groups and hosts that never appeared.
    """
    settings = group.settings
    deadline = time.monotonic() + settings.wait - since_process_start()  # --wait bounds the whole start
    while True:
        missing = _missing(group, senders, receivers)
        if not missing:
            return
        left = deadline - time.monotonic()
        if left <= 0:
            where = ", ".join(settings.connect) or "peers found by scouting"
            raise StartBarrierError(
                f"after {settings.wait:g} s on Zenoh ({settings.mode} mode, connect {where}; run "
                f"{settings.run_id}), no sign of {'; '.join(missing)}: is it started (anodize run ... --host), "
                "with the same run id, token and Zenoh network?")
        with group.peers.changed:  # wakes on every token that comes or goes
            group.peers.changed.wait(min(0.1, left))


def _missing(group: GroupSession, senders: Sequence[ZenohSender], receivers: Sequence[ZenohReceiver]) -> list[str]:
    settings = group.settings
    missing: dict[str, list[str]] = {}
    for sender in senders:
        if not sender.find_reader():
            missing.setdefault(settings.where(sender.receiver), []).append(f"{sender.sender}->{sender.receiver}")
    for receiver in receivers:
        if not receiver.find_writer():
            missing.setdefault(settings.where(receiver.sender), []).append(f"{receiver.sender}->{receiver.receiver}")
    return [f"{where} (for {', '.join(pairs)})" for where, pairs in sorted(missing.items())]
