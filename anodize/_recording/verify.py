"""``anodize verify``: does a recording follow the protocol, and if not, who broke it where.

Each channel of the protocol (an ordered pair of roles) is checked on its own: its
messages, in the recording's order, must be a sequence of labels the sender's local
type may send on it and the receiver's may receive on it (every other action erased:
:mod:`.channel_view`), each with a payload of the label's sort. The first message that
breaks this is the channel's violation, and the sender is blamed, as a live monitor
would blame it. How channels interleave is not checked (docs/recording.md says why).

A recording made by anodize numbers each channel's messages: a number skipped or out
of order means the recording itself lost or reordered a message, and is reported as
such, blaming no role; numbering that starts again at 1 is a restarted group (the
channel starts again from the protocol's beginning). A gap the recorder itself marked
(on :data:`~.tap.GAP_TOPIC`: its writer fell behind and the sender did not wait for it)
is the recording's, reported as a gap, not as a violation: the channel's check goes on
after it from every state the missing messages could have led to.

The protocol's time and value constraints (``within``, ``every``, refinements) are judged
too, across channels in log-time order (:mod:`.held` says how a recording stands for the
roles' clocks): a message that breaks one is its channel's violation, blaming the sender, and
the report says how each constraint held. A protocol without constraints pays nothing for it.

In the same pass the recording's hash chain is checked (:mod:`.evidence`): whether the file
is what the recorder wrote, which is a separate verdict (``VerifyReport.evidence``) from
whether the run followed the protocol.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from sessiontypes import GlobalType, Sort, StateMachine, Transition

from .._ros import ros_type
from .._session.payloads import Validator, validator_for
from ..errors import AnodizeError
from .by_name import sort_text, validator_by_name
from .chain import CHAIN_KEY
from .channel_view import ChannelView, Node, sort_key
from .encoding import JSON_TYPE, SortCodec, UnknownObject, class_sorts, codec_for_sort
from .evidence import Evidence, EvidenceCheck
from .held import (
    Breach,
    Earlier,
    Held,
    RoleTimes,
    constrained,
    constraint_texts,
    constraints_of,
    judge_deadline,
    judge_period,
    judge_refinement,
)
from .metadata import left_out_by, recorded_channels
from .plan import CLOCK_KEY, META, channel_labels
from .reader import RecordedMessage, RecordedTopic, Recording
from .rosout import LOG_KEY
from .tap import GAP_KEY, SEQUENCE_WRAP

__all__ = ["Violation", "ChannelResult", "VerifyReport", "verify", "RECORDING_FAULT", "Gap", "NOT_IMPORTED"]

RECORDING_FAULT = "the recording (no role: a message was lost or reordered after it was sent)"
NOT_IMPORTED = ("payload types named by import path were not imported (the protocol came from the recording); "
                "pass --protocol FILE to check them against your own code")


@dataclass(frozen=True)
class Violation:
    """The first message of a channel that breaks the protocol.

    Attributes:
        channel: ``"Sender->Receiver"``.
        index: the message's position on the channel, from 0.
        log_time: its log time in the recording, ns since the epoch.
        topic: the recording's topic it is on.
        blamed: the role at fault (or :data:`RECORDING_FAULT`).
        role: the role whose local type it breaks.
        state: where that role was on this channel.
        expected: what the channel allowed next.
        actual: what was recorded.
        location: the ``.proto`` location of the interaction concerned.
        reason: what is wrong with the payload, or the recording, when that is the fault.
        kind: for a broken time or value constraint, ``"deadline"``, ``"period"`` or
            ``"refinement"`` (else "").
        late: for a broken time constraint, how far outside it the message was, in ns.
    """

    channel: str
    index: int
    log_time: int
    topic: str
    blamed: str
    role: str
    state: str
    expected: tuple[str, ...]
    actual: str
    location: str
    reason: str = ""
    kind: str = ""
    late: int = 0

    def __str__(self) -> str:
        expected = ", ".join(self.expected) or "nothing more"
        where = f"log time {_clock(self.log_time)}, topic {self.topic}"
        lines = [f"channel {self.channel}, message {self.index} ({where}):",
                 f"  {self.actual}, but {self.role} in state {self.state} expected {expected}"]
        if self.reason:
            lines.append(f"  {self.reason}")
        lines.append(f"  blamed: {self.blamed}" + (f"; see {self.location}" if self.location else ""))
        return "\n".join(lines)


@dataclass(frozen=True)
class Gap:
    """Messages the recorder numbered but could not write (it marked them: not a violation).

    Attributes:
        channel: ``"Sender->Receiver"``.
        first: the sequence number of the first one missing.
        count: how many are missing.
        log_time: when the first of them was sent, ns since the epoch.
    """

    channel: str
    first: int
    count: int
    log_time: int

    def __str__(self) -> str:
        return (f"channel {self.channel}: {self.count} message(s) from number {self.first} not recorded "
                f"(the recorder fell behind; log time {_clock(self.log_time)})")


@dataclass
class ChannelResult:
    channel: str
    messages: int = 0
    violation: Violation | None = None


@dataclass
class VerifyReport:
    """What ``verify`` found.

    Attributes:
        channels: per channel of the protocol that the recording has, its result.
        unknown: recorded channels the protocol does not have (a violation).
        unmapped: recorded topics that are no channel's (not checked).
        missing: channels of the protocol with no message in the recording.
        inside: channels an anodize recording leaves out by design: both ends in one group, in a
            recording of the channels between groups only, or not chosen (``[record]``,
            ``--record-exclude``); not a violation.
        left_out_by: why they are left out, in words (empty for a recording that does not say).
        gaps: messages the recorder marked as not recorded (the recording's, not a violation).
        notes: what else the reader should know (payload classes checked by name only, ...).
        constraints: each time or value constraint of the protocol, and how it held.
        evidence: what the recording's hash chain says of it (None: not checked).
    """

    recording: str
    protocol: str
    channels: dict[str, ChannelResult] = field(default_factory=dict)
    unknown: list[str] = field(default_factory=list)
    unmapped: list[str] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    inside: list[str] = field(default_factory=list)
    left_out_by: str = ""
    gaps: list[Gap] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    constraints: list[Held] = field(default_factory=list)
    evidence: Evidence | None = None
    messages: int = 0
    bytes: int = 0
    seconds: float = 0.0

    @property
    def conforms(self) -> bool:
        return not self.unknown and all(r.violation is None for r in self.channels.values())

    def text(self) -> str:
        checked = sum(r.messages for r in self.channels.values())
        verdict = "conforms to" if self.conforms else "does NOT conform to"
        read = f"{self.messages} read, {self.bytes / 2**20:.1f} MiB in {self.seconds:.2f} s"
        head = f"{self.recording} {verdict} {self.protocol}"
        on = f"{len(self.channels)} channel{'' if len(self.channels) == 1 else 's'}"
        lines = [f"{head}: {checked} messages on {on} checked ({read})"]
        lines.extend(f"violation: {r.violation}" for r in self.channels.values() if r.violation is not None)
        lines.extend(f"unknown channel: {text}" for text in self.unknown)
        lines.extend(f"not checked: topic {text} is on no channel of the protocol (map it with --topics)"
                     for text in self.unmapped)
        lines.extend(f"missing: no message on channel {channel}" for channel in self.missing)
        lines.extend(f"gap: {gap}" for gap in self.gaps)
        if self.inside:
            why = self.left_out_by or "both ends in one group"
            lines.append(f"not recorded ({why}; not checked, not a violation): {', '.join(self.inside)}")
        lines.extend(f"constraint: {held}" for held in self.constraints)
        lines.extend(f"note: {note}" for note in self.notes)
        if self.evidence is not None:
            lines.extend(self.evidence.lines())
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {"recording": self.recording, "protocol": self.protocol, "conforms": self.conforms,
                "channels": {name: {"messages": r.messages,
                                    "violation": None if r.violation is None else r.violation.__dict__}
                             for name, r in self.channels.items()},
                "unknown": self.unknown, "unmapped": self.unmapped, "missing": self.missing, "inside": self.inside,
                "left_out_by": self.left_out_by,
                "gaps": [gap.__dict__ for gap in self.gaps], "notes": self.notes,
                "constraints": [held.__dict__ for held in self.constraints],
                "evidence": None if self.evidence is None else self.evidence.to_dict(),
                "messages": self.messages, "bytes": self.bytes, "seconds": self.seconds}


class _ChannelCheck:
    """The state of one channel's check."""

    def __init__(self, sender: str, receiver: str, machines: Mapping[str, StateMachine]) -> None:
        self.sender, self.receiver = sender, receiver
        self.name = f"{sender}->{receiver}"
        self.views = (ChannelView(machines[sender], "send", receiver), ChannelView(machines[receiver], "recv", sender))
        # An interaction with a period (all its labels: one clock) -> its last message's log time.
        self.periods: dict[Node, int] = {}
        self.reset()
        self.result = ChannelResult(self.name)
        self.sequence = 0
        self.gaps: dict[int, int] = {}  # first missing number -> how many: the recorder's marked gaps

    def reset(self) -> None:
        self.states: list[frozenset[Node]] = [view.start for view in self.views]
        self.periods.clear()

    def check(self, message: RecordedMessage, label: str, codecs: _Codecs, held: _Held | None = None) -> None:
        if held is None:
            self._check(message, label, codecs, None)
            return
        taken, payload = self._check(message, label, codecs, held)
        if payload is None and held.refined:  # not decoded (the channel broke): its fields still count later
            try:
                payload = codecs.decode(message.topic, message.data)
            except (AnodizeError, ValueError, KeyError, TypeError):
                payload = None
        held.record(self, message, taken, payload)  # the message happened, conforming or not

    def _check(self, message: RecordedMessage, label: str, codecs: _Codecs, held: _Held | None
               ) -> tuple[list[list[tuple[Node, Transition]]] | None, object]:
        """Check one message; with constraints, also the transitions it took on each side and its payload."""
        if self.result.violation is not None:
            return None, None
        index = self.result.messages
        self.result.messages += 1
        problem = self._numbering(message.sequence)
        if problem:
            self._fail(message, index, label, 0, RECORDING_FAULT, problem)
            return None, None
        # The label's sorts that the payload fits: a label may carry different sorts on different paths.
        taken = self.views[0].taken(self.states[0], label)
        if not taken:
            self._fail(message, index, label, 0, self.sender)
            return None, None
        fits, reason, payload = _fitting_sorts(message, taken, codecs)
        if not fits:
            self._fail(message, index, label, 0, self.sender, reason)
            return None, payload
        if held is not None:
            return self._judged(message, index, label, fits, payload, held), payload
        for side, view in enumerate(self.views):
            after = view.step(self.states[side], label, fits)
            if not after:
                self._fail(message, index, label, side, self.sender)
                return None, payload
            self.states[side] = after
        return None, payload

    def _judged(self, message: RecordedMessage, index: int, label: str, fits: frozenset[str | None],
                payload: object, held: _Held) -> list[list[tuple[Node, Transition]]] | None:
        """Step both sides through the transitions whose constraints the message keeps (a path
        whose constraints it breaks is not one it took); if there are none, the first breach is
        the channel's violation, blaming the sender."""
        kept_by_side: list[list[tuple[Node, Transition]]] = []
        for side, view in enumerate(self.views):
            options = view.candidates(self.states[side], label, fits)
            if not options:
                self._fail(message, index, label, side, self.sender)
                return None
            kept: list[tuple[Node, Transition]] = []
            first: Breach | None = None
            for node, t in options:
                breach = held.judge(self, side, node, t, label, message, payload)
                if breach is None:
                    kept.append((node, t))
                elif first is None:
                    first = breach
            if first is not None and not kept:
                self._fail(message, index, label, side, self.sender, first.reason, first)
                return None
            kept_by_side.append(kept)
        for side, kept in enumerate(kept_by_side):
            self.states[side] = self.views[side].advance(kept)
        return kept_by_side

    def _numbering(self, sequence: int) -> str:
        if sequence == 0:  # not numbered (not recorded by anodize)
            return ""
        previous, self.sequence = self.sequence, sequence
        if sequence == previous + 1:
            return ""
        if sequence == 1 and previous == SEQUENCE_WRAP:  # 32 bits of numbering ran out: they wrap
            return ""
        if sequence == 1:  # the sender's group started again: so does the channel
            self.reset()
            return ""
        if sequence > previous + 1 and self.gaps.get(previous + 1) == sequence - previous - 1:
            self._skip(sequence - previous - 1)  # a gap the recorder marked: the recording's, not a role's
            return ""
        if sequence > previous + 1:
            return (f"the sender numbered it {sequence} after {previous}: "
                    f"{sequence - previous - 1} message(s) before it are missing from the recording")
        return f"the sender numbered it {sequence} after {previous}: the recording has it out of order"

    def _skip(self, count: int) -> None:
        """Go on from every state ``count`` messages of any label could have led to."""
        for side, view in enumerate(self.views):
            self.states[side] = _after_any(view, self.states[side], count)

    def _fail(self, message: RecordedMessage, index: int, label: str, side: int, blamed: str,
              reason: str = "", breach: Breach | None = None) -> None:
        view = self.views[side]
        nodes = self.states[side]
        allowed = view.allowed(nodes)
        taken = view.taken(nodes, label)
        concerned = taken[0] if taken else (allowed[0] if allowed else None)
        role = self.sender if side == 0 else self.receiver
        location = str(concerned.location) if concerned is not None else ""
        self.result.violation = Violation(
            self.name, index, message.log_time, message.topic.topic, blamed, role, view.describe(nodes),
            tuple(str(t) for t in allowed), _actual(side, self, label, message.topic),
            breach.location if breach is not None else location, reason,
            breach.kind if breach is not None else "", breach.late if breach is not None else 0)


class _Held:
    """The time and value constraints judged across channels (:mod:`.held`): each role's
    previous action and the latest fields of the record payloads it saw, in log-time order."""

    def __init__(self, machines: Mapping[str, StateMachine], timed_roles: frozenset[str], refined: bool) -> None:
        self.refined = refined
        self.times = RoleTimes(machines)
        self.earlier = Earlier()
        self.timed_roles = timed_roles  # roles whose every channel is in the recording: their deadlines are judged
        self.held = constraints_of(machines)  # how each constraint held, for the report

    def judge(self, check: _ChannelCheck, side: int, node: Node, t: Transition, label: str,
              message: RecordedMessage, payload: object) -> Breach | None:
        """The first constraint of ``t`` (on ``side``: 0 the sender's, 1 the receiver's) the message breaks."""
        at = message.log_time
        if side == 1:
            receiver = check.receiver
            previous = self.times.previous(receiver, node[0]) if receiver in self.timed_roles else None
            return judge_deadline(t, receiver, False, previous, at)
        sender = check.sender
        breach = judge_refinement(t, label, payload, self.earlier.of(sender))
        if breach is None and sender in self.timed_roles:
            breach = judge_deadline(t, sender, True, self.times.previous(sender, node[0]), at)
        if breach is None and _at_sender(message):
            breach = judge_period(t, check.periods.get(node), at)
        return breach

    def record(self, check: _ChannelCheck, message: RecordedMessage,
               taken: list[list[tuple[Node, Transition]]] | None, payload: object) -> None:
        """The message happened: it is its sender's and its receiver's latest action."""
        if taken is not None:
            self._tally(check, message, taken)
        for side, role in enumerate((check.sender, check.receiver)):
            machines = {node[0] for node, _ in taken[side]} if taken is not None else set()
            self.times.act(role, machines.pop() if len(machines) == 1 else None, message.log_time)
            self.earlier.saw(role, payload)
        if taken is not None:
            for node, t in taken[0]:
                if t.timing is not None and t.timing.every is not None:
                    check.periods[node] = message.log_time


    def _tally(self, check: _ChannelCheck, message: RecordedMessage,
               taken: list[list[tuple[Node, Transition]]]) -> None:
        """Count the constraints the message was judged by and kept (the first path it took stands for all)."""
        (node, t), (their_node, _) = taken[0][0], taken[1][0]
        texts = constraint_texts(t)
        if not texts:
            return
        at = message.log_time
        for text in texts:
            held = self.held[check.name, t.label, text]
            if text.startswith("every"):
                previous = check.periods.get(node) if _at_sender(message) else None
                if previous is not None:
                    held.judged += 1
                    held.measured(at - previous)
            elif text.endswith("else timeout"):
                continue  # the receiver's alone, and a timeout is in no recording
            elif text.startswith("within"):
                before = [self.times.previous(role, n[0]) for role, n in ((check.sender, node),
                                                                        (check.receiver, their_node))
                          if role in self.timed_roles]
                spans = [at - b for b in before if b is not None]
                if spans:
                    held.judged += 1
                    held.measured(max(spans))
            else:
                held.judged += 1


def _at_sender(message: RecordedMessage) -> bool:
    """Whether the message's log time is its sender's (not the time an external role's message was taken)."""
    return message.topic.metadata.get(f"{META}.sender_group") != "external"


def _after_any(view: ChannelView, nodes: frozenset[Node], count: int) -> frozenset[Node]:
    """The states ``count`` steps of any label lead to from ``nodes`` (the sets repeat: a
    cycle is not walked round more than once)."""
    history = [nodes]
    seen = {nodes: 0}
    for step in range(1, count + 1):
        labels = {t.label for t in view.allowed(nodes)}
        nodes = frozenset().union(*(view.step(nodes, label) for label in labels))
        if nodes in seen:
            start = seen[nodes]
            return history[start + (count - step) % (step - start)]
        seen[nodes] = step
        history.append(nodes)
    return nodes


def _actual(side: int, check: _ChannelCheck, label: str, topic: RecordedTopic) -> str:
    arrow = f"!{check.receiver}" if side == 0 else f"?{check.sender}"
    return f"{arrow}({label}) carrying a {topic.type_name}"


class _Codecs:
    """Decoders of the recorded types, and checks of the protocol's sorts, made once each.

    ``import_classes`` False (the protocol came from the recording): a sort bound to a class
    by import path is checked by the recorded class name (:mod:`.by_name`), never imported.
    """

    def __init__(self, import_classes: bool) -> None:
        self._found: dict[tuple[str, bool], SortCodec] = {}
        self._checks: dict[Sort | None, Validator | str] = {}
        self._import = import_classes

    def check(self, sort: Sort | None) -> Validator | str:
        """The payload check of ``sort``, or why there is none (its class cannot be imported here)."""
        found = self._checks.get(sort)
        if found is None:
            try:
                found = validator_for(sort) if self._import else validator_by_name(sort)
            except AnodizeError as error:  # the sort's class cannot be imported, or its ROS type resolved
                found = f"cannot check the payload: {error}"
            self._checks[sort] = found
        return found

    def decode(self, topic: RecordedTopic, data: bytes | memoryview) -> object:
        as_json = topic.type_name == JSON_TYPE and topic.metadata.get(f"{META}.encoding") == "json"
        key = (topic.type_name, as_json)
        codec = self._found.get(key)
        if codec is None:
            ros = ros_type(topic.type_name)
            codec = self._found[key] = SortCodec(None, ros, json=as_json)
        return codec.decode(data)


def _fitting_sorts(message: RecordedMessage, taken: list[Transition], codecs: _Codecs
                   ) -> tuple[frozenset[str | None], str, object]:
    """The sorts (keys) among ``taken``'s that the message's payload is of, if none, why not, and
    the payload (None if it was not decoded).

    The payload is decoded once, whatever the number of sorts its label may carry.
    """
    reasons: list[str] = []
    candidates: list[tuple[Sort | None, Validator | str]] = []
    for sort in {sort_key(t): t.sort for t in taken}.values():
        recorded = message.topic.type_name
        if recorded != codec_for_sort(sort).type_name:
            reasons.append(f"payload of the wrong sort: recorded a {recorded}, the label carries {sort_text(sort)}")
            continue
        candidates.append((sort, codecs.check(sort)))  # before decoding: the check may import the sort's class
    if not candidates:
        return frozenset(), "; ".join(reasons), None
    try:
        payload = codecs.decode(message.topic, message.data)
    except (AnodizeError, ValueError, KeyError, TypeError) as error:
        expected = " or ".join(sort_text(sort) for sort, _ in candidates)
        return frozenset(), "; ".join([*reasons, f"the payload does not decode as {expected}: {error}"]), None
    fits: set[str | None] = set()
    for sort, check in candidates:
        reason = _payload_problem(payload, sort, check)
        if reason:
            reasons.append(reason)
        else:
            fits.add(sort.key if sort is not None else None)
    return frozenset(fits), "; ".join(reasons), payload


def _payload_problem(payload: object, sort: Sort | None, check: Validator | str) -> str:
    """Why a decoded payload is not of ``sort`` ("" if it is); ``check`` is the sort's validator,
    or why there is none."""
    if isinstance(payload, UnknownObject):
        target = sort.target if sort is not None else None
        return "" if payload.class_name == target else (
            f"payload of the wrong sort: a recorded {payload.class_name}, the label carries {sort_text(sort)}")
    if isinstance(check, str):
        return check
    reason = check(payload)
    return f"payload of the wrong sort: {reason}" if reason else ""


def verify(recording: Recording, global_type: GlobalType, topics: Mapping[str, tuple[str, str, str]] | None = None,
           import_classes: bool = True, machines: Mapping[str, StateMachine] | None = None,
           signing_key: bytes | None = None) -> VerifyReport:
    """Check ``recording`` against ``global_type``.

    Args:
        topics: topic -> ``(sender, receiver, label)`` for topics without anodize's metadata
            (a recording made by another tool).
        import_classes: whether the payload classes ``global_type`` names by import path may be
            imported to check payloads: False when it is the protocol the recording carries
            (untrusted data; the payloads are then checked by their recorded class names, and
            the report says so).
        machines: the roles' state machines, if not ``global_type``'s projections.
        signing_key: the key the recording's chain heads must be signed with (``--key``), if any.

    Raises:
        RecordingError: the recording cannot be read, or its metadata is not anodize's.
    """
    began = time.perf_counter()
    if machines is None:
        machines = {role: global_type.project(role).fsm() for role in global_type.roles}
    labels = channel_labels(machines)
    pairs = {(s, r) for s, r, _ in labels}
    report = VerifyReport(str(recording.path), global_type.name)
    recorded = recorded_channels(recording)
    if not import_classes and class_sorts(t.sort for m in machines.values() for t in m.all_transitions()):
        report.notes.append(NOT_IMPORTED)
    keys: dict[int, tuple[str, str, str]] = {}
    gap_topics: set[int] = set()
    for topic in recording.topics:
        key = _key_of(topic, topics or {})
        if topic.metadata.get(GAP_KEY) == "1":
            gap_topics.add(topic.id)
        elif CLOCK_KEY in topic.metadata or CHAIN_KEY in topic.metadata:
            continue  # a role's clock readings: no channel of the protocol (a replay gives them back)
        elif LOG_KEY in topic.metadata:
            continue  # the roles' log records (/rosout): no channel of the protocol
        elif key is None:
            report.unmapped.append(f"{topic.topic} ({topic.type_name})")
        elif key[:2] not in pairs:
            report.unknown.append(f"{key[0]}->{key[1]} (topic {topic.topic}): global {global_type.name} "
                                  "has no such channel")
        else:
            keys[topic.id] = key
    checks = {pair: _ChannelCheck(*pair, machines) for pair in sorted({k[:2] for k in keys.values()})}
    codecs = _Codecs(import_classes)
    held = _constraints(report, machines, pairs, recorded if recorded is not None else {k[:2] for k in keys.values()})
    evidence = EvidenceCheck(recording.chain, recording.topics, signing_key)
    for message in recording.messages():
        evidence.see(message)
        report.messages += 1
        report.bytes += len(message.data)
        key = keys.get(message.topic.id)
        if key is not None:
            checks[key[:2]].check(message, key[2], codecs, held)
        elif message.topic.id in gap_topics:
            _note_gap(report, checks, message)
    report.channels = {check.name: check.result for check in checks.values()}
    report.evidence = evidence.result()
    if held is not None:
        report.constraints = list(held.held.values())
    # An anodize recording says which channels it records: those inside one group it does not.
    expected = sorted(pairs) if recorded is None else sorted(pair for pair in pairs if pair in recorded)
    report.missing = [f"{s}->{r}" for s, r in expected
                      if f"{s}->{r}" not in report.channels or not report.channels[f"{s}->{r}"].messages]
    report.inside = [f"{s}->{r}" for s, r in sorted(pairs) if (s, r) not in expected]
    if report.inside:
        report.left_out_by = left_out_by(recording)
    report.seconds = time.perf_counter() - began
    return report


def _constraints(report: VerifyReport, machines: Mapping[str, StateMachine], pairs: set[tuple[str, str]],
                 recorded: set[tuple[str, str]]) -> _Held | None:
    """What judges the protocol's time and value constraints (None: it has none: nothing to pay).

    A role's deadlines are judged only if each of its channels is in the recording: its
    previous action could otherwise be one the recording does not have (the report says so).
    """
    timed, refined = constrained(machines)
    if not timed and not refined:
        return None
    complete: set[str] = set()
    for role, machine in machines.items():
        absent = sorted(pair for pair in pairs if role in pair and pair not in recorded)
        if not absent:
            complete.add(role)
        elif any(t.timing is not None and t.timing.within is not None for t in machine.all_transitions()):
            channels = ", ".join(f"{s}->{r}" for s, r in absent)
            report.notes.append(f"deadlines of {role} not judged: its channel(s) {channels} are not in the recording "
                                "(its previous action may be one of theirs; a recording records every channel "
                                "unless [record] or --record-exclude leaves some out)")
    return _Held(machines, frozenset(complete), refined)


def _note_gap(report: VerifyReport, checks: Mapping[tuple[str, str], _ChannelCheck], message: RecordedMessage) -> None:
    """A gap record: which channel's numbers are missing, for its check to accept the skip."""
    try:
        found = json.loads(codec_for_sort(None).ros.deserialize(message.data).data)  # type: ignore[attr-defined]
        gap = Gap(str(found["channel"]), int(found["first"]), int(found["count"]), message.log_time)
        sender, receiver = gap.channel.split("->", 1)
    except (ValueError, KeyError, TypeError, AttributeError, AnodizeError):
        return  # not a gap record anodize wrote: ignored (a skip it does not explain stays a fault)
    report.gaps.append(gap)
    check = checks.get((sender, receiver))
    if check is not None:
        check.gaps[gap.first] = gap.count


def _key_of(topic: RecordedTopic, topics: Mapping[str, tuple[str, str, str]]) -> tuple[str, str, str] | None:
    meta = topic.metadata
    if f"{META}.sender" in meta:
        return meta[f"{META}.sender"], meta.get(f"{META}.receiver", ""), meta.get(f"{META}.label", "")
    return topics.get(topic.topic)


def _clock(stamp: int) -> str:
    import datetime

    moment = datetime.datetime.fromtimestamp(stamp / 1e9, tz=datetime.UTC)
    return f"{stamp / 1e9:.6f} s ({moment:%Y-%m-%d %H:%M:%S.%f} UTC)"
