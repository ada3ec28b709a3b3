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
import io
import json
import os
from pathlib import Path
from typing import NamedTuple

import pytest
from hypothesis import HealthCheck, settings

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
    from anodize._tools import cli
    from tinman.settings import ENVIRONMENT_VARIABLE

    out = tmp_path_factory.mktemp("recorded") / "out" / "tinman"
    key = out.parent.parent / "run.key"
    key.write_bytes(os.urandom(32))
    key.chmod(0o600)
    printed = io.StringIO()
    with pytest.MonkeyPatch.context() as patch, contextlib.redirect_stdout(printed):
        patch.setenv(ENVIRONMENT_VARIABLE, "")  # restored after the run: the run exports its own
        status = cli.main(["run", "tinman", "--quiet", "--duration", "6", "--record", "--sign-key", str(key),
                           "--out", str(out)])
    report = json.loads((out / "report.json").read_text())
    assert status == (0 if report["ok"] else 1), printed.getvalue()
    return RecordedTinMan(out, status, printed.getvalue(), key)
