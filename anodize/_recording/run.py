"""A recorded run, seen from the supervisor: the tap that plans it, and the merge at the end."""

from __future__ import annotations

import dataclasses
import json
import os
import secrets
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .._session.logs import LogEntry
from ..errors import AnodizeError
from ..taps import TapRun
from .merge import merge_parts
from .plan import RecordPlan, channel_labels, record_plan
from .rosout import write_part
from .selection import RecordSelection
from .tap import GroupRecording

__all__ = ["Recording", "LOGS_KEPT", "LOG_TEXT_KEPT"]

LOGS_KEPT = 1_000_000  # log records a recording holds for /rosout; beyond them, records are counted, not kept
LOG_TEXT_KEPT = 64 * 2**20  # and the characters of their messages: the supervisor holds them until the end


class Recording:
    """A channel tap (:mod:`anodize.taps`) that records every message to ``target``, those inside
    a group too (so that every role can be replayed alone; ``inside=False``: only those between
    groups; ``selection``: the channels chosen, :class:`~.selection.RecordSelection`), and every
    reading of each role's clock (``Endpoint.now()``, ``Endpoint.wall()``).

    ``System.run(taps=[Recording("run.mcap")])``: an MCAP file if ``target`` ends in
    ``.mcap``, else a rosbag2 folder (docs/recording.md). Each group writes its part
    beside the target; when the run ends the parts are merged and the report's notes
    say what was recorded. A recording records one run.

    Each channel's messages are chained by SHA-256 (docs/recording.md, "Recordings as
    evidence"); the report gives the digest of the chain heads, and with ``sign_key`` (the
    bytes of a secret key) the heads are signed (HMAC-SHA256) for ``anodize verify --key``.
    """

    def __init__(self, target: str | os.PathLike[str], inside: bool = True,
                 selection: RecordSelection | None = None, sign_key: bytes | None = None) -> None:
        self.target = Path(target)
        self.selection = selection if selection is not None else RecordSelection(inside=inside)
        self.inside = self.selection.inside
        self.sign_key = sign_key
        self.plan: RecordPlan | None = None
        self._run: TapRun | None = None
        self._logs: list[LogEntry] = []
        self._logs_over = 0  # records past LOGS_KEPT or LOG_TEXT_KEPT
        self._log_text = 0  # characters of the kept records' messages

    def begin(self, run: TapRun) -> GroupRecording:
        """Plan which channels each group records, under which topics."""
        if self._run is not None:
            raise AnodizeError(f"recording {self.target} records one run: make another for the next")
        # The parts are written beside the target, so the merge is a rename away on the same file system.
        parts = self.target.with_name(f".{self.target.name}.parts-{os.getpid()}")
        # A channel the selection names must be one of the protocol's (checked here for the Python API;
        # a system file's [record] is checked, located, when the system is built).
        self.selection.check({(s, r) for s, r, _ in channel_labels(run.machines)}, f"global {run.global_type.name}")
        self.plan = dataclasses.replace(record_plan(str(parts), run.machines, run.group_of, run.topics,
                                                    selection=self.selection, qos=run.qos),
                                        run_id=secrets.token_hex(16))  # each chain starts from it
        self._run = run
        return GroupRecording(self.plan)

    def status(self, statuses: Mapping[str, Any]) -> None:
        """Nothing: a recording is of messages, not of statuses."""

    def log(self, entries: Sequence[LogEntry]) -> None:
        """The roles' log records, as they reach the supervisor: recorded on ``/rosout`` at the end."""
        for entry in entries:
            if len(self._logs) < LOGS_KEPT and self._log_text + len(entry.message) <= LOG_TEXT_KEPT:
                self._logs.append(entry)
                self._log_text += len(entry.message)
            else:
                self._logs_over += 1

    def end(self) -> list[str]:
        """Merge the groups' parts into the recording; returns notes for the run's report."""
        run, plan = self._run, self.plan
        if run is None or plan is None:
            return []
        location = run.global_type.location
        info = {"protocol_file": location.path, "protocol_source": "\n".join(run.global_type.source_lines),
                "global": run.global_type.name, "transport": run.transport, "anodize_version": _version(),
                "recorded_channels": " ".join(sorted(f"{s}->{r}" for s, r in plan.at_sender | plan.at_receiver)),
                "role_functions": json.dumps(dict(run.functions)), "group_of": json.dumps(dict(plan.group_of)),
                "run_id": plan.run_id, "record_selection": self.selection.to_json()}
        if self._logs:
            write_part(Path(plan.parts), self._logs, run.global_type.name)
        result = merge_parts(Path(plan.parts), self.target, info, self.sign_key)
        size = f"{result.bytes / 2**20:.1f} MiB"
        chosen = self.selection.describe()
        where = {"every channel": " between and inside groups",
                 "the channels between groups": " between groups"}.get(chosen)
        topics = _count(result.topics, 'topic')
        on = f"{_count(result.channels, 'channel')} ({topics})" if where else \
            f"{_count(result.channels, 'channel')} ({topics}; {chosen})"
        readings = f", and {result.readings} readings of the roles' clocks," if result.readings else ""
        notes = [f"recorded {result.messages} messages ({size}) on {on}{where or ''}{readings} to {self.target}"]
        signed = ", signed (HMAC-SHA256)" if result.signed else ""
        notes.append(f"recording: {_count(result.chains, 'hash chain')}, heads sha256 {result.heads_digest}{signed}")
        if self._logs:
            notes.append(f"recording: {result.logs} log records on /rosout" + (
                f"; {self._logs_over} more were not recorded (over {LOGS_KEPT} records or "
                f"{LOG_TEXT_KEPT // 2**20} MiB of text)" if self._logs_over else ""))
        notes.extend(f"recording: {note}" for note in result.notes)
        return notes


def _count(n: int, word: str) -> str:
    """``1 channel``, ``2 channels``."""
    return f"{n} {word}{'' if n == 1 else 's'}"


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("anodize")
    except PackageNotFoundError:  # run from a checkout that is not installed
        return "unknown"
