"""The hash chain that makes a recording evidence: what it covers, and how it is written.

Every message a group's recorder writes is a link of its channel's chain (a protocol
channel ``Sender->Receiver``, all its labels together; any other recorded topic, such as
the recorder's gaps or a role's clock, is a chain of its own). Link ``i`` is

    h_i = SHA-256(h_{i-1} || sequence || log_time || publish_time || d_i)
    d_i = SHA-256(len(identity) || identity || data)     identity: chain, topic, label

and the first link's ``h_{-1}`` is the chain's genesis, SHA-256 of the run's random id, the
part (the group and its incarnation) and the chain, so no chain can be taken from another
run, group or channel. The writer (:class:`ChainedWriter`, in the recorder's writer thread,
never a sender's) puts after each batch one *link record* per chain on :data:`CHAIN_TOPIC`:
the entries ``(sequence, log_time, publish_time, d_i)`` of the batch and the hash they lead
to. From them alone ``verify`` recomputes the chain, checks it against its head, and then
compares the messages actually in the file with the entries, which tells which message was
removed, inserted, moved or altered (docs/decisions/0050-evidence.md says why links, not
only heads). When the part ends the writer adds the heads (:data:`HEADS_RECORD`).

The merge (:class:`HeadCollector`) folds each part's link records again, so that a part cut
short has heads too, and writes one heads document in the recording: the run id, every
chain's count and head, their digest (what the run report shows) and, with a key, an
HMAC-SHA256 of the document (:func:`heads_record`).
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import json
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from .encoding import codec_for_sort
from .plan import META

__all__ = ["CHAIN_TOPIC", "CHAIN_KEY", "HEADS_RECORD", "ChainedWriter", "HeadCollector", "Links", "chain_of",
           "genesis", "entry_digest", "step", "encode_links", "decode_links", "identity", "heads_document",
           "heads_record", "sign", "ENTRY", "SIGNATURE_KIND", "ChainFormatError"]

CHAIN_TOPIC = "/anodize/recording/chain"  # where the link records are
CHAIN_KEY = f"{META}.chain_links"  # the link channel's metadata key (its value: "1")
HEADS_RECORD = f"{META}.chain"  # the metadata record of the heads (in a part, and in the recording)
SIGNATURE_KIND = "hmac-sha256"
ENTRY = struct.Struct(">QQQ32s")  # sequence, log time, publish time, d_i
_STAMPS = struct.Struct(">QQQ")
_VERSION = b"anodize chain 1\0"


class ChainFormatError(ValueError):
    """A link record or heads document that is not what the recorder writes (untrusted input)."""


def chain_of(topic: str, metadata: Mapping[str, str]) -> str:
    """The chain a recorded topic's messages belong to: its protocol channel, else the topic."""
    sender = metadata.get(f"{META}.sender")
    if sender is not None:
        return f"{sender}->{metadata.get(f'{META}.receiver', '')}"
    return topic


def identity(topic: str, metadata: Mapping[str, str]) -> bytes:
    """What a message's digest says it is on: its chain, topic and label."""
    text = "\0".join((chain_of(topic, metadata), topic, metadata.get(f"{META}.label", "")))
    return text.encode("utf-8", "surrogatepass")


def genesis(run_id: str, part: str, chain: str) -> bytes:
    """The hash before a chain's first link: its run, part and chain."""
    return hashlib.sha256(_VERSION + "\0".join((run_id, part, chain)).encode("utf-8", "surrogatepass")).digest()


def entry_digest(who: bytes, data: bytes | memoryview) -> bytes:
    """``d_i``: the digest of a message's data and what it is on."""
    digest = hashlib.sha256(len(who).to_bytes(4, "big"))
    digest.update(who)
    digest.update(data)
    return digest.digest()


def step(previous: bytes, entry: bytes) -> bytes:
    """``h_i`` from ``h_{i-1}`` and the packed entry (:data:`ENTRY`) of message ``i``."""
    return hashlib.sha256(previous + entry).digest()


@dataclass
class _Chain:
    head: bytes
    count: int = 0
    pending: list[bytes] = field(default_factory=list)  # entries since the last link record
    first_pending: int = 0
    last_time: int = 0


class ChainedWriter:
    """An MCAP writer whose messages are chained: the recorder's writer, seen through this.

    Args:
        writer: the part's ``mcap`` writer.
        run_id: the run's random id.
        part: the part's name (its group and incarnation).
        link_metadata: more metadata for the link channel (rosbag2's QoS, the protocol).
    """

    def __init__(self, writer: Any, run_id: str, part: str, link_metadata: Mapping[str, str]) -> None:
        self._writer = writer
        self._run_id = run_id
        self._part = part
        self._link_metadata = dict(link_metadata)
        self._identities: dict[int, tuple[str, bytes]] = {}  # MCAP channel -> its chain, its identity
        self._chains: dict[str, _Chain] = {}
        self._link_channel: int | None = None

    def start(self, **kwargs: Any) -> None:
        self._writer.start(**kwargs)

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        return int(self._writer.register_schema(name, encoding, data))

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        found = int(self._writer.register_channel(topic, message_encoding, schema_id, metadata or {}))
        self._identities[found] = (chain_of(topic, metadata or {}), identity(topic, metadata or {}))
        return found

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        """Write a message, then chain what was written."""
        self._writer.add_message(channel_id, log_time, data, publish_time, sequence)
        name, who = self._identities[channel_id]
        chain = self._chains.get(name)
        if chain is None:
            chain = self._chains[name] = _Chain(genesis(self._run_id, self._part, name))
        entry = ENTRY.pack(sequence, log_time, publish_time, entry_digest(who, data))
        chain.head = step(chain.head, entry)
        if not chain.pending:
            chain.first_pending = chain.count
        chain.pending.append(entry)
        chain.count += 1
        chain.last_time = max(chain.last_time, log_time)

    def seal(self) -> None:
        """Write a link record for each chain with messages since its last one (after each batch)."""
        for name, chain in sorted(self._chains.items()):
            if not chain.pending:
                continue
            data = encode_links(Links(self._part, name, chain.first_pending, chain.head, chain.pending))
            self._writer.add_message(self._links(), chain.last_time, data, chain.last_time, 0)
            chain.pending = []

    def _links(self) -> int:
        if self._link_channel is None:
            codec = codec_for_sort(None)
            schema = self._writer.register_schema(codec.type_name, "ros2msg", codec.ros.message_definition().encode())
            self._link_channel = int(self._writer.register_channel(CHAIN_TOPIC, "cdr", schema, {
                **self._link_metadata, "topic_type_hash": codec.ros.type_hash, CHAIN_KEY: "1"}))
        return self._link_channel

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.add_metadata(name, data)

    def finish(self) -> None:
        """Seal, write the part's heads, and end the file."""
        self.seal()
        heads = {name: [chain.count, chain.head.hex()] for name, chain in sorted(self._chains.items())}
        self._writer.add_metadata(HEADS_RECORD, {"run_id": self._run_id, "part": self._part,
                                                 "heads": json.dumps(heads)})
        self._writer.finish()


@dataclass
class Links:
    """One link record, decoded: its part, chain, first index, the hash it claims, its entries."""

    part: str
    chain: str
    first: int
    hash: bytes
    entries: list[bytes]


def encode_links(links: Links) -> bytes:
    """A link record's bytes: a JSON String, as the gap records."""
    text = json.dumps({"part": links.part, "chain": links.chain, "first": links.first, "hash": links.hash.hex(),
                       "entries": base64.b64encode(b"".join(links.entries)).decode()})
    codec = codec_for_sort(None)
    return codec.ros.serialize(codec.ros.cls(data=text))


def decode_links(data: bytes | memoryview) -> Links:
    """A link record's content.

    Raises:
        ChainFormatError: it is not a link record as the recorder writes one.
    """
    try:
        text = codec_for_sort(None).ros.deserialize(data).data  # type: ignore[attr-defined]
        found = json.loads(text)
        packed = base64.b64decode(str(found["entries"]), validate=True)
        if len(packed) % ENTRY.size or not packed:
            raise ChainFormatError(f"entries of {len(packed)} bytes, not a whole number of {ENTRY.size}-byte entries")
        first = found["first"]
        if not isinstance(first, int) or isinstance(first, bool) or first < 0:
            raise ChainFormatError(f"first index {first!r}")
        digest = bytes.fromhex(str(found["hash"]))
        if len(digest) != hashlib.sha256().digest_size:
            raise ChainFormatError("a hash that is not 32 bytes")
        return Links(str(found["part"]), str(found["chain"]), first, digest,
                     [packed[at:at + ENTRY.size] for at in range(0, len(packed), ENTRY.size)])
    except ChainFormatError:
        raise
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError, binascii.Error) as error:
        raise ChainFormatError(f"{type(error).__name__}: {error}") from None
    except Exception as error:  # the ROS deserializer's own errors
        raise ChainFormatError(f"not a String message: {type(error).__name__}") from None


class HeadCollector:
    """The merge's account of each chain: its link records folded again, part by part."""

    def __init__(self, run_id: str) -> None:
        self.run_id = run_id
        self.heads: dict[str, dict[str, list[Any]]] = {}  # part -> chain -> [count, head hex]
        self._state: dict[tuple[str, str], tuple[int, bytes]] = {}
        self.notes: list[str] = []

    def see(self, data: bytes | memoryview) -> None:
        """A link record, in the order its part wrote it."""
        try:
            links = decode_links(data)
        except ChainFormatError as error:
            self.notes.append(f"a link record of the hash chain that is not the recorder's: {error}")
            return
        key = (links.part, links.chain)
        count, head = self._state.get(key) or (0, genesis(self.run_id, links.part, links.chain))
        if links.first != count:
            self.notes.append(f"the hash chain of {links.chain} in part {links.part} skips from {count} to "
                              f"{links.first}")
            return
        for entry in links.entries:
            head = step(head, entry)
        if head != links.hash:
            self.notes.append(f"a link record of {links.chain} in part {links.part} does not lead to its hash")
            return
        count += len(links.entries)
        self._state[key] = (count, head)
        self.heads.setdefault(links.part, {})[links.chain] = [count, head.hex()]

    def link_tail(self, part: str, messages: Iterable[tuple[str, bytes, int, int, int, bytes | memoryview]]
                  ) -> list[tuple[int, bytes]]:
        """The link records a part that was not closed (its group was killed) lacks: of its
        messages after each chain's last link record. ``messages``: the part's, in its order,
        as ``(chain, identity, sequence, log time, publish time, data)``; returns
        ``(log time, link record)`` for each chain that had such messages."""
        seen: dict[str, int] = {}
        tails: dict[str, list[bytes]] = {}
        last: dict[str, int] = {}
        for chain, who, sequence, log_time, publish_time, data in messages:
            number = seen[chain] = seen.get(chain, -1) + 1
            if number >= self._state.get((part, chain), (0, b""))[0]:
                tails.setdefault(chain, []).append(ENTRY.pack(sequence, log_time, publish_time,
                                                              entry_digest(who, data)))
                last[chain] = max(last.get(chain, 0), log_time)
        records = []
        for chain, entries in sorted(tails.items()):
            count, head = self._state.get((part, chain)) or (0, genesis(self.run_id, part, chain))
            for entry in entries:
                head = step(head, entry)
            records.append((last[chain], encode_links(Links(part, chain, count, head, entries))))
            self._state[(part, chain)] = (count + len(entries), head)
            self.heads.setdefault(part, {})[chain] = [count + len(entries), head.hex()]
        return records

    def check_part(self, part: str, written: Mapping[str, str]) -> None:
        """Compare the heads a part wrote when it closed with its folded links."""
        try:
            heads = json.loads(written.get("heads", "{}"))
        except ValueError:
            heads = None
        if heads != self.heads.get(part, {}):
            self.notes.append(f"part {part}: the chain heads it wrote are not those its link records lead to")


def heads_document(run_id: str, heads: Mapping[str, Mapping[str, Iterable[Any]]]) -> bytes:
    """The canonical text of a recording's heads (what is digested and signed)."""
    return json.dumps({"run_id": run_id, "heads": heads}, sort_keys=True, separators=(",", ":")).encode()


def sign(key: bytes, document: bytes) -> str:
    """The HMAC-SHA256 of ``document`` with ``key``, in hex."""
    return hmac.new(key, document, hashlib.sha256).hexdigest()


def heads_record(run_id: str, heads: Mapping[str, Mapping[str, Iterable[Any]]],
                 key: bytes | None) -> dict[str, str]:
    """The recording's :data:`HEADS_RECORD`: run id, heads, their digest and, with ``key``, its signature."""
    document = heads_document(run_id, heads)
    record = {"version": "1", "run_id": run_id, "heads": json.dumps(heads, sort_keys=True),
              "digest": hashlib.sha256(document).hexdigest()}
    if key is not None:
        record.update(signature=sign(key, document), signature_kind=SIGNATURE_KIND)
    return record
