"""An MCAP chunk is decompressed within a bound (issue 27: unbounded resources).

A chunk's compressed data is small and what it expands to is not: the ``mcap``
library decompressed a chunk whole, into what its zstd frame says (whatever
the chunk declares) or what its lz4 data expands to, so a recording of a few
kilobytes took gigabytes. A chunk that declares more than the limit
(``ANODIZE_MAX_CHUNK_BYTES``) is refused before it is read, and one that
expands beyond what it declares is refused once it has: ``anodize verify``
says which file, the chunk's offset, the sizes and the limit, under an
address-space limit smaller than the bomb.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hostile_inputs import ANODIZE, GOOD_PROTOCOL, MCAP_MAGIC, assert_clean, run_bounded

BOMB = 2 * 2**30  # what the lying chunks expand to: more than the address space the command gets


def _bytes(record: object) -> bytes:
    from mcap.data_stream import RecordBuilder

    builder = RecordBuilder()
    record.write(builder)  # type: ignore[attr-defined]
    return bytes(builder.end())


def _zeros_zstd(size: int) -> bytes:
    """``size`` zero bytes as one zstd frame that says its size (so the frame, not the chunk, is believed)."""
    import io

    import zstandard

    out = io.BytesIO()
    with zstandard.ZstdCompressor(level=1).stream_writer(out, size=size, closefd=False) as writer:
        block = bytes(2**24)
        for _ in range(size // len(block)):
            writer.write(block)
    return out.getvalue()


def _zeros_lz4(size: int) -> bytes:
    import lz4.frame  # type: ignore[import-untyped]

    compressor = lz4.frame.LZ4FrameCompressor()
    block = bytes(2**24)
    return compressor.begin() + b"".join(compressor.compress(block) for _ in range(size // len(block))) + \
        compressor.flush()


def _messages() -> bytes:
    """A chunk's records: the channel and one message."""
    from mcap.records import Channel, Message

    return (_bytes(Channel(id=1, topic="/t", message_encoding="json", metadata={}, schema_id=1))
            + _bytes(Message(channel_id=1, sequence=0, log_time=1, publish_time=1, data=b"{}")))


def chunk_mcap(path: Path, compression: str, data: bytes, declared: int) -> int:
    """Write an MCAP file with one chunk of ``data`` declaring ``declared`` bytes; return the chunk's offset."""
    from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Schema

    head = MCAP_MAGIC + _bytes(Header(profile="", library="hostile"))
    chunk = _bytes(Chunk(compression=compression, data=data, message_start_time=1, message_end_time=1,
                         uncompressed_crc=0, uncompressed_size=declared))
    body = head + chunk + _bytes(DataEnd(data_section_crc=0))
    summary = (_bytes(Schema(id=1, name="S", encoding="jsonschema", data=b"{}"))
               + _bytes(Channel(id=1, topic="/t", message_encoding="json", metadata={}, schema_id=1))
               + _bytes(ChunkIndex(message_start_time=1, message_end_time=1, chunk_start_offset=len(head),
                                   chunk_length=len(chunk), message_index_offsets={}, message_index_length=0,
                                   compression=compression, compressed_size=len(data),
                                   uncompressed_size=declared)))
    footer = _bytes(Footer(summary_start=len(body), summary_offset_start=0, summary_crc=0))
    path.write_bytes(body + summary + footer + MCAP_MAGIC)
    return len(head)


def _verify(folder: Path, env: dict[str, str] | None = None) -> tuple[int, str]:
    (folder / "p.proto").write_text(GOOD_PROTOCOL, encoding="utf-8")
    outcome = run_bounded([*ANODIZE, "verify", "r.mcap", "--protocol", "p.proto"], folder, env)
    assert_clean(outcome)
    return outcome.status, outcome.stderr


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_a_chunk_that_expands_beyond_what_it_declares_is_refused_before_it_has(
        tmp_path: Path, compression: str) -> None:
    data = _zeros_zstd(BOMB) if compression == "zstd" else _zeros_lz4(BOMB)
    offset = chunk_mcap(tmp_path / "r.mcap", compression, data, declared=64)
    assert (tmp_path / "r.mcap").stat().st_size < 16 * 2**20
    status, stderr = _verify(tmp_path)
    assert status == 1
    assert re.search(rf"r\.mcap: the MCAP chunk at byte {offset} expands beyond the 64 bytes it declares "
                     rf"\(at most {256 * 2**20} bytes are read per chunk\)", stderr), stderr


def test_a_chunk_that_declares_more_than_the_limit_is_refused_before_it_is_read(tmp_path: Path) -> None:
    import zstandard

    offset = chunk_mcap(tmp_path / "r.mcap", "zstd", zstandard.ZstdCompressor().compress(_messages()),
                        declared=2**40)
    status, stderr = _verify(tmp_path)
    assert status == 1
    assert (f"r.mcap: the MCAP chunk at byte {offset} declares {2**40} bytes uncompressed; at most "
            f"{256 * 2**20} bytes are read per chunk (ANODIZE_MAX_CHUNK_BYTES raises the limit)") in stderr


@pytest.mark.parametrize("compression", ["", "zstd", "lz4"])
def test_a_chunk_within_the_limit_is_read(tmp_path: Path, compression: str) -> None:
    import lz4.frame
    import zstandard

    plain = _messages()
    data = {"": plain, "zstd": zstandard.ZstdCompressor().compress(plain), "lz4": lz4.frame.compress(plain)}
    chunk_mcap(tmp_path / "r.mcap", compression, data[compression], declared=len(plain))
    limit = max(len(plain), len(data[compression]))  # lz4 makes so small a chunk larger
    _, stderr = _verify(tmp_path, {"ANODIZE_MAX_CHUNK_BYTES": f"{limit}"})
    assert "chunk" not in stderr, stderr  # read (verify then says what it makes of the recording)
    status_over, stderr_over = _verify(tmp_path, {"ANODIZE_MAX_CHUNK_BYTES": f"{limit - 1}"})
    assert status_over == 1
    assert f"at most {limit - 1} bytes are read per chunk" in stderr_over


def test_a_groups_part_file_holding_a_chunk_is_not_decompressed_when_the_run_is_merged(tmp_path: Path) -> None:
    """A group writes its part of the recording itself, so a hostile group can write anything there;
    its recorder never writes a chunk, and merging the parts after the run decompressed one whole."""
    from mcap.records import Channel, Chunk, DataEnd, Header, Message, Schema

    from anodize._recording.merge import merge_parts

    parts = tmp_path / "parts"
    parts.mkdir()
    bomb = _bytes(Chunk(compression="zstd", data=_zeros_zstd(2**27), message_start_time=1, message_end_time=1,
                        uncompressed_crc=0, uncompressed_size=64))
    (parts / "hostile.mcap").write_bytes(
        MCAP_MAGIC + _bytes(Header(profile="", library="hostile"))
        + _bytes(Schema(id=1, name="S", encoding="jsonschema", data=b"{}"))
        + _bytes(Channel(id=1, topic="/t", message_encoding="json", metadata={}, schema_id=1))
        + _bytes(Message(channel_id=1, sequence=0, log_time=1, publish_time=1, data=b"{}"))
        + bomb + _bytes(DataEnd(data_section_crc=0)) + MCAP_MAGIC)
    result = merge_parts(parts, tmp_path / "r.mcap", {"global": "G"})
    assert ("part hostile.mcap holds an MCAP chunk (zstd compressed, 64 bytes declared), which a group's "
            "recorder never writes: the rest of the part was not read") in result.notes, result.notes


def _chunks_mcap(path: Path, count: int, payload: int, *, length: int | None = None, listed: int = 1) -> None:
    """``count`` uncompressed chunks of one ``payload``-byte message each, every chunk starting at
    log time 1 and its message later (their times overlap); the index gives each chunk's length as
    ``length`` if given, and lists each chunk ``listed`` times."""
    from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Message, Schema

    body = MCAP_MAGIC + _bytes(Header(profile="", library="hostile"))
    indexes = b""
    for number in range(count):
        plain = (_bytes(Channel(id=1, topic="/t", message_encoding="json", metadata={}, schema_id=1))
                 + _bytes(Message(channel_id=1, sequence=number, log_time=100 + number, publish_time=1,
                                  data=b"x" * payload)))
        chunk = _bytes(Chunk(compression="", data=plain, message_start_time=1, message_end_time=100 + number,
                             uncompressed_crc=0, uncompressed_size=len(plain)))
        indexes += listed * _bytes(ChunkIndex(
            message_start_time=1, message_end_time=100 + number, chunk_start_offset=len(body),
            chunk_length=len(chunk) if length is None else length, message_index_offsets={},
            message_index_length=0, compression="", compressed_size=len(plain), uncompressed_size=len(plain)))
        body += chunk
    body += _bytes(DataEnd(data_section_crc=0))
    summary = (_bytes(Schema(id=1, name="S", encoding="jsonschema", data=b"{}"))
               + _bytes(Channel(id=1, topic="/t", message_encoding="json", metadata={}, schema_id=1)) + indexes)
    footer = _bytes(Footer(summary_start=len(body), summary_offset_start=0, summary_crc=0))
    path.write_bytes(body + summary + footer + MCAP_MAGIC)


def _read_all(path: Path) -> list[object]:
    from anodize._recording.mcap_chunks import iter_messages

    with path.open("rb") as stream:
        return list(iter_messages(stream, str(path)))


def test_chunks_whose_times_overlap_hold_no_more_messages_at_once_than_one_chunk_may(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every chunk starting at one time must all be open before the first message is given: a
    file of a few kilobytes could otherwise hold a chunk's limit many times over."""
    from anodize._recording.mcap_chunks import ChunkTooLargeError

    _chunks_mcap(tmp_path / "r.mcap", count=10, payload=1000)
    monkeypatch.setenv("ANODIZE_MAX_CHUNK_BYTES", "4000")  # each chunk is within it; the ten are not
    with pytest.raises(ChunkTooLargeError, match="would hold more than 4000 bytes of them at once"):
        _read_all(tmp_path / "r.mcap")
    monkeypatch.setenv("ANODIZE_MAX_CHUNK_BYTES", "20000")
    assert len(_read_all(tmp_path / "r.mcap")) == 10


def test_a_chunk_the_index_lists_twice_is_read_once(tmp_path: Path) -> None:
    _chunks_mcap(tmp_path / "r.mcap", count=3, payload=10, listed=2)
    assert len(_read_all(tmp_path / "r.mcap")) == 3


@pytest.mark.parametrize("length", [0, 2**62])
def test_a_chunk_length_in_the_index_that_no_chunk_within_the_limit_has_is_refused(
        tmp_path: Path, length: int) -> None:
    _chunks_mcap(tmp_path / "r.mcap", count=1, payload=10, length=length)
    status, stderr = _verify(tmp_path)
    assert status == 1
    assert f"has a length of {length} bytes in the index, which no chunk within the limit" in stderr, stderr
