"""The live view in the supervisor: a Foxglove WebSocket server fed by the groups' taps.

:func:`open_live_view` starts the server, a channel tap (:mod:`anodize.taps`);
``System.run(taps=[view])`` then advertises
every label of every channel on it (ROS 2 schemas: ``ros2msg`` definitions, CDR
messages, so Foxglove's image, pose, path and plot panels read them), forwards
what the groups tap (:mod:`.tap`), publishes each group's state, rate and memory
on :data:`~.plan.STATUS_TOPIC` (JSON), and hands what clients publish on a
channel's topic to the role that sends on it (:mod:`.inputs`), once it is checked
against the label's type: a message that is not is rejected, counted and logged.

The live view is the least critical thing in a run, and is bounded so that no client
can make it hurt a group: the threads that read the groups' taps never wait for a
client (they leave messages in a bounded :class:`~.outbox.Outbox`); one publisher
thread hands them to the SDK, which holds at most :data:`CLIENT_BACKLOG` messages per
client (its oldest go first); every thread of the view, the SDK's included, runs at
the side-work priority (:func:`~anodize._isolation.sched.side_work_priority`: 5 nice
steps below a supervisor that is not real time).
What was not shown is counted per topic, on the status topic as the run goes and in
the run's report at its end.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import socket
import tempfile
import threading
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .._extras import import_extra
from .._isolation.sched import side_work_priority, start_side_work_thread
from .._recording.encoding import SortCodec, codec_for_sort
from .._session.logs import LogEntry
from .._session.payloads import validator_for
from ..errors import AnodizeError
from ..taps import TapRun
from .gate import SUBPROTOCOL, Handshake, SubprotocolGate, describe_offer
from .logs import LOG_SCHEMA, LOG_SCHEMA_NAME, LOG_TOPIC, LogQueue, foxglove_log
from .outbox import Outbox
from .plan import STATUS_TOPIC, LiveLabel, LivePlan, live_plan
from .tap import LARGE, LARGE_RATE, GroupLiveView
from .wire import HELLO, INPUT, MESSAGE, STATS, read_frame, send_frame

__all__ = ["LiveView", "open_live_view", "DEFAULT_PORT", "CLIENT_BACKLOG"]

DEFAULT_PORT = 8765  # Foxglove's default for a WebSocket connection
# Messages the SDK holds for one client at most (its default, 1024, is a gigabyte of images);
# when a client is slower, the SDK drops that client's oldest, not the other clients'.
CLIENT_BACKLOG = 32
_PUBLISH_EVERY = 0.1  # seconds: how often the publisher looks for a new status when nothing came
_PUBLISHED_WITHIN = 5.0  # seconds end() waits for the publisher (side work: a busy machine runs it late)
_log = logging.getLogger("anodize.live")

_STATUS_SCHEMA = {
    "type": "object",
    "properties": {"groups": {"type": "object", "additionalProperties": {
        "type": "object",
        "properties": {"state": {"type": "string"}, "pid": {"type": ["integer", "null"]},
                       "memory_mib": {"type": ["number", "null"]}, "messages": {"type": "integer"},
                       "received": {"type": "integer"}, "rate_hz": {"type": ["number", "null"]},
                       "restarts": {"type": "integer"}, "note": {"type": "string"}}}},
        "live": {"type": "object", "properties": {
            "clients": {"type": "integer"}, "shown": {"type": "integer"},
            "not_shown": {"type": "object", "additionalProperties": {"type": "integer"}}}}},
}

FEATURE = "the live view in Foxglove (--foxglove)"


def open_live_view(port: int = DEFAULT_PORT, host: str = "127.0.0.1") -> LiveView:
    """Start a Foxglove WebSocket server on ``host:port`` (0: any free port; see ``LiveView.port``).

    Raises:
        MissingExtraError: foxglove-sdk is not installed (``anodize[live]``).
        AnodizeError: the port cannot be had.
    """
    import_extra("foxglove.websocket", "live", FEATURE)
    import foxglove
    from foxglove.websocket import Capability, ServerListener

    before = _threads()
    view = LiveView()

    class Listener(ServerListener):
        """Client channels and messages, to the view (the SDK's defaults for the rest)."""

        def on_subscribe(self, client: Any, channel: Any) -> None:
            view.subscribed(client.id, channel.topic, True)

        def on_unsubscribe(self, client: Any, channel: Any) -> None:
            view.subscribed(client.id, channel.topic, False)

        def on_client_advertise(self, client: Any, channel: Any) -> None:
            view.client_advertised(client.id, channel.id, channel.topic, channel.encoding, channel.schema_name or "")

        def on_client_unadvertise(self, client: Any, client_channel_id: int) -> None:
            view.client_unadvertised(client.id, client_channel_id)

        def on_message_data(self, client: Any, client_channel_id: int, data: bytes) -> None:
            view.client_message(client.id, client_channel_id, data)

    try:
        # The SDK's server on the loopback, behind the gate on host:port (its module says why).
        view.server = foxglove.start_server(
            name="anodize", host="127.0.0.1", port=0, context=view.context, server_listener=Listener(),
            capabilities=[Capability.ClientPublish], supported_encodings=["cdr"],
            message_backlog_size=CLIENT_BACKLOG)
        view.gate = SubprotocolGate(host, port, ("127.0.0.1", int(view.server.port)), view.refused, view.lower)
    except Exception as error:  # the SDK's own error type, or OSError: e.g. the port is taken
        view.close()
        raise AnodizeError(f"the live view cannot serve on {host}:{port}: {error}") from None
    view.host = host
    # The SDK's threads (its runtime's workers, started with the first server of the process, and
    # named tokio-*): below every group too. Threads they start later inherit their scheduling class.
    for tid in sorted(_threads() - before | {t for t in _threads() if _thread_name(t).startswith("tokio-")}):
        view.lower(tid)
    return view


def _threads() -> set[int]:
    """The native ids of this process's threads (Linux; elsewhere none are known)."""
    try:
        return {int(name) for name in os.listdir("/proc/self/task")}
    except OSError:
        return set()


def _thread_name(tid: int) -> str:
    try:
        return Path(f"/proc/self/task/{tid}/comm").read_text(encoding="utf-8").strip()
    except OSError:
        return str(tid)


class LiveView:
    """A running Foxglove server for one run (:func:`open_live_view`; :meth:`close` it).

    Attributes:
        port: the port it serves on.
        url: ``ws://host:port``, what the Foxglove app opens.
        outbox: what the groups sent and the publisher has not yet handed to the SDK.
        priorities: thread name -> the scheduling its side work was given.
    """

    def __init__(self) -> None:
        foxglove = import_extra("foxglove", "live", FEATURE)

        self.context = foxglove.Context()
        self.server: Any = None
        self.gate: SubprotocolGate | None = None
        self.refusals: dict[tuple[str, tuple[str, ...]], int] = {}  # (client host, offered) -> connections refused
        self.host = "127.0.0.1"
        self._folder = tempfile.mkdtemp(prefix="anodize-live-")
        self.socket_path = str(Path(self._folder) / "taps")
        self._listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._listener.bind(self.socket_path)
        self._listener.listen()
        self._lock = threading.Lock()
        self.plan: LivePlan | None = None
        self._channels: list[Any] = []            # per label index: its Foxglove channel
        self._codecs: list[SortCodec] = []
        self._status: Any = None
        self._log_channel: Any = None
        self._logs = LogQueue()
        self.logs_shown = 0
        self._groups: dict[str, tuple[socket.socket, threading.Lock]] = {}
        self._connected: set[str] = set()
        self._stats: dict[tuple[str, int], dict[str, Any]] = {}  # (group, connection) -> its tap's latest
        self.outbox = Outbox(large=LARGE)
        self.priorities: dict[str, str] = {}
        self.clients: dict[int, set[str]] = {}  # client -> topics it subscribes to
        self._latest_status: dict[str, Any] | None = None
        self._publisher: threading.Thread | None = None
        self._reading = threading.Condition(self._lock)
        self._readers = 0  # groups' sockets still open
        self._connections = 0  # groups' sockets ever opened
        self.forwarded = 0
        self.client_messages: dict[str, int] = {}  # topic -> delivered to its group
        self.rejected: dict[str, list[int | str]] = {}  # topic -> [count, first reason]
        self._client_channels: dict[tuple[int, int], tuple[str, str, str]] = {}
        self._closed = False

    @property
    def port(self) -> int:
        return self.gate.port if self.gate is not None else 0

    def refused(self, address: str, handshake: Handshake) -> None:
        """A client refused at the gate: one line the first time, then counted for the report."""
        key = (address, handshake.offered if handshake.websocket else ("(plain HTTP)",))
        with self._lock:
            first = all(known != address for known, _ in self.refusals)  # once per client, whatever it offers
            self.refusals[key] = self.refusals.get(key, 0) + 1
        if first:
            _log.warning("foxglove: refused a client at %s: it offered %s, and this live view speaks %s only "
                         "(answered HTTP 400; its further attempts are counted in the report)",
                         address, describe_offer(handshake), SUBPROTOCOL)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    # ---- a run -----------------------------------------------------------------------------
    def begin(self, run: TapRun) -> GroupLiveView:
        """Advertise the run's channels and take the groups' taps (``System.run`` calls it).

        Returns what each group opens: its :class:`~.tap.LiveTap`.
        """
        import foxglove

        if self.plan is not None:
            raise AnodizeError("a live view serves one run: open another for the next")
        plan = live_plan(self.socket_path, run.machines, run.group_of, run.topics)
        by_topic: dict[tuple[str, str], Any] = {}
        for x in plan.labels:
            codec = codec_for_sort(x.sort)
            channel = by_topic.get((x.topic, codec.type_name))
            if channel is None:
                schema = foxglove.Schema(name=codec.type_name, encoding="ros2msg",
                                         data=codec.ros.message_definition().encode())
                channel = by_topic[(x.topic, codec.type_name)] = foxglove.Channel(
                    x.topic, schema=schema, message_encoding="cdr", context=self.context,
                    metadata=_metadata(x, codec, plan))
            self._channels.append(channel)
            self._codecs.append(codec)
        self._status = foxglove.Channel(
            STATUS_TOPIC, message_encoding="json", context=self.context,
            schema=foxglove.Schema(name="anodize.GroupStatuses", encoding="jsonschema",
                                   data=json.dumps(_STATUS_SCHEMA).encode()))
        self._log_channel = foxglove.Channel(
            LOG_TOPIC, message_encoding="json", context=self.context,
            schema=foxglove.Schema(name=LOG_SCHEMA_NAME, encoding="jsonschema", data=json.dumps(LOG_SCHEMA).encode()))
        self.plan = plan
        threading.Thread(target=self._accept_loop, name="anodize-live-accept", daemon=True).start()
        self._publisher = threading.Thread(target=self._publish_loop, name="anodize-live-publish", daemon=True)
        self._publisher.start()
        return GroupLiveView(plan)

    def lower(self, tid: int | None = None) -> None:
        """Put a thread of the view (None: the calling one) below every group; note what was applied."""
        applied = side_work_priority(tid)
        with self._lock:
            self.priorities[threading.current_thread().name if tid is None else _thread_name(tid)] = applied

    def subscribed(self, client: int, topic: str, on: bool) -> None:
        """A client (un)subscribed to ``topic`` (the SDK's listener calls it)."""
        with self._lock:
            topics = self.clients.setdefault(client, set())
            if on:
                topics.add(topic)
            else:
                topics.discard(topic)

    def not_shown(self) -> dict[str, int]:
        """Per topic, the messages the live view did not show: thinned or dropped by the groups'
        taps, or dropped by the server's outbox."""
        plan = self.plan
        if plan is None:
            return {}
        found: dict[str, int] = {}

        def add(index: int, count: int) -> None:
            if 0 <= index < len(plan.labels) and count:
                topic = plan.labels[index].topic
                found[topic] = found.get(topic, 0) + count
        for index, count in list(self.outbox.dropped.items()):
            add(index, count)
        for stats in list(self._stats.values()):
            for index, counts in dict(stats.get("labels", {})).items():
                add(int(index), sum(int(n) for n in counts))
        return found

    def status(self, statuses: Mapping[str, Any]) -> None:
        """Publish the groups' :class:`~anodize._supervision.report.GroupStatus` on the status channel
        (by the publisher: the caller, the supervisor, never waits for a client)."""
        if self._status is None:
            return
        groups = {name: {"state": str(s.state), "pid": s.pid,
                         "memory_mib": None if s.memory is None else round(max(0, s.memory) / 2**20, 2),
                         "messages": s.messages, "received": s.received, "rate_hz": s.rate_hz,
                         "restarts": s.restarts, "note": s.note}
                  for name, s in statuses.items()}
        self._latest_status = {"groups": groups}

    def log(self, entries: Sequence[LogEntry]) -> None:
        """The roles' log records: published on ``/rosout`` as ``foxglove.Log`` (by the publisher)."""
        self._logs.put(entries)

    def _publish_loop(self) -> None:
        """Hand what the groups sent, and the latest status, to the SDK (and so to the clients)."""
        self.lower()
        while True:
            for index, stamp, data in self.outbox.take(_PUBLISH_EVERY):
                with contextlib.suppress(ValueError, OverflowError, TypeError):  # a bad stamp: that one unshown
                    self._channels[index].log(data, log_time=stamp)
                    self.forwarded += 1
            for entry in self._logs.take():
                if self._log_channel is not None:
                    self._log_channel.log(foxglove_log(entry), log_time=int(entry.wall * 1e9))
                    self.logs_shown += 1
            status, self._latest_status = self._latest_status, None
            if status is not None and self._status is not None:
                with self._lock:
                    clients = len(self.clients)
                status["live"] = {"clients": clients, "shown": self.forwarded, "not_shown": self.not_shown()}
                self._status.log(status, log_time=time.time_ns())
            if self.outbox.closed and not self.outbox.held:
                return

    def end(self, wait: float = 1.0) -> list[str]:
        """Notes for the run's report: what was shown, thinned, and taken from clients."""
        plan = self.plan
        if plan is None:
            return []
        with self._reading:  # the groups have ended: their last frames are on their way
            self._reading.wait_for(lambda: self._readers == 0, timeout=wait)
        self.outbox.close()
        if self._publisher is not None:
            self._publisher.join(_PUBLISHED_WITHIN)
        stats = list(self._stats.values())
        thinned = sum(int(s.get("thinned", 0)) for s in stats)
        dropped = sum(int(s.get("dropped", 0)) for s in stats) + sum(self.outbox.dropped.values())
        notes = [f"foxglove: showed {self.forwarded} messages live on {len(set(self._channels))} topics at "
                 f"{self.url} to {len(self.clients)} client(s)"
                 + (f"; {thinned} thinned (large messages at most {LARGE_RATE:g} times a second per topic) and "
                    f"{dropped} dropped (a queue of the live view was full: it shows the newest); the protocol "
                    "keeps every one" if thinned + dropped else "")]
        if self.logs_shown or self._logs.dropped:
            notes.append(f"foxglove: {self.logs_shown} log records on {LOG_TOPIC} ({LOG_SCHEMA_NAME})" + (
                f"; {self._logs.dropped} dropped (the view's log queue was full)" if self._logs.dropped else ""))
        not_shown = self.not_shown()
        if not_shown:
            notes.append("foxglove: not shown, per topic: " + ", ".join(
                f"{topic} {count}" for topic, count in sorted(not_shown.items())))
        if self.priorities:
            applied = sorted(set(self.priorities.values()))
            taps = sorted({str(s.get("priority")) for s in stats if s.get("priority")})
            notes.append(f"foxglove: the live view's {len(self.priorities)} threads ran at {' / '.join(applied)}"
                         + (f", the groups' taps at {' / '.join(taps)}" if taps else "") + " (below every group)")
        groups = set(plan.group_of.values())
        missing = sorted(groups - self._connected)
        if missing:
            notes.append(f"foxglove: groups {', '.join(missing)} did not reach the live view's socket "
                         f"(another host?): their channels were not shown")
        for topic, count in sorted(self.client_messages.items()):
            notes.append(f"foxglove: {count} client messages on {topic} handed to their role")
        for topic, (rejected, reason) in sorted(self.rejected.items()):
            notes.append(f"foxglove: {rejected} client messages on {topic} rejected; the first: {reason}")
        for (address, offered), count in sorted(self.refusals.items()):
            what = ", ".join(offered) or "no subprotocol"
            notes.append(f"foxglove: refused {count} connection(s) from {address}, which offered {what} "
                         f"(the live view speaks {SUBPROTOCOL})")
        return notes

    def close(self) -> None:
        """Stop the server and remove its socket."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(OSError):
            self._listener.shutdown(socket.SHUT_RDWR)
        self._listener.close()
        self.outbox.close()
        with self._lock:
            for sock, _ in self._groups.values():
                with contextlib.suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
        if self.server is not None:  # first: what it sent reaches the clients through the gate
            if self.gate is not None:
                self.gate.settle()  # the SDK drops, when stopped, what it has not yet written
            self.server.stop()
        if self.gate is not None:
            self.gate.close()
        shutil.rmtree(self._folder, ignore_errors=True)

    # ---- the groups' taps -------------------------------------------------------------------
    def _accept_loop(self) -> None:
        self.lower()
        while True:
            try:
                sock, _ = self._listener.accept()
            except OSError:  # closed
                return
            with self._lock:
                self._readers += 1
                connection = self._connections = self._connections + 1
            start_side_work_thread(self._read_group, f"anodize-live-group-{connection}", (sock, connection))

    def _read_group(self, sock: socket.socket, connection: int) -> None:
        self.lower()
        group = None
        # Stats that are not JSON end this group's feed, never the count of readers that end() waits for.
        with contextlib.suppress(OSError, ValueError, OverflowError, TypeError), sock:
            while (frame := read_frame(sock)) is not None:
                kind, index, stamp, data = frame
                if kind == MESSAGE and 0 <= index < len(self._channels):
                    self.outbox.put(index, stamp, data)  # never waits: the publisher hands it on
                elif kind == HELLO:
                    group = data.decode(errors="replace")
                    with self._lock:
                        self._groups[group] = (sock, threading.Lock())  # a restarted group replaces it
                        self._connected.add(group)
                elif kind == STATS:  # the tap's counts so far (a later one replaces it)
                    self._stats[(group or "?", connection)] = json.loads(data)
        with self._reading:
            if group is not None and self._groups.get(group, (None,))[0] is sock:
                del self._groups[group]
            self._readers -= 1
            self._reading.notify_all()

    # ---- clients ---------------------------------------------------------------------------
    def client_advertised(self, client: int, channel: int, topic: str, encoding: str, schema_name: str) -> None:
        self._client_channels[(client, channel)] = (topic, encoding, schema_name)

    def client_unadvertised(self, client: int, channel: int) -> None:
        self._client_channels.pop((client, channel), None)

    def client_message(self, client: int, channel: int, data: bytes) -> None:
        """A client's message: checked against each label on its topic, then handed to the
        label's sender's group."""
        advertised = self._client_channels.get((client, channel))
        plan = self.plan
        if advertised is None or plan is None:
            return
        topic, encoding, schema_name = advertised
        targets = [(i, x) for i, x in enumerate(plan.labels) if x.topic == topic and x.sender in plan.group_of]
        if not targets:
            self._reject(topic, "no role of the run sends on this topic")
            return
        for index, x in targets:
            reason = self._check(index, x, encoding, schema_name, data)
            if reason is not None:
                self._reject(topic, reason)
                continue
            with self._lock:
                found = self._groups.get(plan.group_of[x.sender])
            if found is None:
                continue  # its group is not running (yet, or any more)
            sock, lock = found
            with lock, contextlib.suppress(OSError):
                send_frame(sock, INPUT, index, time.time_ns(), data)
                self.client_messages[topic] = self.client_messages.get(topic, 0) + 1

    def _check(self, index: int, x: LiveLabel, encoding: str, schema_name: str, data: bytes) -> str | None:
        codec = self._codecs[index]
        if encoding != "cdr":
            return f"expected encoding cdr, got {encoding!r}"
        if schema_name and schema_name != codec.type_name:
            return f"expected {codec.type_name}, got {schema_name}"
        try:
            payload = codec.decode(data)
        except Exception as error:  # a client's bytes: anything may be wrong with them
            return f"{type(error).__name__}: {error}"
        reason = validator_for(x.sort)(payload)
        return None if reason is None else f"not a {x.sort.spelling if x.sort else 'message'}: {reason}"

    def _reject(self, topic: str, reason: str) -> None:
        first = self.rejected.setdefault(topic, [0, reason])
        if first[0] == 0:
            _log.warning("live view: a client message on %s rejected: %s", topic, reason)
        first[0] = int(first[0]) + 1


def _metadata(x: LiveLabel, codec: SortCodec, plan: LivePlan) -> dict[str, str]:
    return {"anodize.sender": x.sender, "anodize.receiver": x.receiver, "anodize.label": x.label,
            "anodize.sort": x.sort.key if x.sort is not None else "",
            "anodize.encoding": "json" if codec.json else "cdr",
            "anodize.sender_group": plan.group_of.get(x.sender, "external"),
            "anodize.receiver_group": plan.group_of.get(x.receiver, "external")}
