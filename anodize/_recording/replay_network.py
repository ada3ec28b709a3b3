"""The network a replayed role runs on: its inputs come from a recording, its outputs are compared.

One role runs alone, with a real (monitored) :class:`~anodize._session.endpoint.Endpoint`
on a :class:`ReplayNetwork`:

- a recorded channel *into* the role holds that channel's recorded messages, in order,
  all there from the start (nobody sends them: a replay never waits for a peer); the
  role's doorbell rings for them in the order they were recorded, so ``recv_any`` takes
  them in the recorded interleaving;
- a recorded channel *out of* the role compares each message put into it with the
  recording's next one on that channel (:mod:`.compare`), and raises
  :class:`ReplayDivergenceError` at the first that differs;
- a channel the recording does not have (both ends in one group) takes the role's
  messages and counts them, but cannot compare them; receiving on one cannot be fed.

Nothing waits: a receive beyond the recording's end, a receive on a channel that is not
recorded, and ``Endpoint.sleep(math.inf)`` end the replay (``RoleStopped`` in the role,
the reason in :attr:`ReplayNetwork.ending`); other ``Endpoint.sleep`` calls return at
once, their seconds counted in :attr:`ReplayClock.skipped`.

The role's clock (``Endpoint.now()``, ``Endpoint.wall()``) is the replay's
(:class:`ReplayClock`): each endpoint of the role (its own, each parallel branch's) reads
the readings the recording holds for it, in order; where the recording holds none (a
recording made before clocks were recorded, or the role reads more often than it did in
the run), it reads message time: the recorded time of the last message its thread
received, advanced by that thread's ``Endpoint.sleep`` calls. ``now()`` past an endpoint's
recorded readings goes on from its last one, advanced as message time has advanced since
(the role's monotonic clock and message time count from different origins: a role that
compares a reading with an earlier one, as a period's monitor does, sees the time that passed).

A role that forks into threads is taken through the recorded order of its sends and
clock readings (:mod:`.turnstile`).
"""

from __future__ import annotations

import datetime
import queue
import threading
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from .._session.channel import Channel, Corrupt, Doorbell
from ..errors import AnodizeError, RoleStopped
from .turnstile import BEYOND, Turnstile

if TYPE_CHECKING:
    from .._session.endpoint import Endpoint
    from .reader import RecordedTopic

__all__ = ["RecordedItem", "Divergence", "ReplayDivergenceError", "ReplayNetwork", "ReplayClock",
           "FINISHED", "RECORDING_ENDS", "NOT_RECORDED", "SLEEPS_FOR_EVER", "DIVERGED", "TIMED_OUT"]

# How a replay ended (ReplayNetwork.ending[0], ReplayReport.outcome).
FINISHED = "finished"
RECORDING_ENDS = "recording ends"
NOT_RECORDED = "not recorded"
SLEEPS_FOR_EVER = "sleeps for ever"
DIVERGED = "diverged"
TIMED_OUT = "timed out"


@dataclass(frozen=True)
class RecordedItem:
    """One recorded message of one channel.

    Attributes:
        index: its position on the channel, from 0.
        label: its label.
        log_time: when it was recorded, ns since the epoch.
        data: the recorded bytes.
        topic: the recording's topic it is on.
    """

    index: int
    label: str
    log_time: int
    data: bytes
    topic: RecordedTopic


@dataclass(frozen=True)
class Divergence:
    """The first message where the replayed role did not do what the recording says it did.

    Attributes:
        role: the replayed role.
        channel: ``"Role->Peer"``.
        index: the message's position on the channel, from 0.
        expected: the recorded message (``label(payload)``), or what the recording has
            when the role sent more.
        actual: what the role sent, or did instead.
        reason: how they differ, when the labels are the same.
        log_time: the recorded message's log time (0 when there is none).
    """

    role: str
    channel: str
    index: int
    expected: str
    actual: str
    reason: str = ""
    log_time: int = 0

    def __str__(self) -> str:
        when = ""
        if self.log_time:
            moment = datetime.datetime.fromtimestamp(self.log_time / 1e9, tz=datetime.UTC)
            when = f" (recorded at {moment:%Y-%m-%d %H:%M:%S.%f} UTC)"
        why = f": {self.reason}" if self.reason else ""
        return (f"role {self.role} diverges from the recording on {self.channel}, message {self.index}"
                f"{when}: expected {self.expected}, got {self.actual}{why}")


class ReplayDivergenceError(AnodizeError):
    """Raised in a replayed role at the first message it sends that is not the recorded one.

    Attributes:
        divergence: where and how (:class:`Divergence`).
    """

    def __init__(self, divergence: Divergence) -> None:
        self.divergence = divergence
        super().__init__(str(divergence))


class ReplayClock(threading.Event):
    """The replayed role's clock, and its stop event, which ``Endpoint.sleep`` waits on.

    A finite sleep returns at once (the seconds are added to :attr:`skipped`, and to the
    sleeping thread's message time); a sleep for ever ends the replay. ``now`` and ``wall``
    give each endpoint of the role the readings the run recorded for it, in order (see the
    module docstring); beyond them, message time.

    Args:
        network: the replay's network.
        readings: per endpoint (``""``, ``"1"``, ...), the recorded readings: ``(kind, value,
            time read)`` with kind ``"now"`` or ``"wall"`` (or ``"expiry"``: a deadline passed as the
            endpoint waited), the time in ns since the epoch.
        start: the time (seconds since the epoch) a thread that has received nothing reads.
    """

    def __init__(self, network: ReplayNetwork, readings: Mapping[str, Sequence[tuple[str, float, int]]] | None = None,
                 start: float = 0.0) -> None:
        super().__init__()
        self._network = network
        self.skipped = 0.0
        self._readings = {branch: deque((kind, value) for kind, value, _ in items)
                          for branch, items in (readings or {}).items()}
        self.recorded = sum(len(items) for items in self._readings.values())
        self._held = {branch for branch, items in self._readings.items() if items}
        self.replayed = 0     # readings given back as recorded
        self.from_messages = 0  # readings made of message time
        # Of those, readings past the last one the recording holds for an endpoint that had some: the
        # time the role read there is not known (the run stopped, or the group ended, before the
        # recorder had it; or a crash lost it), so a send that differs after one is not judged a divergence.
        self.past_recorded = 0
        self.differs = ""     # the first reading the role took otherwise than in the run
        self._start = start
        # Per endpoint, its last replayed now() reading and the message time when it was read.
        self._anchors: dict[str, tuple[float, float]] = {}
        self._thread = threading.local()
        self._lock = threading.Lock()

    def wait(self, timeout: float | None = None) -> bool:
        if self.is_set():
            return True
        if timeout is None:
            self._network.stop(SLEEPS_FOR_EVER, f"{self._network.role} sleeps until the run stops "
                                                "(Endpoint.sleep(math.inf))")
            return True
        self.skipped += timeout
        self._thread.time = self._message_time() + timeout
        return False

    def heard(self, log_time: int) -> None:
        """The calling thread received a message recorded at ``log_time`` (ns since the epoch)."""
        self._thread.time = max(self._message_time(), log_time / 1e9)

    def now(self, branch: str) -> float:
        return self._read(branch, "now")

    def expired(self, branch: str) -> bool:
        """Whether endpoint ``branch``'s wait expired here in the run (its next recorded reading
        is an expiry, which is then taken): the replay expires it too, though the message the
        run had not received in time is there."""
        with self._lock:  # a look at the branch's own next reading: only its thread takes them
            readings = self._readings.get(branch)
            if not readings or readings[0][0] != "expiry":
                return False
        self._network.turnstile.take(("clock", branch), self._network.role)  # the expiry's turn
        with self._lock:
            readings = self._readings.get(branch)
            if readings and readings[0][0] == "expiry":
                readings.popleft()
                self.replayed += 1
        return True

    def wall(self, branch: str) -> float:
        return self._read(branch, "wall")

    def _read(self, branch: str, kind: str) -> float:
        if self._readings.get(branch):
            self._network.turnstile.take(("clock", branch), self._network.role)  # the reading's turn
        elif self.recorded and not self.differs:
            # A reading the recording lacks came after every event it holds of the role: a group's
            # recorder writes its roles' sends and readings in the order they happened, and what a
            # run stopped (or a group ended) before writing is the last of them. So it waits for
            # them all: a thread that takes inputs the role never took in the run (sent as the run
            # stopped) acts on them after the role's recorded sends, as it would have in the run.
            self._network.turnstile.take(BEYOND, self._network.role)
        with self._lock:
            readings = self._readings.get(branch)
            if readings:
                recorded, value = readings.popleft()
                if recorded == kind:
                    self.replayed += 1
                    if kind == "now":
                        self._anchors[branch] = (value, self._message_time())
                    return value
                self.differs = self.differs or (
                    f"endpoint {branch or '(the role)'} read {kind}() where the run read {recorded}() "
                    f"(its reading {self.replayed + 1}): the role reads its clock otherwise than in the run")
                for other in self._readings:
                    self._network.turnstile.drop(("clock", other))
                self._readings.clear()  # out of step: the rest would be given to other reads
            self.from_messages += 1
            if branch in self._held and not self.differs:
                self.past_recorded += 1
            anchor = self._anchors.get(branch) if kind == "now" else None
        if anchor is not None:
            value, then = anchor
            return value + (self._message_time() - then)
        return self._message_time()

    def _message_time(self) -> float:
        found: float | None = getattr(self._thread, "time", None)
        return self._start if found is None else found


class ReplayNetwork:
    """The channels of ``role`` (see the module docstring).

    Args:
        role: the replayed role.
        feeds: per peer the role receives from on a recorded channel, its recorded messages.
        expected: per peer the role sends to on a recorded channel, its recorded messages.
        unrecorded_in: per peer the role receives from on a channel the recording does not
            have, why it does not.
        unrecorded_out: peers the role sends to on a channel the recording does not have.
        decode: the payload of a recorded message (raises ``ValueError`` and others when
            the recorded bytes do not decode).
        difference: why a sent payload is not the recorded one ("" when it is).
        readings: per endpoint of the role, its recorded clock readings (:class:`ReplayClock`).
        threads: the role may run several threads (it forks): keep their recorded order
            (:class:`~.turnstile.Turnstile`).
        cuts: per peer whose channel into the role the recording cuts short (messages lost, or
            its sender's group started again), when (ns since the epoch): past its messages, the
            replay ends there.
    """

    def __init__(self, role: str, feeds: Mapping[str, Sequence[RecordedItem]],
                 expected: Mapping[str, Sequence[RecordedItem]], unrecorded_in: Mapping[str, str],
                 unrecorded_out: Sequence[str], decode: Callable[[RecordedItem], object],
                 difference: Callable[[RecordedItem, object], str],
                 readings: Mapping[str, Sequence[tuple[str, float, int]]] | None = None, threads: bool = False,
                 cuts: Mapping[str, int] | None = None) -> None:
        self.role = role
        self._decode = decode
        self._difference = difference
        self._expected = {peer: list(items) for peer, items in expected.items()}
        self.feeds = {peer: _Feed(self, peer, items, cut=(cuts or {}).get(peer)) for peer, items in feeds.items()}
        self.feeds.update({peer: _Feed(self, peer, (), why) for peer, why in unrecorded_in.items()})
        self.checks = {peer: _Check(self, peer) for peer in expected}
        self.checks.update({peer: _Check(self, peer, recorded=False) for peer in unrecorded_out})
        self.queues: dict[tuple[str, str], Channel] = {(peer, role): feed for peer, feed in self.feeds.items()}
        self.queues.update({(role, peer): check for peer, check in self.checks.items()})
        order = sorted(((item.log_time, peer, item.index) for peer, items in feeds.items() for item in items))
        self.doorbells: dict[str, Doorbell] = {role: _Rings(self, [peer for _, peer, _ in order])}
        self.failed: dict[str, str] = {}
        self.alarm = False
        streams: dict[object, list[int]] = {("send", peer): [item.log_time for item in items]
                                            for peer, items in expected.items()}
        streams.update({("clock", branch): [stamp for _, _, stamp in items]
                        for branch, items in (readings or {}).items()})
        self.turnstile = Turnstile(streams, active=threads)
        self.clock = ReplayClock(self, readings, min((item.log_time for items in [*feeds.values(), *expected.values()]
                                                      for item in items[:1]), default=0) / 1e9)
        self.clocks = {role: self.clock}  # the role's Endpoint.now() and wall() (anodize._session.clock)
        self.ending: tuple[str, str] | None = None  # (outcome, detail), the first reason to end
        self.divergence: Divergence | None = None
        self.time_unknown = False  # ended at a send made past the recorded clock readings (ReplayClock)
        self.endpoint: Endpoint | None = None  # set once made: its state goes into the messages
        self._lock = threading.RLock()

    # ---- the Network protocol -------------------------------------------------------------
    def stop_event_for(self, role: str) -> threading.Event:
        return self.clock

    def ring(self, receiver: str, sender: str) -> None:
        """Nobody sends to the replayed role: its rings are the recording's."""

    # ---- ending ---------------------------------------------------------------------------
    def stop(self, outcome: str, detail: str) -> None:
        """End the replay (the first reason given is kept): the role's next action raises ``RoleStopped``."""
        with self._lock:
            if self.ending is None:
                self.ending = (outcome, detail)
            self.alarm = True
        self.clock.set()
        self.turnstile.stop()

    def end(self, outcome: str, detail: str) -> RoleStopped:
        """End the replay; returns the ``RoleStopped`` for the calling role thread to raise."""
        self.stop(outcome, detail)
        return RoleStopped(self.detail())

    def detail(self) -> str:
        return self.ending[1] if self.ending is not None else ""

    def state(self) -> str:
        return "" if self.endpoint is None else f" in state {self.endpoint.state}"

    # ---- what the role sends ----------------------------------------------------------------
    def delivered(self, peer: str, label: str, payload: object) -> None:
        """Compare a message the role sent to ``peer`` with the recording's next one there.

        Raises:
            ReplayDivergenceError: it is another message.
            RoleStopped: the recording holds no more on that channel (the replay ends).
        """
        items = self._expected[peer]
        check = self.checks[peer]
        # Its turn (a role's threads send in the recorded order); beyond the recording, after every other event.
        self.turnstile.take(("send", peer) if check.sent < len(items) else BEYOND, self.role)
        with self._lock:
            if self.ending is not None:
                raise RoleStopped(self.detail())
            channel = f"{self.role}->{peer}"
            if check.sent >= len(items):
                raise self.end(RECORDING_ENDS, f"the recording ends here: {self.role} sends "
                                         f"{_message(label, payload)} on {channel}, but the recording has "
                                         f"only the {len(items)} message(s) before it there")
            item = items[check.sent]
            check.sent += 1
            reason = "another label" if item.label != label else self._difference(item, payload)
            if not reason:
                return
            if self.clock.past_recorded:
                check.sent -= 1  # not compared: the time it was made from is not in the recording
                self.time_unknown = True
                raise self.end(RECORDING_ENDS, f"the recording ends here for {self.role}'s time: it sends "
                                               f"{_message(label, payload)} on {channel} after reading its clock "
                                               f"{self.clock.past_recorded} time(s) past the readings the recording "
                                               "holds, so what it read, and what it sends from here, is not known")
            divergence = Divergence(self.role, channel, item.index, self.recorded_text(item),
                                    _message(label, payload), "" if item.label != label else reason,
                                    item.log_time)
            self.divergence = self.divergence or divergence
            self.stop(DIVERGED, str(divergence))
        raise ReplayDivergenceError(divergence)

    def recorded_text(self, item: RecordedItem) -> str:
        try:
            return _message(item.label, self._decode(item))
        except Exception as error:  # the recording's bytes do not decode: say so, do not fail here
            return f"{item.label}(<does not decode: {error}>)"

    def unsent(self, peer: str) -> list[RecordedItem]:
        """The recorded messages to ``peer`` the role has not sent (yet)."""
        return self._expected.get(peer, [])[self.checks[peer].sent:]

    def payload_of(self, item: RecordedItem) -> object:
        """A recorded message as a channel delivers it: ``(label, payload)``, or ``Corrupt``."""
        try:
            return (item.label, self._decode(item))
        except Exception as error:  # bytes that do not decode: the sender is to blame, as live
            return Corrupt(f"recorded message {item.index} on {item.topic.topic}: {type(error).__name__}: {error}")


def _message(label: str, payload: object) -> str:
    from .compare import short

    return label if payload is None else f"{label}({short(payload)})"


class _Feed:
    """A channel into the replayed role: the recording's messages on it, then the end."""

    def __init__(self, network: ReplayNetwork, peer: str, items: Sequence[RecordedItem],
                 unrecorded: str | None = None, cut: int | None = None) -> None:
        self._network = network
        self._peer = peer
        self._items: deque[object] = deque(items)
        self.recorded = len(self._items)
        self.delivered = 0
        self.unrecorded = unrecorded
        self.cut = cut  # the recording cuts this channel short from then on (ns since the epoch)

    def put(self, item: object) -> None:  # a signal the endpoint puts back
        self._items.append(item)

    def get(self, *, timeout: float | None = None) -> object:
        network = self._network
        if network.ending is not None:
            raise RoleStopped(network.detail())
        channel = f"{self._peer}->{network.role}"
        if self.unrecorded is not None:
            raise network.end(NOT_RECORDED, f"{network.role}{network.state()} receives from {self._peer} on {channel}, "
                                      f"which the recording does not have ({self.unrecorded}): "
                                      f"{network.role} cannot be replayed alone from here")
        if not self._items and self.cut is not None:
            # The next message is lost: what the role did after it came cannot be replayed, but what
            # its other threads did before it was sent can (they may wait for this thread's events,
            # which wait for the lost input: every recorded event is too many to wait for).
            network.turnstile.take_before(self.cut, network.role)
            if network.ending is not None:
                raise RoleStopped(network.detail())
            raise network.end(RECORDING_ENDS, f"the recording ends here: {network.role}{network.state()} waits for "
                                              f"message {self.recorded} on {channel}, where the recording cuts the "
                                              "channel short (see the note on it)")
        if not self._items:
            network.turnstile.take(BEYOND, network.role)  # the role's other threads do what they did first
            if network.ending is not None:
                raise RoleStopped(network.detail())
            raise network.end(RECORDING_ENDS, f"the recording ends here: {network.role}{network.state()} waits for a "
                                        f"message from {self._peer}, and all {self.recorded} recorded on "
                                        f"{channel} have been delivered")
        item = self._items.popleft()
        if not isinstance(item, RecordedItem):
            return item
        self.delivered += 1
        network.clock.heard(item.log_time)
        return network.payload_of(item)

    def get_nowait(self) -> object:
        return self.get()

    def empty(self) -> bool:
        return not self._items


class _Check:
    """A channel out of the replayed role: compares (recorded) or counts (not recorded)."""

    def __init__(self, network: ReplayNetwork, peer: str, recorded: bool = True) -> None:
        self._network = network
        self._peer = peer
        self.recorded = recorded
        self.sent = 0

    def put(self, item: object) -> None:
        if type(item) is not tuple:  # a signal: nobody reads it
            return
        if self.recorded:
            self._network.delivered(self._peer, item[0], item[1])
        else:
            self.sent += 1

    def get(self, *, timeout: float | None = None) -> object:
        raise queue.Empty  # only the replayed role's peers would read it, and they are not here

    def get_nowait(self) -> object:
        raise queue.Empty

    def empty(self) -> bool:
        return True


class _Rings:
    """The replayed role's doorbell: one ring per recorded input, in recorded order."""

    def __init__(self, network: ReplayNetwork, order: list[str]) -> None:
        self._network = network
        self._order = deque(order)

    def put(self, sender: str) -> None:
        self._order.append(sender)

    def get(self, *, timeout: float | None = None) -> str:
        network = self._network
        with network._lock:  # branch threads may wait together
            if network.ending is not None:
                raise RoleStopped(network.detail())
            if self._order:
                return self._order.popleft()
        cuts = [feed.cut for feed in network.feeds.values() if feed.cut is not None]
        if cuts:  # the next input may be one the recording lost: as _Feed.get
            network.turnstile.take_before(min(cuts), network.role)
        else:
            network.turnstile.take(BEYOND, network.role)  # the role's other threads do what they did first
        with network._lock:
            if network.ending is not None:
                raise RoleStopped(network.detail())
            if self._order:
                return self._order.popleft()
        unrecorded = sorted(f"{peer}->{network.role}" for peer, feed in network.feeds.items()
                            if feed.unrecorded is not None)
        lost = sorted(f"{peer}->{network.role}" for peer, feed in network.feeds.items() if feed.cut is not None)
        also = "".join(f" ({', '.join(names)} {what})" for names, what in (
            (unrecorded, "not recorded"), (lost, "cut short")) if names)
        raise network.end(RECORDING_ENDS, f"the recording ends here: {network.role}{network.state()} waits for a "
                                    f"message from any peer, and every recorded one has been delivered{also}")

    def get_nowait(self) -> str:
        with self._network._lock:
            if not self._order:
                raise queue.Empty
            return self._order.popleft()

    def qsize(self) -> int:
        return 0  # the endpoint never drains these rings: each stands for one recorded message
