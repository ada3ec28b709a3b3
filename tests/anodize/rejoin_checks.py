"""What a host cut off and back must see, whatever carries the run (test_hosts_rejoin.py on DDS,
test_zenoh_rejoin.py over a Zenoh router): the systems both run and the checks of their reports.
``cut`` is the host whose link goes down (its producer pauses meanwhile), ``mover`` the one that
moves on without it."""

from __future__ import annotations

from typing import Any

from anodize._supervision.hostview import HELLO_EVERY
from anodize._supervision.report import RoleStatus

# How long to wait, once the data flows, before the cut: the supervisors must have heard each
# other first (a hello every HELLO_EVERY s), since a host never heard cannot be lost, and then
# nobody tells it that the run moved on without it. A quiet CI run cut before the base heard the
# robot's supervisor at all. Four hellos' time; the producer's pause (40 s) leaves room for it.
MEET = 4 * HELLO_EVERY

# The cut-off host's producer: it pauses during the cut, touching no channel. Where both groups
# restart (policy_checks.restart_groups with it), the set is decided on the other host meanwhile.
PAUSING = "rejoin_roles:pausing_producer"

# A producer on the cut-off host, its consumer and an unrelated ticking pair on the other.
BOTH = """
[groups.producing]
host = "{cut}"
roles = {{ P = "rejoin_roles:pausing_producer" }}

[groups.consuming]
host = "{mover}"
on_failure = "{policy}"
{more}
roles = {{ C = "dds_roles:consumer" }}

[groups.ticking]
host = "{mover}"
roles = {{ Q = "dds_roles:ticker", R = "dds_roles:tick_counter" }}
"""


def told_the_run_moved_on(cut_off: dict[str, Any], mover: dict[str, Any], cut: str, moved: str, out: str) -> None:
    """The mover's consumer failed by liveliness during the cut, its ticking pair ran on; the cut-off
    host, back, was told the mover moved on without it, and its producer stopped (before, it woke 40 s
    later, sent, and failed: its reader was long gone)."""
    assert mover["roles"]["C"]["status"] == RoleStatus.FAILED, out
    assert mover["roles"]["C"]["error"]["type"] == "PeerFailedError", out
    assert any(note.startswith(f"lost sight of host {cut} at ") for note in mover["notes"]), out
    assert mover["roles"]["Q"]["status"] == RoleStatus.STOPPED, out  # by the test's Ctrl-C, at the end
    assert (f"host {moved} lost sight of this host (cut off?) and moved on without it: stopping producing, whose "
            "sessions with groups there are over") in cut_off["notes"], out
    assert cut_off["roles"]["P"]["status"] == RoleStatus.STOPPED, out
    # A host it lost is back, when heard again; but the cut follows the first message at once, and
    # may come before the mover's first hello reached it: then it had nothing to lose.
    lost = any(note.startswith(f"lost sight of host {moved} at ") for note in cut_off["notes"])
    assert lost == any(note.startswith(f"host {moved} is back") for note in cut_off["notes"]), out


def heard_the_stop_it_missed(cut_off: dict[str, Any], mover: dict[str, Any], moved: str, out: str) -> None:
    """stop-system on the mover during the cut; the cut-off host, back, heard it in the mover's hellos."""
    why = "group consuming failed and its policy is stop-system"
    assert f"stopping every group: {why}" in mover["notes"], out
    assert mover["roles"]["Q"]["status"] == RoleStatus.STOPPED, out
    # The mover waited (bounded) for the other to come back and say it stops too; it did, from the hellos.
    assert not any("did not answer" in note for note in mover["notes"]), out
    assert f"stopping every group: {why} (on host {moved})" in cut_off["notes"], out
    assert cut_off["roles"]["P"]["status"] == RoleStatus.STOPPED, out


def restarted_as_decided_without_it(cut_off: dict[str, Any], mover: dict[str, Any], moved: str, out: str) -> None:
    """The mover restarted {consuming, producing} as incarnation 1 during the cut; the cut-off host heard
    it in the mover's hellos once back, and restarted its producer as incarnation 1, which met the new
    consumer at a fresh barrier: the consumer saw 0..99 once, in order, from it alone."""
    assert cut_off["ok"] and mover["ok"], out
    assert cut_off["groups"]["producing"]["restarts"] == 1 and mover["groups"]["consuming"]["restarts"] == 1, out
    assert any(f"restarted as incarnation 1 with groups consuming, producing, decided on host {moved}" in note
               for note in cut_off["groups"]["producing"]["notes"]), out
