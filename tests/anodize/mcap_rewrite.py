"""Rewriting a recording message by message: how the tests make a tampered or edited copy."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any


def rewrite(source: Path, target: Path, change: Callable[[list[list[Any]]], None]) -> None:
    """Copy a recording message by message; ``change(messages)`` edits the list of
    ``[channel_key, log_time, sequence, data]`` in place, where ``channel_key`` is
    ``(topic, schema id, metadata items)`` (a new key makes a new channel)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with source.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        schemas = summary.schemas
        messages = [[(c.topic, c.schema_id, tuple(sorted(c.metadata.items()))), m.log_time, m.sequence, m.data]
                    for _, c, m in reader.iter_messages(log_time_order=True)]
        metadata = list(reader.iter_metadata())
    change(messages)
    with target.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros2", library="test")
        ids = {sid: writer.register_schema(s.name, s.encoding, s.data) for sid, s in schemas.items()}
        channels: dict[Any, int] = {}
        for key, log_time, sequence, data in messages:
            if key not in channels:
                channels[key] = writer.register_channel(key[0], "cdr", ids[key[1]], dict(key[2]))
            writer.add_message(channels[key], log_time, data, log_time, sequence)
        for record in metadata:
            writer.add_metadata(record.name, dict(record.metadata))
        writer.finish()
