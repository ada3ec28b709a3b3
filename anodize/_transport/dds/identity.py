"""Who an endpoint says it is: the identity every anodize writer and reader carries in its USER_DATA.

A writer's identity names its run, group, incarnation, host and pid. A reader accepts
samples only from the one writer of the expected group, chosen at the start barrier
(:mod:`.barrier`); other writers' samples are dropped and reported. This keeps other runs
and stray programs out; it is not security: anyone on the network can claim an identity
first. On a ROS topic the identity is one ``key=value`` pair among ROS 2's.
"""

from __future__ import annotations

import os

__all__ = ["identity_of", "ros_userdata", "userdata_fields", "parse_identity", "instance_handle"]


def identity_of(run_id: str, group: str, incarnation: int, host: str) -> bytes:
    """What a writer says it is (its USER_DATA)."""
    return f"anodize1;{run_id};{group};{incarnation};{host};{os.getpid()}".encode()


def ros_userdata(type_hash: str, identity: bytes) -> bytes:
    """The USER_DATA of an endpoint on a ROS topic: ``key=value;`` pairs, as ROS 2 reads them
    (``typehash=RIHS01_...;``, Iron and later), and anodize's identity as one more key."""
    return f"typehash={type_hash};anodize={identity.decode().replace(';', ',')};".encode()


def userdata_fields(data: bytes | None) -> dict[str, str]:
    """The ``key=value;`` pairs of a ROS 2 endpoint's USER_DATA (empty if it has none)."""
    try:
        text = (data or b"").decode()
    except UnicodeDecodeError:
        return {}
    return dict(part.split("=", 1) for part in text.split(";") if "=" in part)


def parse_identity(data: bytes | None) -> tuple[str, str, int, str, int] | None:
    """(run id, group, incarnation, host, pid) of an anodize identity; None for anything else."""
    try:
        text = (data or b"").decode()
        if not text.startswith("anodize1;"):  # on a ROS topic, one key among ROS 2's
            text = userdata_fields(data).get("anodize", "").replace(",", ";")
        tag, run_id, group, incarnation, host, pid = text.split(";")
        return (run_id, group, int(incarnation), host, int(pid)) if tag == "anodize1" else None
    except (UnicodeDecodeError, ValueError):
        return None


def instance_handle(handle: int) -> int:
    """An instance handle as one number: the binding gives the same 64 bits signed in one
    place and unsigned in another."""
    return handle & 0xFFFF_FFFF_FFFF_FFFF
