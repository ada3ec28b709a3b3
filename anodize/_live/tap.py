"""The live view inside a group: the channels it taps, and the thread that forwards them.

Each tapped channel is wrapped (:class:`LiveChannel`). A message is encoded in the
sending thread, as it leaves (once put, an array in a shared slot is the receiver's),
but only when the live view wants it: a label whose last message was large (more than
:data:`LARGE` bytes, e.g. a camera image) is shown at most :data:`LARGE_RATE` times a
second, and the others skip the encoding. Nothing in the sending thread waits: the
message is left for a thread of the group at ordinary priority, which sends it to the
supervisor; large messages wait there in one slot per label (a newer one replaces
it), small ones in a bounded queue (the oldest go first when it is full). The live
view may thus skip messages, counted per label and sent to the supervisor every
:data:`STATS_EVERY` seconds; the protocol and a recording (``--record``) never do. The
tap's threads run at the side-work priority (SCHED_FIFO 1 in a real-time group, else
5 nice steps below the group: :func:`~anodize._isolation.sched.side_work_priority`).

Introspection (``anodize echo|hz``) taps every channel the same way, on demand
(:attr:`~.plan.LivePlan.on_demand`): a label is forwarded only while the supervisor wants
it (a :data:`~.wire.WANT` frame sets one byte the sending thread reads), as a message
(echo) or as its time alone (hz, and for echo the messages thinned); otherwise the
sending thread only counts it, and the counts go with the stats.
"""

from __future__ import annotations

import contextlib
import json
import socket
import threading
import time
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

from .._isolation.sched import side_work_priority
from .._recording.encoding import SortCodec, codec_for_sort
from .._recording.tap import TappedChannel
from .._session.channel import Channel
from ..taps import TapGroup
from .inputs import ClientInput, register_input, unregister_input
from .plan import LivePlan
from .wire import HELLO, INPUT, MESSAGE, STATS, WANT, read_frame, send_frame

__all__ = ["GroupLiveView", "LiveTap", "LiveChannel", "LARGE", "LARGE_RATE", "QUEUE", "WANT_TIMES",
           "WANT_MESSAGES"]

LARGE = 4096       # bytes: a message above this is thinned, and waits in its label's one slot
LARGE_RATE = 10.0  # messages per second a large label is shown at, at most
QUEUE = 4096       # small messages waiting to be forwarded, at most (<= 16 MiB)
_SEND_EVERY = 0.02  # seconds: how often the forwarding thread looks when nothing woke it
STATS_EVERY = 1.0  # seconds between the counts a tap sends the supervisor
CLOSE_WITHIN = 0.5  # seconds a closing tap waits for its thread (its group keeps beating meanwhile)
WANT_TIMES = 1     # on demand: a label's times are wanted (hz); forwarded with no data
WANT_MESSAGES = 2  # on demand: its messages are wanted (echo); a thinned one goes as its time alone


@dataclass(frozen=True)
class GroupLiveView:
    """The live view's :class:`~anodize.taps.GroupTapPlan`: each group opens a :class:`LiveTap`."""

    plan: LivePlan

    def open(self, group: TapGroup) -> LiveTap:
        """The group's tap, connected to the supervisor's socket."""
        return LiveTap(self.plan, group.name, group.machines)


class LiveTap:
    """One group's tap; :meth:`attach` it to the group's network, :meth:`close` at the end.

    If the supervisor's socket cannot be reached, the tap does nothing (the live view
    is for watching; the run goes on) and the supervisor's report names the group.
    """

    def __init__(self, plan: LivePlan, group: str, roles: Iterable[str]) -> None:
        self.plan = plan
        roles = set(roles)
        self.tapped = plan.tapped_here(roles)
        self._codecs: dict[int, SortCodec] = {}
        self._next_at: dict[int, float] = {}        # label -> when it may be shown again
        self._small: deque[tuple[int, int, bytes]] = deque(maxlen=QUEUE)
        self._large: dict[int, tuple[int, bytes]] = {}
        self._wake = threading.Event()
        self._closing = False
        self.shown = self.thinned = self.dropped = self.unencodable = 0
        self._by_label: dict[int, list[int]] = {}  # label -> [thinned, dropped]
        self.priority = ""  # what side_work_priority applied to the forwarding thread
        self.wanted = bytearray(len(plan.labels))  # on demand: per label, WANT_TIMES, WANT_MESSAGES or 0
        self.seen = [0] * len(plan.labels) if plan.on_demand else []  # on demand: per label, messages so far
        self.inputs = [] if plan.on_demand else [
            ClientInput(x, codec_for_sort(x.sort)) for x in plan.labels if x.sender in roles]
        self._sock: socket.socket | None = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            self._sock.connect(plan.socket)
            send_frame(self._sock, HELLO, 0, 0, group.encode())
        except OSError:  # not reachable (another host): the run goes on unshown, the report says so
            self._sock.close()
            self._sock = None
            return
        for found in self.inputs:
            register_input(found)
        self._sender = threading.Thread(target=self._send_loop, name=f"anodize-live:{group}", daemon=True)
        self._sender.start()
        threading.Thread(target=self._read_loop, name=f"anodize-live-in:{group}", daemon=True).start()

    def attach(self, queues: dict[tuple[str, str], Channel]) -> None:
        """Wrap the tapped channels among ``queues`` (in place)."""
        if self._sock is None:
            return
        for pair, end in self.tapped.items():
            channel = queues.get(pair)
            if channel is None:
                continue
            queues[pair] = LiveChannel(channel, self, pair, tap_puts=(end == "send"))

    def offer(self, pair: tuple[str, str], label: str, payload: object) -> None:
        """A message of channel ``pair`` leaving (or arriving): shown unless it is thinned."""
        index = self.plan.index.get((*pair, label))
        if index is None or self._closing:
            return
        if self.plan.on_demand:
            self.seen[index] += 1
            wanted = self.wanted[index]
            if not wanted:  # nobody looks: a count, nothing more
                return
            if wanted == WANT_TIMES:
                self._put_small(index, time.time_ns(), b"")
                return
        now = time.monotonic()
        if now < self._next_at.get(index, 0.0):
            self.thinned += 1
            self._counts(index)[0] += 1
            if self.plan.on_demand:  # its time still counts for a rate
                self._put_small(index, time.time_ns(), b"")
            return
        try:
            data = self._codec(index).encode(payload)
        except Exception:  # not the role's problem (possible only without monitors): not shown
            self.unencodable += 1
            return
        stamp = time.time_ns()
        if len(data) > LARGE:
            self._next_at[index] = now + 1.0 / LARGE_RATE
            if self._large.get(index) is not None:
                self.dropped += 1
                self._counts(index)[1] += 1
            self._large[index] = (stamp, data)
        else:
            self._next_at.pop(index, None)
            self._put_small(index, stamp, data)
            return
        if not self._wake.is_set():
            self._wake.set()

    def _put_small(self, index: int, stamp: int, data: bytes) -> None:
        if len(self._small) == QUEUE:
            self.dropped += 1
            self._counts(self._small[0][0])[1] += 1  # the oldest goes
        self._small.append((index, stamp, data))  # deque.append: atomic, no lock to wait for
        if not self._wake.is_set():
            self._wake.set()

    def _counts(self, index: int) -> list[int]:
        found = self._by_label.get(index)
        if found is None:
            found = self._by_label[index] = [0, 0]
        return found

    def _stats(self) -> bytes:
        return json.dumps({"shown": self.shown, "thinned": self.thinned, "dropped": self.dropped,
                           "unencodable": self.unencodable, "priority": self.priority,
                           "labels": {str(i): list(c) for i, c in list(self._by_label.items())},
                           "inputs": {x.label.topic: [x.received, x.rejected] for x in self.inputs},
                           "seen": list(self.seen)}).encode()

    def _codec(self, index: int) -> SortCodec:
        codec = self._codecs.get(index)
        if codec is None:
            codec = self._codecs[index] = codec_for_sort(self.plan.labels[index].sort)
        return codec

    def _send_loop(self) -> None:
        self.priority = side_work_priority()  # below every role: it inherited the group's priority
        sock = self._sock
        assert sock is not None
        stats_at = time.monotonic() + STATS_EVERY
        try:
            while True:
                self._wake.wait(_SEND_EVERY)
                self._wake.clear()
                closing = self._closing
                while self._small:
                    index, stamp, data = self._small.popleft()
                    send_frame(sock, MESSAGE, index, stamp, data)
                    self.shown += 1
                while self._large:
                    index, (stamp, data) = self._large.popitem()
                    send_frame(sock, MESSAGE, index, stamp, data)
                    self.shown += 1
                if closing or time.monotonic() >= stats_at:
                    send_frame(sock, STATS, 0, time.time_ns(), self._stats())  # its time: for rates
                    stats_at = time.monotonic() + STATS_EVERY
                if closing:
                    return
        except OSError:  # the supervisor went away: nothing more to show
            self._closing = True

    def _read_loop(self) -> None:
        side_work_priority()
        sock = self._sock
        assert sock is not None
        by_index = {self.plan.index[(x.label.sender, x.label.receiver, x.label.label)]: x for x in self.inputs}
        with contextlib.suppress(OSError):
            while (frame := read_frame(sock)) is not None:
                kind, index, stamp, data = frame
                found = by_index.get(index)
                if kind == INPUT and found is not None:
                    found.deliver(data)  # checked by the supervisor already; a failure is only counted
                elif kind == WANT and 0 <= index < len(self.wanted):
                    self.wanted[index] = min(max(stamp, 0), WANT_MESSAGES)

    def close(self) -> None:
        """Forward what is waiting and what was thinned, and disconnect."""
        for found in self.inputs:
            unregister_input(found)
        if self._sock is None:
            return
        self._closing = True
        self._wake.set()
        self._sender.join(timeout=CLOSE_WITHIN)  # a slow supervisor: the last counts are not waited for
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._sock.close()


class LiveChannel(TappedChannel):
    """A channel whose messages are also shown live."""

    def __init__(self, inner: Channel, tap: LiveTap, pair: tuple[str, str], tap_puts: bool) -> None:
        super().__init__(inner, pair, tap_puts)
        self._tap = tap

    def leaving(self, label: str, payload: object) -> object:
        self._tap.offer(self._pair, label, payload)
        return None
