"""Is a recording what its recorder wrote? ``anodize verify``'s check of the hash chain.

The chain (:mod:`.chain`) is checked in two steps. Its link records, folded from each
chain's genesis, must lead to the head in the recording's heads document (whose digest the
run report gave, and which a key may have signed): that proves the entries are the
recorder's. Then the messages in the file, each taken back to its entry, must be exactly
those entries: per chain, both in log-time order, the first difference is the message
removed, inserted, reordered (its content where another's was) or altered (sequence number,
times, payload), with its index among the channel's messages, whatever the sequence numbers
now say. All of it is read as untrusted: a malformed link record or heads document is a
finding, never a traceback.
"""

from __future__ import annotations

import hashlib
import hmac
import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from .chain import (
    CHAIN_KEY,
    CHAIN_TOPIC,
    ENTRY,
    ChainFormatError,
    Links,
    chain_of,
    decode_links,
    entry_digest,
    genesis,
    heads_document,
    identity,
    sign,
    step,
)
from .reader import RecordedMessage, RecordedTopic

__all__ = ["ChainFault", "Evidence", "EvidenceCheck", "NO_CHAIN"]

NO_CHAIN = "no hash chain: cannot tell if messages were removed (a recording by another tool, or an older anodize)"
_AHEAD = 3  # entries that must agree after a removal or an insertion for it to be called one


@dataclass(frozen=True)
class ChainFault:
    """What the chain shows was done to the recording after it was written.

    Attributes:
        channel: the chain's channel (``"Sender->Receiver"``) or other topic.
        index: the message's place among the channel's messages in log-time order (None:
            the chain's own records, not a message).
        kind: ``"removed"``, ``"inserted"``, ``"reordered"``, ``"altered"``, or ``"heads"`` /
            ``"signature"`` for the heads document.
        detail: what was found.
    """

    channel: str
    index: int | None
    kind: str
    detail: str

    def __str__(self) -> str:
        if not self.channel:
            return f"the chain heads: {self.detail}"
        where = f"channel {self.channel}" if "->" in self.channel else f"topic {self.channel}"
        if self.index is not None:
            where += f", message {self.index}"
        return f"{where} {self.kind}: {self.detail}"


@dataclass
class Evidence:
    """The chain's verdict on a recording.

    Attributes:
        chained: whether the recording carries a hash chain at all.
        channels: chains checked.
        messages: messages the chains cover.
        digest: SHA-256 of the heads document (compare it with the run report's).
        signed: whether the heads are signed; ``signature_checked``: and it was checked.
        faults: what was removed, inserted, reordered or altered.
    """

    chained: bool = False
    channels: int = 0
    messages: int = 0
    digest: str = ""
    signed: bool = False
    signature_checked: bool = False
    faults: list[ChainFault] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Evidence: chained, and the chain finds nothing changed."""
        return self.chained and not self.faults

    def lines(self) -> list[str]:
        """The verdict as the report's lines."""
        if not self.chained and not self.faults:
            return [f"note: {NO_CHAIN}"]
        if self.ok:
            signature = ("; signature checked" if self.signature_checked else
                         "; signed: give --key to check the signature" if self.signed else "; not signed")
            chains = f"{self.channels} chain{'' if self.channels == 1 else 's'}"
            held = (f"evidence: the hash chains hold ({chains}, one per channel or other topic; "
                    f"{self.messages} messages)")
            return [f"{held}; chain heads sha256 {self.digest}{signature}"]
        digest = self.digest or "unknown"
        lines = [f"NOT evidence (chain heads sha256 {digest}): the hash chain does not vouch for this recording"]
        lines.extend(f"chain: {fault}" for fault in self.faults)
        return lines

    def to_dict(self) -> dict[str, Any]:
        return {"chained": self.chained, "ok": self.ok, "channels": self.channels, "messages": self.messages,
                "digest": self.digest, "signed": self.signed, "signature_checked": self.signature_checked,
                "faults": [fault.__dict__ for fault in self.faults]}


class EvidenceCheck:
    """The chain check, fed the recording's messages in the one pass verify makes over them.

    Args:
        heads: the recording's heads document (``Recording.chain``), or None.
        topics: the recording's topics.
        key: the key the heads must be signed with, if one was given.
    """

    def __init__(self, heads: dict[str, str] | None, topics: Iterable[RecordedTopic], key: bytes | None) -> None:
        self._heads = heads
        self._key = key
        self._links: list[Links] = []
        self._bad_links: list[str] = []
        self._chains: dict[int, tuple[str, bytes]] = {}
        self._link_topics: set[int] = set()
        for topic in topics:
            if topic.metadata.get(CHAIN_KEY) == "1":
                self._link_topics.add(topic.id)
            else:
                self._chains[topic.id] = (chain_of(topic.topic, topic.metadata),
                                          _identity(topic))
        self._present: dict[str, list[bytes]] = {}
        self._chained = heads is not None or bool(self._link_topics)  # else nothing to compare (no cost)

    def see(self, message: RecordedMessage) -> None:
        """One message of the recording (any topic), in log-time order."""
        topic = message.topic.id
        if not self._chained:
            return
        if topic in self._link_topics:
            try:
                self._links.append(decode_links(message.data))
            except ChainFormatError as error:
                self._bad_links.append(str(error))
            return
        name, who = self._chains[topic]
        publish = message.publish_time if message.publish_time >= 0 else message.log_time
        self._present.setdefault(name, []).append(
            ENTRY.pack(message.sequence, message.log_time, publish, entry_digest(who, message.data)))

    def result(self) -> Evidence:
        """The verdict, once every message was seen."""
        evidence = Evidence()
        if not self._chained:
            if self._key is not None:
                evidence.faults.append(ChainFault("", None, "signature", f"--key given, but there is nothing signed: "
                                                                          f"{NO_CHAIN}"))
            return evidence
        evidence.chained = True
        evidence.faults.extend(ChainFault(CHAIN_TOPIC, None, "altered", f"a link record cannot be read: {reason}")
                               for reason in self._bad_links[:3])
        run_id, heads = self._read_heads(evidence)
        expected, complete, declared = self._fold(run_id, heads, evidence)
        names = sorted(set(expected) | set(self._present))
        evidence.channels = len(names)
        for name in names:
            present = self._present.get(name, [])
            evidence.messages += len(present)
            fault = _compare(name, expected.get(name, []), present, complete.get(name, False), declared.get(name, 0))
            if fault is not None:
                evidence.faults.append(fault)
        return evidence

    def _read_heads(self, evidence: Evidence) -> tuple[str, dict[str, dict[str, list[Any]]]]:
        """The heads document's run id and heads (checked, with its digest and signature)."""
        record = self._heads
        if record is None:
            evidence.faults.append(ChainFault("", None, "heads", "the recording has link records but no chain "
                                                                 "heads (the heads record was removed?)"))
            return "", {}
        run_id = record.get("run_id", "")
        try:
            heads = json.loads(record.get("heads", ""))
            _check_heads(heads)
        except (ValueError, TypeError, RecursionError) as error:
            evidence.faults.append(ChainFault("", None, "heads", f"the heads record is malformed: {error}"))
            return run_id, {}
        document = heads_document(run_id, heads)
        evidence.digest = hashlib.sha256(document).hexdigest()
        if record.get("digest") != evidence.digest:
            evidence.faults.append(ChainFault("", None, "heads", "the heads record's digest is not that of its heads "
                                                                 "(the heads were altered)"))
        signature = record.get("signature")
        evidence.signed = signature is not None
        if self._key is not None:
            if signature is None:
                evidence.faults.append(ChainFault("", None, "signature", "--key given, but the heads are not signed"))
            elif not hmac.compare_digest(str(signature), sign(self._key, document)):
                evidence.faults.append(ChainFault("", None, "signature", "the heads do not match their signature "
                                                                         "with this key (the heads were altered, "
                                                                         "or signed with another key)"))
            else:
                evidence.signature_checked = True
        return run_id, heads

    def _fold(self, run_id: str, heads: dict[str, dict[str, list[Any]]], evidence: Evidence
              ) -> tuple[dict[str, list[bytes]], dict[str, bool], dict[str, int]]:
        """Per chain: the entries its link records prove, whether they reach its head(s), and
        how many messages its head(s) say there are."""
        by_part: dict[tuple[str, str], list[Links]] = {}
        for links in self._links:
            by_part.setdefault((links.part, links.chain), []).append(links)
        expected: dict[str, list[bytes]] = {}
        complete: dict[str, bool] = {}
        declared: dict[str, int] = {}
        for part, chain in sorted(set(by_part) | {(p, c) for p, chains in heads.items() for c in chains}):
            head = heads.get(part, {}).get(chain)
            entries, reached = _fold_part(run_id, part, chain, sorted(by_part.get((part, chain), []),
                                                                       key=lambda links: links.first), head, evidence)
            expected.setdefault(chain, []).extend(entries)
            complete[chain] = complete.get(chain, True) and reached
            declared[chain] = declared.get(chain, 0) + (int(head[0]) if head is not None else len(entries))
        return expected, complete, declared


def _identity(topic: RecordedTopic) -> bytes:
    return identity(topic.topic, topic.metadata)


def _check_heads(heads: object) -> None:
    if not isinstance(heads, dict):
        raise TypeError("expected a JSON object of part -> channel -> [count, head]")
    for chains in heads.values():
        if not isinstance(chains, dict):
            raise TypeError("expected a JSON object of channel -> [count, head] for each part")
        for head in chains.values():
            if (not isinstance(head, list) or len(head) != 2 or not isinstance(head[0], int)
                    or isinstance(head[0], bool) or head[0] < 0 or not isinstance(head[1], str)):
                raise TypeError(f"expected [count, head] for each channel; found {str(head)[:60]}")


def _fold_part(run_id: str, part: str, chain: str, records: list[Links], head: list[Any] | None,
               evidence: Evidence) -> tuple[list[bytes], bool]:
    """One part's chain: the entries its link records prove (up to the first that does not
    follow), and whether they reach the head the heads document gives it."""
    entries: list[bytes] = []
    value = genesis(run_id, part, chain)
    for links in records:
        if links.first != len(entries):
            if links.first > len(entries):
                kind, what = "removed", f"the link records of messages {len(entries)} to {links.first - 1} are missing"
            else:
                kind, what = "inserted", f"a link record repeats messages from {links.first}"
            evidence.faults.append(ChainFault(chain, None, kind, f"{what} (part {part})"))
            return entries, False
        for entry in links.entries:
            value = step(value, entry)
        if value != links.hash:
            evidence.faults.append(ChainFault(chain, None, "altered", f"the link record of messages from "
                                                                      f"{links.first} does not lead to its hash "
                                                                      f"(part {part})"))
            return entries, False
        entries.extend(links.entries)
    if head is None:
        evidence.faults.append(ChainFault(chain, None, "inserted", f"part {part}: a chain the heads do not name"))
        return entries, False
    if len(entries) == head[0] and value.hex() == head[1]:
        return entries, True
    if len(entries) < head[0]:
        return entries, False  # the tail's link records are gone: the comparison says which messages
    evidence.faults.append(ChainFault(chain, None, "altered", f"part {part}: the link records do not lead to the "
                                                              "chain's head (they were made again?)"))
    return entries, False


def _order(entry: bytes) -> bytes:
    """Log time, publish time, sequence, digest: big-endian, so bytes sort as the numbers."""
    return entry[8:24] + entry[:8] + entry[24:]


def _compare(chain: str, expected: list[bytes], present: list[bytes], complete: bool,
             declared: int) -> ChainFault | None:
    """The first difference between the entries the chain proves and the messages in the file."""
    if not expected and not complete and declared == 0:
        return ChainFault(chain, 0, "inserted", "a channel that no chain covers")
    wanted = sorted(expected, key=_order)
    found = sorted(present, key=_order)
    if wanted == found:
        if complete:
            return None
        return ChainFault(chain, len(found), "removed", f"the chain's head says {declared} messages; "
                                                        f"the file has {len(found)} (its tail was cut)")
    common = min(len(wanted), len(found))
    index = next((i for i in range(common) if wanted[i] != found[i]), common)
    if index == common:
        if len(found) < len(wanted):
            return ChainFault(chain, index, "removed", f"the last {len(wanted) - index} message(s): the chain has "
                                                       f"{len(wanted)}, the file {len(found)}")
        if complete:
            return ChainFault(chain, index, "inserted", f"{len(found) - index} message(s) after the chain's last")
        if len(found) < declared:
            return ChainFault(chain, len(found), "removed", f"the chain's head says {declared} messages; "
                                                            f"the file has {len(found)} (its tail was cut)")
        return ChainFault(chain, index, "altered", "the link records of the messages from here on are missing: "
                                                   "they cannot be checked")
    return _diagnose(chain, wanted, found, index)


def _diagnose(chain: str, wanted: list[bytes], found: list[bytes], i: int) -> ChainFault:
    """What happened at ``i``, the first place the file differs from the chain."""
    e, p = ENTRY.unpack(wanted[i]), ENTRY.unpack(found[i])
    if e[1:] == p[1:]:
        return ChainFault(chain, i, "altered", f"its sequence number was rewritten: recorded {e[0]}, now {p[0]}")
    wanted_at = {ENTRY.unpack(entry)[1:]: n for n, entry in enumerate(wanted)}
    found_at = {ENTRY.unpack(entry)[1:]: n for n, entry in enumerate(found)}
    j = wanted_at.get(p[1:])
    if j is not None and j > i and _agree(wanted, j, found, i):
        return ChainFault(chain, i, "removed", f"{j - i} message(s) from here are not in the file")
    k = found_at.get(e[1:])
    if k is not None and k > i and _agree(wanted, i, found, k):
        return ChainFault(chain, i, "inserted", f"{k - i} message(s) here that the chain does not have")
    content = {(ENTRY.unpack(entry)[0], ENTRY.unpack(entry)[3]): n for n, entry in enumerate(wanted)}
    moved = content.get((p[0], p[3]))
    if moved is not None and moved != i:
        return ChainFault(chain, i, "reordered", f"recorded as message {moved}, it is now message {i}")
    changed = [what for what, a, b in (("sequence number", e[0], p[0]), ("log time", e[1], p[1]),
                                       ("publish time", e[2], p[2]), ("payload or topic", e[3], p[3])) if a != b]
    return ChainFault(chain, i, "altered", f"its {', '.join(changed)} differ(s) from what was recorded")


def _agree(wanted: list[bytes], j: int, found: list[bytes], k: int) -> bool:
    """Whether the entries after ``wanted[j]`` and ``found[k]`` agree (ignoring sequence numbers,
    which a removal's renumbering rewrites) for a few places."""
    for t in range(1, _AHEAD + 1):
        if j + t >= len(wanted) or k + t >= len(found):
            return True
        if wanted[j + t][8:] != found[k + t][8:]:
            return False
    return True
