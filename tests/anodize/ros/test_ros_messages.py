"""ROS 2 message types (anodize._ros): checks, CDR against Cyclone DDS's own encoder, hashes, decoding
garbage, and ROS messages crossing processes."""

from __future__ import annotations

import re
import secrets
import sys
from typing import Any

import numpy as np
import pytest
from budget import examples
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

pytest.importorskip("rosbags", reason="ROS 2 message types need the ros extra")

import ros_roles  # after the skip: it resolves ROS types
from rosbags.typesys import Stores, get_typestore

import anodize
import sessiontypes
from anodize import AnodizeError, ProtocolViolationError
from anodize._ros import DEFAULT_DISTRO, RosDecodeError, RosEncodeError, RosType, ros_type
from anodize._ros import messages as ros_messages
from anodize._session.payloads import exact_types_for, validator_for
from anodize._transport.codec import Codec, DecodeError, EncodeError, FrameKind
from anodize._transport.shm import ArrayRing, RingReader, remove_run_segments

STORE = get_typestore(Stores.ROS2_JAZZY)  # the definitions, read independently of anodize._ros
TINMAN = ["sensor_msgs/msg/Joy", "geometry_msgs/msg/Twist", "geometry_msgs/msg/PoseStamped", "nav_msgs/msg/Path",
          "sensor_msgs/msg/Image", "std_msgs/msg/Header"]
# Beside TinMan's: fixed arrays, bounded strings and sequences, bool, byte and char kinds.
MORE = ["sensor_msgs/msg/CameraInfo", "geometry_msgs/msg/PoseWithCovariance", "shape_msgs/msg/SolidPrimitive",
        "rmw_dds_common/msg/NodeEntitiesInfo", "rcl_interfaces/msg/ParameterValue",
        "rcl_interfaces/msg/ParameterDescriptor", "rmw_dds_common/msg/Gid", "std_msgs/msg/Byte",
        "std_msgs/msg/Char", "std_msgs/msg/Empty", "std_msgs/msg/String"]
TYPES = TINMAN + MORE

BASE, NAME, ARRAY, SEQUENCE = 1, 2, 3, 4  # rosbags.interfaces.Nodetype
RANGES = {"int8": (-128, 127), "uint8": (0, 255), "int16": (-2**15, 2**15 - 1), "uint16": (0, 2**16 - 1),
          "int32": (-2**31, 2**31 - 1), "uint32": (0, 2**32 - 1), "int64": (-2**63, 2**63 - 1),
          "uint64": (0, 2**64 - 1), "char": (0, 255), "byte": (-128, 127)}
DTYPES = {**{kind: kind for kind in RANGES}, "char": "uint8", "byte": "int8", "bool": "bool",
          "float32": "float32", "float64": "float64"}
Path, PoseStamped, Pose = (ros_type(n).cls for n in ("nav_msgs/msg/Path", "geometry_msgs/msg/PoseStamped",
                                                       "geometry_msgs/msg/Pose"))
Point, Quaternion, Vector3 = (ros_type(n).cls for n in ("geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion",
                                                        "geometry_msgs/msg/Vector3"))
Header, Time, Joy = (ros_type(n).cls for n in ("std_msgs/msg/Header", "builtin_interfaces/msg/Time",
                                               "sensor_msgs/msg/Joy"))


# ---- values of a type, from its definition --------------------------------------------------------

def scalars(kind: str, bound: int = 0) -> st.SearchStrategy[Any]:
    if kind in RANGES:
        return st.integers(*RANGES[kind])
    if kind == "float32":
        return st.floats(width=32, allow_nan=False)
    if kind == "float64":
        return st.floats(allow_nan=False)
    if kind == "bool":
        return st.booleans()
    # NUL ends a string for DDS; a bound counts bytes of UTF-8
    text = st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=12)
    return text.filter(lambda s: len(s.encode()) <= bound) if bound else text


def messages(name: str) -> st.SearchStrategy[Any]:
    """Valid values of message ``name``: what rosbags decodes (numpy arrays for primitive arrays)."""
    fields = {}
    for field_name, (node, detail) in STORE.fielddefs[name][1]:
        if node == BASE:
            fields[field_name] = scalars(*detail)
        elif node == NAME:
            fields[field_name] = st.deferred(lambda d=detail: messages(d))
        else:
            (item_node, item), count = detail
            size = {"min_size": count, "max_size": count} if node == ARRAY else {"max_size": min(count or 3, 3)}
            if item_node == NAME:
                fields[field_name] = st.lists(messages(item), **size)
            elif item[0] in DTYPES:
                shape = st.integers(size.get("min_size", 0), size["max_size"] + (5 if node == SEQUENCE and not count
                                                                                  else 0)).map(lambda n: (n,))
                fields[field_name] = hnp.arrays(np.dtype(DTYPES[item[0]]), shape, elements=scalars(item[0]))
            else:
                fields[field_name] = st.lists(scalars(*item), **size)
    return st.builds(STORE.types[name], **fields)


def assert_same(a: Any, b: Any, where: str = "") -> None:
    """Field by field: the same classes, numpy arrays of the same dtype and items, equal scalars."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        assert isinstance(a, np.ndarray) and isinstance(b, np.ndarray), where
        assert a.dtype == b.dtype and np.array_equal(a, b), where
    elif hasattr(type(a), "__msgtype__"):
        assert type(a) is type(b), where
        for field_name, _ in STORE.fielddefs[type(a).__msgtype__][1]:
            assert_same(getattr(a, field_name), getattr(b, field_name), f"{where}.{field_name}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for index, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{index}]")
    else:
        assert type(a) is type(b) and a == b, where


def to_idl(name: str, value: Any) -> Any:
    """The Cyclone DDS instance holding ``value`` (rosbags' signed bytes as the octets they are)."""
    def member(description: tuple[Any, Any], item: Any) -> Any:
        node, detail = description
        if node == NAME:
            return to_idl(detail, item)
        if node == BASE:
            return item % 256 if detail[0] == "byte" else item
        return [member(detail[0], x) for x in (item.tolist() if isinstance(item, np.ndarray) else item)]
    fields = {f: member(d, getattr(value, f)) for f, d in STORE.fielddefs[name][1]}
    return ros_type(name).idl_class()(**fields)


@pytest.fixture(scope="module")
def cyclone() -> None:
    pytest.importorskip("cyclonedds.idl", reason="the cross-check needs the Cyclone DDS binding")


# ---- resolving --------------------------------------------------------------------------------------

def test_a_type_is_resolved_once_per_name_and_distro_with_ros_2_names() -> None:
    twist = ros_type("geometry_msgs/msg/Twist")
    assert ros_type("ros:geometry_msgs/msg/Twist") is twist and twist.distro == DEFAULT_DISTRO == "jazzy"
    assert (twist.name, twist.dds_name) == ("geometry_msgs/msg/Twist", "geometry_msgs::msg::dds_::Twist_")
    assert twist.cls is STORE.types["geometry_msgs/msg/Twist"]
    humble = ros_type("geometry_msgs/msg/Twist", "humble")
    assert humble is not twist and humble.distro == "humble" and humble != twist
    assert repr(twist).startswith("RosType(name='geometry_msgs/msg/Twist', distro='jazzy', cls=<class ")


@pytest.mark.parametrize(("name", "distro", "message"), [
    ("geometry_msgs/msg/Twister", None, "ROS 2 jazzy has no message type 'geometry_msgs/msg/Twister'"),
    ("std_srvs/srv/Trigger", None,
     "ROS 2 jazzy has no message type 'std_srvs/srv/Trigger' (a sort names a message: pkg/msg/Name)"),
    ("geometry_msgs/msg/Twist", "rolling", "unknown ROS 2 distribution 'rolling'; rosbags knows dashing, "),
])
def test_an_unknown_type_or_distro_is_named(name: str, distro: str | None, message: str) -> None:
    with pytest.raises(AnodizeError, match=f"^{re.escape(message)}"):
        ros_type(name, distro)


def test_without_rosbags_the_error_says_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ros_messages, "_STORES", {})
    monkeypatch.setattr(ros_messages, "_TYPES", {})
    monkeypatch.setitem(sys.modules, "rosbags.typesys", None)  # import fails
    expected = "install it with: pip install 'anodize[ros]'"
    with pytest.raises(AnodizeError, match=re.escape(expected)):
        ros_type("geometry_msgs/msg/Twist")


def test_a_ros_sort_is_checked_by_the_monitor() -> None:
    (sort,) = sessiontypes.loads('type T = "ros:geometry_msgs/msg/Twist"\nglobal G(A, B) = A -> B : t(T)',
                                 "t.proto").sorts.values()
    twist = ros_type("geometry_msgs/msg/Twist")
    assert exact_types_for(sort) == frozenset()
    check = validator_for(sort)
    assert check(ros_roles.twist()) is None
    assert check(Vector3(1.0, 2.0, 3.0)) == "expected geometry_msgs/msg/Twist, got geometry_msgs/msg/Vector3"
    assert check == twist.check


# ---- (a) checks ----------------------------------------------------------------------------------

@pytest.mark.parametrize("name", TYPES)
def test_valid_values_fit(name: str) -> None:
    ros = ros_type(name)

    @settings(max_examples=examples(30), deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(value=messages(name))
    def fits(value: Any) -> None:
        assert ros.check(value) is None

    fits()


def header(sec: int = 1) -> Any:
    return Header(stamp=Time(sec=sec, nanosec=0), frame_id="map")


def pose() -> Any:
    return Pose(position=Point(1.0, 2.0, 3.0), orientation=Quaternion(0.0, 0.0, 0.0, 1.0))


def pose_stamped(**changes: Any) -> Any:
    return PoseStamped(**{"header": header(), "pose": pose(), **changes})


def camera_info(**changes: Any) -> Any:
    cls = ros_type("sensor_msgs/msg/CameraInfo").cls
    roi = ros_type("sensor_msgs/msg/RegionOfInterest").cls(0, 0, 640, 480, False)
    fields = {"header": header(), "height": 480, "width": 640, "distortion_model": "plumb_bob", "d": np.zeros(5),
              "k": np.eye(3).ravel(), "r": [0.0] * 9, "p": np.zeros(12), "binning_x": 0, "binning_y": 0, "roi": roi}
    return cls(**{**fields, **changes})


WRONG = [  # (type, value, the whole reason)
    ("sensor_msgs/msg/Joy", Joy(header=header(2**32), axes=[], buttons=[]),
     "field header.stamp.sec: expected int32 (-2**31..2**31-1), got 4294967296"),
    ("sensor_msgs/msg/Joy", Joy(header=header(), axes=["fast", "slow"], buttons=[]),
     "field axes[0]: expected float32, got str 'fast'"),
    ("sensor_msgs/msg/Joy", Joy(header=header(), axes=np.zeros(2), buttons=[]),
     "field axes: expected a sequence of float32, got ndarray of float64"),
    ("sensor_msgs/msg/Joy", Joy(header=header(), axes=[1.0, 1e39], buttons=[]),
     "field axes[1]: expected float32 (at most 3.4028235e+38 in magnitude), got 1e+39"),
    ("sensor_msgs/msg/Joy", Joy(header=header(), axes=[], buttons=(1, True)),
     "field buttons[1]: expected int32 (-2**31..2**31-1), got bool True"),
    ("sensor_msgs/msg/Joy", Joy(header=Time(sec=0, nanosec=0), axes=[], buttons=[]),
     "field header: expected std_msgs/msg/Header, got builtin_interfaces/msg/Time"),
    ("sensor_msgs/msg/Joy", Joy(header=header(), axes="1.0", buttons=[]),
     "field axes: expected a sequence of float32, got str '1.0'"),
    ("geometry_msgs/msg/Twist", Vector3(1.0, 2.0, 3.0),
     "expected geometry_msgs/msg/Twist, got geometry_msgs/msg/Vector3"),
    ("geometry_msgs/msg/Twist", {"linear": Vector3(0.0, 0.0, 0.0)}, "expected geometry_msgs/msg/Twist, got dict"),
    ("geometry_msgs/msg/Twist", ros_type("geometry_msgs/msg/Twist").cls(Vector3("1", 0.0, 0.0), Vector3(0.0, 0.0, 0.0)),
     "field linear.x: expected float64, got str '1'"),
    ("geometry_msgs/msg/Twist", ros_type("geometry_msgs/msg/Twist").cls(Vector3(0.0, 0.0, 0.0), Point(0.0, 0.0, 0.0)),
     "field angular: expected geometry_msgs/msg/Vector3, got geometry_msgs/msg/Point"),
    ("geometry_msgs/msg/PoseStamped", pose_stamped(pose=Point(0.0, 0.0, 0.0)),
     "field pose: expected geometry_msgs/msg/Pose, got geometry_msgs/msg/Point"),
    ("nav_msgs/msg/Path", Path(header=header(), poses=[pose_stamped(), pose_stamped(header=header(-2**31 - 1))]),
     "field poses[1].header.stamp.sec: expected int32 (-2**31..2**31-1), got -2147483649"),
    ("nav_msgs/msg/Path", Path(header=header(), poses=[pose_stamped(), pose()]),
     "field poses[1]: expected geometry_msgs/msg/PoseStamped, got geometry_msgs/msg/Pose"),
    ("nav_msgs/msg/Path", Path(header=header(), poses=pose_stamped()),
     "field poses: expected a sequence of geometry_msgs/msg/PoseStamped, got geometry_msgs/msg/PoseStamped"),
    ("sensor_msgs/msg/Image", ros_roles.Image(header=header(), height=-1, width=1, encoding="mono8", is_bigendian=0,
                                              step=1, data=np.zeros(1, np.uint8)),
     "field height: expected uint32 (0..2**32-1), got -1"),
    ("sensor_msgs/msg/Image", ros_roles.Image(header=header(), height=480, width=640, encoding="rgb8",
                                              is_bigendian=0, step=1920, data=np.zeros((480, 640, 3), np.uint8)),
     "field data: expected a 1-D sequence of uint8, got ndarray of shape (480, 640, 3)"),
    ("sensor_msgs/msg/Image", ros_roles.Image(header=header(), height=1, width=1, encoding="mono8", is_bigendian=0,
                                              step=1, data=np.zeros(1, np.int16)),
     "field data: expected a sequence of uint8, got ndarray of int16"),
    ("sensor_msgs/msg/Image", ros_roles.Image(header=header(), height=1, width=1, encoding=b"mono8", is_bigendian=0,
                                              step=1, data=b"\x00"),
     "field encoding: expected string, got bytes b'mono8'"),
    ("sensor_msgs/msg/CameraInfo", camera_info(k=np.zeros(8)), "field k: expected 9 items (float64[9]), got 8"),
    ("sensor_msgs/msg/CameraInfo", camera_info(r=[0.0] * 10), "field r: expected 9 items (float64[9]), got 10"),
    ("sensor_msgs/msg/CameraInfo", camera_info(d=np.zeros(5, np.float32)),
     "field d: expected a sequence of float64, got ndarray of float32"),
    ("sensor_msgs/msg/CameraInfo", camera_info(d=None), "field d: expected a sequence of float64, got None"),
    ("geometry_msgs/msg/PoseWithCovariance",
     ros_type("geometry_msgs/msg/PoseWithCovariance").cls(pose=pose(), covariance=np.zeros(35)),
     "field covariance: expected 36 items (float64[36]), got 35"),
    ("shape_msgs/msg/SolidPrimitive", ros_type("shape_msgs/msg/SolidPrimitive").cls(
        type=1, dimensions=[1.0, 2.0, 3.0, 4.0], polygon=ros_type("geometry_msgs/msg/Polygon").cls(points=[])),
     "field dimensions: expected at most 3 items (float64[<=3]), got 4"),
    ("rmw_dds_common/msg/NodeEntitiesInfo", ros_type("rmw_dds_common/msg/NodeEntitiesInfo").cls(
        node_namespace="/", node_name="é" * 129, reader_gid_seq=[], writer_gid_seq=[]),
     "field node_name: expected string<=256 (at most 256 bytes of UTF-8), got a str of 258 bytes"),
    ("std_msgs/msg/String", ros_type("std_msgs/msg/String").cls(data="\ud800"),
     "field data: expected string (text UTF-8 can encode), got str '\\ud800'"),
    ("std_msgs/msg/Byte", ros_type("std_msgs/msg/Byte").cls(data=200),
     "field data: expected byte (-128..127, as rosbags holds a byte), got 200"),
    ("rcl_interfaces/msg/ParameterValue", ros_type("rcl_interfaces/msg/ParameterValue").cls(
        type=0, bool_value=1, integer_value=0, double_value=0.0, string_value="", byte_array_value=b"",
        bool_array_value=[], integer_array_value=[], double_array_value=[], string_array_value=[]),
     "field bool_value: expected bool, got int 1"),
]


@pytest.mark.parametrize(("name", "value", "reason"), WRONG, ids=[reason.split(":")[0] for _, _, reason in WRONG])
def test_a_value_that_does_not_fit_is_refused_naming_the_field(name: str, value: Any, reason: str) -> None:
    ros = ros_type(name)
    assert ros.check(value) == reason
    with pytest.raises(RosEncodeError, match=f"^{re.escape(f'cannot encode a {name}: {reason}')}$"):
        ros.serialize(value)


def test_what_fits_besides_numpy_arrays_of_rosbags_dtypes() -> None:
    joy = ros_type("sensor_msgs/msg/Joy")
    image = ros_type("sensor_msgs/msg/Image")
    lists = Joy(header=header(), axes=[1, 2.5, np.float32(3.0)], buttons=(np.int64(1), 2))
    assert joy.check(lists) is None
    assert_same(joy.deserialize(joy.serialize(lists)),
                Joy(header=header(), axes=np.array([1, 2.5, 3], np.float32), buttons=np.array([1, 2], np.int32)))
    assert type(lists.axes) is list  # serialising converted a copy, not the caller's message
    raw = ros_roles.Image(header=header(), height=1, width=3, encoding="mono8", is_bigendian=0, step=3,
                          data=b"\x01\x02\x03")
    strided = ros_roles.Image(header=header(), height=1, width=3, encoding="mono8", is_bigendian=0, step=3,
                              data=np.arange(6, dtype=np.uint8)[1::2])
    assert image.check(raw) is None and image.check(strided) is None
    assert image.deserialize(image.serialize(raw)).data.tolist() == [1, 2, 3]
    assert image.deserialize(image.serialize(strided)).data.tolist() == [1, 3, 5]
    nan = Joy(header=header(), axes=[float("nan"), float("inf")], buttons=[])
    assert joy.check(nan) is None


def another_message(name: str) -> Any:
    """An instance of a message class other than ``name``'s."""
    return Time(sec=0, nanosec=0) if name != "builtin_interfaces/msg/Time" else ros_type("std_msgs/msg/Empty").cls()


# Mutations of one field, by what the field is: (description) -> [(wrong value, path suffix)].
def wrong_values(description: tuple[Any, Any], value: Any) -> list[tuple[Any, str]]:
    node, detail = description
    if node == BASE:
        kind, bound = detail
        if kind in RANGES:
            low, high = RANGES[kind]
            return [(high + 1, ""), (low - 1, ""), ("1", ""), (1.0, "")]
        if kind.startswith("float"):
            return [("1.5", ""), (None, ""), (True, "")] + ([(1e39, "")] if kind == "float32" else [])
        if kind == "bool":
            return [(1, ""), (None, "")]
        return [(b"text", ""), (1, "")] + ([("x" * (bound + 1), "")] if bound else [])
    if node == NAME:
        return [(another_message(detail), ""), (None, "")]
    (item_node, item), count = detail
    wrong: list[tuple[Any, str]] = [(7, "")]
    if count and len(value):  # one item too many
        wrong.append((list(value) + [value[0]] * (count + 1 - len(value)), ""))
    if item_node == NAME:
        wrong.append(([another_message(item)] * max(len(value), 1), "[0]"))
    elif item[0] in DTYPES:
        other = "complex64" if item[0] != "complex64" else "float64"
        wrong.append((np.zeros(len(value), other), ""))
        wrong.append((np.zeros((len(value) or 1, 2), DTYPES[item[0]]), ""))
        wrong.append((["x"] * max(len(value), 1), "[0]"))
    else:
        wrong.append(([b"x"] * max(len(value), 1), "[0]"))
    return wrong


def leaves(name: str, value: Any, path: str = "") -> list[tuple[str, Any, str, tuple[Any, Any]]]:
    """Every field under ``value``: (path, owner, attribute, description)."""
    found = []
    for field_name, description in STORE.fielddefs[name][1]:
        here = f"{path}.{field_name}" if path else field_name
        found.append((here, value, field_name, description))
        node, detail = description
        if node == NAME:
            found += leaves(detail, getattr(value, field_name), here)
        elif node in (ARRAY, SEQUENCE) and detail[0][0] == NAME:
            for index, item in enumerate(getattr(value, field_name)):
                found += leaves(detail[0][1], item, f"{here}[{index}]")
    return found


@pytest.mark.parametrize("name", TYPES)
def test_one_wrong_field_is_refused_with_its_path(name: str) -> None:
    ros = ros_type(name)

    @settings(max_examples=examples(25), deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(value=messages(name), data=st.data())
    def refused(value: Any, data: st.DataObject) -> None:
        path, owner, attr, description = data.draw(st.sampled_from(leaves(name, value)))
        original = getattr(owner, attr)
        wrong, below = data.draw(st.sampled_from(wrong_values(description, original)))
        setattr(owner, attr, wrong)
        reason = ros.check(value)
        assert reason is not None and reason.startswith(f"field {path}{below}"), (path, wrong, reason)
        with pytest.raises(RosEncodeError):
            ros.serialize(value)
        setattr(owner, attr, original)
        assert ros.check(value) is None

    refused()


# ---- (b) the bytes ROS 2 publishes ----------------------------------------------------------------

@pytest.mark.parametrize("name", TYPES)
def test_cdr_is_what_cyclone_dds_encodes_and_decodes_back(name: str, cyclone: None) -> None:
    ros = ros_type(name)
    idl = ros.idl_class()
    assert idl.__idl_typename__ == ros.dds_name  # type: ignore[attr-defined]

    @settings(max_examples=examples(25), deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(value=messages(name))
    def same_bytes(value: Any) -> None:
        data = ros.serialize(value)
        assert data[:4] == b"\x00\x01\x00\x00"  # XCDR1, little endian
        assert data == to_idl(name, value).serialize(use_version_2=False)
        assert_same(ros.deserialize(data), value)

    same_bytes()


def test_idl_classes_name_nested_types_as_ros_2_does(cyclone: None) -> None:
    path = ros_type("nav_msgs/msg/Path").idl_class()
    assert ros_type("nav_msgs/msg/Path").idl_class() is path
    hints = path.__annotations__
    assert hints["header"] is ros_type("std_msgs/msg/Header").idl_class()
    assert hints["header"].__idl_typename__ == "std_msgs::msg::dds_::Header_"
    assert "geometry_msgs::msg::dds_::PoseStamped_" in repr(ros_type("geometry_msgs/msg/PoseStamped").idl_class())
    assert path.__idl__.get_type_info() is not None  # the XTypes information Cyclone advertises


# ---- (c) type hashes ------------------------------------------------------------------------------

@pytest.mark.parametrize("name", TYPES)
def test_type_hash_is_rosbags_rihs01(name: str) -> None:
    assert re.fullmatch(r"RIHS01_[0-9a-f]{64}", ros_type(name).type_hash)
    assert ros_type(name).type_hash == STORE.hash_rihs01(name)


def test_type_hash_of_std_msgs_string_is_the_one_ros_2_jazzy_publishes() -> None:
    assert ros_type("std_msgs/msg/String").type_hash == (
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18")


# ---- (d) decoding anything ---------------------------------------------------------------------------

@pytest.mark.parametrize("name", TYPES)
def test_decoding_garbage_raises_ros_decode_error_only(name: str) -> None:
    ros = ros_type(name)

    @settings(max_examples=examples(60), deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(data=st.binary(max_size=64) | st.binary(max_size=60).map(lambda b: b"\x00\x01\x00\x00" + b))
    def decodes_or_refuses(data: bytes) -> None:
        try:
            value = ros.deserialize(data)
        except RosDecodeError as error:
            refused = error
        else:
            assert ros.check(value) is None
            return
        assert str(refused).startswith(f"cannot decode a {name}: ")

    decodes_or_refuses()


@pytest.mark.parametrize("name", TYPES)
def test_truncated_or_damaged_messages_raise_ros_decode_error_only(name: str) -> None:
    ros = ros_type(name)

    @settings(max_examples=examples(25), deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(value=messages(name), data=st.data())
    def refuses(value: Any, data: st.DataObject) -> None:
        whole = ros.serialize(value)
        cut = data.draw(st.integers(0, len(whole) - 1))
        with pytest.raises(RosDecodeError):
            ros.deserialize(whole[:cut])
        damaged = bytearray(whole)
        for _ in range(data.draw(st.integers(1, 4))):
            damaged[data.draw(st.integers(0, len(whole) - 1))] = data.draw(st.integers(0, 255))
        try:
            decoded = ros.deserialize(memoryview(damaged))
        except RosDecodeError:
            pass
        else:
            assert ros.check(decoded) is None

    refuses()


@pytest.mark.parametrize(("name", "data", "reason"), [
    ("sensor_msgs/msg/Joy", b"", "SerdeError: Invalid or unsupported CDR encapsulation."),
    ("sensor_msgs/msg/Joy", b"\x00\x01\x00\x00" + bytes(8) + b"\x01\x00\x00\x00\x00" + bytes(3) + b"\xff\xff\xff\xff",
     "SerdeError: Invalid sequence length 4294967295 at offset 20."),
    ("nav_msgs/msg/Path", b"\x00\x01\x00\x00" + bytes(8) + b"\x01\x00\x00\x00\x00" + bytes(3) + b"\xff\xff\xff\x7f",
     "SerdeError: Invalid sequence length 2147483647 at offset 20."),
    ("std_msgs/msg/String", b"\x00\x01\x00\x00\x03\x00\x00\x00\xff\xfe\x00",
     ("SerdeError: Could not deserialize 'std_msgs/msg/String': 'utf-8' codec can't decode byte 0xff in "
      "position 0: invalid start byte")),
    ("shape_msgs/msg/SolidPrimitive", ros_type("shape_msgs/msg/SolidPrimitive").serialize(
        ros_type("shape_msgs/msg/SolidPrimitive").cls(type=1, dimensions=[1.0, 2.0, 3.0],
                                                      polygon=ros_type("geometry_msgs/msg/Polygon").cls(points=[])))
     .replace(b"\x03\x00\x00\x00", b"\x02\x00\x00\x00", 1),
     "SerdeError: CDR message size mismatch for 'shape_msgs/msg/SolidPrimitive'."),
])
def test_huge_lengths_and_bad_text_are_refused_with_a_reason(name: str, data: bytes, reason: str) -> None:
    with pytest.raises(RosDecodeError, match=f"^{re.escape(f'cannot decode a {name}: {reason}')}$") as caught:
        ros_type(name).deserialize(data)
    assert (caught.value.type_name, caught.value.reason) == (name, reason)


def test_a_decoded_sequence_over_its_bound_is_refused() -> None:
    solid = ros_type("shape_msgs/msg/SolidPrimitive")
    three = solid.serialize(solid.cls(type=1, dimensions=[1.0, 2.0, 3.0],
                                      polygon=ros_type("geometry_msgs/msg/Polygon").cls(points=[])))
    # the count 3 is the 4 bytes after the type (a uint8, padded to 4); 4 items need 8 more bytes
    four = three[:8] + b"\x04\x00\x00\x00" + three[12:36] + bytes(8) + three[36:]
    with pytest.raises(RosDecodeError, match=re.escape(
            "cannot decode a shape_msgs/msg/SolidPrimitive: field dimensions: expected at most 3 items "
            "(float64[<=3]), got 4")):
        solid.deserialize(four)


# ---- the codec: ROS messages as CDR, large ones through shared memory --------------------------------

def frame_round_trip(sender: Codec, receiver: Codec, payload: object) -> Any:
    frame = sender.message_frame("m", payload)
    kind, (label, got) = receiver.decode_body(frame[4:])
    assert (kind, label) == (FrameKind.MESSAGE, "m")
    return got


@pytest.fixture
def ring_prefix():
    run = f"test{secrets.token_hex(4)}"
    yield f"anodize-{run}-c"
    remove_run_segments(run)


def test_the_codec_carries_ros_messages_as_cdr(ring_prefix: str) -> None:
    twist, image = ros_type("geometry_msgs/msg/Twist"), ros_type("sensor_msgs/msg/Image")
    codec = Codec(ros_types=[twist, image])
    frame = codec.message_frame("cmd", ros_roles.twist())
    assert twist.serialize(ros_roles.twist()) in frame
    assert frame_round_trip(codec, codec, ros_roles.twist()) == ros_roles.twist()
    small = ros_roles.Image(header=header(), height=1, width=2, encoding="mono8", is_bigendian=0, step=2,
                            data=np.array([7, 9], np.uint8))
    got = frame_round_trip(codec, codec, small)
    assert_same(got, small)
    assert got.data.flags.writeable  # a private copy
    ring = ArrayRing(ring_prefix, slots=2)
    sender, receiver = Codec(ring=ring, ros_types=[image]), Codec(read_array=RingReader().read, ros_types=[image])
    frame = sender.message_frame("frame", ros_roles.image())
    assert len(frame) < 200  # the CDR went through shared memory
    got = receiver.decode_body(frame[4:])[1][1]
    assert ros_roles.same_image(got, ros_roles.image()) and not got.data.flags.writeable  # a view of the slot


def test_the_codec_refuses_ros_messages_the_protocol_does_not_name() -> None:
    twist, image = ros_type("geometry_msgs/msg/Twist"), ros_type("sensor_msgs/msg/Image")
    with pytest.raises(EncodeError, match=r"^cannot carry a rosbags\..*\.geometry_msgs__msg__Twist across processes"):
        Codec(ros_types=[image]).message_frame("cmd", ros_roles.twist())
    body = Codec(ros_types=[twist]).message_frame("cmd", ros_roles.twist())[4:]
    with pytest.raises(DecodeError, match=r"^ROS message type 'jazzy:geometry_msgs/msg/Twist' is not named by the "
                                          r"protocol$"):
        Codec(ros_types=[image]).decode_body(body)
    humble = Codec(ros_types=[ros_type("geometry_msgs/msg/Twist", "humble")])  # the same rosbags class
    with pytest.raises(DecodeError, match=r"^ROS message type 'humble:geometry_msgs/msg/Twist' is not named"):
        Codec(ros_types=[twist]).decode_body(humble.message_frame("cmd", ros_roles.twist())[4:])


def test_a_corrupt_ros_message_is_a_decode_error(ring_prefix: str) -> None:
    codec = Codec(ros_types=[ros_type("std_msgs/msg/String")])
    body = bytearray(codec.message_frame("s", ros_type("std_msgs/msg/String").cls(data="hello"))[4:])
    body[-3] = 0xFF  # inside the text
    with pytest.raises(DecodeError, match=r"^cannot decode a std_msgs/msg/String: SerdeError: .*utf-8"):
        codec.decode_body(bytes(body))
    with pytest.raises(DecodeError):
        codec.decode_body(bytes(body[:-4]))
    assert codec.decode_body(codec.message_frame("n", 5)[4:]) == (FrameKind.MESSAGE, ("n", 5))


@settings(max_examples=examples(100), deadline=None)
@given(data=st.binary(max_size=40))
def test_garbage_after_a_ros_tag_is_a_decode_error(data: bytes) -> None:
    codec = Codec(ros_types=[ros_type("sensor_msgs/msg/Joy")])
    name = b"jazzy:sensor_msgs/msg/Joy"
    body = b"M\x01\x00\x00\x00m" + bytes((20,)) + len(name).to_bytes(4, "little") + name + data
    try:
        _, (_, value) = codec.decode_body(body)
    except DecodeError:
        return
    assert ros_type("sensor_msgs/msg/Joy").check(value) is None


# ---- (e) across processes -------------------------------------------------------------------------------

PROTOCOLS = sessiontypes.loads("""
type Twist = "ros:geometry_msgs/msg/Twist"
type Image = "ros:sensor_msgs/msg/Image"
global Drive(Pilot, Base) = Pilot -> Base : cmd(Twist). Pilot -> Base : frame(Image).
                            Base -> Pilot : cmd(Twist). Base -> Pilot : frame(Image)
global Steer(Pilot, Base) = Pilot -> Base : cmd(Twist)
""", "test_ros_messages.proto").globals


def run(global_name: str, pilot: Any, base: Any) -> anodize.RunReport:
    system = anodize.System(PROTOCOLS[global_name], transport=anodize.Processes())
    system.group("pilot").role("Pilot", pilot)
    system.group("base").role("Base", base)
    return system.run(timeout=60)


@pytest.mark.slow
def test_a_twist_and_an_image_round_trip_between_processes() -> None:
    report = run("Drive", ros_roles.pilot, ros_roles.base)
    assert report.ok, report.summary()
    assert report.messages == {"Pilot->Base": 2, "Base->Pilot": 2}


@pytest.mark.slow
def test_a_payload_of_the_wrong_class_is_the_senders_violation() -> None:
    report = run("Steer", ros_roles.wrong_pilot, ros_roles.waiting_base)
    error = report.roles["Pilot"].error
    assert isinstance(error, ProtocolViolationError), report.summary()
    assert (error.blame, error.reason) == (
        "Pilot", "field linear: expected geometry_msgs/msg/Vector3, got geometry_msgs/msg/Point")
    assert report.roles["Base"].status == "failed"


def test_a_ros_type_is_a_frozen_value() -> None:
    twist = ros_type("geometry_msgs/msg/Twist")
    with pytest.raises(AttributeError):
        twist.name = "x"  # type: ignore[misc]
    assert isinstance(twist, RosType) and hash(twist) == hash(ros_type("geometry_msgs/msg/Twist"))
