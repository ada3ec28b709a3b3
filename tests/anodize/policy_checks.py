"""The several-host failure-policy cases that the DDS and the Zenoh tests share: each case's
groups (the tail of a system file, hosts A and B) and the checks of the two hosts' reports."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from anodize._supervision.report import RoleStatus

# P fails on host A with the default policy (stop); B's consumer is told, B's ticking pair runs on.
STOP_GROUPS = """
[groups.producing]
host = "A"
roles = { P = "dds_roles:failing_producer" }

[groups.consuming]
host = "B"
roles = { C = "dds_roles:consumer" }

[groups.ticking]
host = "B"
roles = { Q = "rejoin_roles:few_ticks", R = "dds_roles:tick_counter" }
"""


def stop_system_groups(failing: str = "A", other: str = "B") -> str:
    """P fails on host ``failing`` and its policy is stop-system: the consumer and the ticking pair
    on ``other`` stop too, the pair although it has nothing to do with P."""
    return f"""
[groups.producing]
host = "{failing}"
on_failure = "stop-system"
roles = {{ P = "dds_roles:failing_producer" }}

[groups.consuming]
host = "{other}"
roles = {{ C = "dds_roles:consumer" }}

[groups.ticking]
host = "{other}"
roles = {{ Q = "dds_roles:ticker", R = "dds_roles:tick_counter" }}
"""


def restart_groups(producer: str, producing: str = "A", consuming: str = "B") -> str:
    """A producer on host ``producing`` and its consumer on ``consuming``, each restarted once at
    most; ``producer`` is its role function, ``module:function``."""
    return f"""
[groups.producing]
host = "{producing}"
on_failure = "restart"
max_restarts = 1
roles = {{ P = "{producer}" }}

[groups.consuming]
host = "{consuming}"
on_failure = "restart"
max_restarts = 1
roles = {{ C = "dds_roles:consumer" }}
"""


def restart_env(tmp_path: Path) -> dict[str, str]:
    """For ``failing_once_producer``: where it remembers its first failure, and 300 numbers."""
    return {"DDS_TEST_MARKER": str(tmp_path / "failed-once"), "DDS_TEST_COUNT": "300"}


def check_stop(a: dict[str, Any], b: dict[str, Any]) -> None:
    assert a["roles"]["P"]["status"] == RoleStatus.FAILED
    assert b["roles"]["C"]["error"]["type"] == "PeerFailedError", b["roles"]
    assert b["groups"]["ticking"]["status"] == "done", b["groups"]  # nothing to do with P: it ran to its end
    assert not any("stopping every group" in note for note in a["notes"] + b["notes"])


def check_restarted_as_one(a: dict[str, Any], b: dict[str, Any]) -> None:
    # The second incarnations ran the whole session: the consumer saw 0..299 in order from
    # the new producer (the old one's numbers 0..4 went to the old consumer only).
    assert a["groups"]["producing"]["restarts"] == 1, a
    assert b["groups"]["consuming"]["restarts"] == 1, b
    assert a["roles"]["P"]["status"] == RoleStatus.DONE, a["roles"]
    assert b["roles"]["C"]["status"] == RoleStatus.DONE, b["roles"]


def check_used_up(a: dict[str, Any], b: dict[str, Any]) -> None:
    producing = a["groups"]["producing"]
    assert (producing["restarts"], len(producing["failures"]), producing["status"]) == (1, 2, "failed"), producing
    assert b["groups"]["consuming"]["restarts"] == 1, b["groups"]
    assert b["roles"]["C"]["error"]["type"] == "PeerFailedError", b["roles"]
