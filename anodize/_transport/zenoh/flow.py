"""Back pressure and acknowledgement on Zenoh channels by credits.

The receiver tells the sender, on the channel's ``.../credit`` key, two counts: how many
samples it has handed on to its role (the credit: the sender puts at most :data:`WINDOW`
samples, and about :data:`WINDOW_BYTES`, ahead of it, so a receiver that falls behind
holds bounded memory) and how many it has received in order (the acknowledgement: the
sender keeps every sample not yet acknowledged, at most a window of them, and sends them
again when the acknowledgement does not move for :data:`RESEND` seconds; Zenoh is
reliable per hop only, and a router that restarts loses what it held). The receiver
credits every :data:`CREDIT_EVERY` samples or :data:`CREDIT_BYTES` bytes handed on, and
whenever its counts have moved since it last said them, every :data:`TICK` seconds (from
the group's flow thread: a receiver that goes idle does not put a credit back after each
message of a ping-pong).
"""

from __future__ import annotations

import struct

__all__ = ["WINDOW", "WINDOW_BYTES", "CREDIT_EVERY", "CREDIT_BYTES", "CREDIT", "POLL", "TICK", "RESEND",
           "IDLE", "window_for", "credit_every_for"]

WINDOW = 224
WINDOW_BYTES = 16 << 20
CREDIT_EVERY = 32
CREDIT_BYTES = WINDOW_BYTES // 4
CREDIT = struct.Struct("<QQ8s")  # handed on, received in order, the receiver's id
POLL = 0.05  # seconds between looks at failures and stops while waiting
TICK = 0.05  # seconds between two rounds of pending credits and resends
RESEND = 0.5  # seconds without a new acknowledgement before what is unacknowledged is sent again
IDLE = 0.0001  # seconds without a put after which a channel is idle: its next put goes express


def window_for(capacity: int | None) -> int:
    """The samples a sender may have in flight on a channel of that capacity (None: unbounded)."""
    return WINDOW if capacity is None else min(WINDOW, capacity)


def credit_every_for(capacity: int | None) -> int:
    """How often a receiver credits: at least twice per window, which a capacity may narrow."""
    return CREDIT_EVERY if capacity is None else max(1, min(CREDIT_EVERY, capacity // 2))
