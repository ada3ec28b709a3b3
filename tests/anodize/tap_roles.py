"""A channel tap for tests (importable by group processes): each group writes what it tapped to a file."""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from anodize._recording.tap import TappedChannel
from anodize._session.channel import Channel
from anodize.taps import TapGroup, TapRun


@dataclass(frozen=True)
class FileTapPlan:
    """Picklable: it crosses into group processes."""

    folder: str
    close_seconds: float = 0.0  # how long closing takes (a recording's tail on a slow disk)

    def open(self, group: TapGroup) -> FileGroupTap:
        return FileGroupTap(Path(self.folder) / f"{group.name}-{group.incarnation}.json", group, self.close_seconds)


class FileGroupTap:
    """Counts what the group's roles put on the channels it was offered."""

    def __init__(self, path: Path, group: TapGroup, close_seconds: float = 0.0) -> None:
        self.path = path
        self.group = group
        self.close_seconds = close_seconds
        self.sent: dict[str, int] = {}

    def attach(self, queues: dict[tuple[str, str], Channel]) -> None:
        for pair, channel in list(queues.items()):
            if pair[0] in self.group.machines:  # tapped where it is sent
                queues[pair] = _Counting(channel, self, f"{pair[0]}->{pair[1]}")  # type: ignore[assignment]

    def close(self) -> None:
        time.sleep(self.close_seconds)
        self.path.write_text(json.dumps({"roles": sorted(self.group.machines), "sent": self.sent}))


class _Counting(TappedChannel):
    """Counts each message as it leaves (the channel's other traffic passes untouched)."""

    def __init__(self, inner: Channel, tap: FileGroupTap, name: str) -> None:
        super().__init__(inner, (name, ""), at_sender=True)
        self._tap = tap
        self._name = name

    def leaving(self, label: str, payload: object) -> object:
        self._tap.sent[self._name] = self._tap.sent.get(self._name, 0) + 1
        return None


class FileTap:
    """The supervisor's half: a :class:`anodize.ChannelTap`."""

    def __init__(self, folder: Path, close_seconds: float = 0.0) -> None:
        self.folder = folder
        self.close_seconds = close_seconds
        self.runs: list[TapRun] = []
        self.statuses = 0

    def begin(self, run: TapRun) -> FileTapPlan:
        self.runs.append(run)
        return FileTapPlan(str(self.folder), self.close_seconds)

    def status(self, statuses: Mapping[str, Any]) -> None:
        self.statuses += 1

    def end(self) -> list[str]:
        seen = {p.stem: json.loads(p.read_text()) for p in sorted(self.folder.glob("*.json"))}
        return [f"file tap: {name} sent {data['sent']}" for name, data in seen.items()]
