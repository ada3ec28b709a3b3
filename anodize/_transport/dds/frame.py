"""The DDS type of every anodize channel topic, and its samples as raw CDR.

Frames of :mod:`anodize._transport.codec` are written as CDR built here and taken as raw
CDR, so a large array costs a copy, not the binding's element-by-element encoding.

This module must not use ``from __future__ import annotations``: the binding resolves
the IDL annotations of :class:`Frame` itself.
"""

import struct
from dataclasses import dataclass

from .binding import IdlStruct, idl_types

__all__ = ["Frame", "cdr_sample", "ros_sample", "LENGTH"]

LENGTH = struct.Struct("<I")  # a CDR sequence's length


@dataclass
class Frame(IdlStruct, typename="anodize::Frame"):
    """One codec frame (4-byte length, then the body) as octets."""

    data: idl_types.sequence[idl_types.uint8]  # type: ignore[type-arg]  # the binding's own generic


_CDR_HEADER = Frame(data=[]).serialize()[:4]  # type: ignore[arg-type]  # the encapsulation the binding itself writes


def cdr_sample(frame: bytes) -> bytes:
    """A codec frame (4-byte length, body) as the CDR of an ``anodize::Frame`` sample."""
    sample = _CDR_HEADER + LENGTH.pack(len(frame)) + frame
    return sample + b"\0" * (-len(sample) % 4)


def ros_sample(cdr: bytes) -> bytes:
    """Serialized ROS data padded to a multiple of 4 bytes, the padding counted in the low bits of the
    encapsulation options (as XTypes says and Cyclone's own serializer does)."""
    pad = -len(cdr) % 4
    if not pad:
        return cdr
    return cdr[:3] + bytes((cdr[3] | pad,)) + cdr[4:] + b"\0" * pad
