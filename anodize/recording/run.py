"""A recorded run, seen from the supervisor: the plan it hands the groups, and the merge at the end."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path

from sessiontypes import GlobalType

from .merge import merge_parts
from .plan import RecordPlan

__all__ = ["RecordedRun"]


class RecordedRun:
    """The recording ``target`` of one run, made by the groups following ``plan``."""

    def __init__(self, target: str | os.PathLike[str], plan: RecordPlan) -> None:
        self.target = Path(target)
        self.plan = plan

    def finish(self, global_type: GlobalType, transport: str, functions: Mapping[str, str]) -> list[str]:
        """Merge the groups' parts into the recording; returns notes for the run's report.

        ``functions`` (role -> ``module:function``) goes into the recording for ``anodize replay``.
        """
        location = global_type.location
        info = {"protocol_file": location.path, "protocol_source": "\n".join(global_type.source_lines),
                "global": global_type.name, "transport": transport, "anodize_version": _version(),
                "recorded_channels": " ".join(sorted(f"{s}->{r}" for s, r in
                                                     self.plan.at_sender | self.plan.at_receiver)),
                "role_functions": json.dumps(dict(functions)), "group_of": json.dumps(dict(self.plan.group_of))}
        result = merge_parts(Path(self.plan.parts), self.target, info)
        size = f"{result.bytes / 2**20:.1f} MiB"
        notes = [f"recorded {result.messages} messages ({size}) on {result.channels} channels between groups to "
                 + str(self.target)]
        notes.extend(f"recording: {note}" for note in result.notes)
        return notes


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("anodize")
    except PackageNotFoundError:  # run from a checkout that is not installed
        return "unknown"
