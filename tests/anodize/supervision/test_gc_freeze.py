"""A group's process freezes what its start made before its roles run, so no garbage collection
in a role's thread scans the modules, classes and endpoints again (a full collection holds the
GIL throughout: 11-18 ms for TinMan's control group's heap, more than its joystick may slip)."""

from __future__ import annotations

import gc_roles
import pytest

import anodize
import sessiontypes

pytestmark = pytest.mark.slow  # group processes

SEEN = sessiontypes.loads(gc_roles.PROTOCOL, "seen.proto").globals["S"]


def test_a_group_process_freezes_its_start_before_its_roles_run() -> None:
    system = anodize.System(SEEN, transport=anodize.Processes())
    system.group("a").role("A", gc_roles.reporter)
    system.group("b").role("B", gc_roles.checker)
    report = system.run(timeout=60)
    assert report.ok, report.summary()  # B found A's function frozen, among at least 10,000 objects
