"""``anodize replay``: run one role's code against a recording, at a desk.

The role's function runs alone, on a monitored endpoint whose channels come from the
recording (:mod:`.replay_network`): what it receives is what its peers sent in the
recorded run, in the same order; what it sends is compared, message by message, with
what it sent then (:mod:`.compare` says how payloads are compared), and its monitor
checks every action against the protocol as in a live run. A failure seen on the robot
is then the same failure here, with a debugger at hand.

Time is the replay's. A role that reads its clock through its endpoint
(``Endpoint.now()``, ``Endpoint.wall()``) reads, in a replay, the readings it took in the
recorded run, in order, each endpoint (the role's, each parallel branch's) its own: a
recording records every reading. Where the recording has none for it (a recording made
before clocks were recorded, or a role that reads its clock more often than it did in
the run), it reads message time: the recorded time of the message its thread received
last, advanced by that thread's ``Endpoint.sleep`` arguments (``now()`` past an endpoint's
readings goes on from its last one, advanced as message time advances). ``Endpoint.sleep``
returns at once.

What a replay cannot reproduce: time read past the endpoint (``time.monotonic()``,
``time.sleep`` in the role's code: it still sleeps); a ``recv(..., timeout=...)`` that
timed out in the run (it gets the next recorded message instead; a wait under the
protocol's ``within`` that expired in the run does expire again: the recording says where);
the interleaving of a
role's own threads (each thread gets its channels' messages in the recorded order, and
its own clock readings, but two threads that share state run as the replay's scheduler
runs them); and the channels a recording leaves out (those it was told to leave out,
or both ends in one group in a recording of the channels between groups only): messages
the role sends there are counted, not compared, and a receive there ends the replay,
saying that the role cannot be replayed alone from there.
"""

from __future__ import annotations

import json
import math
import sys
import threading
import traceback
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from sessiontypes import GlobalType, Transition

from .._session.endpoint import Endpoint, peers_of
from .._session.typed import argument_for
from ..errors import AnodizeError, ConfigurationError, ProtocolViolationError, RoleStopped
from .compare import TopicCodecs, payload_difference
from .encoding import class_sorts, codec_for_sort, imported_class
from .metadata import group_of, left_out_by, recorded_channels
from .plan import CLOCK_KEY, GAP_KEY, META
from .reader import RecordedMessage, Recording
from .replay_network import (
    DIVERGED,
    FINISHED,
    NOT_RECORDED,
    TIMED_OUT,
    Divergence,
    RecordedItem,
    ReplayDivergenceError,
    ReplayNetwork,
)

__all__ = ["replay", "ReplayReport"]

_FAILED = "failed"


@dataclass
class ReplayReport:
    """How a replay went.

    Attributes:
        outcome: how it ended: ``finished``, ``recording ends``, ``not recorded`` (a receive on
            a channel the recording leaves out), ``sleeps for ever``, ``diverged``, ``failed``
            (the role raised, a protocol violation included), ``timed out``.
        detail: the same in a sentence.
        divergence: the first message the role did not send as recorded, if any.
        error: what the role raised (a ``ProtocolViolationError``, or its own exception).
        received: per channel into the role, (messages delivered, messages recorded).
        compared: per channel out of the role, (messages compared, messages recorded).
        uncompared: per channel out of the role that the recording leaves out, messages sent.
        slept: seconds of ``Endpoint.sleep`` that the replay skipped.
        clock: readings of the role's clock: (given back as recorded, recorded, read from
            message time instead).
        notes: what else the reader should know (a recording cut short, ...).
    """

    recording: str
    protocol: str
    role: str
    function: str
    outcome: str = ""
    detail: str = ""
    divergence: Divergence | None = None
    error: BaseException | None = None
    traceback: str = ""
    received: dict[str, tuple[int, int]] = field(default_factory=dict)
    compared: dict[str, tuple[int, int]] = field(default_factory=dict)
    uncompared: dict[str, int] = field(default_factory=dict)
    slept: float = 0.0
    clock: tuple[int, int, int] = (0, 0, 0)
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """The role sent what the recording says (at least one message was compared: a replay that
        compared nothing has shown nothing), followed the protocol, and did not fail."""
        return (self.divergence is None and self.error is None and self.outcome not in (TIMED_OUT, _FAILED)
                and self.messages_compared > 0)

    @property
    def messages_compared(self) -> int:
        """Messages the role sent that were compared with the recorded ones."""
        return sum(done for done, _ in self.compared.values())

    def text(self) -> str:
        nothing = (self.divergence is None and self.error is None and self.outcome not in (TIMED_OUT, _FAILED)
                   and not self.messages_compared)
        verdict = ("COMPARED NOTHING: the role sent no message on a recorded channel, so the replay shows "
                   "nothing (not a pass)" if nothing else
                   "matches the recording and follows the protocol, as far as the role can be replayed alone "
                   "(INCOMPLETE: see 'ended')" if self.ok and self.outcome == NOT_RECORDED else
                   "matches the recording and follows the protocol" if self.ok else
                   "DIVERGES from the recording" if self.divergence is not None else
                   "VIOLATES the protocol" if isinstance(self.error, ProtocolViolationError) else
                   "FAILED")
        head = f"replay of role {self.role} ({self.function}) from {self.recording}, global {self.protocol}"
        lines = [f"{head}: {verdict}", f"  ended: {self.detail}"]
        lines.extend(f"  received on {channel}: {done} delivered of {total} recorded"
                     for channel, (done, total) in self.received.items())
        lines.extend(f"  sent on {channel}: {done} compared of {total} recorded"
                     for channel, (done, total) in self.compared.items())
        lines.extend(f"  sent on {channel}: {_messages(sent)}, not compared (the recording does not have "
                     "this channel)" for channel, sent in self.uncompared.items())
        if self.slept:
            lines.append(f"  Endpoint.sleep: {self.slept:g} s of sleeping skipped")
        replayed, recorded, from_messages = self.clock
        if recorded or from_messages:
            lines.append(f"  clock: {replayed} of {recorded} recorded readings given back"
                         + (f", {from_messages} read from message time" if from_messages else ""))
        if self.divergence is not None:
            lines.append(f"divergence: {self.divergence}")
        if self.error is not None:
            kind = "violation" if isinstance(self.error, ProtocolViolationError) else "error"
            lines.append(f"{kind}: {type(self.error).__name__}: {self.error}")
            if kind == "error" and self.traceback:
                lines.append(self.traceback.rstrip())
        lines.extend(f"note: {note}" for note in self.notes)
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {"recording": self.recording, "protocol": self.protocol, "role": self.role,
                "function": self.function, "ok": self.ok, "outcome": self.outcome, "detail": self.detail,
                "messages_compared": self.messages_compared,
                "divergence": None if self.divergence is None else self.divergence.__dict__,
                "error": None if self.error is None else f"{type(self.error).__name__}: {self.error}",
                "received": self.received, "compared": self.compared, "uncompared": self.uncompared,
                "slept": self.slept, "clock": {"replayed": self.clock[0], "recorded": self.clock[1],
                                               "from_messages": self.clock[2]}, "notes": self.notes}


def _messages(count: int) -> str:
    return f"{count} message{'' if count == 1 else 's'}"


def replay(recording: Recording, global_type: GlobalType, role: str, function: Callable[..., Any],
           topics: Mapping[str, tuple[str, str, str]] | None = None, timeout: float = 60.0,
           import_classes: bool = True) -> ReplayReport:
    """Run ``function`` as ``role`` against ``recording`` (see the module docstring).

    Nothing the recording names is imported or called: the code that runs is ``function``,
    which the caller gives.

    Args:
        function: the role's function (taking an ``Endpoint`` or the typed initial state).
        topics: topic -> ``(sender, receiver, label)`` for topics without anodize's metadata.
        timeout: seconds the role may run; a role still running then is stopped at its
            next action, and the replay does not pass.
        import_classes: whether the payload classes ``global_type`` names by import path may
            be imported for the role's monitor: False when it is the protocol the recording
            carries (untrusted data); each class must then be one a module imported already
            (by ``function``'s own code) defines.

    Raises:
        ConfigurationError: ``role`` is not a role of ``global_type``, or (``import_classes``
            False) a payload class of the role's is not imported.
        RecordingError: the recording cannot be read, or its metadata is not anodize's.
    """
    if role not in global_type.roles:
        raise ConfigurationError(f"global {global_type.name} has no role {role}; expected one of "
                                 f"{', '.join(global_type.roles)}")
    name = f"{getattr(function, '__module__', '?')}:{getattr(function, '__qualname__', repr(function))}"
    report = ReplayReport(str(recording.path), global_type.name, role, name)
    machine = global_type.project(role).fsm()
    if not import_classes:
        _require_imported(recording, machine.all_transitions())
    sends_to, receives_from = peers_of(machine)
    listed, groups = recorded_channels(recording), group_of(recording)  # checked before anything runs
    readings: dict[str, list[tuple[str, float, int]]] = {}
    cut: dict[tuple[str, str], int] = {}  # channels cut short: taken up to the cut; when it was (ns)
    streams = _streams(recording, role, topics or {}, report.notes, readings, cut)
    recorded = set(streams) if listed is None else listed
    why = _why_unrecorded(groups, left_out_by(recording))
    codecs = TopicCodecs()

    def decode(item: RecordedItem) -> object:
        return codecs.codec(item.topic).decode(item.data)

    def difference(item: RecordedItem, payload: object) -> str:
        return payload_difference(codecs.codec(item.topic), item.data, payload)

    network = ReplayNetwork(
        role,
        feeds={p: streams.get((p, role), []) for p in sorted(receives_from) if (p, role) in recorded},
        cuts={p: cut[(p, role)] for p in sorted(receives_from) if (p, role) in cut},
        expected={p: streams.get((role, p), []) for p in sorted(sends_to) if (role, p) in recorded},
        unrecorded_in={p: why(p, role) for p in sorted(receives_from) if (p, role) not in recorded},
        unrecorded_out=[p for p in sorted(sends_to) if (role, p) not in recorded],
        decode=decode, difference=difference, readings=readings, threads=bool(machine.forks))
    endpoint = network.endpoint = Endpoint(role, global_type.name, machine, network)
    _run(function, endpoint, network, timeout, report)
    _account(network, report, sorted(f"{p}->{role}" for p, r in cut if r == role))
    return report


def _run(function: Callable[..., Any], endpoint: Endpoint, network: ReplayNetwork, timeout: float,
         report: ReplayReport) -> None:
    """Run the role on a thread of its own (so that a role that never ends cannot hang the replay)."""
    raised: list[BaseException] = []

    def body() -> None:
        try:
            function(argument_for(function, endpoint))
            unfinished = endpoint.unfinished()
            if unfinished and network.ending is None:
                raise unfinished[0].end_violation()
        except BaseException as error:  # reported, never swallowed
            raised.append(error)

    def threads_end(args: threading.ExceptHookArgs) -> None:
        """A thread of the role's own ended by an exception: stopped by the replay (a divergence
        included: the network has it) is how it ends; anything else is the role's failure."""
        if args.exc_value is not None and not isinstance(args.exc_value, (RoleStopped, ReplayDivergenceError)):
            raised.append(args.exc_value)
            network.stop(_FAILED, f"{endpoint.role}'s thread {args.thread.name if args.thread else '?'} raised "
                                  f"{type(args.exc_value).__name__}")

    thread = threading.Thread(target=body, name=f"replay:{endpoint.role}", daemon=True)
    hook, threading.excepthook = threading.excepthook, threads_end
    try:
        thread.start()
        thread.join(timeout)
        if thread.is_alive():
            network.stop(TIMED_OUT, f"{endpoint.role} did not end within {timeout:g} s (it computes, or waits "
                                    "outside its endpoint, e.g. in time.sleep); it was stopped at its next action")
            thread.join(2.0)
    finally:
        threading.excepthook = hook
    error = raised[0] if raised else None
    if network.ending is not None:
        report.outcome, report.detail = network.ending
        if report.outcome == DIVERGED:
            report.detail = f"{endpoint.role} was stopped at its first divergence"
    elif error is None:
        report.outcome, report.detail = FINISHED, f"{endpoint.role} returned at the end of its local type"
    if isinstance(error, (RoleStopped, ReplayDivergenceError)):
        return
    if error is not None:
        report.error = error
        if network.ending is None:
            report.outcome = _FAILED
            report.detail = f"{endpoint.role} raised {type(error).__name__} in state {endpoint.state}"
        if not isinstance(error, ProtocolViolationError):
            report.traceback = "".join(traceback.format_exception(error))


def _account(network: ReplayNetwork, report: ReplayReport, cut_in: list[str]) -> None:
    """Fill in the counts, and the divergence of a role that stopped sending before the recording did
    (not judged when a channel into the role is cut short, ``cut_in``: a gap of the recording's
    left the role without the input that made it send the rest)."""
    role = network.role
    report.received = {f"{peer}->{role}": (feed.delivered, feed.recorded)
                       for peer, feed in network.feeds.items() if feed.unrecorded is None}
    report.compared = {f"{role}->{peer}": (check.sent, check.sent + len(network.unsent(peer)))
                       for peer, check in network.checks.items() if check.recorded}
    report.uncompared = {f"{role}->{peer}": check.sent for peer, check in network.checks.items()
                         if not check.recorded}
    clock = network.clock
    report.slept = clock.skipped
    report.clock = (clock.replayed, clock.recorded, clock.from_messages)
    if clock.differs:
        report.notes.append(f"clock: {clock.differs}; from there on it reads message time")
    if network.turnstile.out_of_order:
        report.notes.append(f"threads: {network.turnstile.out_of_order}")
    report.divergence = network.divergence
    # Ended where the recorded role could not have sent more? Then what it did not send, it should have.
    if report.divergence is not None or report.error is not None or report.outcome in (NOT_RECORDED, TIMED_OUT):
        return
    if cut_in:
        if any(network.unsent(peer) for peer in network.checks if network.checks[peer].recorded):
            report.notes.append(f"the recorded messages {report.role} sent after the break on {', '.join(cut_in)} "
                                "are not compared: it did not get the input that made it send them")
        return
    if network.time_unknown:
        left = sum(len(network.unsent(peer)) for peer in network.checks if network.checks[peer].recorded)
        report.notes.append(f"the last {left} recorded message(s) {report.role} sent are not compared: it made "
                            "them after reading its clock past the readings the recording holds")
        return
    for peer in network.checks:
        unsent = network.unsent(peer) if network.checks[peer].recorded else []
        if unsent:
            first = unsent[0]
            report.divergence = Divergence(role, f"{role}->{peer}", first.index, network.recorded_text(first),
                                           f"nothing more ({report.detail})",
                                           f"the recording has {len(unsent)} more message(s) there", first.log_time)
            return


def _streams(recording: Recording, role: str, topics: Mapping[str, tuple[str, str, str]],
             notes: list[str], readings: dict[str, list[tuple[str, float, int]]], broken: dict[tuple[str, str], int],
             ) -> dict[tuple[str, str], list[RecordedItem]]:
    """The recorded messages of the channels into and out of ``role``, per channel, in order;
    the role's clock readings go into ``readings``, per endpoint, in order.

    A channel's messages are taken up to the first break in their numbering (a message lost,
    or the sender's group started again), or up to a gap the recording records on it (its
    recorder fell behind: the messages after the last one kept are lost, none may follow): what
    follows is not the same run of the role. So are the clock's readings. The channels cut so
    go into ``broken``, with the time of the cut (ns since the epoch: a gap's, else the last
    message's kept).
    """
    keys: dict[int, tuple[str, str, str]] = {}
    clock_topics = {topic.id for topic in recording.topics if topic.metadata.get(CLOCK_KEY) == role}
    gap_topics = {topic.id for topic in recording.topics if topic.metadata.get(GAP_KEY)}
    clock_read = 0
    for topic in recording.topics:
        meta = topic.metadata
        key = ((meta[f"{META}.sender"], meta.get(f"{META}.receiver", ""), meta.get(f"{META}.label", ""))
               if f"{META}.sender" in meta else topics.get(topic.topic))
        if key is not None and role in key[:2]:
            keys[topic.id] = key
    streams: dict[tuple[str, str], list[RecordedItem]] = {}
    for message in recording.messages():
        if message.topic.id in clock_topics:
            if clock_read >= 0:
                clock_read = _reading(message, clock_read, readings, notes)
            continue
        if message.topic.id in gap_topics:
            _gap(message, role, streams, broken, notes)
            continue
        key = keys.get(message.topic.id)
        if key is None or key[:2] in broken:
            continue
        items = streams.setdefault(key[:2], [])
        if message.sequence and message.sequence != len(items) + 1:
            broken[key[:2]] = items[-1].log_time if items else message.log_time
            restart = message.sequence == 1
            notes.append(f"{key[0]}->{key[1]}: replayed up to message {len(items) - 1}; the next one is numbered "
                         f"{message.sequence} ({'its sender started again' if restart else 'messages are missing'})")
            continue
        items.append(RecordedItem(len(items), key[2], message.log_time, bytes(message.data), message.topic))
    return streams


def _gap(message: RecordedMessage, role: str, streams: dict[tuple[str, str], list[RecordedItem]],
         broken: dict[tuple[str, str], int], notes: list[str]) -> None:
    """A gap record: a channel into ``role`` is cut where its recorder lost messages."""
    try:
        found = json.loads(codec_for_sort(None).ros.deserialize(bytes(message.data)).data)  # type: ignore[attr-defined]
        sender, receiver = str(found["channel"]).split("->", 1)
        first, count = int(found["first"]), int(found["count"])
    except (ValueError, KeyError, TypeError, AttributeError):
        return  # not a gap record anodize wrote: verify says so, the replay goes by the numbering
    pair = (sender, receiver)
    if receiver != role or pair in broken:
        return
    broken[pair] = message.log_time  # when the first message lost was sent
    notes.append(f"{sender}->{receiver}: replayed up to message {len(streams.get(pair, [])) - 1}; the recording "
                 f"lost {count} message(s) from number {first} on (its recorder fell behind)")


def _reading(message: RecordedMessage, done: int, readings: dict[str, list[tuple[str, float, int]]],
             notes: list[str]) -> int:
    """Take one recorded clock reading into ``readings``; returns the readings taken, or -1 at a
    break in their numbering or a reading that does not decode (the rest is not taken)."""
    if message.sequence and message.sequence != done + 1:
        notes.append(f"clock: {done} readings replayed; the next one is numbered {message.sequence} "
                     "(readings are missing): message time from there")
        return -1
    try:
        found = json.loads(codec_for_sort(None).ros.deserialize(bytes(message.data)).data)  # type: ignore[attr-defined]
        branch = found.pop("branch")
        (kind, value), = found.items()
        if (not isinstance(branch, str) or kind not in ("now", "wall", "expiry") or not isinstance(value, float)
                or not math.isfinite(value)):  # JSON may say NaN or Infinity: no clock reads that
            raise ValueError(f"not a reading: {found!r}")
    except (AnodizeError, ValueError, TypeError, KeyError, AttributeError, RecursionError) as error:
        notes.append(f"clock: reading {done + 1} on {message.topic.topic} does not decode ({error}): "
                     "message time from there")
        return -1
    readings.setdefault(branch, []).append((kind, value, message.log_time))
    return done + 1


def _why_unrecorded(groups: Mapping[str, str], left_out: str) -> Callable[[str, str], str]:
    """Why a channel is not in the recording; ``left_out``: the recording's own account
    (:func:`~.metadata.left_out_by`; empty: a recording of the channels between groups only)."""
    def why(sender: str, receiver: str) -> str:
        group = groups.get(sender)
        if f"{sender}->{receiver}" in left_out.rpartition("left out: ")[2].split(", "):
            return "the run's recording left it out (--record-exclude, or [record] in the system file)"
        if left_out.startswith("only the channels chosen"):
            return "the run recorded only the channels chosen in [record], and not this one"
        if group is not None and group == groups.get(receiver):
            return f"{sender} and {receiver} are both in group {group}, and only channels between groups are recorded"
        return "no message of it was recorded"

    return why


def _require_imported(recording: Recording, transitions: Iterable[Transition]) -> None:
    """Each payload class the role's transitions name by import path is one an imported module
    defines: building the role's monitor then imports nothing (the protocol is the recording's).

    Raises:
        ConfigurationError: one is not (naming it, and how to give it).
    """
    for sort in class_sorts(t.sort for t in transitions):
        assert sort.target is not None
        if imported_class(sort.target) is not None:
            continue
        module = sort.target.partition(":")[0]
        why = (f"module {module} is not imported by your code" if module not in sys.modules else
               f"module {module} defines no class {sort.target.partition(':')[2]}")
        raise ConfigurationError(
            f"the protocol of {recording.path} names payload class {sort.target} (sort {sort.spelling}), and {why}: "
            "a replay does not import what a recording names; import it in your role's module, or pass "
            "--protocol FILE")
