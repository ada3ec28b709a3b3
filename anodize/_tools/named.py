"""Named systems: ``anodize run NAME`` for systems that packages register.

A package registers a system under the entry-point group ``anodize.systems``::

    [project.entry-points."anodize.systems"]
    tinman = "tinman.app:TINMAN"

The object named there follows :class:`NamedSystem`: it adds its own command-line
options, builds the :class:`System` to run, may describe progress in one line,
and turns the run report into its own results. anodize finds it by name at run
time and never imports the package otherwise.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from pathlib import Path
from typing import Protocol

from .._recording.selection import RecordSelection
from .._supervision.report import GroupStatus, RunReport
from .._supervision.system import System
from ..errors import AnodizeError

__all__ = ["ENTRY_POINT_GROUP", "NamedSystem", "Prepared", "Finished", "find_named", "named_systems"]

ENTRY_POINT_GROUP = "anodize.systems"


@dataclass
class Prepared:
    """What a named system hands back to be run: the system, its timeout (seconds), where
    to record it (None: not recorded; every channel is recorded, inside groups too, unless
    ``record_selection`` chooses, e.g. the system file's ``[record]``; ``record_inside=False``:
    only the channels between groups), and ``stop_when``: asked about twice a second
    while the run goes, it ends the run early by returning a reason (None: go on; see
    ``System.run``)."""

    system: System
    timeout: float | None
    grace: float = 3.0
    record: Path | None = None
    stop_when: Callable[[], str | None] | None = None
    record_inside: bool = True
    record_selection: RecordSelection | None = None

    def selection(self) -> RecordSelection:
        """The channels to record: ``record_selection``, else every one ``record_inside`` allows."""
        if self.record_selection is not None:
            return self.record_selection
        return RecordSelection(inside=self.record_inside)


@dataclass
class Finished:
    """A named system's results: lines for people, and whether the run met its goals."""

    ok: bool
    lines: list[str] = field(default_factory=list)


class NamedSystem(Protocol):
    """The object a package registers under ``anodize.systems``."""

    summary: str  # one line for ``anodize run --help``

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        """Add this system's options to ``anodize run NAME``'s parser."""

    def prepare(self, args: argparse.Namespace, log: Callable[[str], None]) -> Prepared:
        """Build the system for these options (raise ``AnodizeError`` for bad ones).

        ``args.param``, ``args.remap`` and ``args.namespace`` are the composition options
        ``anodize run NAME`` always offers (``-p``, ``-r``, ``--namespace``): give them to the
        system file's :meth:`SystemConfig.with_overrides`.

        ``log`` shows a line to the user (e.g. that a long preparation is under way).
        """

    def progress(self, statuses: dict[str, GroupStatus], elapsed: float) -> str:
        """One line describing the run so far."""

    def finish(self, report: RunReport, args: argparse.Namespace) -> Finished:
        """Turn the run report into this system's results (files written, lines to print)."""


def named_systems() -> list[str]:
    """The names registered by installed packages, sorted."""
    return sorted({ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)})


def find_named(name: str) -> NamedSystem | None:
    """The system registered as ``name``, or None.

    Raises:
        AnodizeError: it is registered but cannot be loaded.
    """
    for point in entry_points(group=ENTRY_POINT_GROUP, name=name):
        try:
            return point.load()  # type: ignore[no-any-return]
        except Exception as error:  # the package's import failed: say which and why
            raise AnodizeError(f"named system {name!r} ({point.value}) cannot be loaded: "
                               f"{type(error).__name__}: {error}") from None
    return None
