"""How far long work has got, for people: a progress bar on a terminal, a line now and then in a log.

Rendering the synthetic sequence (``anodize run tinman`` the first time, ``tinman
generate``) and running visual odometry over a sequence (``tinman vo-eval``) take a
minute or more. The functions that do the work report ``(done, total)`` to an
optional callback; :class:`FrameProgress` is that callback for the command lines.

On a terminal it draws a bar with `rich <https://rich.readthedocs.io>`_: frames done of
the total, per cent, rate, time taken and time left. Anywhere else (a log, a pipe) it
writes one plain line every ``LOG_EVERY`` seconds, and a last one at the end if it wrote
any: short work leaves no trace, long work a few lines, never one per frame.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from types import TracebackType
from typing import TextIO

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    Task,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.text import Text

__all__ = ["FrameProgress"]


class FrameProgress:
    """A ``progress(done, total)`` callback that shows the work on ``stream``.

    Nothing is shown until the first call, so it costs nothing when the work turns
    out not to be needed (a sequence already cached). It closes itself when ``done``
    reaches ``total``; use it as a context manager (or call :meth:`close`) so that the
    bar is finished and the terminal left tidy when the work fails or is interrupted.

    Args:
        description: what is being done, e.g. ``"rendering"``; starts the line.
        stream: where to show it (``sys.stderr`` by default).
        enabled: ``False`` (e.g. for ``--quiet``) shows nothing at all.
        clock: seconds, for the log's pacing and rate (tests give their own).
    """

    LOG_EVERY = 10.0  # seconds between two lines in a log

    def __init__(self, description: str, stream: TextIO | None = None, *, enabled: bool = True,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.description = description
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.clock = clock
        self.done = 0
        self.total = 0
        self.lines = 0  # lines written to a log
        self._started: float | None = None
        self._logged = 0.0
        self._bar: _Bar | None = None
        self._closed = False

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled or self._closed:
            return
        self.done, self.total = done, total
        if self._started is None:
            self._started = self._logged = self.clock()
            if _interactive(self.stream):
                self._bar = _Bar(self.stream, self.description, total)
        if self._bar is not None:
            self._bar.update(done, total)
        elif self.clock() - self._logged >= self.LOG_EVERY and done < total:
            self._logged = self.clock()
            self._log(self._line())
        if done >= total:
            self.close()  # the finished bar stays on the screen; what is printed next goes below it

    def close(self) -> None:
        """Finish the bar (it stays on the screen) or, in a log that has had lines, write the last one."""
        if self._closed:
            return
        self._closed = True
        if self._bar is not None:
            self._bar.stop()
        elif self.lines and self._started is not None:
            self._log(f"{self.description}: {self.done}/{self.total} frames in "
                      f"{_clock_time(self.clock() - self._started)}")

    def __enter__(self) -> FrameProgress:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()

    def _line(self) -> str:
        assert self._started is not None
        elapsed = self.clock() - self._started
        line = f"{self.description}: {self.done}/{self.total} frames"
        if self.total:
            line += f" ({100 * self.done // self.total}%)"
        rate = self.done / elapsed if elapsed > 0 else 0.0
        if rate > 0:
            line += f", {rate:.1f} fps, {_clock_time((self.total - self.done) / rate)} left"
        return line

    def _log(self, line: str) -> None:
        self.stream.write(line + "\n")
        self.stream.flush()
        self.lines += 1


def _interactive(stream: TextIO) -> bool:
    """A terminal a bar can be redrawn on (not a file, a pipe or TERM=dumb)."""
    try:
        if not stream.isatty():
            return False
    except (AttributeError, ValueError):  # no isatty, or closed
        return False
    return Console(file=stream).is_interactive


def _clock_time(seconds: float) -> str:
    minutes, second = divmod(round(seconds), 60)
    hours, minute = divmod(minutes, 60)
    return f"{hours}:{minute:02d}:{second:02d}"


class _Bar:
    """rich's progress display with one task: ``rendering ━━━━━━╸━━━ 412/900 46% 10.3 fps 0:00:40 ETA 0:00:47``."""

    def __init__(self, stream: TextIO, description: str, total: int) -> None:
        # print() is not redirected through the bar: rich would move stdout's lines to this stream.
        self.progress = Progress(
            TextColumn("{task.description}"), BarColumn(bar_width=None), MofNCompleteColumn(),
            TaskProgressColumn(), _RateColumn(), TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
            console=Console(file=stream), refresh_per_second=5, redirect_stdout=False, redirect_stderr=False)
        self.task = self.progress.add_task(description, total=total)
        self.progress.start()

    def update(self, done: int, total: int) -> None:
        self.progress.update(self.task, completed=done, total=total)

    def stop(self) -> None:
        self.progress.refresh()
        self.progress.stop()


class _RateColumn(ProgressColumn):
    """Frames per second (rich's own speed column counts bytes)."""

    def render(self, task: Task) -> Text:
        speed = task.finished_speed or task.speed
        return Text("  ? fps" if speed is None else f"{speed:4.1f} fps", style="progress.data.speed")
