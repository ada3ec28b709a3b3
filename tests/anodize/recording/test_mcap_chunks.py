"""Reading an MCAP file chunk by chunk within a bound gives the messages ``mcap``'s own reader gives."""

from __future__ import annotations

import io

from budget import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from anodize._recording.mcap_chunks import iter_messages


def _recording(times: list[int], chunk_size: int, compression: str, chunked: bool) -> bytes:
    from mcap.writer import CompressionType, Writer

    stream = io.BytesIO()
    writer = Writer(stream, chunk_size=chunk_size, compression=CompressionType[compression],
                    use_chunking=chunked)
    writer.start(profile="", library="test")
    schema = writer.register_schema("S", "jsonschema", b"{}")
    channels = [writer.register_channel(f"/t{i}", "json", schema) for i in range(2)]
    for sequence, time in enumerate(times):
        writer.add_message(channels[sequence % 2], time, b"{}", time, sequence=sequence)
    writer.finish()
    return stream.getvalue()


@given(st.lists(st.integers(0, 20), max_size=60), st.sampled_from([64, 256, 4096]),
       st.sampled_from(["NONE", "ZSTD", "LZ4"]), st.booleans())
@settings(deadline=None, max_examples=examples(100))
def test_messages_come_in_the_order_mcap_gives(times: list[int], chunk_size: int, compression: str,
                                               chunked: bool) -> None:
    from mcap.reader import make_reader

    data = _recording(times, chunk_size, compression, chunked)
    theirs = [(c.id, m.log_time, m.sequence)
              for _, c, m in make_reader(io.BytesIO(data)).iter_messages(log_time_order=True)]
    ours = [(c.id, m.log_time, m.sequence) for c, m in iter_messages(io.BytesIO(data), "r.mcap")]
    assert ours == theirs
