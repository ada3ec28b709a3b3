"""The pieces of logging: the capture, the control messages that carry records, the fan-out, the terminal."""

from __future__ import annotations

import dataclasses
import io
import logging
import threading

import pytest

from anodize import GroupStatus, LogEntry
from anodize._session.logs import LogCapture, bind_role, severity_name
from anodize._supervision.control import Logs, decode_control, encode_control
from anodize._supervision.logcarry import BATCH, from_message, to_messages
from anodize._supervision.logfanout import LogFanout
from anodize._supervision.report import GroupState
from anodize._tools.cli import LiveStatus
from anodize._tools.loglines import LogLines

ENTRY = LogEntry(role="P", group="a", level=logging.WARNING, logger="P", message="battery low", wall=1.5e9,
                 monotonic=12.0, file="roles.py", function="producer", line=7)


@pytest.fixture
def capture() -> LogCapture:
    found = LogCapture({"P": "a", "C": "b"}, capacity=3)
    found.install()
    yield found
    found.uninstall()
    bind_role(None)


def test_a_record_is_the_roles_by_its_thread_or_its_loggers_name(capture: LogCapture) -> None:
    logging.getLogger("not.a.role").warning("nobody's")  # not a role's thread, not a role's logger
    logging.getLogger("C").warning("C's by its name")

    def role_thread() -> None:
        bind_role("P")
        logging.getLogger("some.module").warning("P's by its thread")
    thread = threading.Thread(target=role_thread)
    thread.start()
    thread.join()
    entries, dropped = capture.drain()
    assert [(e.role, e.group, e.severity, e.message) for e in entries] == [
        ("C", "b", "WARN", "C's by its name"), ("P", "a", "WARN", "P's by its thread")]
    assert dropped == {}


def test_past_its_capacity_records_are_dropped_and_counted_by_severity(capture: LogCapture) -> None:
    log = logging.getLogger("P")
    for i in range(5):
        log.error("number %d", i)
    log.critical("the last")
    entries, dropped = capture.drain()
    assert [e.message for e in entries] == ["number 0", "number 1", "number 2"]  # the first kept
    assert dropped == {"ERROR": 2, "FATAL": 1}
    assert capture.drain() == ([], {})


def test_an_exception_logged_carries_its_traceback(capture: LogCapture) -> None:
    try:
        raise ValueError("lidar unplugged")
    except ValueError:
        logging.getLogger("P").exception("scan failed")
    (entry,), _ = capture.drain()
    assert entry.message.startswith("scan failed\nTraceback") and "ValueError: lidar unplugged" in entry.message


@pytest.mark.parametrize(("level", "name"), [(5, "DEBUG"), (logging.INFO, "INFO"), (25, "INFO"),
                                             (logging.WARNING, "WARN"), (logging.ERROR, "ERROR"),
                                             (logging.CRITICAL, "FATAL"), (99, "FATAL")])
def test_pythons_levels_are_named_as_ros_names_severities(level: int, name: str) -> None:
    assert severity_name(level) == name


def test_records_travel_in_batches_and_come_back_the_same() -> None:
    entries = [ENTRY] * (BATCH + 1)
    messages = list(to_messages(entries, {"INFO": 4}))
    assert [len(m.roles) for m in messages] == [BATCH, 1] and messages[0].dropped == {"INFO": 4}
    decoded = [decode_control(encode_control(m)[4:]) for m in messages]
    assert all(isinstance(m, Logs) for m in decoded)
    assert [e for m in decoded for e in from_message(m, "a", ("P",))] == entries  # type: ignore[arg-type]
    assert list(to_messages([], {})) == []


def test_a_batch_naming_another_groups_role_or_uneven_is_refused() -> None:
    (message,) = to_messages([ENTRY], {})
    with pytest.raises(ValueError, match="roles not of group b: P"):
        from_message(message, "b", ("C",))
    with pytest.raises(ValueError, match="columns differ"):
        from_message(Logs(roles=("P",), levels=()), "a", ("P",))


def test_a_receiver_that_raises_is_dropped_and_named_and_the_others_go_on() -> None:
    seen: list[str] = []

    def broken(entries: object) -> None:
        raise OSError("disk full")
    fanout = LogFanout([("Broken", broken), ("on_log", lambda entries: seen.extend(e.message for e in entries))])
    fanout([ENTRY])
    fanout([ENTRY])
    assert seen == ["battery low", "battery low"]
    assert fanout.problems == ["logging: Broken raised OSError: disk full; it is handed no more records"]


class Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_terminal_shows_records_ros_style_above_the_live_lines_and_quiet_keeps_warnings() -> None:
    stream = Tty()
    cleared: list[bool] = []
    lines = LogLines(stream, logging.WARNING, lambda: cleared.append(True))
    lines([dataclasses.replace(ENTRY, level=logging.INFO, message="hidden"), ENTRY])
    assert stream.getvalue() == "[WARN] [1500000000.000000] [P]: battery low\n" and cleared == [True]
    lines([dataclasses.replace(ENTRY, level=logging.DEBUG)])
    assert cleared == [True]  # nothing shown: the live lines stay


def test_live_status_lines_are_cleared_for_a_record_and_drawn_again() -> None:
    stream = Tty()
    status = LiveStatus(stream)
    groups = {name: GroupStatus(name=name, state=GroupState.RUNNING, pid=1, memory=0, messages=0, received=0,
                                rate_hz=None, restarts=0, note="") for name in ("a", "b")}
    status(groups)
    status.clear()
    assert stream.getvalue().endswith("\x1b[2F\x1b[J") and status.drawn == 0
    status(groups)  # drawn anew below the records, not over them
    assert not stream.getvalue().endswith("\x1b[2F\x1b[J") and status.drawn == 2


def test_a_record_of_no_role_still_reaches_pythons_last_resort(capture: LogCapture,
                                                                capsys: pytest.CaptureFixture[str],
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    root = logging.getLogger()
    monkeypatch.setattr(root, "handlers", [capture])  # as in a group's process: ours is the only handler
    logging.getLogger("some.library").warning("a library's warning")
    logging.getLogger("some.library").info("a library's chatter")
    assert capsys.readouterr().err == "a library's warning\n"
    assert capture.drain() == ([], {})
