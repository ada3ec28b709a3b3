"""Who wrote a sample: a short binary header on every sample, the writer's claim once.

As rmw_zenoh carries a publisher's GID and sequence number in each sample's attachment,
anodize carries, in 16 bytes, the sample's number on its channel and the writer's random
id. The writer's claim (its run: run id and the token's digest; group, incarnation, host
and pid) follows the header on the writer's first sample only (number 0, and that
sample's resends): it names a writer in the report of a receiver that rejects it, and
the writer's liveliness token (``.../writer/.../<group>/<incarnation>/<id>`` under the
run's prefix) already binds the id to its group and incarnation. A receiver accepts
samples only from the one writer chosen at the start barrier (:mod:`.peers`); the others
are dropped, counted and reported. This keeps other runs and stray programs out; it is
not security: anyone who reads the run's traffic can copy a writer's id, as it could copy
the whole claim when every sample carried it (no weaker than that).
"""

from __future__ import annotations

import os
import secrets
import struct

__all__ = ["Claim", "HEADER", "new_writer_id", "attachment", "parse_attachment", "claim_of"]

HEADER = struct.Struct("<Q8s")  # the sample's number on its channel, the writer's id
_TAG = "anodize1"
_CLAIM_MAX = 512  # bytes of a claim a receiver reads (the rest, from the network, is ignored)


class Claim:
    """What one writer says it is, encoded once (its first sample carries these bytes)."""

    def __init__(self, claim_run: str, group: str, incarnation: int, host: str, writer_id: bytes) -> None:
        self.writer_id = writer_id
        self.text = f"{_TAG};{claim_run};{group};{incarnation};{host};{os.getpid()};{writer_id.hex()}"
        self.encoded = self.text.encode()


def new_writer_id() -> bytes:
    """A fresh random id for one end of a channel (8 bytes)."""
    return secrets.token_bytes(8)


def attachment(number: int, claim: Claim) -> bytes:
    """The attachment of sample ``number`` of a writer: the header, and the claim on sample 0."""
    header = HEADER.pack(number, claim.writer_id)
    return header + claim.encoded if number == 0 else header


def parse_attachment(data: bytes) -> tuple[int, bytes] | None:
    """(number, writer id) of an attachment; None for one that is not anodize's.
    The bytes come from the network: anything may be in them."""
    if len(data) < HEADER.size:
        return None
    parsed: tuple[int, bytes] = HEADER.unpack_from(data)
    return parsed


def claim_of(data: bytes) -> str:
    """The claim an attachment carries after its header ("" if none), at most 512 bytes of it."""
    return data[HEADER.size:HEADER.size + _CLAIM_MAX].decode(errors="replace")
