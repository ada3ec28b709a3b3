"""A group's start on DDS is bounded by ``--wait`` alone (issue 32): a group whose process is
still importing its roles when the wait is over fails then, not a minute later."""

from __future__ import annotations

import dds_roles
import pytest
import slow_import_roles
from dds_hosts import domain

import anodize
import sessiontypes

pytest.importorskip("cyclonedds", reason="the dds extra (cyclonedds) is not installed")

STREAM = sessiontypes.loads(dds_roles.STREAM, "stream.proto").globals["Stream"]


@pytest.mark.slow  # a DDS group's process, for the wait and the 2 s beyond it
def test_a_group_still_importing_when_the_wait_is_over_fails_then(monkeypatch: pytest.MonkeyPatch) -> None:
    # Its module sleeps 30 s on import: before, the start timeout was 60 s plus the wait, so the
    # group got through its imports and then failed at its barrier, 31 s in.
    monkeypatch.setenv("HOSTS_TEST_SLOW_IMPORT", "30")
    system = anodize.System(STREAM, transport=anodize.Dds(domain=domain(), run_id="slowimport", host="robot",
                                                         wait=1.0))
    system.group("producing", host="robot").role("P", slow_import_roles.producer)
    system.group("consuming", host="base").role("C", dds_roles.consumer)
    report = system.run(timeout=30)
    assert not report.ok
    assert str(report.groups["producing"].error) == (
        "StartTimeout: group producing's process did not get ready within 3 s (importing its roles?)")
