"""Back pressure on DDS channels by credits: how far a sender may write ahead of its receiver.

The receiver tells the sender, on the channel's ``.../credit`` topic (keep-last 1), how
many samples it has handed on to its role; the sender writes at most :data:`WINDOW`
samples (and about :data:`WINDOW_BYTES`) ahead of that, fewer than the reader's resource
limit (:data:`READER_SAMPLES`), so the reader never has to reject one (Cyclone then
recovers only by NACK and retransmission, which made back pressure cost about 100 us a
message) and a receiver that falls behind holds bounded memory (a few large frames, or
many small messages). The receiver says how many it has taken every :data:`CREDIT_EVERY`
samples or :data:`CREDIT_BYTES` bytes; a channel's capacity narrows both.
"""

from __future__ import annotations

import struct

__all__ = ["READER_SAMPLES", "WINDOW", "WINDOW_BYTES", "CREDIT_EVERY", "CREDIT_BYTES", "COUNT", "POLL", "TAKE",
           "window_for", "credit_every_for"]

READER_SAMPLES = 256  # samples a receiver's DDS reader holds at most
WINDOW = 224
WINDOW_BYTES = 16 << 20
CREDIT_EVERY = 32
CREDIT_BYTES = WINDOW_BYTES // 4
COUNT = struct.Struct("<Q")  # a credit: the samples taken so far
POLL = 0.05  # seconds between looks at a peer's liveliness (asking Cyclone costs tens of µs)
TAKE = 32  # samples taken per call


def window_for(capacity: int | None) -> int:
    """The samples a sender may have in flight on a channel of that capacity (None: unbounded)."""
    return WINDOW if capacity is None else min(WINDOW, capacity)


def credit_every_for(capacity: int | None) -> int:
    """How often a receiver credits: at least twice per window, which a capacity may narrow
    below :data:`CREDIT_EVERY`."""
    return CREDIT_EVERY if capacity is None else max(1, min(CREDIT_EVERY, capacity // 2))
