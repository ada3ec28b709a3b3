"""Introspection of a running system: what ``anodize ps|status|channels|echo|hz`` ask a run.

:class:`Introspection` is a channel tap (:mod:`anodize.taps`) that ``anodize run`` always
installs. It answers clients on the run's socket (:mod:`.runs`: only the same user's) with
one JSON request line each, and JSON lines back:

- ``{"op": "info"}``: the run (id, pid, system, started, transport, groups, state);
- ``{"op": "status"}``: each group's :class:`~anodize.GroupStatus` (roles, rates,
  high-water marks, scheduling), as the supervisor last had it;
- ``{"op": "channels"}``: every label of every channel, its topic, sort, messages so far
  and rate;
- ``{"op": "echo"|"hz", "channel": C}``: a stream of the messages (or only their times)
  of the labels ``C`` names (``Sender->Receiver:label``, ``Sender->Receiver`` or a topic),
  with a beat every second (:mod:`.watchers`).

The groups tap every channel with the live view's tap (:class:`~.tap.LiveTap`) on
demand: it counts each message and forwards nothing until a client watches a label
(docs/decisions, "introspection"). Every thread here runs at the side-work priority.
"""

from __future__ import annotations

import contextlib
import datetime
import itertools
import json
import os
import socket
import threading
from collections import deque
from collections.abc import Mapping
from typing import Any

from .._isolation.sched import side_work_priority, start_side_work_thread
from .._recording.encoding import SortCodec, codec_for_sort
from ..errors import MissingExtraError
from ..taps import TapRun
from .plan import LivePlan, live_plan
from .runs import in_use, listen, run_dir, run_id, same_user, socket_path, taps_path
from .tap import WANT_MESSAGES, WANT_TIMES, GroupLiveView
from .watchers import Watcher
from .wire import HELLO, MESSAGE, STATS, WANT, read_frame, send_frame

__all__ = ["Introspection", "REQUEST_BYTES", "RATE_WINDOW"]

REQUEST_BYTES = 4096  # a request line's length at most
REQUEST_WITHIN = 5.0  # seconds a client has to send its request
RATE_WINDOW = 3.0     # seconds a channel's rate is measured over (its group's tap counts every second)


class Introspection:
    """A run's introspection server: :meth:`begin` it with the run (as a tap), :meth:`close` it after.

    Args:
        name: the system's name (its run id is ``<name>-<pid>``).
        source: the system file, or the named system.

    Raises:
        AnodizeError: the runs' directory is not this user's alone.
        OSError: the socket cannot be made.
    """

    def __init__(self, name: str, source: str = "") -> None:
        folder = run_dir(create=True)
        self.run = run_id(name, os.getpid())
        self.path = socket_path(self.run, folder)
        for again in itertools.count(2):  # a second run of this process at once: <name>.2-<pid>
            if not in_use(self.path):
                break
            self.run = run_id(f"{name}.{again}", os.getpid())
            self.path = socket_path(self.run, folder)
        self._taps_path = taps_path(self.run, folder)
        self._listener = listen(self.path)
        self._taps: socket.socket | None = None
        self._lock = threading.Lock()
        self.info: dict[str, Any] = {
            "run": self.run, "pid": os.getpid(), "system": name, "source": source,
            "started": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
            "transport": "", "protocol": "", "groups": [], "state": "starting"}
        self.plan: LivePlan | None = None
        self._ros_topics: set[tuple[str, str, str]] = set()
        self._codecs: list[SortCodec] = []
        self._names: list[str] = []
        self._statuses: dict[str, Any] = {}
        self._groups: dict[int, tuple[socket.socket, threading.Lock]] = {}  # connection -> its socket
        self._stats: dict[int, dict[str, Any]] = {}  # connection -> its tap's latest stats
        self._connections = 0
        self._samples: dict[int, deque[tuple[int, list[int]]]] = {}  # connection -> (time, its counts per label)
        self._watchers: dict[int, list[Watcher]] = {}  # label -> who watches it
        self._wanted: dict[int, int] = {}  # label -> what the groups forward of it now
        self.clients = 0
        self.watchers: list[Watcher] = []  # every client that watched labels, for the report's note
        self._closed = False
        threading.Thread(target=self._accept_clients, name="anodize-introspect", daemon=True).start()

    # ---- the run (a channel tap) -----------------------------------------------------------
    def begin(self, run: TapRun) -> GroupLiveView:
        """The run begins: take the groups' taps (on demand) on the run's taps socket."""
        self._taps = listen(self._taps_path)
        plan = live_plan(str(self._taps_path), run.machines, run.group_of, run.topics, on_demand=True)
        with self._lock:
            self._ros_topics = set(run.topics)
            self._names = [f"{x.sender}->{x.receiver}:{x.label}" for x in plan.labels]
            self.info.update(transport=run.transport, protocol=run.global_type.name,
                             groups=sorted(set(run.group_of.values())), state="running")
            self.plan = plan
        threading.Thread(target=self._accept_groups, args=(self._taps,), name="anodize-introspect-taps",
                         daemon=True).start()
        return GroupLiveView(plan)

    def status(self, statuses: Mapping[str, Any]) -> None:
        """Keep the groups' latest status."""
        groups = {name: {"state": str(s.state), "pid": s.pid, "memory": s.memory, "messages": s.messages,
                         "received": s.received, "rate_hz": s.rate_hz, "restarts": s.restarts, "note": s.note,
                         "roles": dict(s.roles), "sent": dict(s.sent), "high_water": dict(s.high_water),
                         "scheduling": s.scheduling} for name, s in statuses.items()}
        with self._lock:
            self._statuses = groups

    def end(self) -> list[str]:
        """The run is over: the watchers stop; a note if anyone looked."""
        with self._lock:
            self.info["state"] = "ended"
            watchers = [w for found in self._watchers.values() for w in found]
        for watcher in watchers:
            watcher.close()
        if not self.clients:
            return []
        dropped = sum(w.dropped for w in self.watchers)
        return [f"introspection: answered {self.clients} client(s) at {self.path}"
                + (f"; {dropped} messages dropped for clients that read slower than the run sent" if dropped else "")]

    def close(self) -> None:
        """Stop serving and remove the run's sockets."""
        if self._closed:
            return
        self._closed = True
        for listener, path in ((self._listener, self.path), (self._taps, self._taps_path)):
            if listener is not None:
                with contextlib.suppress(OSError):
                    listener.shutdown(socket.SHUT_RDWR)
                listener.close()
            with contextlib.suppress(OSError):
                path.unlink()
        with self._lock:
            watchers = [w for found in self._watchers.values() for w in found]
            groups = list(self._groups.values())
        for watcher in watchers:
            watcher.close()
            with contextlib.suppress(OSError):
                watcher.sock.shutdown(socket.SHUT_RDWR)
        for sock, _ in groups:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)

    # ---- the groups' taps ------------------------------------------------------------------
    def _accept_groups(self, listener: socket.socket) -> None:
        side_work_priority()
        while True:
            try:
                sock, _ = listener.accept()
            except OSError:  # closed
                return
            if not same_user(sock):
                sock.close()
                continue
            with self._lock:
                connection = self._connections = self._connections + 1
            start_side_work_thread(self._read_group, f"anodize-introspect-group-{connection}", (sock, connection))

    def _read_group(self, sock: socket.socket, connection: int) -> None:
        side_work_priority()
        with contextlib.suppress(OSError, ValueError, OverflowError, TypeError), sock:
            while (frame := read_frame(sock)) is not None:
                kind, index, stamp, data = frame
                if kind == MESSAGE:
                    for watcher in self._watchers.get(index, ()):
                        watcher.offer(index, stamp, data)  # never waits for the client
                elif kind == HELLO:
                    lock = threading.Lock()
                    with self._lock:
                        self._groups[connection] = (sock, lock)
                        wanted = dict(self._wanted)
                    with lock:  # what is watched already (a group started late, or again)
                        for label, mode in wanted.items():
                            send_frame(sock, WANT, label, mode, b"")
                elif kind == STATS:
                    stats = json.loads(data)
                    with self._lock:
                        self._stats[connection] = stats
                        samples = self._samples.setdefault(connection, deque())
                        samples.append((stamp, [int(n) for n in stats.get("seen", ())]))
                        while len(samples) > 2 and stamp - samples[1][0] >= RATE_WINDOW * 1e9:
                            samples.popleft()
        with self._lock:
            self._groups.pop(connection, None)
            self._samples.pop(connection, None)  # a group gone has no rate (its counts stay in the totals)

    def _seen(self) -> list[int]:
        """Messages so far per label (every group's tap, every incarnation); under the lock."""
        total = [0] * len(self._names)
        for stats in self._stats.values():
            for index, count in enumerate(stats.get("seen", ())[:len(total)]):
                total[index] += int(count)
        return total

    def _rates(self) -> dict[int, float]:
        """Messages per second per label over the last :data:`RATE_WINDOW` seconds of the taps'
        counts (each group's tap counts the labels it taps); under the lock."""
        rates: dict[int, float] = {}
        for samples in self._samples.values():
            if len(samples) < 2 or samples[-1][0] <= samples[0][0]:
                continue
            (then, before), (now, after) = samples[0], samples[-1]
            for index, (a, b) in enumerate(zip(before, after, strict=False)):
                if b > a or index not in rates:
                    rates[index] = rates.get(index, 0.0) + (b - a) / ((now - then) / 1e9)
        return rates

    def _tap_losses(self, labels: list[int]) -> int:
        """What the groups' taps did not forward of ``labels`` so far (their queues were full)."""
        with self._lock:
            return sum(int(counts[1]) for stats in self._stats.values()
                       for index, counts in dict(stats.get("labels", {})).items() if int(index) in labels)

    def _want(self, labels: list[int]) -> None:
        """Tell the groups what is wanted of ``labels`` now. The change is decided under the
        lock; the frames go out after it, so a group slow to read holds up no status."""
        with self._lock:
            changed = []
            for label in labels:
                mode = max((w.mode for w in self._watchers.get(label, ())), default=0)
                if self._wanted.get(label, 0) != mode:
                    self._wanted[label] = mode
                    changed.append((label, mode))
            groups = list(self._groups.values())
        for sock, lock in groups:
            with lock, contextlib.suppress(OSError):
                for label, mode in changed:
                    send_frame(sock, WANT, label, mode, b"")

    # ---- clients ---------------------------------------------------------------------------
    def _accept_clients(self) -> None:
        side_work_priority()
        while True:
            try:
                sock, _ = self._listener.accept()
            except OSError:  # closed
                return
            start_side_work_thread(self._serve_client, "anodize-introspect-client", (sock,))

    def _serve_client(self, sock: socket.socket) -> None:
        side_work_priority()
        with contextlib.suppress(OSError), sock:
            if not same_user(sock):
                _answer(sock, {"error": f"refused: this run answers only uid {os.getuid()}"})
                return
            sock.settimeout(REQUEST_WITHIN)
            try:
                request = json.loads(_request_line(sock))
                op = str(request.get("op", ""))
            except (ValueError, AttributeError):
                _answer(sock, {"error": "expected one JSON request line, e.g. {\"op\": \"info\"}"})
                return
            sock.settimeout(None)
            with self._lock:
                self.clients += 1
            if op in ("echo", "hz"):
                self._watch(sock, str(request.get("channel", "")), WANT_MESSAGES if op == "echo" else WANT_TIMES)
            else:
                _answer(sock, self._answer(op))

    def _answer(self, op: str) -> dict[str, Any]:
        with self._lock:
            if op == "info":
                return dict(self.info)
            if op == "status":
                return {"run": dict(self.info), "groups": self._statuses}
            if op == "channels":
                return {"run": dict(self.info), "channels": self._channels()}
        return {"error": f"unknown request {op!r}; expected info, status, channels, echo or hz"}

    def _channels(self) -> list[dict[str, Any]]:
        """Every label of the run, with its messages so far and rate; under the lock."""
        plan = self.plan
        if plan is None:
            return []
        seen = self._seen()
        rates = self._rates()
        found = []
        for index, x in enumerate(plan.labels):
            rate = rates.get(index)
            found.append({"channel": self._names[index],
                          "topic": x.topic if (x.sender, x.receiver, x.label) in self._ros_topics else "",
                          "type": x.sort.spelling if x.sort is not None else "",
                          "messages": seen[index], "rate_hz": rate,
                          "groups": [plan.group_of.get(x.sender, "external"),
                                     plan.group_of.get(x.receiver, "external")]})
        return found

    def _labels(self, channel: str) -> list[int]:
        plan = self.plan
        if plan is None:
            return []
        return [i for i, x in enumerate(plan.labels)
                if channel in (self._names[i], f"{x.sender}->{x.receiver}")
                or (channel.startswith("/") and channel == x.topic)]

    def _watch(self, sock: socket.socket, channel: str, mode: int) -> None:
        with self._lock:
            labels = self._labels(channel)
            if not labels:
                some = ", ".join(self._names[:3]) or "none yet: the run has not begun"
                _answer(sock, {"error": f"no channel {channel!r} in run {self.run}; expected Sender->Receiver:label, "
                                        f"Sender->Receiver or a topic (e.g. {some}; see 'anodize channels "
                                        f"{self.run}')"})
                return
            if self.info["state"] == "ended":
                _answer(sock, {"error": f"run {self.run} has ended"})
                return
            if mode == WANT_MESSAGES and not self._codecs:  # made at the first echo: hz needs no extra
                try:
                    self._codecs = [codec_for_sort(x.sort) for x in self.plan.labels] if self.plan else []
                except MissingExtraError as error:
                    _answer(sock, {"error": str(error)})
                    return
            watcher = Watcher(sock, mode, self._names, self._codecs, lambda: self._tap_losses(labels))
            self.watchers.append(watcher)
            for label in labels:
                self._watchers[label] = [*self._watchers.get(label, []), watcher]  # readers iterate the old list
        _answer(sock, {"watching": [self._names[i] for i in labels]})
        self._want(labels)
        try:
            watcher.serve()
        finally:
            with self._lock:
                for label in labels:
                    self._watchers[label] = [w for w in self._watchers.get(label, []) if w is not watcher]
            self._want(labels)


def _request_line(sock: socket.socket) -> str:
    """The client's request: one line of at most :data:`REQUEST_BYTES` bytes."""
    data = b""
    while b"\n" not in data and len(data) < REQUEST_BYTES:
        chunk = sock.recv(REQUEST_BYTES - len(data))
        if not chunk:
            break
        data += chunk
    return data.partition(b"\n")[0].decode("utf-8", errors="replace")


def _answer(sock: socket.socket, answer: dict[str, Any]) -> None:
    sock.sendall((json.dumps(answer, default=str) + "\n").encode())
