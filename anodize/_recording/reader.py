"""Reading a recording: an MCAP file, or a rosbag2 folder (MCAP or SQLite storage).

Messages come out in the order of their log time (the recorder's clock), each with its
topic, ROS type, the MCAP channel's metadata (empty where the storage keeps none) and
its sequence number (0 where none was recorded). Nothing here knows protocols.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sessiontypes.limits import RECORDING, RECORDING_METADATA, InputLimit, check_file

from .._extras import import_extra
from ..errors import AnodizeError
from .chain import HEADS_RECORD
from .mcap_chunks import ChunkTooLargeError, iter_messages
from .plan import META

__all__ = ["RecordedTopic", "RecordedMessage", "RecordingError", "open_recording", "Recording"]


class RecordingError(AnodizeError):
    """A recording that cannot be read (the message says which file and why)."""


@dataclass(frozen=True)
class RecordedTopic:
    """One channel of the recording: a topic, its message type, its metadata."""

    topic: str
    type_name: str
    metadata: dict[str, str] = field(default_factory=dict, hash=False, compare=False)
    id: int = 0


@dataclass(frozen=True)
class RecordedMessage:
    topic: RecordedTopic
    log_time: int
    sequence: int
    data: bytes | memoryview
    publish_time: int = -1  # -1: the storage keeps none (the log time stands for it)


class Recording:
    """An open recording: its topics, the ``anodize`` record (if anodize made it), its messages."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.topics: list[RecordedTopic] = []
        self.info: dict[str, str] = {}
        self.chain: dict[str, str] | None = None  # the hash chain's heads record (:mod:`.chain`), if any
        self._files: list[Path] = []
        self._bag: Any = None
        if path.is_dir():
            if not (path / "metadata.yaml").exists():
                raise RecordingError(f"{path}: a folder without metadata.yaml is not a rosbag2 recording")
            self._files = sorted(path.glob("*.mcap"))
            _check_sizes([path / "metadata.yaml"], RECORDING_METADATA)
            _check_sizes(self._files or [f for f in path.iterdir() if f.suffix == ".db3"], RECORDING)
            if not self._files:  # SQLite storage: rosbags reads it (no channel metadata there)
                self._open_bag(path)
        elif path.exists():
            _check_sizes([path], RECORDING)  # a device or a FIFO is refused here, before it is read
            self._files = [path]
        else:
            raise RecordingError(f"{path}: no such file or folder")
        if self._files:
            self._read_summaries()

    def _open_bag(self, path: Path) -> None:
        import_extra("rosbags.rosbag2", "record", "reading a rosbag2 recording")
        from rosbags.rosbag2 import Reader

        try:
            self._bag = Reader(path)
            self._bag.open()
        except Exception as error:  # rosbags raises several kinds for a bad bag
            raise RecordingError(f"{path}: not a readable rosbag2 recording: {error}") from None
        self.topics = [RecordedTopic(c.topic, c.msgtype, {}, c.id) for c in self._bag.connections]

    def _read_summaries(self) -> None:
        import_extra("mcap.reader", "record", "reading an MCAP recording")
        from mcap.reader import make_reader

        for number, file in enumerate(self._files):
            try:
                with file.open("rb") as stream:
                    reader = make_reader(stream)
                    summary = reader.get_summary()
                    if summary is None:
                        raise RecordingError(f"{file}: the MCAP file has no summary (was its writer stopped "
                                             "before the end?)")
                    for channel in summary.channels.values():
                        schema = summary.schemas.get(channel.schema_id)
                        type_name = schema.name if schema is not None else ""
                        self.topics.append(RecordedTopic(channel.topic, type_name, dict(channel.metadata),
                                                         number * 2**16 + channel.id))
                    for record in reader.iter_metadata():
                        if record.name == META:
                            self.info = dict(record.metadata)
                        elif record.name == HEADS_RECORD:
                            self.chain = dict(record.metadata)
            except RecordingError:
                raise
            except Exception as error:  # mcap raises several kinds for a damaged file
                raise RecordingError(f"{file}: not a readable MCAP file: {type(error).__name__}: {error}") from None

    def messages(self) -> Iterator[RecordedMessage]:
        """Every message, in log-time order."""
        if self._bag is not None:
            by_id = {t.id: t for t in self.topics}
            for connection, stamp, data in self._bag.messages():
                yield RecordedMessage(by_id[connection.id], stamp, 0, data)
            return
        yield from self._mcap_messages()

    def _mcap_messages(self) -> Iterator[RecordedMessage]:
        import heapq

        by_id = {t.id: t for t in self.topics}

        def one(number: int, file: Path) -> Iterator[RecordedMessage]:
            with file.open("rb") as stream:
                try:
                    for channel, message in iter_messages(stream, str(file)):
                        yield RecordedMessage(by_id[number * 2**16 + channel.id], message.log_time,
                                              message.sequence, message.data, message.publish_time)
                except ChunkTooLargeError as error:
                    raise RecordingError(str(error)) from None
                except Exception as error:  # a damaged chunk
                    raise RecordingError(f"{file}: cannot read on: {type(error).__name__}: {error}") from None

        yield from heapq.merge(*(one(n, f) for n, f in enumerate(self._files)), key=lambda m: m.log_time)

    def close(self) -> None:
        if self._bag is not None:
            self._bag.close()
            self._bag = None

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _check_sizes(files: list[Path], limit: InputLimit) -> None:
    """Refuse a file of the recording that is not regular or is larger than ``limit``."""
    for file in files:
        try:
            check_file(file, limit)
        except OSError as error:
            raise RecordingError(f"{file}: {error.strerror or error}") from None


def open_recording(path: str | Path) -> Recording:
    """Open an MCAP file or a rosbag2 folder.

    Raises:
        RecordingError: it does not exist or cannot be read.
    """
    return Recording(Path(path))
