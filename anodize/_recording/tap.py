"""Recording inside a group: the channels it records, and the thread that writes its part.

Each recorded channel is wrapped (:class:`RecordingChannel`): a message is encoded
(:mod:`.encoding`) in the sending thread, as it leaves, so what is recorded is what was
sent, even if the sender changes the payload afterwards; a thread of the group writes
it to the group's part file (an MCAP file without chunks, flushed every 0.1 s, so a
group that is killed loses at most its last tenth of a second). That thread runs at
the side-work priority (:func:`~anodize._isolation.sched.side_work_priority`: SCHED_FIFO 1
in a real-time group, else 5 nice steps below the group), below every role of the group, so recording does
not delay the control loop; a sender never touches the disk (channels are registered
in the part by the writer). Its queue is bounded: when it
falls behind by more than :data:`BACKLOG` bytes (an eighth of the group's memory bound,
if that is less), a slow disk say, a sender does not wait for it; the message keeps its
sequence number but is not recorded, and the recording gets a gap record on
:data:`GAP_TOPIC` (the channel, the first missing number, how many) where the message
would have been, so ``anodize verify`` reports a gap of the recording's, not a
violation, and the run's report counts what was lost. When the group ends, the writer
has :data:`CLOSE_WITHIN` seconds to write what is queued; what it has not written by
then becomes a gap too. The supervisor merges the parts when the run ends (:mod:`.merge`).

The recorder also keeps its roles' clocks (:meth:`Recorder.clocks`, which the group gives
its network: :mod:`anodize._session.clock`): each reading a role takes (``Endpoint.now()``,
``Endpoint.wall()``, the end of an ``Endpoint.sleep``) goes on the role's clock channel
(:data:`CLOCK_TOPIC`, metadata :data:`CLOCK_KEY`), numbered and stamped, for
``anodize replay`` to give back; like a message, it never waits for the writer.
"""

from __future__ import annotations

import contextlib
import json
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from sessiontypes import StateMachine

from .._extras import import_extra
from .._isolation.sched import restore_thread_scheduling, side_work_priority, thread_scheduling
from .._session.channel import Channel
from .._session.endpoint import put_each
from .._transport.qos_profiles import RELIABLE_KEEP_ALL
from ..taps import TapGroup
from .chain import ChainedWriter
from .encoding import SortCodec, codec_for_sort
from .plan import CLOCK_KEY, CLOCK_TOPIC, GAP_KEY, GAP_TOPIC, META, PROFILE, ChannelLabel, RecordPlan

__all__ = ["GroupRecording", "Recorder", "RecordingChannel", "TappedChannel", "SEQUENCE_WRAP", "BACKLOG",
           "channel_metadata", "QOS_PROFILES", "GAP_TOPIC", "GAP_KEY", "CLOSE_WITHIN", "open_part",
           "RecordingClock"]

FEATURE = "recording a run (--record)"
BACKLOG = 64 * 2**20  # bytes a group's recorder may hold; beyond it, messages become a gap
SEQUENCE_WRAP = 2**32 - 1  # the largest MCAP sequence number
CLOSE_WITHIN = 1.0    # seconds the writer has, once its group ends, to write what is queued (the
                      # group keeps beating meanwhile, so a longer close is no liveness verdict)
_FLUSH_EVERY = 0.1    # seconds
_BATCH = 64           # messages the writer takes from its queue at a time
_GAP = -1             # in the queue, in place of an MCAP channel: a gap record
_CLOCK = -2           # in the queue, _CLOCK - i: a reading of the clock of the group's i-th role


def open_part(path: Path) -> IO[bytes]:
    """The part file a recorder writes (a seam: tests put a slow disk here)."""
    return path.open("wb")

# What anodize's channels offer, as rosbag2 writes it (metadata version 9): reliable, keep all, volatile.
QOS_PROFILES = RELIABLE_KEEP_ALL.yaml()


def channel_metadata(item: ChannelLabel, codec: SortCodec, protocol: str,
                     group_of: Mapping[str, str]) -> dict[str, str]:
    """The metadata of a recorded label's MCAP channel: rosbag2's keys, then anodize's."""
    sort = item.sort
    return {
        "offered_qos_profiles": QOS_PROFILES,
        "topic_type_hash": codec.ros.type_hash,
        f"{META}.protocol": protocol,
        f"{META}.sender": item.sender,
        f"{META}.receiver": item.receiver,
        f"{META}.label": item.label,
        f"{META}.sort": sort.key if sort is not None else "",
        f"{META}.sort_target": (sort.target or "") if sort is not None else "",
        f"{META}.encoding": "json" if codec.json else "cdr",
        f"{META}.sender_group": group_of.get(item.sender, "external"),
        f"{META}.receiver_group": group_of.get(item.receiver, "external"),
    }


@dataclass(frozen=True)
class GroupRecording:
    """A recording's :class:`~anodize.taps.GroupTapPlan`: each group opens a :class:`Recorder`."""

    plan: RecordPlan

    def open(self, group: TapGroup) -> Recorder:
        """The group's recorder (it writes the group's part of the recording)."""
        return Recorder(self.plan, group.name, group.incarnation, group.protocol, group.machines, group.memory)


class Recorder:
    """One group's recorder; :meth:`attach` it to the group's network, :meth:`close` at the end."""

    def __init__(self, plan: RecordPlan, group: str, incarnation: int, protocol: str,
                 machines: Mapping[str, StateMachine], memory: int | None = None,
                 opener: Callable[[Path], IO[bytes]] | None = None) -> None:
        import_extra("mcap.writer", "record", FEATURE)
        from mcap.writer import CompressionType, Writer

        self.plan = plan
        self.protocol = protocol
        self.recorded = plan.recorded_here(machines)
        self._labels = _local_labels(machines, self.recorded)
        Path(plan.parts).mkdir(parents=True, exist_ok=True)
        self.path = Path(plan.parts) / f"{group}-{incarnation}.mcap"
        self._file = (opener or open_part)(self.path)
        # Every message written is chained (:mod:`.chain`), in this writer's thread, not a sender's.
        self._writer = ChainedWriter(Writer(self._file, use_chunking=False, compression=CompressionType.NONE,
                                            enable_crcs=False), plan.run_id, self.path.stem,
                                     {"offered_qos_profiles": QOS_PROFILES, f"{META}.protocol": protocol})
        self._writer.start(profile=PROFILE, library="anodize")
        self._channels: dict[tuple[str, str, str], tuple[int, SortCodec]] = {}
        self._schemas: dict[str, int] = {}
        self._pending: deque[tuple[int, int, int, bytes]] = deque()
        self._pending_bytes = 0
        # A group with a memory bound spends at most an eighth of it on a backlog.
        self.backlog = BACKLOG if memory is None else max(2**20, min(BACKLOG, memory // 8))
        self._sequence: dict[tuple[str, str], int] = dict.fromkeys(self.recorded, 0)
        self._lock = threading.Condition()
        self._closing = False
        self.written = 0
        self.unrecorded: dict[str, list[int | str]] = {}  # "A->B:label" -> [count, first reason]
        self.broken = ""  # why the writer stopped, if it did
        self._io = threading.Lock()  # the part file's writer: one thread at a time
        self._pair_of: dict[int, tuple[str, str]] = {}  # queued label -> its channel
        self._keys: list[tuple[ChannelLabel, SortCodec]] = []  # queued label -> what it is
        self._mcap: dict[int, int] = {}  # queued label -> its MCAP channel in the part
        self._writing: list[tuple[int, int, int, bytes]] = []  # the batch being written
        self._gaps: dict[tuple[str, str], list[int]] = {}  # channel -> [first number, count, time] not queued
        self.lost: dict[tuple[str, str], int] = {}  # channel -> messages not recorded: the writer was behind
        self._gap_channel: int | None = None
        self._roles = sorted(machines)
        self._clock_sequence = dict.fromkeys(self._roles, 0)
        self._clock_channels: dict[int, int] = {}  # queue number -> the part's MCAP channel
        self.clock_lost: dict[str, int] = {}  # role -> clock readings not recorded (the writer was behind)
        self._give_up = threading.Event()  # close: the disk is too slow to wait for what is queued
        self.priority = ""  # what side_work_priority applied to the writer
        for key in sorted(self._labels):  # codecs made now, not in a role's first send (building one takes time)
            self._register(key)
        self._tid: int | None = None  # the writer's native id, once it runs
        self._group_scheduling: tuple[int, int, int] | None = None
        self._thread = threading.Thread(target=self._write_loop, name=f"anodize-record:{group}", daemon=True)
        self._thread.start()

    def attach(self, queues: dict[tuple[str, str], Channel]) -> None:
        """Wrap the recorded channels among ``queues`` (in place)."""
        for pair, end in self.recorded.items():
            if pair in queues:
                queues[pair] = RecordingChannel(queues[pair], self, pair, at_sender=(end == "send"))

    def clocks(self) -> dict[str, RecordingClock]:
        """The clocks of the group's roles: the machine's, each reading recorded (:mod:`anodize._session.clock`)."""
        return {role: RecordingClock(self, role) for role in self._roles}

    def reading(self, role: str, branch: str, kind: str, value: float) -> None:
        """Record that ``role``'s endpoint ``branch`` read ``value`` from its clock (``kind``: "now"
        or "wall"; "expiry": a deadline passed as it waited), on the role's clock channel; never
        waits (beyond the backlog it is lost, and the channel's numbering shows the gap to a replay)."""
        codec = codec_for_sort(None)  # a JSON String
        data = codec.ros.serialize(codec.ros.cls(data=json.dumps({"branch": branch, kind: value})))
        with self._lock:
            stamp = time.time_ns()  # under the lock: the role's readings are numbered in the order of their times
            sequence = self._clock_sequence[role] = self._clock_sequence[role] % SEQUENCE_WRAP + 1
            if self.broken or self._closing or self._pending_bytes + len(data) > self.backlog:
                self.clock_lost[role] = self.clock_lost.get(role, 0) + 1
                return
            self._pending.append((_CLOCK - self._roles.index(role), stamp, sequence, data))
            self._pending_bytes += len(data)
            self._lock.notify_all()

    def encode(self, pair: tuple[str, str], label: str, payload: object) -> tuple[int, int, bytes] | None:
        """A message of channel ``pair`` as it will be recorded: (label's number, time, bytes).

        A payload that cannot be encoded (possible only without monitors) is counted, with the
        first reason, in the part's ``anodize.unrecorded`` metadata: the run goes on.
        """
        stamp = time.time_ns()
        try:
            channel_id, codec = self._channel(pair, label)
            return channel_id, stamp, codec.encode(payload)
        except Exception as error:  # the recording's problem, not the role's: say so at the end
            self._count_unrecorded(pair, label, f"{type(error).__name__}: {error}")
            return None

    def _count_unrecorded(self, pair: tuple[str, str], label: str, reason: str) -> None:
        key = f"{pair[0]}->{pair[1]}" + (f":{label}" if label else "")
        first = self.unrecorded.setdefault(key, [0, reason])
        first[0] = int(first[0]) + 1

    def queue(self, pair: tuple[str, str], encoded: tuple[int, int, bytes]) -> None:
        """Hand an encoded message to the writer; never waits for it. Beyond the backlog the
        message is numbered but not recorded: a gap, recorded as such before the next one."""
        channel_id, stamp, data = encoded
        with self._lock:
            if self.broken:  # the writer failed (e.g. a full disk): counted, never waited for
                self._count_unrecorded(pair, "", self.broken)
                return
            # MCAP's sequence is 32 bits: after 2**32 - 1 it wraps to 1 (verify knows).
            sequence = self._sequence[pair] = self._sequence[pair] % SEQUENCE_WRAP + 1
            if self._pending_bytes + len(data) > self.backlog or self._closing:
                self._lose(pair, sequence, stamp, 1)
                return
            gap = self._gaps.pop(pair, None)
            if gap is not None:
                self._pending.append(self._gap_record(pair, *gap))
            self._pending.append((channel_id, stamp, sequence, data))
            self._pending_bytes += len(data)
            self._lock.notify_all()

    def _lose(self, pair: tuple[str, str], first: int, stamp: int, count: int) -> None:
        """``count`` messages of ``pair`` from number ``first`` on are not recorded (lock held)."""
        gap = self._gaps.get(pair)
        if gap is None:
            self._gaps[pair] = [first, count, stamp]
        else:
            gap[1] += count
        self.lost[pair] = self.lost.get(pair, 0) + count

    def _gap_record(self, pair: tuple[str, str], first: int, count: int, stamp: int) -> tuple[int, int, int, bytes]:
        """A queue entry for the gap channel: ``count`` messages from number ``first`` are missing."""
        text = json.dumps({"channel": f"{pair[0]}->{pair[1]}", "first": first, "count": count})
        codec = codec_for_sort(None)  # a JSON String
        return _GAP, stamp, 0, codec.ros.serialize(codec.ros.cls(data=text))

    def _channel(self, pair: tuple[str, str], label: str) -> tuple[int, SortCodec]:
        key = (*pair, label)
        found = self._channels.get(key)
        if found is None:
            with self._lock:
                found = self._channels.get(key) or self._register(key)
        return found

    def _register(self, key: tuple[str, str, str]) -> tuple[int, SortCodec]:
        """A label's number in the queue and its codec (lock held). Nothing is written here: the
        sender's thread never touches the disk; the writer registers the MCAP channel."""
        item = self._labels.get(key) or ChannelLabel(*key, None)
        codec = codec_for_sort(item.sort)
        number = len(self._keys)
        self._keys.append((item, codec))
        self._pair_of[number] = (key[0], key[1])
        found = self._channels[key] = (number, codec)
        return found

    def _mcap_channel(self, number: int) -> int:
        """The part's MCAP channel of queued label ``number``, registered at its first message
        (the writer's thread, holding ``_io``)."""
        found = self._mcap.get(number)
        if found is None:
            item, codec = self._keys[number]
            schema = self._schemas.get(codec.type_name)
            if schema is None:
                schema = self._schemas[codec.type_name] = self._writer.register_schema(
                    codec.type_name, "ros2msg", codec.ros.message_definition().encode())
            key = (item.sender, item.receiver, item.label)
            topic = self.plan.topics.get(key) or f"/anodize/{key[0]}/{key[1]}/{key[2]}"
            metadata = channel_metadata(item, codec, self.protocol, self.plan.group_of)
            metadata["offered_qos_profiles"] = self.plan.qos.get(topic, QOS_PROFILES)  # per topic, as rosbag2
            found = self._mcap[number] = self._writer.register_channel(topic, "cdr", schema, metadata)
        return found

    def _gap_channel_id(self) -> int:
        """The part's gap channel, registered at its first gap (the caller holds ``_io``)."""
        if self._gap_channel is None:
            codec = codec_for_sort(None)
            schema = self._schemas.get(codec.type_name)
            if schema is None:
                schema = self._schemas[codec.type_name] = self._writer.register_schema(
                    codec.type_name, "ros2msg", codec.ros.message_definition().encode())
            self._gap_channel = self._writer.register_channel(GAP_TOPIC, "cdr", schema, {
                "offered_qos_profiles": QOS_PROFILES, "topic_type_hash": codec.ros.type_hash,
                f"{META}.protocol": self.protocol, GAP_KEY: "1"})
        return self._gap_channel

    def _clock_channel_id(self, number: int) -> int:
        """The part's clock channel of queued number ``number`` (``_CLOCK - i``), registered at its
        first reading (the caller holds ``_io``)."""
        found = self._clock_channels.get(number)
        if found is None:
            role = self._roles[_CLOCK - number]
            codec = codec_for_sort(None)
            schema = self._schemas.get(codec.type_name)
            if schema is None:
                schema = self._schemas[codec.type_name] = self._writer.register_schema(
                    codec.type_name, "ros2msg", codec.ros.message_definition().encode())
            found = self._clock_channels[number] = self._writer.register_channel(
                CLOCK_TOPIC.format(role=role), "cdr", schema, {
                    "offered_qos_profiles": QOS_PROFILES, "topic_type_hash": codec.ros.type_hash,
                    f"{META}.protocol": self.protocol, CLOCK_KEY: role})
        return found

    def _write_loop(self) -> None:
        self._tid = threading.get_native_id()
        self._group_scheduling = thread_scheduling()  # what it inherited: given back at close
        self.priority = side_work_priority()  # below every role: it inherited the group's priority
        if self._closing:  # closed before it ran: drain at the group's scheduling, as close gives it
            restore_thread_scheduling(self._tid, self._group_scheduling)
        try:
            self._write_until_closed()
        except Exception as error:  # a full disk, say: the run goes on, unrecorded, and says so
            with self._lock:
                self.broken = f"the recording's writer failed: {type(error).__name__}: {error}"
                for channel_id, *_ in [*self._writing, *self._pending]:
                    if channel_id >= 0:
                        self._count_unrecorded(self._pair_of.get(channel_id, ("?", "?")), "", self.broken)
                self._writing = []
                self._pending.clear()
                self._pending_bytes = 0
                self._lock.notify_all()

    def _write_until_closed(self) -> None:
        last_flush = time.monotonic()
        while True:
            with self._lock:
                while not self._pending and not self._closing:
                    self._lock.wait(_FLUSH_EVERY)
                    if time.monotonic() - last_flush >= _FLUSH_EVERY:
                        break
                # Kept until written (a failure counts it); a batch at a time, so that what is still
                # queued when the group ends can be given up (close) rather than waited for.
                batch = self._writing = [self._pending.popleft() for _ in range(min(_BATCH, len(self._pending)))]
                closing = self._closing
            with self._io:
                for done, (channel_id, stamp, sequence, data) in enumerate(batch):
                    if self._give_up.is_set():  # the group has ended and the disk is slow: the rest is a gap
                        self._write_gaps(batch[done:])
                        return
                    target = (self._mcap_channel(channel_id) if channel_id >= 0 else
                              self._gap_channel_id() if channel_id == _GAP else self._clock_channel_id(channel_id))
                    self._writer.add_message(target, stamp, data, stamp, sequence)
                    self.written += channel_id >= 0
            self._writing = []
            with self._lock:
                self._pending_bytes -= sum(len(item[3]) for item in batch if item[0] != _GAP)
                self._lock.notify_all()
            if time.monotonic() - last_flush >= _FLUSH_EVERY or closing:
                with self._io:
                    self._writer.seal()  # the link records of what was written since the last flush
                self._file.flush()
                last_flush = time.monotonic()
            if closing and not batch:
                return
            if self._give_up.is_set():
                self._write_gaps([])
                return

    def _write_gaps(self, unwritten: list[tuple[int, int, int, bytes]]) -> None:
        """Give up ``unwritten`` and what is queued: write one gap record per channel instead
        (the caller holds ``_io``)."""
        with self._lock:
            records = self._abandon([*unwritten, *self._pending])
            self._pending.clear()
            self._pending_bytes = 0
            self._writing = []
        for _, stamp, _, data in records:
            self._writer.add_message(self._gap_channel_id(), stamp, data, stamp, 0)
        self._file.flush()

    def close(self, within: float = CLOSE_WITHIN) -> None:
        """Write what is queued (for at most ``within`` seconds: the rest becomes a gap), end the
        part file properly, and stop the writer."""
        deadline = time.monotonic() + within
        # The group's roles have ended: finishing the recording is now the group's own work, not
        # side work, so the writer drains at the group's scheduling, not below a busy machine's load.
        if self._tid is not None:
            restore_thread_scheduling(self._tid, self._group_scheduling)
        with self._lock:
            self._closing = True
            self._close_gaps()
            self._lock.notify_all()
        self._thread.join(within / 2)
        if self._thread.is_alive():  # a slow disk: what is still queued is not waited for
            self._give_up.set()  # the writer stops after the write it is in, and writes the gaps
            with self._lock:
                self._lock.notify_all()
            self._thread.join(max(0.0, deadline - time.monotonic()))
            if self._thread.is_alive():  # stuck in a write: the part is left unfinished (the merge keeps it)
                return
        behind = f"the recording's writer fell behind (a slow disk?) and was not waited for: a gap on {GAP_TOPIC}"
        for pair, count in sorted(self.lost.items()):
            self.unrecorded[f"{pair[0]}->{pair[1]}"] = [count, behind]
        with contextlib.suppress(Exception):  # best effort: a broken writer fails again (the merge notes it)
            self._writer.add_metadata(f"{META}.side_work", {"writer_priority": self.priority})
            said = {key: f"{count} messages not recorded; the first: {reason}"
                    for key, (count, reason) in self.unrecorded.items()}
            said.update({f"clock of {role}": f"{count} clock readings not recorded (the writer was behind): a "
                                             f"replay of {role} follows message time from the first"
                         for role, count in sorted(self.clock_lost.items())})
            if said:
                self._writer.add_metadata(f"{META}.unrecorded", said)
            self._writer.finish()
            self._file.close()

    def _close_gaps(self) -> None:
        """Queue a record of each gap still open (lock held): there is no next message to put it before."""
        for pair, gap in sorted(self._gaps.items()):
            self._pending.append(self._gap_record(pair, *gap))
        self._gaps.clear()

    def _abandon(self, unwritten: list[tuple[int, int, int, bytes]]) -> list[tuple[int, int, int, bytes]]:
        """The gap records that replace ``unwritten`` (lock held): per channel, one gap from its
        first message not written to the last it numbered."""
        first: dict[tuple[str, str], tuple[int, int]] = {}
        for channel_id, stamp, sequence, data in unwritten:
            if channel_id < _GAP:  # a clock reading: lost, as the clock channel's numbering shows
                continue
            if channel_id == _GAP:
                found = json.loads(codec_for_sort(None).ros.deserialize(data).data)  # type: ignore[attr-defined]
                sender, receiver = str(found["channel"]).split("->", 1)
                first.setdefault((sender, receiver), (int(found["first"]), stamp))
                continue  # its messages were counted when they were lost
            pair = self._pair_of.get(channel_id, ("?", "?"))
            first.setdefault(pair, (sequence, stamp))
            self.lost[pair] = self.lost.get(pair, 0) + 1
        return [self._gap_record(pair, sequence, (self._sequence.get(pair, sequence) - sequence) % SEQUENCE_WRAP + 1,
                                 stamp) for pair, (sequence, stamp) in first.items()]


class RecordingClock:
    """A role's clock in a recorded run: the machine's, each reading recorded by its group's
    :class:`Recorder` (``anodize replay`` gives them back to the role, in order)."""

    def __init__(self, recorder: Recorder, role: str) -> None:
        self._recorder = recorder
        self._role = role

    def now(self, branch: str) -> float:
        value = time.monotonic()
        self._recorder.reading(self._role, branch, "now", value)
        return value

    def wall(self, branch: str) -> float:
        value = time.time()
        self._recorder.reading(self._role, branch, "wall", value)
        return value

    def expiry(self, branch: str) -> None:
        """A deadline passed while the endpoint waited with nothing there (``else timeout`` or a
        miss): recorded among the readings, so that a replay expires at the same point."""
        self._recorder.reading(self._role, branch, "expiry", time.monotonic())


class TappedChannel:
    """A channel whose messages something else also sees (a recording, the live view):
    as they are put, at the sending end, or as they are taken, at the receiving end (the
    channels of an external sender). Subclasses say what to do with a message before it
    leaves (:meth:`leaving`, whose result :meth:`left` gets once it has gone)."""

    def __init__(self, inner: Channel, pair: tuple[str, str], at_sender: bool) -> None:
        self._inner = inner
        self._pair = pair
        self._at_sender = at_sender

    def leaving(self, label: str, payload: object) -> object:
        """A message is about to go (or has just arrived); returns what :meth:`left` gets."""
        raise NotImplementedError

    def left(self, token: object) -> None:
        """The message :meth:`leaving` saw has gone."""

    def put(self, item: object) -> None:
        if not (self._at_sender and type(item) is tuple):  # messages are plain tuples, signals are not
            self._inner.put(item)
            return
        token = self.leaving(item[0], item[1])
        self._inner.put(item)
        self.left(token)

    def put_many(self, items: list[tuple[str, object]]) -> None:
        """Several messages (``Endpoint.send_many``): each seen, the batch handed on at once."""
        tokens = [self.leaving(label, payload) for label, payload in items] if self._at_sender else []
        put_many = getattr(self._inner, "put_many", None)
        try:
            if put_many is not None:
                put_many(items)
            else:
                put_each(self._inner, items)
        except BaseException as error:  # those that went out are recorded all the same
            tokens = tokens[:getattr(error, "sent_in_batch", 0)]
            raise
        finally:
            for token in tokens:
                self.left(token)

    def take_ready(self, limit: int) -> list[tuple[str, object]]:
        """Messages already arrived (``Endpoint.recv_many``): at the receiving end each is
        seen as it is taken, so none is taken in a batch here."""
        take = getattr(self._inner, "take_ready", None)
        return take(limit) if take is not None and self._at_sender else []

    def give_back(self, items: list[tuple[str, object]]) -> None:
        self._inner.give_back(items)  # type: ignore[attr-defined]

    def get(self, *, timeout: float | None = None) -> object:
        return self._taken(self._inner.get(timeout=timeout))

    def get_nowait(self) -> object:
        return self._taken(self._inner.get_nowait())

    def _taken(self, item: object) -> object:
        if not self._at_sender and type(item) is tuple:
            self.left(self.leaving(item[0], item[1]))
        return item

    def empty(self) -> bool:
        return self._inner.empty()

    def __getattr__(self, name: str) -> Any:  # qsize, buffer, ... of the transport's channel
        return getattr(self._inner, name)


class RecordingChannel(TappedChannel):
    """A channel whose messages are also recorded. A message is encoded before it leaves:
    once put, an array in a shared slot is the receiver's."""

    def __init__(self, inner: Channel, recorder: Recorder, pair: tuple[str, str], at_sender: bool) -> None:
        super().__init__(inner, pair, at_sender)
        self._recorder = recorder

    def leaving(self, label: str, payload: object) -> object:
        return self._recorder.encode(self._pair, label, payload)

    def left(self, token: object) -> None:
        if token is not None:
            self._recorder.queue(self._pair, token)  # type: ignore[arg-type]


def _local_labels(machines: Mapping[str, StateMachine],
                  recorded: Mapping[tuple[str, str], str]) -> dict[tuple[str, str, str], ChannelLabel]:
    """The labels (with sorts) of the recorded channels, from the local roles' machines."""
    found: dict[tuple[str, str, str], ChannelLabel] = {}
    for role, machine in machines.items():
        for t in machine.all_transitions():
            if t.peer is None:
                continue
            pair = (role, t.peer) if t.action == "send" else (t.peer, role)
            if pair in recorded:
                found.setdefault((*pair, t.label), ChannelLabel(*pair, t.label, t.sort))
    return found


