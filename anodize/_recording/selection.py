"""Which channels a recording records: every one by default, or the system file's choice.

A recording records every channel of the protocol, those inside a group too (as
``ros2 bag record -a`` records every topic; docs/recording.md says why), unless it
is told otherwise: a system file's ``[record]`` table names the channels to record
(``channels = ["Joy->Control"]``: only these) or to leave out (``exclude = [...]``:
everything but these), and ``anodize run --record-exclude A->B`` leaves one out;
``inside = False`` (``--record-between``) records only the channels between groups, as
recordings did before. A channel is named as in ``[channels]``: ``"Sender->Receiver"``.

A recording selects whole channels, never one label of a channel: ``verify`` checks a
channel's labels in their order and ``replay`` feeds them in their order, so a channel
missing one of its labels could be neither checked nor replayed.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from sessiontypes import GlobalType
from sessiontypes.graph import communication_graph

from ..errors import ConfigurationError

__all__ = ["RecordSelection", "SelectionError", "parse_channel", "selection_from_table", "SELECTION_KEYS"]

SELECTION_KEYS = ("channels", "exclude", "inside")  # the keys of a system file's [record] table


class SelectionError(ConfigurationError):
    """A ``[record]`` table or a ``--record-exclude`` that names no channel, or not in the
    form expected. ``key``: where (``channels``, ``exclude[2]``, ...), ``problem``: what."""

    def __init__(self, key: str, problem: str) -> None:
        self.key = key
        self.problem = problem
        super().__init__(f"{key}: {problem}")


@dataclass(frozen=True)
class RecordSelection:
    """The channels a recording records (picklable).

    Attributes:
        inside: record the channels inside a group too (the default); False: only those
            between groups (and from external roles).
        channels: record only these ``(sender, receiver)`` channels (None: every one
            ``inside`` allows); named explicitly, a channel is recorded even inside a group.
        exclude: never record these.
    """

    inside: bool = True
    channels: frozenset[tuple[str, str]] | None = None
    exclude: frozenset[tuple[str, str]] = frozenset()

    def chooses(self, pair: tuple[str, str], group_of: Mapping[str, str]) -> bool:
        """Whether channel ``pair`` is recorded in a run whose roles run in ``group_of``'s groups."""
        if pair in self.exclude:
            return False
        if self.channels is not None:
            return pair in self.channels
        return self.inside or group_of.get(pair[0]) != group_of.get(pair[1])

    def for_run(self, between: bool, exclude: Iterable[str], global_type: GlobalType) -> RecordSelection:
        """The selection with the command line's ``--record-between`` and ``--record-exclude`` applied.

        Raises:
            SelectionError: an excluded name is not of the form ``"Sender->Receiver"``, or not a
                channel of ``global_type``; ``between`` beside a ``[record] channels`` list.
        """
        if between and self.channels is not None:  # it would change nothing: say so rather than ignore it
            raise SelectionError("--record-between", "the system file's [record] channels already names the "
                                                     "channels recorded; leave one of the two out")
        chosen = RecordSelection(False, self.channels, self.exclude) if between else self
        names = frozenset(parse_channel(name, f"--record-exclude {name}") for name in exclude)
        excluded = RecordSelection(exclude=names)
        try:
            excluded.check(communication_graph(global_type).edges, f"global {global_type.name}")
        except SelectionError as error:
            raise SelectionError("--record-exclude", error.problem) from None
        return RecordSelection(chosen.inside, chosen.channels, chosen.exclude | excluded.exclude)

    def check(self, pairs: Iterable[tuple[str, str]], what: str) -> None:
        """Every channel the selection names is one of ``pairs`` (the protocol's, ``what``).

        Raises:
            SelectionError: naming the first unknown channel and the channels there are.
        """
        known = set(pairs)
        for key, chosen in (("channels", self.channels or frozenset()), ("exclude", self.exclude)):
            unknown = sorted(pair for pair in chosen if pair not in known)
            if unknown:
                there = ", ".join(f"{s}->{r}" for s, r in sorted(known))
                raise SelectionError(f"{key}", f"{what} has no channel {unknown[0][0]}->{unknown[0][1]}; "
                                               f"expected one of {there}")

    def describe(self) -> str:
        """The selection in words, for the run's report: ``every channel``, ``between groups``, ..."""
        if self.channels is not None:
            head = "the channels chosen in [record]"
        else:
            head = "every channel" if self.inside else "the channels between groups"
        if self.exclude:
            head += " but " + ", ".join(f"{s}->{r}" for s, r in sorted(self.exclude))
        return head

    def to_json(self) -> str:
        """The selection as recorded in the recording's metadata (``record_selection``)."""
        return json.dumps({"inside": self.inside,
                           "channels": None if self.channels is None else sorted(f"{s}->{r}" for s, r in self.channels),
                           "exclude": sorted(f"{s}->{r}" for s, r in self.exclude)})


def parse_channel(name: object, key: str) -> tuple[str, str]:
    """``"Sender->Receiver"`` as a pair.

    Raises:
        SelectionError: not a string of that form (``"A->B:label"`` included: a recording
            selects whole channels).
    """
    expected = 'expected a channel "Sender->Receiver"'
    if not isinstance(name, str):
        raise SelectionError(key, f"{expected}, got {_kind(name)}")
    sender, arrow, receiver = name.partition("->")
    if arrow and ":" in receiver and sender and receiver.split(":", 1)[0]:
        raise SelectionError(key, f"{expected}, got {name!r}: a recording selects whole channels (verify checks "
                                  "a channel's labels in order, and replay feeds them in order); write "
                                  f"{sender.strip()}->{receiver.split(':', 1)[0].strip()}")
    sender, receiver = sender.strip(), receiver.strip()
    if not arrow or not sender.isidentifier() or not receiver.isidentifier():
        raise SelectionError(key, f"{expected}, got {name!r}")
    return sender, receiver


def selection_from_table(table: object) -> RecordSelection:
    """A system file's ``[record]`` table (its shape; the channels against the protocol are
    checked by :meth:`RecordSelection.check` once the protocol is loaded).

    Raises:
        SelectionError: an unknown key, or a value not of the expected form.
    """
    if table is None:
        return RecordSelection()
    if not isinstance(table, dict):
        raise SelectionError("", f'expected a table such as [record] exclude = ["A->B"], got {_kind(table)}')
    for key in table:
        if key not in SELECTION_KEYS:
            raise SelectionError(key, f"unknown key; expected one of {', '.join(SELECTION_KEYS)}")
    inside = table.get("inside", True)
    if not isinstance(inside, bool):
        raise SelectionError("inside", f"expected true or false, got {_kind(inside)}")
    channels = _channel_list(table, "channels") if "channels" in table else None
    exclude = _channel_list(table, "exclude") if "exclude" in table else frozenset()
    if channels is not None and not channels:
        raise SelectionError("channels", 'expected at least one channel such as "A->B" (to record nothing, '
                                         "run without --record)")
    return RecordSelection(inside, channels, exclude)


def _channel_list(table: Mapping[str, object], key: str) -> frozenset[tuple[str, str]]:
    value = table[key]
    if not isinstance(value, list):
        raise SelectionError(key, f'expected an array of channels such as ["A->B"], got {_kind(value)}')
    return frozenset(parse_channel(item, f"{key}[{index}]") for index, item in enumerate(value))


def _kind(value: object) -> str:
    if isinstance(value, str):
        return repr(value) if len(value) <= 60 else f"{value[:57]!r}..."
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return str(value)
    if isinstance(value, list):
        return "an array"
    return "a table" if isinstance(value, dict) else f"a {type(value).__name__}"
