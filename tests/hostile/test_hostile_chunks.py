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
