"""The start barrier: a group starts only once every channel's other end has appeared on DDS.

Until then nothing is written, so nothing goes only to a reader of an incarnation that is
ending (a restart), and nothing is missed by the new one. The wait counts from the moment the
group's process started: ``--wait`` bounds a group's whole start (importing its roles, then
the barrier), and the supervisor, which allows exactly that, hears the barrier's own report
of what is missing before its start timeout would fire.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping, Sequence

from ..started import since_process_start
from .receiver import DdsReceiver, InLane
from .sender import DdsSender, OutLane
from .settings import DdsSettings, StartBarrierError

__all__ = ["wait_for_peers"]


def wait_for_peers(settings: DdsSettings, senders: Sequence[DdsSender], receivers: Sequence[DdsReceiver]) -> None:
    """Return once every channel's other end has appeared, or raise when the wait is over.

    Raises:
        StartBarrierError: naming the groups and hosts that never appeared.
    """
    deadline = time.monotonic() + settings.wait - since_process_start()
    while True:
        missing = _missing(settings, senders, receivers)
        if not missing:
            return
        if time.monotonic() > deadline:
            raise StartBarrierError(
                f"after {settings.wait:g} s on DDS domain {settings.domain} (run {settings.run_id}), "
                f"no sign of {'; '.join(missing)}: is it started (anodize run ... --host), with the same "
                f"run id, domain and network?")
        time.sleep(0.02)


def _missing(settings: DdsSettings, senders: Sequence[DdsSender], receivers: Sequence[DdsReceiver]) -> list[str]:
    missing: dict[str, list[str]] = {}
    for sender in senders:
        if not sender.find_reader():
            missing.setdefault(settings.where(sender.receiver), []).append(
                f"{sender.sender}->{sender.receiver}" + _on_topics(sender.ros))
    for receiver in receivers:
        if not receiver.find_writer():
            missing.setdefault(settings.where(receiver.sender), []).append(
                f"{receiver.sender}->{receiver.receiver}" + _on_topics(receiver.ros.values()))
    return [f"{where} (for {', '.join(pairs)})" for where, pairs in sorted(missing.items())]


def _on_topics(lanes: Iterable[OutLane | InLane] | Mapping[str, OutLane]) -> str:
    topics = [lane.topic for lane in (lanes.values() if isinstance(lanes, Mapping) else lanes)]
    return f" on ROS topic{'s' if len(topics) > 1 else ''} {', '.join(topics)}" if topics else ""

