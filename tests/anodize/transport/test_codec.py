"""The cross-process codec and the shared-memory rings, without processes."""

from __future__ import annotations

import contextlib
import enum
import gc
import math
import os
import pickle
import re
import secrets
from dataclasses import dataclass

import numpy as np
import pytest
from budget import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from anodize._transport.codec import HEADER, Codec, DecodeError, EncodeError, FrameKind
from anodize._transport.shm import ArrayRing, RingReader, remove_run_segments

scalars = (st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False)
           | st.text() | st.binary() | st.binary().map(bytearray)
           | st.complex_numbers(allow_nan=False))
hashables = st.recursive(st.none() | st.booleans() | st.integers() | st.text() | st.binary(),
                         lambda inner: st.tuples(inner, inner) | st.frozensets(inner, max_size=3),
                         max_leaves=8)
values = st.recursive(
    scalars,
    lambda inner: (st.lists(inner, max_size=4) | st.tuples(inner, inner)
                   | st.dictionaries(hashables, inner, max_size=4) | st.sets(hashables, max_size=4)
                   | st.frozensets(hashables, max_size=4)),
    max_leaves=20)


def round_trip(codec: Codec, label: str, payload: object) -> tuple[str, object]:
    frame = codec.message_frame(label, payload)
    (length,) = HEADER.unpack_from(frame)
    assert length == len(frame) - 4
    kind, value = codec.decode_body(frame[4:])
    assert kind == FrameKind.MESSAGE
    return value


@settings(max_examples=examples(300), deadline=None)
@given(label=st.text(min_size=1, max_size=20), payload=values)
def test_builtin_values_round_trip_with_their_types(label: str, payload: object) -> None:
    got_label, got = round_trip(Codec(), label, payload)
    assert got_label == label
    assert got == payload
    assert _same_types(got, payload)


def _same_types(a: object, b: object) -> bool:
    if type(a) is not type(b):
        return False
    # b has a's type: testing it too only tells mypy so.
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same_types(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict) and isinstance(b, dict):
        keys = {k: k for k in b}
        return all(_same_types(k, keys[k]) and _same_types(v, b[k]) for k, v in a.items())
    return True


@settings(max_examples=examples(300), deadline=None)
@given(body=st.binary(max_size=64))
def test_arbitrary_bytes_never_decode_into_anything_but_a_decode_error(body: bytes) -> None:
    with contextlib.suppress(DecodeError):
        Codec().decode_body(body)


@settings(max_examples=examples(200), deadline=None)
@given(payload=values, cut=st.integers(min_value=1, max_value=40))
def test_a_truncated_frame_is_a_decode_error(payload: object, cut: int) -> None:
    body = Codec().message_frame("l", payload)[4:]
    if cut < len(body):
        with pytest.raises(DecodeError):
            Codec().decode_body(body[:-cut])


def test_a_failure_frame_carries_its_cause() -> None:
    frame = Codec.failure_frame("MemoryBoundError: too big")
    assert Codec().decode_body(frame[4:]) == (FrameKind.FAILURE, "MemoryBoundError: too big")


@dataclass(frozen=True)
class Pose:
    x: float
    y: float
    covariance: np.ndarray

    def __post_init__(self) -> None:
        Pose.constructed += 1

    constructed = 0


class Plain:
    def __init__(self, value: int) -> None:
        self.value = value


class Evil:
    def __reduce__(self) -> tuple[object, tuple[str]]:
        return (os.system, ("echo pwned",))


def test_named_dataclasses_are_rebuilt_field_by_field_without_running_init() -> None:
    codec = Codec([Pose])
    pose = Pose(1.0, 2.5, np.eye(3))
    before = Pose.constructed
    _, got = round_trip(codec, "pose", pose)
    assert Pose.constructed == before
    assert isinstance(got, Pose) and (got.x, got.y) == (1.0, 2.5)
    assert np.array_equal(got.covariance, np.eye(3)) and got.covariance.dtype == np.float64


def test_classes_the_protocol_does_not_name_are_refused_on_both_sides() -> None:
    with pytest.raises(EncodeError, match="Plain"):
        Codec().message_frame("x", [Plain(1)])
    body = Codec([Pose]).message_frame("pose", Pose(0.0, 0.0, np.zeros(1)))[4:]
    with pytest.raises(DecodeError, match="not named by the protocol"):
        Codec().decode_body(body)


def test_named_plain_classes_are_pickled_and_unpickling_loads_nothing_else() -> None:
    _, got = round_trip(Codec([Plain]), "p", Plain(7))
    assert isinstance(got, Plain) and got.value == 7
    # A frame claiming to hold a Plain but carrying a pickle that would call os.system:
    name = f"{Plain.__module__}:{Plain.__qualname__}".encode()
    evil = pickle.dumps(Evil())
    import struct
    payload = bytes([19]) + struct.pack("<I", len(name)) + name + struct.pack("<I", len(evil)) + evil
    body = bytes([FrameKind.MESSAGE]) + struct.pack("<I", 1) + b"p" + payload
    with pytest.raises(DecodeError, match=r"posix\.system|os\.system|does not name"):
        Codec([Plain]).decode_body(body)


def test_numpy_values_keep_dtype_shape_and_content() -> None:
    codec = Codec()
    for array in (np.arange(12, dtype=np.int16).reshape(3, 4), np.zeros((0, 5)),
                  np.asfortranarray(np.random.default_rng(1).random((4, 3))),
                  np.arange(10)[::3], np.array(3.5, dtype=np.float32)):
        _, got = round_trip(codec, "a", array)
        assert got.dtype == array.dtype and got.shape == array.shape
        assert np.array_equal(got, array)
    _, scalar = round_trip(codec, "s", np.float32(1.5))
    assert scalar == np.float32(1.5) and type(scalar) is np.float32
    with pytest.raises(EncodeError, match="object"):
        codec.message_frame("o", np.array([object()]))


def test_non_finite_floats_survive() -> None:
    _, got = round_trip(Codec(), "f", [math.inf, -math.inf, math.nan])
    assert got[0] == math.inf and got[1] == -math.inf and math.isnan(got[2])


@pytest.fixture
def ring_prefix():
    run = f"test{secrets.token_hex(4)}"
    yield f"anodize-{run}-c"
    remove_run_segments(run)


def test_large_arrays_travel_as_views_of_slots_released_when_the_last_view_dies(ring_prefix) -> None:
    ring = ArrayRing(ring_prefix, slots=2)
    sender, receiver = Codec(ring=ring), Codec(read_array=RingReader().read)
    image = np.random.default_rng(0).integers(0, 255, (480, 640, 3), dtype=np.uint8)
    frame = sender.message_frame("image", image)
    assert len(frame) < 200  # only the slot's address crossed
    _, (_, got) = receiver.decode_body(frame[4:])
    assert np.array_equal(got, image) and ring.in_use() == 1
    view = got[10:20, ::2]
    del got
    gc.collect()
    assert ring.in_use() == 1  # a view still reads the slot
    del view
    gc.collect()
    assert ring.in_use() == 0


def test_a_sender_with_every_slot_held_waits_and_gives_up_when_told_the_peer_is_gone(ring_prefix) -> None:
    gone: list[str] = []
    ring = ArrayRing(ring_prefix, slots=2, peer_gone=lambda: gone[0] if gone else None)
    reader = RingReader()
    receiver = Codec(read_array=reader.read)
    sender = Codec(ring=ring)
    held = [receiver.decode_body(sender.message_frame("a", np.ones(100_000))[4:])[1][1] for _ in range(2)]
    assert ring.in_use() == 2
    gone.append("receiver failed")
    with pytest.raises(BrokenPipeError, match="receiver failed"):
        ring.write(np.ones(100_000))
    del held


def test_a_ring_grows_for_bigger_arrays_and_the_reader_rejects_forged_addresses(ring_prefix) -> None:
    ring = ArrayRing(ring_prefix, slots=2)
    reader = RingReader()
    small = ring.write(np.ones(100_000, dtype=np.uint8))
    big = ring.write(np.ones(3_000_000, dtype=np.uint8))
    assert small[0] != big[0]  # a new generation
    assert reader.read(*big, "|u1", (3_000_000,)).sum() == 3_000_000
    with pytest.raises(ValueError, match=r"^slot 1 at offset \d+ is not a filled slot of ring "):
        reader.read(big[0], 1, big[2], "|u1", (10,))  # slot 1 was never filled
    with pytest.raises(ValueError, match=r"^ring '\.\./etc/passwd' does not belong to this channel$"):
        reader.read("../etc/passwd", 0, 4096, "|u1", (1,))


def test_an_array_filled_in_a_claimed_slot_is_sent_without_a_copy_and_handed_over(ring_prefix) -> None:
    ring = ArrayRing(ring_prefix, slots=2)
    sender, receiver = Codec(ring=ring), Codec(read_array=RingReader().read)
    image = ring.claim_array((480, 640, 3), np.uint8)
    image[:] = 7
    address = image.__array_interface__["data"][0]
    _, (_, got) = receiver.decode_body(sender.message_frame("image", image)[4:])
    assert got.__array_interface__["data"][0] != 0 and int(got.sum()) == 7 * image.size
    assert not image.flags.writeable  # the slot is the receiver's now
    assert ring.in_use() == 1
    unsent = ring.claim_array((10,), np.float64)
    assert unsent.__array_interface__["data"][0] != address
    assert ring.in_use() == 2
    del unsent
    gc.collect()
    assert ring.in_use() == 1  # a claimed slot never sent comes back
    del got
    gc.collect()
    assert ring.in_use() == 0


def test_garbage_in_a_named_pickle_a_missing_field_or_a_missing_ring_is_a_decode_error(ring_prefix) -> None:
    import struct

    def body(tag: int, name: bytes, rest: bytes) -> bytes:
        return (bytes([FrameKind.MESSAGE]) + struct.pack("<I", 1) + b"p" + bytes([tag])
                + struct.pack("<I", len(name)) + name + rest)

    plain = f"{Plain.__module__}:{Plain.__qualname__}".encode()
    with pytest.raises(DecodeError):
        Codec([Plain]).decode_body(body(19, plain, struct.pack("<I", 3) + b"\x80\x05\xff"))
    pose = Codec([Pose]).message_frame("pose", Pose(1.0, 2.0, np.zeros(2)))[4:]
    fewer = pose.replace(struct.pack("<I", 3), struct.pack("<I", 2), 1)  # claims 2 fields of 3
    with pytest.raises(DecodeError):
        Codec([Pose]).decode_body(fewer)
    reader = RingReader()
    shared = Codec(ring=ArrayRing(ring_prefix)).message_frame("a", np.ones(100_000))[4:]
    remove_run_segments(ring_prefix.split("-")[1])
    with pytest.raises(DecodeError):
        Codec(read_array=reader.read).decode_body(shared)


def test_a_reader_maps_only_its_channels_rings_and_each_slot_once(ring_prefix) -> None:
    ring = ArrayRing(ring_prefix + "x", slots=2)
    address = ring.write(np.ones(100_000))
    other_channel = RingReader()
    with pytest.raises(ValueError, match="does not belong"):
        other_channel.read(*address, "<f8", (100_000,), prefix=ring_prefix + "y")
    reader = RingReader()
    first = reader.read(*address, "<f8", (100_000,), prefix=ring_prefix)
    with pytest.raises(ValueError, match=r"^slot \d+ at offset \d+ is not a filled slot of ring "):  # still viewed
        reader.read(*address, "<f8", (100_000,), prefix=ring_prefix)
    assert first.sum() == 100_000


def _gives_up_after(seconds: float):
    import time

    deadline = time.monotonic() + seconds
    return lambda: "test deadline: the slot never came back" if time.monotonic() > deadline else None


def test_a_sent_buffer_collected_late_does_not_free_a_newer_claim_of_its_slot(ring_prefix) -> None:
    ring = ArrayRing(ring_prefix, slots=1, peer_gone=_gives_up_after(5.0))
    reader = RingReader()
    sender, receiver = Codec(ring=ring), Codec(read_array=reader.read)
    left = ring.claim_array((1000,), np.uint8)
    _, (_, got) = receiver.decode_body(sender.message_frame("a", left)[4:])
    del got
    gc.collect()  # the receiver released the slot; the sender still holds `left`
    right = ring.claim_array((1000,), np.uint8)
    del left
    gc.collect()  # left's finalizer must not free right's claim
    assert ring.in_use() == 1
    right[:] = 1
    assert ring._sent_in_place(right) is not None


def test_an_ndarray_sort_still_travels_as_an_array() -> None:
    _, got = round_trip(Codec([np.ndarray]), "image", np.arange(6).reshape(2, 3))
    assert isinstance(got, np.ndarray) and got.tolist() == [[0, 1, 2], [3, 4, 5]]


# ---- pickle on the wire (issue 11) ------------------------------------------------------------
def pickled_body(cls_name: str, data: bytes, label: bytes = b"p") -> bytes:
    """A message body whose payload claims to be a pickled ``cls_name`` and carries ``data``."""
    import struct

    name = cls_name.encode()
    return (bytes([FrameKind.MESSAGE]) + struct.pack("<I", len(label)) + label + bytes([19])
            + struct.pack("<I", len(name)) + name + struct.pack("<I", len(data)) + data)


def name_of(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


class Other:
    def __init__(self, value: int) -> None:
        self.value = value


SET_STATE_RAN: list[object] = []


@dataclass
class Flagged:
    """A dataclass whose unpickling would show: __init__ and __setstate__ leave a mark."""

    value: int

    def __post_init__(self) -> None:
        SET_STATE_RAN.append("init")

    def __setstate__(self, state: object) -> None:
        SET_STATE_RAN.append(state)


# PROTO 5, NONE, LONG_BINPUT 2**27, STOP: the unpickler would grow its memo to 2**28 slots (2 GiB).
MEMO_BOMB = b"\x80\x05N" + b"r" + (2**27).to_bytes(4, "little") + b"."


@pytest.mark.parametrize("codec", [Codec([Plain]), Codec()], ids=["Plain named", "nothing named"])
def test_a_memo_index_bomb_is_refused_without_allocating(codec: Codec) -> None:
    import resource
    import tracemalloc

    body = pickled_body(name_of(Plain), MEMO_BOMB)
    assert len(body) < 60
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB
    tracemalloc.start()
    try:
        with pytest.raises(DecodeError, match=r"memo index 134217728 out of sequence|not named by the protocol"):
            codec.decode_body(body)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2**20
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss_before < 100 * 2**10


def test_a_codec_without_pickled_classes_never_unpickles() -> None:
    harmless = pickle.dumps([1, 2, 3], protocol=5)  # loads no class: the old unpickler took it
    for codec in (Codec(), Codec([Pose])):  # nothing, or only a dataclass, named
        with pytest.raises(DecodeError, match=r"^pickled payload class 'test_codec:Plain' is not named by the "
                                              r"protocol; nothing travels pickled on this channel$"):
            codec.decode_body(pickled_body(name_of(Plain), harmless))
    with pytest.raises(DecodeError, match=r"^pickled payload class 'builtins:dict' never travels pickled "
                                          r"\(it has its own tag\)$"):
        Codec([dict]).decode_body(pickled_body("builtins:dict", pickle.dumps({}, protocol=5)))


def test_a_frame_naming_one_class_carrying_another_is_refused() -> None:
    codec = Codec([Plain, Other])
    with pytest.raises(DecodeError, match=r"^pickled payload of class 'test_codec:Plain' refused: it refers to "
                                          r"test_codec\.Other, not to the payload's class$"):
        codec.decode_body(pickled_body(name_of(Plain), pickle.dumps(Other(1), protocol=5)))
    with pytest.raises(DecodeError, match="does not hold exactly one instance"):  # data, not a Plain
        codec.decode_body(pickled_body(name_of(Plain), pickle.dumps([1, 2], protocol=5)))
    _, got = round_trip(codec, "o", Other(5))
    assert isinstance(got, Other) and got.value == 5


def test_a_dataclass_never_arrives_pickled_and_none_of_its_code_runs() -> None:
    codec = Codec([Flagged])
    data = pickle.dumps(Flagged(1), protocol=5)
    SET_STATE_RAN.clear()
    with pytest.raises(DecodeError, match=r"^pickled payload class 'test_codec:Flagged' never travels pickled "
                                          r"\(a dataclass travels field by field\)$"):
        codec.decode_body(pickled_body(name_of(Flagged), data))
    assert SET_STATE_RAN == []
    frame = codec.message_frame("f", Flagged(2))  # as it does travel: field by field, no code of its own
    SET_STATE_RAN.clear()
    _, got = codec.decode_body(frame[4:])[1]
    assert isinstance(got, Flagged) and got.value == 2 and SET_STATE_RAN == []


def test_the_control_channel_refuses_pickle() -> None:
    from anodize._supervision.control import ControlTag, decode_control

    go = pickle.dumps((int(ControlTag.GO),), protocol=5)  # a well-formed Go, had it been unpickled
    with pytest.raises(DecodeError, match="nothing travels pickled on this channel"):
        decode_control(pickled_body(name_of(Plain), go, label=b"control"))
    with pytest.raises(DecodeError, match="nothing travels pickled on this channel"):
        decode_control(pickled_body(name_of(Plain), MEMO_BOMB, label=b"control"))


class Slotted:
    __slots__ = ("a", "b")

    def __init__(self, a: int, b: object) -> None:
        self.a, self.b = a, b


class Shade(enum.Enum):
    DARK = 1


class Bag(list[int]):
    pass


class Holder:
    def __init__(self) -> None:
        self.data = [1, 2.5, "x", b"b", None, True, (1, 2, 3, 4), {1, 2}, frozenset({3}),
                     bytearray(b"q"), 10**30, {"k": [1]}, -(2**70)]
        self.me = self
        self.kids = [Holder.__new__(Holder) for _ in range(3)]


@pytest.mark.parametrize("value", [Plain(7), Slotted(1, "b"), Shade.DARK, Bag([1, 2]), Holder()],
                         ids=lambda v: type(v).__name__)
def test_what_plain_classes_pickle_to_passes_the_scan(value: object) -> None:
    _, got = round_trip(Codec([type(value)]), "v", value)
    assert type(got) is type(value)
    if isinstance(value, Holder):
        assert got.me is got and got.data == value.data and len(got.kids) == 3
    if isinstance(value, Bag):
        assert got == [1, 2]


class Tampering:
    def __reduce__(self) -> tuple[object, ...]:
        import collections

        return (collections.OrderedDict, ())


def test_a_sender_whose_pickle_refers_to_another_class_is_refused_at_the_sender() -> None:
    with pytest.raises(EncodeError, match=r"^cannot send a pickled Tampering: it refers to "
                                          r"collections\.OrderedDict, not to the payload's class$"):
        Codec([Tampering]).message_frame("t", Tampering())


STR = lambda text: b"\x8c" + bytes([len(text)]) + text.encode()  # noqa: E731 (SHORT_BINUNICODE)


@pytest.mark.parametrize(("data", "reason"), [
    # BUILD on the class itself would set class attributes in the receiver.
    (b"\x80\x05" + STR("test_codec") + STR("Plain") + b"\x93" + b"N}" + STR("x") + b"Ks" + b"\x86b.",
     "BUILD of something other than an instance of the payload's class"),
    # A frame claiming more bytes than there are.
    (b"\x80\x05\x95" + (2**40).to_bytes(8, "little") + b"N.", "a frame of 1099511627776 bytes, more than"),
    # A bytearray crossing its frame's end (CPython 3.11's unpickler then frees it while exported).
    (b"\x80\x05\x95" + (5).to_bytes(8, "little") + b"\x96" + (1).to_bytes(8, "little") + b"q.",
     "an opcode crosses the end of its frame at byte 16"),
    # A BINBYTES claiming 2 GiB: refused without reading (or allocating) them.
    (b"\x80\x05B" + (2**31).to_bytes(4, "little") + b"x.", "malformed pickle: expected 2147483648 bytes"),
    # Opcodes of older protocols and of other machinery.
    (b"cos\nsystem\n(S'echo pwned'\ntR.", "pickle protocol 0 or 1 (only 2 to 5)"),
    (b"\x80\x05" + b"cos\nsystem\n.", "it refers to os.system, not to the payload's class"),
    (b"\x80\x05" + b"\x82\x01.", "opcode EXT1 is not allowed"),
    (b"\x80\x05" + b"N" + b"Q.", "opcode BINPERSID is not allowed"),
    (b"\x80\x05" + b"\x97.", "opcode NEXT_BUFFER is not allowed"),
    # REDUCE of something that is not the class; a memo read of nothing.
    (b"\x80\x05" + STR("x") + b")R.", "REDUCE of something other than the payload's class"),
    (b"\x80\x05h\x00.", "memo index 0 was never stored"),
    # Bytes after the end; a huge int.
    (b"\x80\x05" + STR("test_codec") + STR("Plain") + b"\x93)\x81.junk", "4 bytes after the pickle's end"),
    (b"\x80\x05\x8b" + (4096).to_bytes(4, "little") + b"\x01" * 4096 + b".", "an int of more than 2048 bytes"),
])
def test_the_scan_refuses_what_a_plain_pickle_never_holds(data: bytes, reason: str) -> None:
    with pytest.raises(DecodeError, match=re.escape(reason)):
        Codec([Plain]).decode_body(pickled_body(name_of(Plain), data))


@settings(max_examples=examples(300), deadline=None)
@given(position=st.integers(min_value=0), value=st.integers(min_value=0, max_value=255))
def test_a_mutated_pickle_is_refused_or_is_still_one_plain(position: int, value: int) -> None:
    data = bytearray(pickle.dumps(Plain(7), protocol=5))
    data[position % len(data)] = value
    try:
        _, (_, got) = Codec([Plain]).decode_body(pickled_body(name_of(Plain), bytes(data)))
    except DecodeError:
        return
    assert type(got) is Plain


def _decode_one_by_one(codec: Codec, stream: bytes) -> list[object]:
    found: list[object] = []
    at = 0
    while len(stream) - at >= 4:
        (length,) = HEADER.unpack_from(stream, at)
        if len(stream) - at - 4 < length:
            break
        try:
            found.append(codec.decode_body(stream[at + 4:at + 4 + length]))
        except DecodeError as error:
            found.append(("error", str(error)))
        at += 4 + length
    return found


def _decode_with_runs(codec: Codec, stream: bytes) -> list[object]:
    """As PipeReceiver does: runs of small messages at once, anything else one by one."""
    from collections import deque

    buffer, at, found = bytearray(stream), 0, []
    ready: deque[tuple[object, int]] = deque()
    while True:
        at = codec.decode_run(buffer, at, ready)
        found.extend((FrameKind.MESSAGE, item) for item, _ in ready)
        ready.clear()
        if len(buffer) - at < 4 or len(buffer) - at - 4 < HEADER.unpack_from(buffer, at)[0]:
            return found
        (length,) = HEADER.unpack_from(buffer, at)
        try:
            found.append(codec.decode_body(bytes(buffer[at + 4:at + 4 + length])))
        except DecodeError as error:
            found.append(("error", str(error)))
        at += 4 + length


frames = st.one_of(
    st.tuples(st.sampled_from(["num", "stop", "é"]), st.none() | st.integers(-2**63, 2**63 - 1)).map(
        lambda lp: Codec().message_frame(*lp)),
    st.tuples(st.sampled_from(["num", "other"]), values).map(lambda lp: Codec().message_frame(*lp)),
    st.text(max_size=10).map(Codec.failure_frame),
    st.binary(max_size=12).map(lambda b: HEADER.pack(len(b)) + b),  # garbage, in a frame
)


@settings(max_examples=examples(200))
@given(stream=st.lists(frames, max_size=30).map(b"".join), cut=st.integers(0, 30))
def test_decoding_runs_of_small_messages_gives_what_decoding_each_frame_gives(stream: bytes, cut: int) -> None:
    stream = stream[:len(stream) - cut] if cut < len(stream) else stream  # a last frame may be incomplete
    runs, each = Codec(), Codec()
    _decode_one_by_one(runs, stream)  # labels are learnt by decoding them once, as in a receiver
    assert _decode_with_runs(runs, stream) == _decode_one_by_one(each, stream)
