"""The DDS type of every anodize channel topic.

Kept apart because the Cyclone DDS binding resolves IDL annotations itself: this
module must not use ``from __future__ import annotations``.
"""

from dataclasses import dataclass

from cyclonedds.idl import IdlStruct, types

__all__ = ["Frame"]


@dataclass
class Frame(IdlStruct, typename="anodize::Frame"):
    """One codec frame (4-byte length, then the body) as octets."""

    data: types.sequence[types.uint8]  # type: ignore[type-arg]  # the binding's own generic
