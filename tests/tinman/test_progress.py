"""Progress people see: the bar of long work (rendering, visual odometry) and the live line of a run."""

from __future__ import annotations

import io
import re

import pytest

from anodize import GroupStatus
from anodize._supervision.report import GroupState
from anodize._tools.cli import ProgressLine
from tinman.app import TinMan
from tinman.progress import FrameProgress
from tinman.settings import Settings

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


class Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


@pytest.fixture(autouse=True)
def an_ordinary_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    """80 columns, and none of the variables by which users make rich draw or not draw."""
    monkeypatch.setenv("COLUMNS", "80")
    monkeypatch.setenv("TERM", "xterm-256color")
    for name in ("FORCE_COLOR", "NO_COLOR", "TTY_COMPATIBLE", "TTY_INTERACTIVE", "JUPYTER_COLUMNS"):
        monkeypatch.delenv(name, raising=False)


def shown(screen: str) -> list[str]:
    """The lines a terminal showed over time, colours and cursor movements taken out."""
    return [line for line in ANSI.sub("", screen).replace("\r", "\n").splitlines() if line.strip()]


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


# ---- the progress bar ---------------------------------------------------------------------

def test_a_bar_is_drawn_on_a_terminal_and_reaches_the_total() -> None:
    screen = Terminal()
    with FrameProgress("rendering", screen) as progress:
        for done in range(301):
            progress(done, 300)
    lines = shown(screen.getvalue())
    last = lines[-1]
    assert re.fullmatch(r"rendering ━+ 300/300 100% +[\d.]+ fps \d:\d\d:\d\d ETA 0:00:00", last.rstrip()), last
    assert "\u2501" in last  # a bar, drawn by rich
    assert all(len(line) <= 80 for line in lines)
    assert screen.getvalue().endswith("\n\x1b[?25h")  # finished: the cursor below the bar, and visible


def test_the_bar_closes_itself_at_the_total_and_a_failure_leaves_the_terminal_tidy() -> None:
    screen = Terminal()
    progress = FrameProgress("rendering", screen)
    progress(0, 2)
    progress(2, 2)
    drawn = screen.getvalue()
    assert shown(drawn)[-1].startswith("rendering") and "2/2" in shown(drawn)[-1]
    progress(2, 2)  # after the end: nothing more
    progress.close()
    assert screen.getvalue() == drawn

    def interrupted(progress: FrameProgress) -> None:
        progress(0, 10)
        progress(4, 10)
        raise KeyboardInterrupt

    screen = Terminal()
    with pytest.raises(KeyboardInterrupt), FrameProgress("rendering", screen) as progress:
        interrupted(progress)  # the bar is closed on the way out
    assert "4/10" in shown(screen.getvalue())[-1]
    assert screen.getvalue().endswith("\x1b[?25h")  # the cursor shown again


def test_nothing_is_shown_before_the_first_report_or_when_disabled() -> None:
    screen = Terminal()
    with FrameProgress("rendering", screen):
        pass  # e.g. the sequence was cached: there was nothing to do
    with FrameProgress("rendering", screen, enabled=False) as progress:  # --quiet
        for done in range(11):
            progress(done, 10)
    assert screen.getvalue() == ""


def test_a_dumb_terminal_is_treated_as_a_log(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TERM", "dumb")
    screen = Terminal()
    with FrameProgress("rendering", screen) as progress:
        for done in range(11):
            progress(done, 10)
    assert screen.getvalue() == ""


def test_in_a_log_short_work_writes_nothing() -> None:
    log = io.StringIO()
    with FrameProgress("visual odometry", log) as progress:
        for done in range(101):
            progress(done, 100)
    assert log.getvalue() == ""


def test_in_a_log_long_work_writes_a_line_every_ten_seconds_and_one_at_the_end() -> None:
    log, clock = io.StringIO(), Clock()
    with FrameProgress("rendering", log, clock=clock) as progress:
        for done in range(901):  # 900 frames at 10 per second: 90 s
            clock.now = 100.0 + done / 10
            progress(done, 900)
    lines = log.getvalue().splitlines()
    assert len(lines) == 9  # not 900
    assert lines[0] == "rendering: 100/900 frames (11%), 10.0 fps, 0:01:20 left"
    assert lines[-2].startswith("rendering: 800/900 frames (88%), ")
    assert lines[-1] == "rendering: 900/900 frames in 0:01:30"
    assert "\x1b" not in log.getvalue() and "\r" not in log.getvalue()


# ---- the live line of 'anodize run tinman' ------------------------------------------------

def statuses(**states: tuple[GroupState, float | None]) -> dict[str, GroupStatus]:
    return {name: GroupStatus(name=name, state=state, rate_hz=rate, messages=123_456)
            for name, (state, rate) in states.items()}


BUSY = statuses(control=(GroupState.RUNNING, 1523.0), perception=(GroupState.RESTARTING, 62.0),
                planning=(GroupState.RUNNING, 1.0), simulation=(GroupState.STARTING, None))


def tinman(duration: float = 20.0) -> TinMan:
    system = TinMan()
    system.settings = Settings(duration=duration)
    return system


def test_tinmans_line_fits_80_columns() -> None:
    line = tinman(120.0).progress(BUSY, 100.04)
    assert line == "TinMan 100.0/120s con 1523/s per restart pla 1/s sim start"
    assert len(line) <= 80
    worst = statuses(**dict.fromkeys(("control", "perception", "planning", "simulation"),
                                     (GroupState.RESTARTING, 99999.0)))
    assert len(tinman(3600.0).progress(worst, 3599.9)) <= 80


def test_a_failed_group_shows_on_tinmans_line() -> None:
    failed = {**BUSY, "planning": GroupStatus(name="planning", state=GroupState.FAILED, rate_hz=3.0)}
    assert tinman().progress(failed, 12.3) == "TinMan 12.3/20s con 1523/s per restart pla FAILED sim start"


def test_tinmans_line_is_in_full_where_the_terminal_is_wide(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "200")
    assert tinman().progress(BUSY, 12.34) == ("TinMan 12.3/20 s | control running 1523 msg/s | perception restarting "
                                              "| planning running 1 msg/s | simulation starting")


def test_tinmans_line_on_the_terminal_is_redrawn_within_80_columns() -> None:
    screen = Terminal()
    line = ProgressLine(screen, tinman().progress)
    line(BUSY)
    line({**BUSY, "perception": GroupStatus(name="perception", state=GroupState.FAILED)})
    line.close()
    drawn = ANSI.sub("", screen.getvalue()).split("\r")[1:]
    assert [text.startswith("TinMan ") for text in drawn] == [True, True]
    assert all(len(text.rstrip("\n")) <= 80 for text in drawn)
    assert "per FAILED" in drawn[1]
