"""An MCAP file's messages, each chunk decompressed within a bound.

The ``mcap`` library decompresses a chunk whole, into as many bytes as the
chunk says (zstd) or as its data expands to (lz4): a small recording whose
chunk expands to gigabytes took that much memory. Here a chunk whose
declared uncompressed size, or whose compressed record, is larger than
:data:`sessiontypes.limits.MCAP_CHUNK` is refused before it is read, and one
that expands beyond the size it declares is refused once it has produced one
byte more than that (decompression stops there). The records in the
decompressed bytes are parsed by ``mcap`` itself.

Messages come out in the order ``mcap``'s own reader gives with
``log_time_order=True``: by log time, then by the chunk's place in the file
and the message's place in its chunk.
"""

from __future__ import annotations

import heapq
import io
from collections.abc import Iterator
from typing import IO, Any

from sessiontypes.limits import MCAP_CHUNK

__all__ = ["ChunkTooLargeError", "iter_messages"]

_RECORD_HEAD = 1 + 8  # a record's opcode and length, before its content
_RECORD_SLACK = 2**16  # a chunk record's own fields beyond its data (its compression's name, times, sizes)


class ChunkTooLargeError(ValueError):
    """A chunk larger than the limit, by its declaration or by what it expands to (the reader says
    it to the user as a ``RecordingError``: this is not one of anodize's public errors)."""


def iter_messages(stream: IO[bytes], path: str) -> Iterator[tuple[Any, Any]]:
    """Every ``(channel, message)`` of the MCAP file open as ``stream``, in log-time order.

    Raises:
        ChunkTooLargeError: a chunk is (or says it is) larger than the limit.
        Exception: what ``mcap`` raises for a damaged file.
    """
    from mcap.reader import make_reader

    reader = make_reader(stream)
    summary = reader.get_summary()
    if summary is None or not summary.chunk_indexes:
        yield from _unindexed(stream, path)
        return
    limit = MCAP_CHUNK.bytes()
    # (log time, chunk offset, message's place in it or -1 for a chunk not read yet, tie, item)
    queue: list[tuple[int, int, int, int, Any]] = []
    tie = 0
    chunks: dict[int, Any] = {}
    for index in summary.chunk_indexes:
        chunks.setdefault(index.chunk_start_offset, index)  # a chunk the index lists twice is read once
    for offset, index in chunks.items():
        queue.append((index.message_start_time, offset, -1, tie, index))
        tie += 1
    heapq.heapify(queue)
    held = 0  # bytes of messages read from chunks and not yet given out
    while queue:
        _, offset, place, _, item = heapq.heappop(queue)
        if place >= 0:
            held -= len(item[1].data)
            yield item
            continue
        _check_declared(path, offset, item.uncompressed_size, item.compressed_size, limit)
        if not _RECORD_HEAD < item.chunk_length <= limit + _RECORD_SLACK:
            raise ChunkTooLargeError(f"{_where(path, offset)} has a length of {item.chunk_length} bytes in the "
                                     f"index, which no chunk within the limit of {limit} bytes has "
                                     f"({MCAP_CHUNK.variable} raises the limit)")
        stream.seek(offset + _RECORD_HEAD, io.SEEK_SET)
        record = stream.read(item.chunk_length - _RECORD_HEAD)  # the chunk record, read no further
        for number, (channel, message) in enumerate(_chunk_messages(record, path, offset, limit,
                                                                    summary.channels)):
            held += len(message.data)
            _check_held(path, held, limit)
            heapq.heappush(queue, (message.log_time, offset, number, tie, (channel, message)))
            tie += 1


def _chunk_messages(record: bytes, path: str, offset: int, limit: int,
                    channels: dict[int, Any]) -> Iterator[tuple[Any, Any]]:
    from mcap.data_stream import ReadDataStream
    from mcap.records import Chunk, Message
    from mcap.stream_reader import breakup_chunk

    chunk = Chunk.read(ReadDataStream(io.BytesIO(record)))
    _check_declared(path, offset, chunk.uncompressed_size, len(chunk.data), limit)  # the index may differ
    plain = _decompressed(chunk, path, offset, limit)
    for inner in breakup_chunk(plain):
        if isinstance(inner, Message):
            yield channels[inner.channel_id], inner


def _unindexed(stream: IO[bytes], path: str) -> Iterator[tuple[Any, Any]]:
    """A file without chunk indexes, read through (as ``mcap`` does: sorted whole)."""
    from mcap.records import Channel, Chunk, Message
    from mcap.stream_reader import StreamReader, breakup_chunk

    limit = MCAP_CHUNK.bytes()
    stream.seek(0, io.SEEK_SET)
    channels: dict[int, Any] = {}
    found: list[tuple[Any, Any]] = []
    held = 0  # a file without an index is sorted whole: bounded as the chunks' messages held at once are
    for record in StreamReader(stream, skip_magic=False, emit_chunks=True).records:
        inner_records = [record]
        if isinstance(record, Chunk):
            _check_declared(path, None, record.uncompressed_size, len(record.data), limit)
            inner_records = breakup_chunk(_decompressed(record, path, None, limit))
        for inner in inner_records:
            if isinstance(inner, Channel):
                channels[inner.id] = inner
            elif isinstance(inner, Message):
                found.append((channels[inner.channel_id], inner))
                held += len(inner.data)
                _check_held(path, held, limit)
    found.sort(key=lambda pair: pair[1].log_time)
    return iter(found)


def _check_held(path: str, held: int, limit: int) -> None:
    """Chunks whose times overlap are all open at once to give their messages in log-time order:
    what they hold together is bounded as one chunk is."""
    if held > limit:
        raise ChunkTooLargeError(
            f"{path}: giving the messages in log-time order would hold more than {limit} bytes of them at "
            f"once (chunks whose times overlap, or a file without chunk indexes); {MCAP_CHUNK.variable} "
            "raises the limit")


def _where(path: str, offset: int | None) -> str:
    return f"{path}: the MCAP chunk" + (f" at byte {offset}" if offset is not None else "")


def _check_declared(path: str, offset: int | None, uncompressed: int, compressed: int, limit: int) -> None:
    for size, what in ((uncompressed, "uncompressed"), (compressed, "compressed")):
        if size > limit:
            raise ChunkTooLargeError(
                f"{_where(path, offset)} declares {size} bytes {what}; at most {limit} bytes are read "
                f"per chunk ({MCAP_CHUNK.variable} raises the limit)")


def _decompressed(chunk: Any, path: str, offset: int | None, limit: int) -> Any:
    """``chunk`` with its data decompressed, at most one byte past its declared size."""
    from mcap.records import Chunk

    declared = chunk.uncompressed_size
    most = min(declared, limit) + 1
    if chunk.compression == "zstd":
        import zstandard

        reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data))
        parts: list[bytes] = []
        got = 0
        while got < most:
            part = reader.read(most - got)
            if not part:
                break
            parts.append(part)
            got += len(part)
        data = b"".join(parts)
    elif chunk.compression == "lz4":
        import lz4.frame  # type: ignore[import-untyped]

        data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=most)
    elif chunk.compression == "":
        data = chunk.data
    else:
        from mcap.exceptions import UnsupportedCompressionError

        raise UnsupportedCompressionError(chunk.compression)
    if len(data) > declared:
        raise ChunkTooLargeError(f"{_where(path, offset)} expands beyond the {declared} bytes it declares "
                                 f"(at most {limit} bytes are read per chunk)")
    return Chunk(compression="", data=data, message_end_time=chunk.message_end_time,
                 message_start_time=chunk.message_start_time, uncompressed_crc=0,
                 uncompressed_size=len(data))
