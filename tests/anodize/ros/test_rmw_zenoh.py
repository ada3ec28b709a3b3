"""rmw_zenoh's format (``anodize._ros.rmw_zenoh``) against rmw_zenoh's own published examples.

The literal key expressions are copied from ``docs/design.md`` of github.com/ros2/rmw_zenoh at
commit 99a6a2bd10b949052f4f12c5854825dc005e95a5 ("Topic and Service name mapping to Zenoh key
expressions" and "Graph Cache"); the attachment layout is that document's "Publishers" section
(8 + 8 + 1 + 16 bytes). The GID hash is held to the system's libxxhash where it is present
(Debian's libxxhash0), and to digests taken from it, literal here, where it is not.
"""

from __future__ import annotations

import contextlib
import string

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from anodize._ros import ros_type
from anodize._ros.rmw_zenoh import (
    ATTACHMENT_SIZE,
    Attachment,
    Entity,
    RmwQos,
    RmwZenohFormatError,
    TopicInfo,
    dds_type_name,
    encode_attachment,
    entity_gid,
    entity_key,
    parse_attachment,
    parse_entity_key,
    parse_qos,
    qos_text,
    topic_key,
)

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ADD_TWO_INTS_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
LISTENER = "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
LISTENER_SUB = ("@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/"
                f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,10:,:,:,,")
TALKER_PUB = ("@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
              f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,")
SERVER = ("@ros2_lv/2/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/%add_two_ints/"
          f"example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS_HASH}/::,10:,:,:,,")
CLIENT = ("@ros2_lv/2/e1dc8d1b45ae8717fce78689cc655685/0/10/SC/%/%/add_two_ints_client/%add_two_ints/"
          f"example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS_HASH}/::,10:,:,:,,")
DOC_TOKENS = (LISTENER, LISTENER_SUB, TALKER_PUB, SERVER, CLIENT)


def test_data_keys_are_those_of_the_design_document() -> None:
    assert topic_key(0, "/chatter", "std_msgs::msg::dds_::String_", STRING_HASH) == \
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    assert topic_key(0, "/robot1/chatter", "std_msgs::msg::dds_::String_", STRING_HASH) == \
        f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    assert topic_key(2, "/add_two_ints", "example_interfaces::srv::dds_::AddTwoInts_", ADD_TWO_INTS_HASH) == \
        f"2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS_HASH}"


def test_type_name_and_hash_come_out_as_rmw_zenoh_writes_them() -> None:
    """The DDS type name and the RIHS01 hash anodize takes from rosbags equal the document's for std_msgs/String."""
    kind = ros_type("std_msgs/msg/String")
    assert dds_type_name("std_msgs/msg/String") == kind.dds_name == "std_msgs::msg::dds_::String_"
    assert kind.type_hash == STRING_HASH


@pytest.mark.parametrize("token", DOC_TOKENS)
def test_the_documents_tokens_parse_and_format_back(token: str) -> None:
    entity = parse_entity_key(token)
    assert entity_key(entity) == token


def test_a_parsed_token_says_what_the_document_says() -> None:
    talker = parse_entity_key(TALKER_PUB)
    assert (talker.domain, talker.zid, talker.node_id, talker.entity_id, talker.kind) == \
        (2, "8b20917502ee955ac4476e0266340d5c", "0", "10", "MP")
    assert (talker.enclave, talker.namespace, talker.node) == ("/", "/", "talker")
    assert talker.topic == TopicInfo("/chatter", "std_msgs::msg::dds_::String_", STRING_HASH, RmwQos(depth=7))
    listener = parse_entity_key(LISTENER)
    assert listener.kind == "NN" and listener.topic is None and listener.node == "listener"


def test_qos_text_leaves_rmw_zenohs_defaults_empty() -> None:
    assert qos_text(RmwQos()) == "::,:,:,:,,"
    assert qos_text(RmwQos(depth=10)) == "::,10:,:,:,,"
    # The comment of the older liveliness_utils.cpp: best effort, transient local, keep all.
    assert qos_text(RmwQos(reliability=2, durability=1, history=2, depth=10)) == "2:1:2,10:,:,:,,"
    assert RmwQos.of("reliable", "keep_all", 0, "volatile") == RmwQos(history=2)
    assert RmwQos.of("best_effort", "keep_last", 5, "volatile") == RmwQos(reliability=2, depth=5)


def test_the_gid_is_xxh3_128_of_the_token_low_half_first() -> None:
    # Digests taken from libxxhash 0.8 (XXH3_128bits), low64 then high64, little-endian.
    assert entity_gid(TALKER_PUB).hex() == "ac170f31eadcd9ff0cd86d7a17907d1c"
    assert entity_gid(LISTENER).hex() == "49877999dacb858702d11ac823785912"


def test_the_attachment_is_33_bytes_as_the_design_document_lays_them_out() -> None:
    gid = bytes(range(16))
    raw = encode_attachment(Attachment(1, 1_700_000_000_123_456_789, gid))
    assert len(raw) == ATTACHMENT_SIZE == 33
    assert raw[:8] == (1).to_bytes(8, "little")
    assert raw[8:16] == (1_700_000_000_123_456_789).to_bytes(8, "little")
    assert raw[16] == 16 and raw[17:] == gid


def test_the_attachment_is_what_zenohs_own_serializer_writes() -> None:
    """rmw_zenoh writes it with zenoh-cpp's ext::Serializer; zenoh-python's z_serialize is the same format."""
    ext = pytest.importorskip("zenoh.ext")
    gid = bytes(range(100, 116))
    expected = ext.z_serialize((ext.Int64(42), ext.Int64(-5), gid)).to_bytes()
    assert encode_attachment(Attachment(42, -5, gid)) == expected
    assert parse_attachment(expected) == Attachment(42, -5, gid)


chunks = st.text(string.ascii_letters + string.digits + "_", min_size=1, max_size=12)
names = st.lists(chunks, min_size=1, max_size=3).map(lambda parts: "/" + "/".join(parts))
qoses = st.builds(RmwQos, st.sampled_from([0, 1, 2, 3]), st.sampled_from([0, 1, 2, 3]), st.sampled_from([0, 1, 2, 3]),
                  st.integers(0, 2**64 - 1), st.tuples(st.integers(0, 2**40), st.integers(0, 10**9)),
                  st.tuples(st.integers(0, 2**40), st.integers(0, 10**9)), st.sampled_from([0, 1, 3, 4, 5]),
                  st.tuples(st.integers(0, 2**40), st.integers(0, 10**9)))
topics = st.builds(TopicInfo, names, chunks.map(lambda n: f"pkg::msg::dds_::{n}_"),
                   st.text("0123456789abcdef", min_size=64, max_size=64).map(lambda h: "RIHS01_" + h), qoses)


@st.composite
def entities(draw: st.DrawFn) -> Entity:
    kind = draw(st.sampled_from(["NN", "MP", "MS", "SS", "SC"]))
    return Entity(draw(st.integers(0, 232)), draw(st.text("0123456789abcdef", min_size=1, max_size=32)),
                  str(draw(st.integers(0, 99))), str(draw(st.integers(0, 999))), kind,
                  draw(st.sampled_from(["/", "/sros/enclave"])), draw(st.sampled_from(["/", "/robot1", "/a/b"])),
                  draw(chunks), None if kind == "NN" else draw(topics))


@settings(max_examples=100, deadline=None)
@given(entities())
def test_tokens_round_trip(entity: Entity) -> None:
    assert parse_entity_key(entity_key(entity)) == entity


@settings(max_examples=200, deadline=None)
@given(qoses)
def test_qos_round_trips(qos: RmwQos) -> None:
    assert parse_qos(qos_text(qos)) == qos


@settings(max_examples=200, deadline=None)
@given(st.integers(-2**63, 2**63 - 1), st.integers(-2**63, 2**63 - 1), st.binary(min_size=16, max_size=16))
def test_attachments_round_trip(sequence: int, timestamp: int, gid: bytes) -> None:
    attachment = Attachment(sequence, timestamp, gid)
    assert parse_attachment(encode_attachment(attachment)) == attachment


@pytest.mark.parametrize(("token", "reason"), [
    ("", "chunks"),
    ("@ros2_lv/0/z/0/0/NN/%/%", "chunks"),
    ("@other/0/z/0/0/NN/%/%/n", "admin space"),
    ("@ros2_lv/0/z/0/0/XX/%/%/n", "entity kind"),
    ("@ros2_lv/x/z/0/0/NN/%/%/n", "domain"),
    ("@ros2_lv/99999999999999999999999/z/0/0/NN/%/%/n", "domain"),
    ("@ros2_lv/0/z/0/0/NN/%//n", "empty chunk"),
    ("@ros2_lv/0/z/0/0/NN/%/*/n", "wildcard"),
    ("@ros2_lv/0/z/0/0/NN/%/%/n/extra", "a NN has 9"),
    ("@ros2_lv/0/z/0/1/MP/%/%/n/%t/T/H", "a MP has 13"),
    ("@ros2_lv/0/z/0/1/MP/%/%/n/%t/T/H/1:2", "6 parts"),
    ("@ros2_lv/0/z/0/1/MP/%/%/n/%t/T/H/::,:,:,:,", "part 6"),
    ("@ros2_lv/0/z/0/1/MP/%/%/n/%t/T/H/9::,:,:,:,,", "no policy"),
    ("@ros2_lv/0/z/0/1/MP/%/%/n/%t/T/H/::,-1:,:,:,,", "unsigned"),
    ("@ros2_lv/0/z/0/1/MP/%/%/n/%t/T/H/::,99999999999999999999:,:,:,,", "unsigned"),
    ("@ros2_lv/0/" + "z" * 5000 + "/0/0/NN/%/%/n", "at most"),
])
def test_hostile_tokens_are_refused_by_name(token: str, reason: str) -> None:
    with pytest.raises(RmwZenohFormatError, match=reason) as caught:
        parse_entity_key(token)
    assert len(str(caught.value)) < 400  # bounded, whatever came


@pytest.mark.parametrize(("raw", "reason"), [
    (b"", "0 bytes"),
    (bytes(32), "32 bytes"),
    (bytes(34), "34 bytes"),
    (bytes(16) + b"\x0f" + bytes(16), "GID length 15"),
    (bytes(16) + b"\x90" + bytes(16), "GID length 144"),
    (bytes(10**6), "1000000 bytes"),
])
def test_hostile_attachments_are_refused_by_name(raw: bytes, reason: str) -> None:
    with pytest.raises(RmwZenohFormatError, match=reason):
        parse_attachment(raw)


def test_encoding_refuses_what_rmw_zenoh_could_not_read() -> None:
    with pytest.raises(RmwZenohFormatError, match="16 bytes"):
        encode_attachment(Attachment(1, 1, bytes(15)))
    with pytest.raises(RmwZenohFormatError, match="int64"):
        encode_attachment(Attachment(2**63, 1, bytes(16)))


@settings(max_examples=150, deadline=None)
@given(st.one_of(st.text(max_size=300), st.lists(st.sampled_from(
    ["@ros2_lv", "0", "NN", "MP", "%", "", "*", "::,:,:,:,,", "a:b", "é", "\x00"]), max_size=16).map("/".join)))
def test_any_text_either_parses_or_is_refused_by_name(text: str) -> None:
    with contextlib.suppress(RmwZenohFormatError):
        parse_entity_key(text)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=64))
def test_any_bytes_either_parse_or_are_refused_by_name(raw: bytes) -> None:
    with contextlib.suppress(RmwZenohFormatError):
        parse_attachment(raw)
