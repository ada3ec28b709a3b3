"""ROS 2 on Zenoh as rmw_zenoh writes it: key expressions, liveliness tokens, attachments.

rmw_zenoh (``rmw_zenoh_cpp``, ROS 2's tier-1 middleware for routed networks) maps each
ROS 2 entity onto Zenoh. A ROS node on it finds anodize's topics only if anodize writes
exactly the same names and bytes, so this module follows rmw_zenoh's sources line by
line; each function names the file and the commit of ``github.com/ros2/rmw_zenoh`` it
follows (all under ``rmw_zenoh_cpp/src/detail/`` but the design document):

- a topic's **data key expression** ``<domain>/<topic>/<dds type>/<type hash>``
  (``0/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_...``): :func:`topic_key`;
- the **liveliness token** of each node, publisher and subscription, under the
  hermetic ``@ros2_lv`` prefix, with ``/`` in names mangled to ``%`` and the QoS in
  a compact text where each policy equal to rmw_zenoh's default is left empty:
  :class:`Entity`, :func:`entity_key`, :func:`parse_entity_key`, :func:`qos_text`;
- the entity's **GID**: the XXH3-128 hash of its token's key expression:
  :func:`entity_gid`;
- the **attachment** of every sample: sequence number (from 1), source timestamp (ns
  since the epoch), the publisher's GID, in Zenoh's serialisation (33 bytes):
  :func:`encode_attachment`, :func:`parse_attachment`.

Everything here is pure Python and imports no Zenoh. What comes from the network (a
token another node declared, an attachment) is hostile: the parse functions bound
what they read and fail only with :class:`RmwZenohFormatError`.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

from .._extras import import_extra
from ..errors import AnodizeError

__all__ = ["ADMIN_SPACE", "KINDS", "GID_SIZE", "ATTACHMENT_SIZE", "RmwZenohFormatError", "RmwQos", "TopicInfo",
           "Entity", "Attachment", "mangle", "demangle", "dds_type_name", "topic_key", "qos_text", "parse_qos",
           "entity_key", "parse_entity_key", "entity_gid", "check_type_hash", "encode_attachment",
           "parse_attachment", "SOURCES"]

SOURCES = {  # file -> the commit of github.com/ros2/rmw_zenoh whose text this module follows
    "docs/design.md": "99a6a2bd10b949052f4f12c5854825dc005e95a5",
    "rmw_zenoh_cpp/src/detail/liveliness_utils.cpp": "3411fdec149fe0c932f24d4d79ef908eb81d7482",
    "rmw_zenoh_cpp/src/detail/attachment_helpers.cpp": "534747dca92adf15e1b1b975123037ca278db5ba",
    "rmw_zenoh_cpp/src/detail/qos.cpp": "7efeee2b9009b816a4bd4a3148af3cca40f753d5",
    "rmw_zenoh_cpp/src/detail/rmw_publisher_data.cpp": "3e19ec730c529035a648aec80c0ae0a056943b8c",
    "rmw_zenoh_cpp/src/detail/zenoh_utils.cpp": "1322545421bb9f937c9e91bb0d1edceb2d52186f",
}

ADMIN_SPACE = "@ros2_lv"  # liveliness_utils.cpp: ADMIN_SPACE
KINDS = ("NN", "MP", "MS", "SS", "SC")  # node, message publisher/subscription, service server/client
GID_SIZE = 16  # RMW_GID_STORAGE_SIZE (rmw/types.h, Jazzy and later)
ATTACHMENT_SIZE = 8 + 8 + 1 + GID_SIZE
MAX_KEY = 4096  # bytes of a token's key expression worth reading; real ones are a few hundred
_SLASH, _MANGLED = "/", "%"  # liveliness_utils.cpp: SLASH_REPLACEMENT
_HASH = re.compile(r"RIHS01_[0-9a-f]{64}")  # REP-2016's RIHS01 type hash, as rosidl_stringify_type_hash
_NUMBER = re.compile(r"[0-9]{1,20}")
_CHUNK = re.compile(r"[^/*$?#\s]+")  # one chunk of a Zenoh key expression: no wildcard, no '/'

# rmw/types.h enums, as the QoS text writes them.
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
KEEP_LAST, KEEP_ALL = 1, 2
AUTOMATIC = 1
INFINITE = (9223372036, 854775807)  # RMW_DURATION_INFINITE: (sec, nsec)
_RELIABILITIES = {0, 1, 2, 3}  # liveliness_utils.cpp: str_to_qos_reliability (BEST_AVAILABLE is refused)
_DURABILITIES = {0, 1, 2, 3}  # str_to_qos_durability
_HISTORIES = {0, 1, 2, 3}  # str_to_qos_history
_LIVELINESSES = {0, 1, 3, 4, 5}  # str_to_qos_liveliness (no MANUAL_BY_NODE)


class RmwZenohFormatError(AnodizeError):
    """Text or bytes that are not what rmw_zenoh writes.

    Attributes:
        what: what was being read: ``"liveliness token"``, ``"attachment"``, ``"QoS"``, ...
        shown: the start of what was read (at most 120 characters), for the message.
        reason: what is wrong with it.
    """

    def __init__(self, what: str, shown: str, reason: str) -> None:
        self.what = what
        self.shown = shown
        self.reason = reason
        super().__init__(str(self))

    def __str__(self) -> str:
        return f"not an rmw_zenoh {self.what}: {self.reason} (in {self.shown})"


def _shown(value: str | bytes) -> str:
    text = repr(value[:120])
    return text + ("..." if len(value) > 120 else "")


@dataclass(frozen=True)
class RmwQos:
    """An entity's QoS as rmw states it (``rmw_qos_profile_t``), after rmw_zenoh's adaptation.

    The defaults are rmw_zenoh's own (``qos.cpp``, ``QoS::QoS``): reliable, volatile, keep
    last 42, every duration infinite, automatic liveliness. Enum values are rmw/types.h's.

    Attributes:
        reliability: 1 reliable, 2 best effort (0 system default, 3 unknown).
        durability: 1 transient local, 2 volatile.
        history: 1 keep last, 2 keep all.
        depth: samples kept (keep last).
        deadline, lifespan, lease: ``(sec, nsec)``; the liveliness lease is ``lease``.
        liveliness: 1 automatic.
    """

    reliability: int = RELIABLE
    durability: int = VOLATILE
    history: int = KEEP_LAST
    depth: int = 42
    deadline: tuple[int, int] = INFINITE
    lifespan: tuple[int, int] = INFINITE
    liveliness: int = AUTOMATIC
    lease: tuple[int, int] = INFINITE

    @classmethod
    def of(cls, reliability: str, history: str, depth: int, durability: str) -> RmwQos:
        """The QoS of anodize's names (``"reliable"``/``"best_effort"``, ``"keep_all"``/``"keep_last"``,
        ``"volatile"``/``"transient_local"``); keep-all's depth 0 becomes rmw_zenoh's 42, as
        ``QoS::best_available_qos`` makes a depth of 0."""
        return cls(RELIABLE if reliability == "reliable" else BEST_EFFORT,
                   TRANSIENT_LOCAL if durability == "transient_local" else VOLATILE,
                   KEEP_ALL if history == "keep_all" else KEEP_LAST, depth or 42)


_DEFAULT_QOS = RmwQos()


def mangle(name: str) -> str:
    """``name`` with each ``/`` replaced by ``%`` (liveliness_utils.cpp, ``mangle_name``)."""
    return name.replace(_SLASH, _MANGLED)


def demangle(name: str) -> str:
    """``name`` with each ``%`` replaced by ``/`` (liveliness_utils.cpp, ``demangle_name``)."""
    return name.replace(_MANGLED, _SLASH)


def dds_type_name(type_name: str) -> str:
    """The type name rmw_zenoh puts in keys, as DDS spells it: ``geometry_msgs/msg/Twist`` ->
    ``geometry_msgs::msg::dds_::Twist_`` (docs/design.md, "Topic and Service name mapping")."""
    package, kind, name = type_name.removeprefix("ros:").split("/")
    return f"{package}::{kind}::dds_::{name}_"


def _strip_slashes(name: str) -> str:
    """One leading and one trailing ``/`` off (liveliness_utils.cpp, ``strip_slashes``)."""
    start = 1 if name.startswith("/") else 0
    end = len(name) - 1 if name.endswith("/") and len(name) > start else len(name)
    return name[start:end]


def topic_key(domain: int, topic: str, dds_type: str, type_hash: str) -> str:
    """The key expression a topic's samples are put on: ``<domain>/<topic>/<type>/<hash>``.

    liveliness_utils.cpp, ``TopicInfo::TopicInfo`` (the topic's fully qualified name with
    its leading ``/`` stripped, so ``/robot1/chatter`` is two chunks); docs/design.md gives
    ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...``.
    """
    return f"{domain}/{_strip_slashes(topic)}/{dds_type}/{type_hash}"


def qos_text(qos: RmwQos) -> str:
    """The QoS chunk of a token: ``<rel>:<dur>:<hist>,<depth>:<dl s>,<dl ns>:<ls s>,<ls ns>:<lv>,<lease s>,<lease ns>``,
    each value left empty where it equals rmw_zenoh's default (liveliness_utils.cpp,
    ``qos_to_keyexpr``): a reliable, volatile, keep-last-10 publisher is ``::,10:,:,:,,``."""
    def value(mine: int, default: int) -> str:
        return "" if mine == default else str(mine)

    d = _DEFAULT_QOS
    return (f"{value(qos.reliability, d.reliability)}:{value(qos.durability, d.durability)}:"
            f"{value(qos.history, d.history)},{value(qos.depth, d.depth)}:"
            f"{value(qos.deadline[0], d.deadline[0])},{value(qos.deadline[1], d.deadline[1])}:"
            f"{value(qos.lifespan[0], d.lifespan[0])},{value(qos.lifespan[1], d.lifespan[1])}:"
            f"{value(qos.liveliness, d.liveliness)},"
            f"{value(qos.lease[0], d.lease[0])},{value(qos.lease[1], d.lease[1])}")


def parse_qos(text: str) -> RmwQos:
    """The QoS of a token's QoS chunk (liveliness_utils.cpp, ``keyexpr_to_qos``; stricter: exactly
    the six parts and their components that ``qos_to_keyexpr`` writes, numbers of at most 20 digits).

    Raises:
        RmwZenohFormatError: not a QoS chunk.
    """
    parts = text.split(":")
    counts = (1, 1, 2, 2, 2, 3)
    if len(parts) != len(counts):
        raise RmwZenohFormatError("QoS", _shown(text), f"expected 6 parts separated by ':', got {len(parts)}")
    fields = [part.split(",") for part in parts]
    for index, (got, count) in enumerate(zip(fields, counts, strict=False)):
        if len(got) != count:
            raise RmwZenohFormatError("QoS", _shown(text), f"part {index + 1} has {len(got)} values, expected {count}")

    def number(raw: str, default: int, allowed: set[int] | None = None) -> int:
        if raw == "":
            return default
        if not _NUMBER.fullmatch(raw) or int(raw) >= 1 << 64:
            raise RmwZenohFormatError("QoS", _shown(text), f"{raw!r} is not an unsigned 64-bit number")
        if allowed is not None and int(raw) not in allowed:
            raise RmwZenohFormatError("QoS", _shown(text), f"{raw} is no policy rmw_zenoh knows here")
        return int(raw)

    d = _DEFAULT_QOS
    (rel,), (dur,), (hist, depth), (dl_s, dl_ns), (ls_s, ls_ns), (lv, lv_s, lv_ns) = fields
    return RmwQos(number(rel, d.reliability, _RELIABILITIES), number(dur, d.durability, _DURABILITIES),
                  number(hist, d.history, _HISTORIES), number(depth, d.depth),
                  (number(dl_s, d.deadline[0]), number(dl_ns, d.deadline[1])),
                  (number(ls_s, d.lifespan[0]), number(ls_ns, d.lifespan[1])),
                  number(lv, d.liveliness, _LIVELINESSES), (number(lv_s, d.lease[0]), number(lv_ns, d.lease[1])))


@dataclass(frozen=True)
class TopicInfo:
    """The topic of a publisher, subscription, service or client (liveliness_utils.hpp, ``TopicInfo``).

    Attributes:
        name: the fully qualified ROS name, ``/cmd_vel``.
        dds_type: ``geometry_msgs::msg::dds_::Twist_``.
        type_hash: ``RIHS01_`` and 64 hex digits.
        qos: the entity's QoS.
    """

    name: str
    dds_type: str
    type_hash: str
    qos: RmwQos = _DEFAULT_QOS


@dataclass(frozen=True)
class Entity:
    """One ROS 2 entity of rmw_zenoh's graph: a node, or a publisher/subscription/service/client of one.

    Attributes:
        domain: the ROS domain (``ROS_DOMAIN_ID``).
        zid: the Zenoh session's id as Zenoh prints it (hex).
        node_id: the node's number within its context (``"0"`` for the first).
        entity_id: the entity's number within the context (the node's own for a node).
        kind: ``"NN"``, ``"MP"``, ``"MS"``, ``"SS"`` or ``"SC"``.
        enclave: the SROS enclave, ``/`` when none.
        namespace: the node's namespace, ``/`` when none.
        node: the node's name.
        topic: the topic of an entity that is not a node (None for a node).
    """

    domain: int
    zid: str
    node_id: str
    entity_id: str
    kind: str
    enclave: str
    namespace: str
    node: str
    topic: TopicInfo | None = None


def entity_key(entity: Entity) -> str:
    """The key expression of an entity's liveliness token.

    ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node>``
    and, for a publisher/subscription/service/client, ``/<topic>/<type>/<hash>/<qos>``;
    names mangled (liveliness_utils.cpp, ``Entity::Entity``). docs/design.md's talker:
    ``@ros2_lv/2/8b20.../0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/RIHS01_df66.../::,7:,:,:,,``.
    """
    parts = [ADMIN_SPACE, str(entity.domain), entity.zid, entity.node_id, entity.entity_id, entity.kind,
             mangle(entity.enclave), mangle(entity.namespace), mangle(entity.node)]
    if entity.topic is not None:
        topic = entity.topic
        parts += [mangle(topic.name), mangle(topic.dds_type), mangle(topic.type_hash), qos_text(topic.qos)]
    return "/".join(parts)


def parse_entity_key(key: str) -> Entity:
    """The entity a liveliness token's key expression declares (liveliness_utils.cpp, ``Entity::make``
    from a key expression; stricter: 9 chunks for a node and 13 for the others, exactly).

    Raises:
        RmwZenohFormatError: not such a key expression (too long, a chunk missing or empty,
            another admin space, an unknown kind, a domain or QoS that does not parse).
    """
    if not isinstance(key, str):
        raise RmwZenohFormatError("liveliness token", _shown(repr(key)), "expected a key expression (str)")
    if len(key) > MAX_KEY:
        raise RmwZenohFormatError("liveliness token", _shown(key), f"{len(key)} characters, at most {MAX_KEY} read")
    parts = key.split("/")
    if len(parts) < 9:
        raise RmwZenohFormatError("liveliness token", _shown(key), f"{len(parts)} chunks, expected at least 9")
    if any(not _CHUNK.fullmatch(part) for part in parts[1:]):
        raise RmwZenohFormatError("liveliness token", _shown(key), "an empty chunk or one with a wildcard")
    if parts[0] != ADMIN_SPACE:
        raise RmwZenohFormatError("liveliness token", _shown(key), f"expected the admin space {ADMIN_SPACE}")
    kind = parts[5]
    if kind not in KINDS:
        raise RmwZenohFormatError("liveliness token", _shown(key), f"entity kind {kind!r}, expected one of "
                                  + ", ".join(KINDS))
    expected = 9 if kind == "NN" else 13
    if len(parts) != expected:
        raise RmwZenohFormatError("liveliness token", _shown(key), f"{len(parts)} chunks, a {kind} has {expected}")
    if not _NUMBER.fullmatch(parts[1]) or int(parts[1]) >= 1 << 32:
        raise RmwZenohFormatError("liveliness token", _shown(key), f"domain {parts[1]!r} is not a number")
    topic = None
    if kind != "NN":
        topic = TopicInfo(demangle(parts[9]), demangle(parts[10]), demangle(parts[11]), parse_qos(parts[12]))
    return Entity(int(parts[1]), parts[2], parts[3], parts[4], kind, demangle(parts[6]), demangle(parts[7]),
                  demangle(parts[8]), topic)


def entity_gid(key: str) -> bytes:
    """An entity's 16-byte GID: XXH3-128 of its token's key expression, the low 64 bits first
    (liveliness_utils.cpp, ``Entity::Entity``: ``memcpy`` of ``low64`` then ``high64``)."""
    xxhash = import_extra("xxhash", "zenoh", "rmw_zenoh's GIDs")  # imported when a GID is made, not with anodize
    digest = int(xxhash.xxh3_128_intdigest(key.encode()))
    return (digest & (1 << 64) - 1).to_bytes(8, "little") + (digest >> 64).to_bytes(8, "little")


def check_type_hash(text: str) -> str | None:
    """Why ``text`` is not a RIHS01 type hash (``RIHS01_`` and 64 lowercase hex digits), or None."""
    return None if _HASH.fullmatch(text) else "expected RIHS01_ and 64 lowercase hex digits"


@dataclass(frozen=True)
class Attachment:
    """What rmw_zenoh attaches to each sample (attachment_helpers.hpp, ``AttachmentData``).

    Attributes:
        sequence: the publisher's sequence number, 1 for its first sample (rmw_publisher_data.cpp).
        timestamp: when it was published, ns since the UNIX epoch (zenoh_utils.cpp,
            ``get_system_time_in_ns``).
        gid: the publisher's 16-byte GID (:func:`entity_gid`).
    """

    sequence: int
    timestamp: int
    gid: bytes


_LAYOUT = struct.Struct("<qqB16s")


def encode_attachment(attachment: Attachment) -> bytes:
    """The attachment's 33 bytes, as zenoh-cpp's ``ext::Serializer`` writes them in
    ``AttachmentData::serialize_to_zbytes`` (attachment_helpers.cpp): the sequence number and
    the timestamp as little-endian int64, then the GID as a sequence: its length (16, one
    LEB128 byte) and its bytes (docs/design.md, "Publishers").

    Raises:
        RmwZenohFormatError: a number outside int64 or a GID that is not 16 bytes.
    """
    gid = bytes(attachment.gid)
    if len(gid) != GID_SIZE:
        raise RmwZenohFormatError("attachment", _shown(gid), f"a GID has {GID_SIZE} bytes, got {len(gid)}")
    for name, value in (("sequence number", attachment.sequence), ("timestamp", attachment.timestamp)):
        if not -(1 << 63) <= value < 1 << 63:
            raise RmwZenohFormatError("attachment", str(value), f"the {name} does not fit an int64")
    return _LAYOUT.pack(attachment.sequence, attachment.timestamp, GID_SIZE, gid)


def parse_attachment(data: bytes | bytearray | memoryview) -> Attachment:
    """The attachment of a sample (attachment_helpers.cpp, ``AttachmentData(const zenoh::Bytes &)``).

    Raises:
        RmwZenohFormatError: not exactly 33 bytes, or a GID length other than 16.
    """
    raw = bytes(data[:ATTACHMENT_SIZE + 1])
    if len(raw) != ATTACHMENT_SIZE:
        raise RmwZenohFormatError("attachment", _shown(raw),
                                  f"{len(data)} bytes, expected {ATTACHMENT_SIZE} (int64, int64, 16-byte GID)")
    sequence, timestamp, length, gid = _LAYOUT.unpack(raw)
    if length != GID_SIZE:
        raise RmwZenohFormatError("attachment", _shown(raw), f"GID length {length}, expected {GID_SIZE}")
    return Attachment(sequence, timestamp, gid)
