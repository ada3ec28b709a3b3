"""What one host's supervisor knows of the other supervisors of its run, from their hellos.

Every supervisor says a :class:`~.words.HelloWord` every half second. From them this
supervisor knows:

- **who claims which group.** Two live supervisors that claim one group (``anodize run
  --host A`` started on two machines, or two system files that place a group differently)
  are a split brain: :meth:`HostView.split` names both;
- **who is lost and who is back.** A supervisor not heard for ``lost_after`` seconds (and
  that did not say it was leaving) is lost: its host is *gone* for this one, which moves on
  without it, and keeps the incarnations that host's groups had then. When the same
  supervisor is heard again, its host is back; it stays in :attr:`HostView.gone` for another
  ``lost_after`` seconds, so that the returning host hears (in our hellos) that we moved on.
- **who was cut off from us lately.** A gap in a supervisor's hello numbers means hellos were
  lost on the way: the carrier lost its session (a cut), whether or not the silence lasted
  ``lost_after`` here. Time alone cannot tell that: a supervisor whose loop is held up on a
  busy machine takes a second's hellos at once but missed none, and a link that comes back
  may first deliver a hello said before the cut (Zenoh does), then the ones said after it.
  A hello numbered no higher than the last one taken is stale (a repeat or a replay) and is
  not taken at all.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass

from .words import HelloWord

__all__ = ["HostView", "LOST_AFTER", "HELLO_EVERY"]

HELLO_EVERY = 0.5  # seconds between two hellos of a supervisor
LOST_AFTER = 3.0   # seconds without a hello before a supervisor counts as lost (six hellos missed)


@dataclass
class _Peer:
    hello: HelloWord
    heard_at: float
    lost_at: float | None = None
    missed_at: float | None = None  # when a gap in its hello numbers was last seen


class HostView:
    """This supervisor's view of the others.

    Args:
        host, pid, supervisor: who this supervisor is (for the reports).
        lost_after: seconds without a hello before a supervisor counts as lost.
    """

    def __init__(self, host: str, pid: int, supervisor: str, lost_after: float = LOST_AFTER) -> None:
        self.me = f"host {host} (supervisor {supervisor or '?'}, pid {pid}: this one)"
        self.lost_after = lost_after
        self.peers: dict[str, _Peer] = {}  # by supervisor id
        self.gone: dict[str, dict[str, int]] = {}  # host -> its groups' incarnations when it was lost
        self.back: dict[str, float] = {}  # host -> when it was heard again
        self.started = time.monotonic()

    def hear(self, hello: HelloWord, now: float) -> str | None:
        """Note a hello; returns a line for the report when its supervisor was lost and is back."""
        peer = self.peers.get(hello.supervisor)
        if peer is None:
            self.peers[hello.supervisor] = _Peer(hello, now)
            return None
        if self.stale(hello):
            return None
        if hello.number > peer.hello.number + 1:
            peer.missed_at = now
        peer.hello, peer.heard_at = hello, now
        if peer.lost_at is None:
            return None
        line = (f"host {hello.host} is back (its supervisor {hello.supervisor} heard again after "
                f"{now - peer.lost_at + self.lost_after:.1f} s of silence)")
        peer.lost_at = None
        self.back[hello.host] = now
        return line

    def stale(self, hello: HelloWord) -> bool:
        """Whether ``hello`` is older than one already heard from its supervisor (a repeat or a
        replay: the carriers deliver in order): it tells nothing new, and is not taken."""
        peer = self.peers.get(hello.supervisor)
        return peer is not None and hello.number <= peer.hello.number

    def missed_lately(self, supervisor: str, now: float) -> bool:
        """Whether hellos of ``supervisor`` were lost on the way (a cut) within ``lost_after`` seconds."""
        peer = self.peers.get(supervisor)
        return peer is not None and peer.missed_at is not None and now - peer.missed_at <= self.lost_after

    def look(self, now: float) -> list[HelloWord]:
        """The supervisors lost since the last look (their last hellos); their hosts are gone."""
        lost = []
        for peer in self.peers.values():
            if peer.lost_at is None and peer.hello.state != "ended" and now - peer.heard_at > self.lost_after:
                peer.lost_at = now
                self.gone[peer.hello.host] = dict(peer.hello.groups)
                self.back.pop(peer.hello.host, None)
                lost.append(peer.hello)
        for host, at in list(self.back.items()):
            if now - at > self.lost_after:  # it has heard our hellos since: it knows we moved on
                del self.back[host]
                self.gone.pop(host, None)
        return lost

    def split(self, hello: HelloWord, mine: Mapping[str, int]) -> tuple[str, set[str]] | None:
        """Whether ``hello`` claims a group that this supervisor, or another live one, claims:
        a sentence naming both claimants and the groups claimed twice, or None."""
        # A claimant counts while it says hello: one silent for two hellos is more likely a supervisor
        # restarted on its host (a new id, the same groups) than a second one running (whose hellos go on:
        # the next one is checked again).
        now = time.monotonic()
        claimants = [(self.me, set(mine))] + [
            (_who(p.hello), set(p.hello.groups)) for sid, p in self.peers.items()
            if sid != hello.supervisor and p.lost_at is None and p.hello.state != "ended"
            and now - p.heard_at <= 2 * HELLO_EVERY]
        for who, groups in claimants:
            shared = groups & set(hello.groups)
            if shared:
                names = ", ".join(sorted(shared))
                return (f"split brain: group{'s' if len(shared) > 1 else ''} {names} claimed by two supervisors, "
                        f"{who} and {_who(hello)} (is `anodize run --host {hello.host}` running twice, or do two "
                        "system files place a group differently?); neither can be trusted to be the one its "
                        "peers met, so every group of the run stops"), shared
        return None

    def unreached(self) -> list[str]:
        """Hosts whose supervisor has not said it stops or leaves (one cut off, or that has not
        heard our stop yet)."""
        return sorted({p.hello.host for p in self.peers.values() if p.hello.state == "running"})


def _who(hello: HelloWord) -> str:
    return f"host {hello.host} (supervisor {hello.supervisor or '?'}, pid {hello.pid})"
