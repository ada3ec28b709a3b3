"""The receiver's hot loop: the compiled ``decode_run`` against its pure-Python reference.

Both must take exactly the same frames from any bytes (a peer's bytes are hostile), and a
run between processes must work on either: ``ANODIZE_PURE_PYTHON=1`` makes a group's
process use the reference.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import sys
import sysconfig
import threading
from collections import deque
from pathlib import Path
from typing import Any

import pytest
from budget import examples
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parents[1]))

import send_many_roles

import sessiontypes
from anodize import Processes, System
from anodize._transport import frames
from anodize._transport.codec import HEADER, Codec, FrameKind, Tag

try:
    from anodize._transport._frames import SmallFrameWriter as CompiledWriter
    from anodize._transport._frames import decode_run as compiled_run
except ImportError:
    compiled_run = None
    CompiledWriter = None

CAN_BUILD = shutil.which("cc") is not None and Path(sysconfig.get_paths()["include"], "Python.h").exists()
needs_compiled = pytest.mark.skipif(compiled_run is None, reason="anodize was installed without a C compiler "
                                    "or Python's headers, so the compiled decoder was not built")
NAMES = {b"num": "num", b"stop": "stop", "é".encode(): "é"}

STREAM = sessiontypes.loads("global S(A, B) = mu t. A -> B : { num(int). t, fin }", "s.proto").globals["S"]


def test_the_compiled_loop_is_built_wherever_it_can_be() -> None:
    """The extension is optional only for machines without a compiler: here it must be there."""
    if not CAN_BUILD:
        pytest.skip("this machine has no C compiler or no Python headers: the extension is optional there")
    assert compiled_run is not None
    assert (os.environ.get("ANODIZE_PURE_PYTHON", "") in ("", "0")) == frames.COMPILED


def test_the_reference_shares_the_codecs_constants() -> None:
    assert (frames._MESSAGE, frames._NONE, frames._INT) == (FrameKind.MESSAGE, Tag.NONE, Tag.INT)


small = st.tuples(st.sampled_from(["num", "stop", "é", "unknown"]),
                  st.none() | st.integers(-2**63, 2**63 - 1)).map(lambda lp: Codec().message_frame(*lp))
other = st.tuples(st.sampled_from(["num", "stop"]), st.floats() | st.text(max_size=3) | st.integers(2**63, 2**70)
                  ).map(lambda lp: Codec().message_frame(*lp))
garbage = st.one_of(
    st.binary(max_size=16).map(lambda b: HEADER.pack(len(b)) + b),  # any body, framed
    st.binary(max_size=16),  # not even framed
    # A message frame whose label length runs past the frame, or up to its very end.
    st.tuples(st.integers(0, 2**32 - 1), st.binary(max_size=10)).map(
        lambda nb: HEADER.pack(5 + len(nb[1])) + b"M" + nb[0].to_bytes(4, "little") + nb[1]),
    st.text(max_size=8).map(Codec.failure_frame),
)


@st.composite
def crafted(draw: st.DrawFn) -> bytes:
    """A message frame of a known label, with any tag and payload, and lengths a little off."""
    label = draw(st.sampled_from(list(NAMES)))
    body = (b"M" + ((len(label) + draw(st.sampled_from([0, 0, 0, -1, 1, 2**31]))) % 2**32).to_bytes(4, "little")
            + label + bytes([draw(st.sampled_from([Tag.NONE, Tag.INT, Tag.TRUE, Tag.FLOAT]) | st.integers(0, 255))])
            + draw(st.sampled_from([0, 1, 7, 8, 9]).flatmap(lambda n: st.binary(min_size=n, max_size=n))))
    return HEADER.pack(max(0, len(body) + draw(st.sampled_from([0, 0, 0, -1, 1])))) + body


@needs_compiled
@settings(max_examples=examples(300))
@given(stream=st.lists(st.one_of(small, small, other, garbage, crafted()), max_size=20).map(b"".join),
       cut=st.integers(0, 12))
def test_the_compiled_loop_takes_what_the_reference_takes(stream: bytes, cut: int) -> None:
    buffer = bytearray(stream[:max(0, len(stream) - cut)])
    assert compiled_run is not None
    for start in range(len(buffer) + 1):  # a run stops at the first frame it leaves: start at each byte
        expected: deque[tuple[object, int]] = deque()
        got: deque[tuple[object, int]] = deque()
        assert compiled_run(buffer, start, NAMES, got) == frames.decode_run_python(buffer, start, NAMES, expected)
        assert list(got) == list(expected)
        for (mine, _), (theirs, _) in zip(got, expected, strict=True):  # the same types, not just equal values
            assert [type(x) for x in mine] == [type(x) for x in theirs]  # type: ignore[attr-defined]


def _frame(label: bytes, tag: int, payload: bytes = b"", label_size: int | None = None, extra: int = 0) -> bytes:
    body = b"M" + (len(label) if label_size is None else label_size).to_bytes(4, "little") + label + bytes([tag])
    return HEADER.pack(len(body + payload) + extra) + body + payload


EDGES = {  # frames one byte or one tag away from those a run takes
    "none": _frame(b"num", Tag.NONE), "int": _frame(b"num", Tag.INT, (-5).to_bytes(8, "little", signed=True)),
    "true": _frame(b"num", Tag.TRUE), "none and a byte": _frame(b"num", Tag.NONE, b"\0"),
    "int of 7 bytes": _frame(b"num", Tag.INT, b"\1" * 7), "int of 9 bytes": _frame(b"num", Tag.INT, b"\1" * 9),
    "float": _frame(b"num", Tag.FLOAT, b"\0" * 8), "unknown label": _frame(b"nun", Tag.NONE),
    "label past the frame": _frame(b"num", Tag.NONE, label_size=5),
    "label of 2**32-1": _frame(b"num", Tag.NONE, label_size=2**32 - 1),
    "length one short": _frame(b"num", Tag.NONE, extra=-1), "length one long": _frame(b"num", Tag.NONE, extra=1),
    "failure": Codec.failure_frame("x"), "empty label": _frame(b"", Tag.NONE),
}


@needs_compiled
@pytest.mark.parametrize("edge", EDGES)
def test_the_compiled_loop_treats_each_edge_as_the_reference_does(edge: str) -> None:
    small_one = Codec().message_frame("stop", 7)
    assert compiled_run is not None
    for buffer in (bytearray(EDGES[edge]), bytearray(small_one + EDGES[edge] + small_one)):
        expected: deque[tuple[object, int]] = deque()
        got: deque[tuple[object, int]] = deque()
        names = {**NAMES, b"": ""}
        assert compiled_run(buffer, 0, names, got) == frames.decode_run_python(buffer, 0, names, expected)
        assert list(got) == list(expected)


@needs_compiled
def test_the_compiled_loop_refuses_what_the_reference_refuses() -> None:
    assert compiled_run is not None
    for run in (compiled_run, frames.decode_run_python):
        with pytest.raises(ValueError, match="negative"):
            run(bytearray(b"\0" * 8), -1, NAMES, deque())
    with pytest.raises(TypeError):
        compiled_run(bytearray(), 0, [], deque())  # names must be a dict
    with pytest.raises(TypeError):
        compiled_run("not bytes", 0, NAMES, deque())


@needs_compiled
def test_a_failing_append_stops_the_compiled_loop_with_its_error() -> None:
    class Full(deque):  # type: ignore[type-arg]
        def append(self, item: object) -> None:
            raise OverflowError("full")

    frame = Codec().message_frame("num", 1)
    assert compiled_run is not None
    with pytest.raises(OverflowError, match="full"):
        compiled_run(bytearray(frame * 3), 0, NAMES, Full())


@pytest.mark.slow
@pytest.mark.parametrize("pure", [False, True])
def test_a_stream_between_processes_arrives_whole_with_either_decoder(
        pure: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    if not pure and not frames.COMPILED:
        pytest.skip("the compiled decoder is not in use here (not built, or ANODIZE_PURE_PYTHON is set)")
    if pure:
        monkeypatch.setenv("ANODIZE_PURE_PYTHON", "1")
    else:
        monkeypatch.delenv("ANODIZE_PURE_PYTHON", raising=False)
    monkeypatch.setenv("SEND_MANY_OUT", str(tmp_path / "got.json"))
    system = System(STREAM, transport=Processes())
    system.group("a").role("A", "send_many_roles:batch_sender")  # one write for many frames: runs to decode
    system.group("b").role("B", "send_many_roles:frames_receiver")
    report = system.run(timeout=60)
    assert report.ok, report.summary()
    result = json.loads((tmp_path / "got.json").read_text())
    assert result == {"compiled": not pure, "got": list(range(send_many_roles.COUNT))}


def _pipe_bytes(put_items: Any, items: list[tuple[str, object]]) -> bytes:
    """What ``put_items`` writes for ``items`` into a fresh pipe, read back whole."""
    read, write = os.pipe()
    chunks: list[bytes] = []

    def drain() -> None:  # concurrently: a batch may be larger than the pipe
        while chunk := os.read(read, 65536):
            chunks.append(chunk)

    reader = threading.Thread(target=drain)
    reader.start()
    try:
        put_items(write, items)
    finally:
        os.close(write)
        reader.join()
        os.close(read)
    return b"".join(chunks)


@needs_compiled
@settings(max_examples=examples(200))
@given(st.lists(st.tuples(st.sampled_from(["num", "stop", "é", "x" * 5000]),
                          st.none() | st.integers(-2**70, 2**70) | st.booleans() | st.floats(allow_nan=False)
                          | st.text(max_size=3)), max_size=30))
def test_the_compiled_writer_writes_the_frames_the_codec_builds(items: list[tuple[str, object]]) -> None:
    """Small ints and no payload in C (once the codec has cached the label's frame), the rest by
    the fallback: the bytes in the pipe are the codec's frames, in order."""
    assert CompiledWriter is not None

    def compiled(fd: int, items: list[tuple[str, object]]) -> None:
        codec = Codec()

        def fallback(item: object) -> None:
            label, payload = item  # type: ignore[misc]
            os.write(fd, codec.message_frame(label, payload))

        write = CompiledWriter(fd, *codec.small_frames(), fallback)
        for item in items:
            write(item)

    def reference(fd: int, items: list[tuple[str, object]]) -> None:
        codec = Codec()
        for label, payload in items:
            os.write(fd, codec.message_frame(label, payload))

    assert _pipe_bytes(compiled, items) == _pipe_bytes(reference, items)


@needs_compiled
def test_the_compiled_writer_takes_a_cached_label_itself_and_hands_on_the_rest() -> None:
    assert CompiledWriter is not None
    codec = Codec()
    handed: list[object] = []
    read, write = os.pipe()
    writer = CompiledWriter(write, *codec.small_frames(), handed.append)
    writer(("num", 1))  # the codec has not built this label's prefix yet
    codec.message_frame("num", 0)
    codec.message_frame("num", None)
    writer(("num", 2))
    writer(("num", None))
    writer(("num", 2**63))  # too big for 8 bytes
    writer(("num", True))  # a bool is not an int here, as in the codec
    writer(["num", 3])  # not a tuple
    assert handed == [("num", 1), ("num", 2**63), ("num", True), ["num", 3]]
    os.close(write)
    assert os.read(read, 1000) == codec.message_frame("num", 2) + codec.message_frame("num", None)
    os.close(read)
    # A write that fails (the read end is gone) goes to the fallback, which reports it its way.
    gone_read, gone_write = os.pipe()
    os.close(gone_read)
    failed: list[object] = []

    def report(item: object) -> None:
        failed.append(item)
        raise ConnectionError("the receiver is gone")

    with pytest.raises(ConnectionError, match="receiver is gone"):
        CompiledWriter(gone_write, *codec.small_frames(), report)(("num", 5))
    assert failed == [("num", 5)]
    os.close(gone_write)


@needs_compiled
@settings(max_examples=examples(200))
@given(st.lists(st.tuples(st.sampled_from(["num", "stop", "new"]),
                          st.none() | st.integers(-2**64, 2**64) | st.just(1.5)), max_size=40),
       st.integers(0, 45), st.integers(0, 5000))
def test_the_compiled_batch_writes_the_run_of_cached_small_frames(
        items: list[tuple[str, object]], start: int, repeat: int) -> None:
    """``write_many`` takes the items from ``start`` while their frames are cached (ints of 8
    bytes or no payload, labels the codec has built), in writes of at most 64 KiB."""
    assert CompiledWriter is not None
    codec = Codec()
    for label in ("num", "stop"):  # "new" has never been sent: not cached
        codec.message_frame(label, 0)
        codec.message_frame(label, None)
    items = items * (200 if repeat > 2500 else 1)  # some batches larger than one write of 64 KiB
    start = min(start, len(items))
    taken: list[int] = []

    def write_many(fd: int, items: list[tuple[str, object]]) -> None:
        result = CompiledWriter(fd, *codec.small_frames(), lambda item: None).write_many(items, start)
        taken.append(result[0])
        assert result[1] == 0

    written = _pipe_bytes(write_many, items)
    run = 0
    for label, payload in items[start:]:
        if label == "new" or not (payload is None or (type(payload) is int and -2**63 <= payload < 2**63)):
            break
        run += 1
    assert taken == [run]
    assert written == b"".join(codec.message_frame(label, payload) for label, payload in items[start:start + run])


@needs_compiled
def test_a_failed_batch_write_says_why_and_how_many_frames_went() -> None:
    assert CompiledWriter is not None
    codec = Codec()
    codec.message_frame("num", 0)
    read, write = os.pipe()
    os.close(read)
    taken, error = CompiledWriter(write, *codec.small_frames(), lambda item: None).write_many([("num", 1)] * 10, 0)
    os.close(write)
    assert (taken, error) == (0, errno.EPIPE)
