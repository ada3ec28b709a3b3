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

import os
from pathlib import Path

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
