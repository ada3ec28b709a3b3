"""Hypothesis profiles for the whole suite, and the fixtures several packages' tests share.

- ``dev`` (the default on a developer's machine): random, with the example database,
  so a failure found once is replayed until it is fixed.
- ``ci`` (the default where ``CI`` is set, as ``.ci/run`` does): derandomized and without
  a database, so every CI run tries the same examples and a green run stays green.
- ``thorough``: ten times the examples of every property test, for a hunting campaign:
  ``pytest --hypothesis-profile=thorough tests``.
- ``rerun``: a quarter of the examples, derandomized: the suite's second pass over the
  endpoint tests on the pure-Python core (a differential check; the first pass, on the
  compiled core, tried the full count).

Property tests scale their own example counts with :func:`budget.examples`, so the
profile's multiplier reaches tests that set ``max_examples`` explicitly.
"""

from __future__ import annotations

import contextlib
import fcntl
import io
import os
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import pytest
from hypothesis import HealthCheck, settings
from machine_stalls import tinman_run

pytest_plugins = ["bytecode_cache"]  # tests/bytecode_cache.py: one compile of the sources per session

settings.register_profile("dev", deadline=None)
settings.register_profile("ci", deadline=None, derandomize=True, database=None, print_blob=True)
settings.register_profile("thorough", deadline=None, max_examples=1000,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("rerun", deadline=None, max_examples=25, derandomize=True, database=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")  # --hypothesis-profile overrides


@pytest.fixture(scope="session")
def tinman_sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 6 s synthetic TinMan sequence (the start of the default patrol), generated once per
    session: TinMan's system tests and the ROS interop tests play it back and only read it
    (rendering it takes seconds)."""
    from tinman.sequences import generate

    return generate(tmp_path_factory.mktemp("sequence") / "room", duration=6.0)


@pytest.fixture(scope="session")
def mypy_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One ``--cache-dir`` for the suite's mypy runs over generated code (tests/anodize/tools/test_codegen*.py,
    tests/anodize/test_timed_end_to_end.py): anodize, sessiontypes and numpy, which every run follows, are
    analysed once instead of once per run (most of each run's time). mypy checks each cached module
    against its source's hash and the options it was checked with, so an entry that does not fit is
    analysed again, never trusted; the files a test names are judged as without a cache."""
    return tmp_path_factory.mktemp("mypy_cache")


class RecordedTinMan(NamedTuple):
    """One recorded TinMan run: its folder, the command's exit status, what it printed, and the
    key its recording's chain heads were signed with."""

    out: Path
    status: int
    printed: str
    key: Path


@pytest.fixture(scope="session")
def tinman_recorded(tmp_path_factory: pytest.TempPathFactory) -> RecordedTinMan:
    """``anodize run tinman --duration 6 --record`` (the README's run, shorter: live camera,
    default world, no --patrol), once per session, in ``<tmp>/out/tinman`` (the folder the default
    settings name, seen from ``<tmp>``). The tests that read a whole TinMan run's recording, report
    or output share it (replay, verify, the live camera's odometry); they only read it."""
    out = tmp_path_factory.mktemp("recorded") / "out" / "tinman"
    key = out.parent.parent / "run.key"
    key.write_bytes(os.urandom(32))
    key.chmod(0o600)
    printed = io.StringIO()
    with pytest.MonkeyPatch.context() as patch, contextlib.redirect_stdout(printed):  # both restored after
        status, report = tinman_run(patch, out, "--duration", "6", "--record", "--sign-key", str(key),
                                    before=lambda: (printed.seek(0), printed.truncate()))
    assert status == (0 if report["ok"] else 1), printed.getvalue()
    return RecordedTinMan(out, status, printed.getvalue(), key)



# Tests whose systems run groups at real-time priority and judge their timing (TinMan, the
# isolation and spin tests, the examples with priorities, the timed end-to-end runs) run ALONE
# when the suite runs on two workers (`-n 2`, the README's command): one such test holds a lock
# that pauses the other worker, so it sees the machine a serial run gives it (and, in the
# busy-machine runs, the CPU hogs beside it: load at normal priority, which is what the project's
# promise is about). Two tests' systems at once would each bring several processes, some at
# real-time priority, onto 2 cores: two robots on one computer, not the situation the promise is
# about. The lock is writer-preferring (a turnstile): the real-time test waits for the other
# worker's current test to end, and no new test starts before it has run.
_REAL_TIME = ("tests/tinman/", "tests/anodize/isolation/", "tests/anodize/transport/test_spin",
              "tests/test_examples.py", "tests/test_first_system.py", "tests/anodize/supervision/test_system.py",
              "tests/anodize/live/test_side_work_live.py", "tests/anodize/recording/test_side_work_recording.py",
              "tests/anodize/ros/test_ros_interop.py", "tests/anodize/recording/test_recording.py",
              "tests/anodize/test_timed_end_to_end.py")
_SHARED_RUNS = {"tinman_recorded", "tinman_sequence"}  # session fixtures that run TinMan: computed once, alone
_LOCK_WAIT = 1800.0  # seconds: far above any test of the suite, so a lock never outlives a hung test silently


def _real_time(item: pytest.Item) -> bool:
    return item.nodeid.startswith(_REAL_TIME) or bool(_SHARED_RUNS & set(getattr(item, "fixturenames", ())))


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        # Meant to keep them on one worker (xdist's loadgroup), so the session fixtures that run TinMan
        # run once; in the suite's runs both workers still took some (left to find out why). The lock
        # below is what keeps them apart.
        if _real_time(item):
            item.add_marker(pytest.mark.xdist_group("real-time"))


def _flock(handle: io.BufferedRandom, mode: int) -> None:
    deadline = time.monotonic() + _LOCK_WAIT
    while True:
        try:
            fcntl.flock(handle, mode | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            if time.monotonic() > deadline:
                raise TimeoutError(f"the suite's real-time lock was held for over {_LOCK_WAIT:g} s") from None
            time.sleep(0.02)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> object:
    folder = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    if folder is None or not hasattr(item.config, "workerinput"):
        # One process, or a pytest a test started (it inherits the variable, but is no worker:
        # its tests are part of the test that started it, which holds the lock already).
        return (yield)
    base = Path(tempfile.gettempdir()) / f"anodize-suite-{folder}"
    with open(f"{base}.turnstile", "a+b") as turnstile, open(f"{base}.lock", "a+b") as lock:
        _flock(turnstile, fcntl.LOCK_EX)
        try:
            _flock(lock, fcntl.LOCK_EX if _real_time(item) else fcntl.LOCK_SH)
        finally:
            fcntl.flock(turnstile, fcntl.LOCK_UN)
        try:
            return (yield)
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
