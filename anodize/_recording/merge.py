"""The end of a recorded run: the groups' parts merged into one recording.

The parts are merged in time order into one indexed MCAP file (``ros2`` profile),
with what ``ros2 bag`` needs of it: the ``rosbag2`` metadata record inside the file,
and, when the recording is a folder, ``metadata.yaml`` beside it. The file also holds
an ``anodize`` metadata record: the protocol's source and the global type's name, so
``anodize verify`` needs nothing else to check it.

A part cut short (its group was killed) is read up to its last whole message.

Each part's hash chains (:mod:`.chain`) pass through as they are: a chain is one group's,
so it is in one part. The merge folds their link records again and writes the heads
document (with a key, signed), so a part cut short has heads too.
"""

from __future__ import annotations

import heapq
import shutil
from collections.abc import Iterator
from dataclasses import dataclass, field
from io import StringIO
from pathlib import Path
from typing import Any

from .._extras import import_extra
from .chain import CHAIN_KEY, CHAIN_TOPIC, HEADS_RECORD, HeadCollector, chain_of, heads_record, identity
from .encoding import codec_for_sort
from .plan import CLOCK_KEY, GAP_KEY, META, PROFILE
from .rosout import LOG_KEY

__all__ = ["MergeResult", "merge_parts", "recording_file"]

FEATURE = "recording a run (--record)"


@dataclass
class MergeResult:
    """What was written: the file, its folder form (if any), counts and problems to report."""

    path: Path
    messages: int = 0
    channels: int = 0  # the protocol's channels (sender->receiver) with a message recorded
    topics: int = 0  # the recording's topics of messages: one per label of a channel (each an MCAP channel)
    bytes: int = 0
    readings: int = 0  # of the roles' clocks, on their clock channels (not counted in messages, channels)
    chains: int = 0  # hash chains (one per recorded channel or other topic)
    heads_digest: str = ""  # SHA-256 of the heads document (:func:`.chain.heads_document`)
    signed: bool = False
    logs: int = 0  # the roles' log records on /rosout (not counted in messages, channels either)
    notes: list[str] = field(default_factory=list)


def recording_file(target: Path) -> tuple[Path, Path | None]:
    """Where a recording asked for as ``target`` goes: the MCAP file, and the rosbag2 folder if
    ``target`` is one (``run.mcap`` is a file; ``runs/today`` a folder with ``today_0.mcap``)."""
    if target.suffix == ".mcap":
        return target, None
    return target / f"{target.name}_0.mcap", target


def merge_parts(parts: Path, target: Path, run_info: dict[str, str], sign_key: bytes | None = None) -> MergeResult:
    """Merge the part files in ``parts`` into the recording ``target``, then remove ``parts``.

    Args:
        parts: the folder the groups wrote into.
        target: the recording asked for (see :func:`recording_file`).
        run_info: the ``anodize`` metadata record: protocol source, global, transport, run id, ...
        sign_key: the key that signs the chain heads (HMAC-SHA256), if any.
    """
    import_extra("mcap.writer", "record", FEATURE)
    from mcap.writer import CompressionType, Writer

    path, folder = recording_file(target)
    path.parent.mkdir(parents=True, exist_ok=True)
    result = MergeResult(path)
    sources = [_Part(p) for p in sorted(parts.glob("*.mcap"))]
    with path.open("wb") as stream:
        writer = Writer(stream, compression=CompressionType.NONE, chunk_size=4 * 2**20)
        writer.start(profile=PROFILE, library="anodize")
        ids: dict[tuple[int, int], int] = {}  # (part, channel in part) -> channel in the recording
        schemas: dict[tuple[str, bytes], int] = {}
        known: dict[tuple[str, int, tuple[tuple[str, str], ...]], int] = {}  # a restarted group's channels again
        topics: dict[int, dict[str, Any]] = {}
        clocks: set[int] = set()  # the recording's clock channels
        links: set[int] = set()  # the recording's link channel (:mod:`.chain`)
        collector = HeadCollector(run_info.get("run_id", ""))
        pairs: set[tuple[str, str]] = set()  # the protocol's channels (sender, receiver) recorded
        logs: set[int] = set()  # and its log channel
        gaps: set[int] = set()  # and its gap channel

        def channel_of(number: int, channel_id: int) -> int:
            """The recording's channel of a part's, registered at its first message (one pass)."""
            topic, type_name, definition, metadata = sources[number].channels[channel_id]
            schema = schemas.get((type_name, definition))
            if schema is None:
                schema = schemas[(type_name, definition)] = writer.register_schema(type_name, "ros2msg", definition)
            key = (topic, schema, tuple(sorted(metadata.items())))
            new = known.get(key)
            if new is None:
                new = known[key] = writer.register_channel(topic, "cdr", schema, metadata)
                if CLOCK_KEY in metadata:
                    clocks.add(new)
                elif CHAIN_KEY in metadata:
                    links.add(new)
                elif f"{META}.sender" in metadata:
                    pairs.add((metadata[f"{META}.sender"], metadata.get(f"{META}.receiver", "")))
                elif LOG_KEY in metadata:  # the roles' log records (/rosout): no channel either
                    logs.add(new)
                elif GAP_KEY in metadata:  # the recorder's gap records: no message, no channel, no topic
                    gaps.add(new)
                topics[new] = {"name": topic, "type": type_name, "hash": metadata.get("topic_type_hash", ""),
                               "qos": metadata.get("offered_qos_profiles", ""), "count": 0}
            ids[(number, channel_id)] = new
            return new

        start, end = 2**63 - 1, 0
        for number, channel_id, log_time, publish_time, sequence, data in heapq.merge(
                *(source.messages(n) for n, source in enumerate(sources)), key=lambda m: m[2]):
            new = ids.get((number, channel_id)) or channel_of(number, channel_id)
            writer.add_message(new, log_time, data, publish_time, sequence)
            topics[new]["count"] += 1
            start, end = min(start, log_time), max(end, log_time)
            if new in links:
                collector.see(data)
            elif new in clocks:
                result.readings += 1
            elif new in logs:
                result.logs += 1
            elif new not in gaps:  # the recorder's gap records count as none of these
                result.messages += 1
            result.bytes += len(data)
        for source in sources:
            if source.heads is not None:
                collector.check_part(source.path.stem, source.heads)
                continue
            # Not closed by a recorder (its group was killed), or the supervisor's /rosout part
            # (written at the end, :mod:`.rosout`): the merge links what no writer had linked.
            for log_time, data in collector.link_tail(source.path.stem, _Part(source.path).chained()):
                if not links:
                    links.add(_link_channel(writer, topics))
                writer.add_message(min(links), log_time, data, log_time, 0)
                topics[min(links)]["count"] += 1
                result.bytes += len(data)
        result.channels = len(pairs)
        result.topics = len(topics) - len(clocks) - len(links) - len(logs) - len(gaps)
        for source in sources:
            result.notes.extend(source.notes)
        result.notes.extend(collector.notes)
        ran_at: dict[str, list[str]] = {}
        for source in sources:
            if source.priority:
                ran_at.setdefault(source.priority, []).append(source.path.stem)
        if ran_at:
            result.notes.append("the groups' writers ran at " + "; ".join(
                f"{priority} ({', '.join(parts)})" for priority, parts in sorted(ran_at.items())))
        if result.messages + result.readings + result.logs == 0:  # nothing was written: no time span
            start = end = 0
        bag = _bag_metadata(path.name, topics, start, end, sum(topic["count"] for topic in topics.values()))
        writer.add_metadata("rosbag2", {"serialized_metadata": _yaml(bag)})
        writer.add_metadata(META, run_info)
        chain = heads_record(collector.run_id, collector.heads, sign_key)
        writer.add_metadata(HEADS_RECORD, chain)
        result.chains = len({name for chains in collector.heads.values() for name in chains})
        result.heads_digest, result.signed = chain["digest"], sign_key is not None
        writer.finish()  # type: ignore[no-untyped-call]
    if folder is not None:
        (folder / "metadata.yaml").write_text(_yaml({"rosbag2_bagfile_information": bag}), encoding="utf-8")
    shutil.rmtree(parts, ignore_errors=True)
    return result


def _link_channel(writer: Any, topics: dict[int, dict[str, Any]]) -> int:
    """The recording's link channel, for a merge whose parts wrote no link record."""
    codec = codec_for_sort(None)
    schema = writer.register_schema(codec.type_name, "ros2msg", codec.ros.message_definition().encode())
    new = int(writer.register_channel(CHAIN_TOPIC, "cdr", schema, {"topic_type_hash": codec.ros.type_hash,
                                                                  CHAIN_KEY: "1"}))
    topics[new] = {"name": CHAIN_TOPIC, "type": codec.type_name, "hash": codec.ros.type_hash, "qos": "", "count": 0}
    return new


class _Part:
    """One group's part file, read as a stream (it may end early)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.notes: list[str] = []
        self.channels: dict[int, tuple[str, str, bytes, dict[str, str]]] = {}
        self._schemas: dict[int, tuple[str, bytes]] = {}
        self.priority = ""  # what the part's writer ran at (its group's side-work priority)
        self.heads: dict[str, str] | None = None  # the chain heads it wrote when it closed

    def _records(self) -> Iterator[Any]:
        from mcap.records import Chunk
        from mcap.stream_reader import StreamReader

        with self.path.open("rb") as stream:
            try:
                for record in StreamReader(stream, skip_magic=False, emit_chunks=True).records:
                    if isinstance(record, Chunk):
                        # A group writes its part unchunked and uncompressed (tap.Recorder); a chunk
                        # is not its recorder's, and decompressing it could take any amount of memory.
                        self.notes.append(f"part {self.path.name} holds an MCAP chunk ({record.compression or 'not'} "
                                          f"compressed, {record.uncompressed_size} bytes declared), which a group's "
                                          "recorder never writes: the rest of the part was not read")
                        return
                    yield record
            except Exception as error:  # a part cut short: its group was killed mid-write
                note = f"part {self.path.name} ends early ({type(error).__name__}); kept what was whole"
                if note not in self.notes:
                    self.notes.append(note)

    def _note_definitions(self, record: Any) -> None:
        """Keep a schema or channel as it is read; a part's account of what it could not record."""
        from mcap.records import Channel, Metadata, Schema

        if isinstance(record, Schema):
            self._schemas[record.id] = (record.name, record.data)
        elif isinstance(record, Channel):
            name, definition = self._schemas[record.schema_id]
            self.channels[record.id] = (record.topic, name, definition, dict(record.metadata))
        elif isinstance(record, Metadata) and record.name == f"{META}.unrecorded":
            self.notes.extend(f"{key}: {text}" for key, text in record.metadata.items())
        elif isinstance(record, Metadata) and record.name == f"{META}.side_work":
            self.priority = record.metadata.get("writer_priority", "")
        elif isinstance(record, Metadata) and record.name == HEADS_RECORD:
            self.heads = dict(record.metadata)

    def chained(self) -> Iterator[tuple[str, bytes, int, int, int, bytes]]:
        """The part's messages as the chain sees them (:meth:`.chain.HeadCollector.link_tail`)."""
        for _, channel_id, log_time, publish_time, sequence, data in self.messages(0):
            topic, _, _, metadata = self.channels[channel_id]
            if CHAIN_KEY not in metadata:
                yield chain_of(topic, metadata), identity(topic, metadata), sequence, log_time, publish_time, data

    def messages(self, number: int) -> Iterator[tuple[int, int, int, int, int, bytes]]:
        from mcap.records import Message

        for record in self._records():  # a part registers each channel before its first message
            if isinstance(record, Message):
                yield number, record.channel_id, record.log_time, record.publish_time, record.sequence, record.data
            else:
                self._note_definitions(record)


def _bag_metadata(file_name: str, topics: dict[int, dict[str, Any]], start: int, end: int,
                  count: int) -> dict[str, Any]:
    """rosbag2's description of the recording (metadata version 9, as ROS 2 Jazzy writes)."""
    from ruamel.yaml import YAML

    def qos(text: str) -> Any:
        return YAML(typ="safe").load(text) if text else []

    return {
        "version": 9,
        "storage_identifier": "mcap",
        "relative_file_paths": [file_name],
        "duration": {"nanoseconds": end - start},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": count,
        "topics_with_message_count": [
            {"topic_metadata": {"name": t["name"], "type": t["type"], "serialization_format": "cdr",
                                "offered_qos_profiles": qos(t["qos"]), "type_description_hash": t["hash"]},
             "message_count": t["count"]}
            for t in topics.values()],
        "compression_format": "",
        "compression_mode": "",
        "files": [{"path": file_name, "starting_time": {"nanoseconds_since_epoch": start},
                   "duration": {"nanoseconds": end - start}, "message_count": count}],
        "custom_data": {},
        "ros_distro": "jazzy",
    }


def _yaml(data: Any) -> str:
    from ruamel.yaml import YAML

    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    out = StringIO()
    yaml.dump(data, out)
    return out.getvalue()
