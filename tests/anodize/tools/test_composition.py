"""Composing a system file: [params.Role], -p overrides, include, namespaces and remaps (issue 30 item 2)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from anodize import RosBridge, build_system, load_config
from anodize._supervision.rosnames import resolve_topics
from anodize._tools.cli import main
from anodize._tools.config import ConfigError
from anodize._tools.includes import read_system_data
from anodize.errors import ConfigurationError

STREAM = "global Stream(P, C) = mu t. P -> C : { data(int). t, stop. end }\n"
ROS_STREAM = ('type Int32 = "ros:std_msgs/msg/Int32"\n'
              "global Stream(P, C) = P -> C : data(Int32). P -> C : stop(Int32). end\n")

SYSTEM = '''\
protocol = "stream.proto"
global = "Stream"
transport = {{ kind = "inproc" }}
timeout = 20

[params.P]
count = 2
out = "{out}"

[groups.a]
roles = {{ P = "param_roles:producer" }}

[groups.b]
roles = {{ C = "param_roles:consumer" }}
'''


@pytest.fixture
def system(tmp_path: Path) -> Path:
    (tmp_path / "stream.proto").write_text(STREAM, encoding="utf-8")
    path = tmp_path / "system.toml"
    path.write_text(SYSTEM.format(out=tmp_path / "given.json"), encoding="utf-8")
    return path


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    try:
        status = main(list(argv))
    except SystemExit as exit_:
        status = exit_.code if isinstance(exit_.code, int) else 1
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "internal error" not in err
    return status, out, err


def given_to_p(system: Path) -> dict[str, object]:
    return json.loads((system.parent / "given.json").read_text())  # type: ignore[no-any-return]


# ---- [params.Role] and -p ---------------------------------------------------------------------

def test_the_file_s_parameters_reach_the_role(capsys: pytest.CaptureFixture[str], system: Path) -> None:
    status, _, err = run(capsys, "run", str(system), "--quiet")
    assert status == 0, err
    assert given_to_p(system) == {"count": 2, "gain": 1.0, "gain_type": "float", "tag": "", "flags": None}


def test_p_overrides_the_file_and_adds_parameters_as_toml_values(
        capsys: pytest.CaptureFixture[str], system: Path) -> None:
    status, _, err = run(capsys, "run", str(system), "--quiet", "-p", "P.count=4", "-p", "P.gain=0.5",
                         "--param", 'P.tag="front"', "-p", "P.flags=[true, false]", "-p", "P.count=3")
    assert status == 0, err
    assert given_to_p(system) == {"count": 3, "gain": 0.5, "gain_type": "float", "tag": "front", "flags": [True, False]}


@pytest.mark.parametrize(("override", "message"), [
    ("Q.count=1", "error: command line: -p Q.count: no role Q runs in a group of {system}; expected one of P, C"),
    ("P.speed=1", ("error: command line: -p P.speed: producer takes no such parameter; its parameters: count, "
                  "flags, gain, out, tag")),
    ("P.count=0.5", "error: command line: -p P.count: expected int, got float (0.5)"),
    ("P.tag=front", ('error: command line: -p P.tag: expected a TOML value such as 0.3, true, "text" or [1, 2], '
                    "got front (a string is quoted: -p 'P.tag=\"front\"')")),
    ("P.xs=[1, \"a\"]", ("error: command line: -p P.xs: expected an array of one type (bool, int, float or str, "
                        "as ROS parameters), got list[int | str]")),
    ("count=1", "error: command line: -p count=1: expected Role.name=value, such as Planner.speed=0.3"),
])
def test_a_bad_override_is_a_usage_error_naming_it(capsys: pytest.CaptureFixture[str], system: Path,
                                                   override: str, message: str) -> None:
    assert run(capsys, "run", str(system), "--quiet", "-p", override) == (2, "", message.format(system=system) + "\n")
    assert not (system.parent / "given.json").exists()  # nothing ran


def test_a_wrong_parameter_in_the_file_is_located_at_its_key(capsys: pytest.CaptureFixture[str],
                                                             system: Path) -> None:
    system.write_text(system.read_text().replace("count = 2", 'count = "2"'), encoding="utf-8")
    assert run(capsys, "run", str(system), "--quiet") == (
        1, "", f'error: {system}: params.P.count: expected int, got str ("2")\n')


# ---- include ----------------------------------------------------------------------------------

def test_an_including_file_wins_key_by_key_and_paths_stay_relative_to_their_file(
        capsys: pytest.CaptureFixture[str], system: Path) -> None:
    base = system.parent / "base" / "base.toml"
    base.parent.mkdir()
    (base.parent / "stream.proto").write_text(STREAM, encoding="utf-8")
    base.write_text(system.read_text().replace('out = "', 'tag = "base"\nout = "'), encoding="utf-8")
    system.unlink()
    (system.parent / "stream.proto").unlink()  # the protocol is the base's, beside it
    top = system.parent / "robot.toml"
    top.write_text('include = ["base/base.toml"]\n\n[params.P]\ncount = 5\n\n[groups.a]\npriority = 10\n',
                   encoding="utf-8")
    config = load_config(top)
    assert config.protocol == base.parent / "stream.proto"
    assert config.params["P"] == {"count": 5, "tag": "base", "out": str(system.parent / "given.json")}
    assert config.groups["a"].priority == 10 and config.groups["a"].roles == {"P": "param_roles:producer"}
    assert run(capsys, "run", str(top), "--quiet")[0] == 0
    assert given_to_p(system)["count"] == 5


def test_an_included_protocol_is_found_when_the_file_is_named_from_another_directory(
        system: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # 'anodize run examples/fleet/robot1.toml' from the checkout's root: the included file's
    # protocol was anchored to the relative examples/fleet, then the including file's folder again.
    (system.parent / "robot.toml").write_text('include = ["system.toml"]\n', encoding="utf-8")
    monkeypatch.chdir(system.parent.parent)
    config = load_config(Path(system.parent.name) / "robot.toml")
    assert config.protocol.resolve() == system.parent / "stream.proto"


def test_an_error_in_an_included_value_names_the_included_file(system: Path) -> None:
    system.write_text(system.read_text().replace("count = 2", "count = [1, true]"), encoding="utf-8")
    top = system.parent / "top.toml"
    top.write_text('include = ["system.toml"]\ntimeout = 3\n', encoding="utf-8")
    with pytest.raises(ConfigError) as raised:
        load_config(top)
    assert (raised.value.path, raised.value.key) == (str(system), "params.P.count")


def test_an_include_cycle_is_refused_at_the_include_that_closes_it(tmp_path: Path) -> None:
    (tmp_path / "a.toml").write_text('include = ["b.toml"]\n', encoding="utf-8")
    (tmp_path / "b.toml").write_text('include = ["./a.toml"]\n', encoding="utf-8")
    with pytest.raises(ConfigError) as raised:
        load_config(tmp_path / "a.toml")
    a, b = tmp_path.resolve() / "a.toml", tmp_path.resolve() / "b.toml"
    assert str(raised.value) == f"{tmp_path / 'b.toml'}: include: include cycle: {a} -> {b} -> {a}"


# ---- namespaces and remaps ---------------------------------------------------------------------

def test_relative_names_resolve_in_the_group_s_then_the_system_s_namespace_then_remaps_apply() -> None:
    topics = {"A->B": "cmd_vel", "B->A": "scan", "C->A": "/tf", "X->B": "joy"}
    namespaces = {"A": "arm", "B": "/base", "C": ""}
    assert resolve_topics(topics, "/r1", namespaces, {}) == {
        "A->B": "/r1/arm/cmd_vel", "B->A": "/base/scan", "C->A": "/tf", "X->B": "/base/joy"}
    assert resolve_topics(topics, "", {}, {"cmd_vel": "/r2/cmd_vel", "/tf": "tf_static"}) == {
        "A->B": "/r2/cmd_vel", "B->A": "/scan", "C->A": "/tf_static", "X->B": "/joy"}
    with pytest.raises(ConfigurationError, match=r"^remap /r1/cmd: no topic of the system is named so; its topics "
                                                 r"are /r1/cmd_vel$"):
        resolve_topics({"A->B": "cmd_vel"}, "/r1", {}, {"cmd": "x"})


def test_a_namespace_or_remap_that_is_no_ros_name_is_refused() -> None:
    with pytest.raises(ConfigurationError, match=r"^RosBridge namespace '/r 1': expected a ROS namespace"):
        RosBridge(namespace="/r 1")
    with pytest.raises(ConfigurationError, match=r"^RosBridge remap 'a__b': ROS topic names may not contain '__'"):
        RosBridge(remap={"/a": "a__b"})


def test_namespace_and_remaps_name_the_recorded_topics(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    from anodize._recording.reader import open_recording

    (tmp_path / "stream.proto").write_text(ROS_STREAM, encoding="utf-8")
    system = tmp_path / "system.toml"
    system.write_text(SYSTEM.format(out=tmp_path / "given.json").replace(
        "[groups.a]", '[ros.topics]\n"P->C:data" = "data"\n"P->C:stop" = "stop"\n\n[groups.a]'), encoding="utf-8")
    system.write_text(system.read_text().replace("param_roles:producer", "param_roles:ros_producer"), encoding="utf-8")
    recording = tmp_path / "run.mcap"
    status, _, err = run(capsys, "run", str(system), "--quiet", "-p", "P.count=1", "--namespace", "/r1",
                         "-r", "stop:=/halt", "--record", str(recording))
    assert status == 0, err
    topics = {topic.topic for topic in open_recording(recording).topics}
    assert {"/r1/data", "/halt"} <= topics, topics


def test_a_bad_namespace_or_remap_on_the_command_line_is_a_usage_error(
        capsys: pytest.CaptureFixture[str], system: Path) -> None:
    assert run(capsys, "run", str(system), "--namespace", "r 1") == (
        2, "", ("error: command line: --namespace r 1: expected a ROS namespace such as \"/robot1\" (tokens of "
               "letters, digits and '_')\n"))
    assert run(capsys, "run", str(system), "-r", "/cmd_vel") == (
        2, "", "error: command line: -r /cmd_vel: expected from:=to, such as /cmd_vel:=/r1/cmd_vel\n")
    assert run(capsys, "run", str(system), "-r", "/cmd_vel:=/x") == (
        2, "", "error: command line: -r /cmd_vel: no topic of the system is named so; its topics are (none)\n")


def test_the_python_api_takes_the_same_values(system: Path) -> None:
    built = build_system(load_config(system).with_overrides(["P.count=1"], [], "/r1"))
    assert built.params == {"P": {"count": 1, "out": str(system.parent / "given.json")}}
    assert built.ros is not None and built.ros.namespace == "/r1"


# ---- the include merge, as a property -------------------------------------------------------

_TABLES = st.recursive(st.integers(0, 9), lambda inner: st.dictionaries(st.sampled_from("abc"), inner, max_size=3),
                       max_leaves=8)
_FILES = st.dictionaries(st.sampled_from("abc"), _TABLES, max_size=3)


def _toml(table: dict[str, object]) -> str:
    def value(v: object) -> str:
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        return str(v)
    return "".join(f"{key} = {value(v)}\n" for key, v in table.items())


def _leaves(table: dict[str, object], prefix: str = "") -> dict[str, object]:
    found: dict[str, object] = {}
    for key, v in table.items():
        dotted = f"{prefix}.{key}" if prefix else key
        found.update(_leaves(v, dotted) if isinstance(v, dict) else {dotted: v})  # an empty table: no leaf
    return found


def _paths(table: dict[str, object], prefix: str = "") -> set[str]:
    """Every dotted key of ``table``, tables' too."""
    found: set[str] = set()
    for key, v in table.items():
        dotted = f"{prefix}.{key}" if prefix else key
        found |= {dotted} | (_paths(v, dotted) if isinstance(v, dict) else set())
    return found


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(base=_FILES, top=_FILES)
def test_the_including_file_wins_key_by_key_and_every_value_names_its_file(
        tmp_path: Path, base: dict[str, object], top: dict[str, object]) -> None:
    (tmp_path / "base.toml").write_text(_toml(base), encoding="utf-8")
    (tmp_path / "top.toml").write_text('include = ["base.toml"]\n' + _toml(top), encoding="utf-8")
    merged = read_system_data(tmp_path / "top.toml", "top.toml")
    leaves, base_leaves, top_leaves = _leaves(merged.data), _leaves(base), _leaves(top)
    top_paths = _paths(top)
    for key, value in top_leaves.items():  # everything the including file says holds
        assert leaves[key] == value and merged.origin(key, "?") == "top.toml"
    for key, value in base_leaves.items():  # and the base's, where the including file says nothing on its path
        said = key in top_paths or any(k.startswith(key + ".") for k in top_paths) or any(
            key.startswith(k + ".") for k in top_leaves)  # (a table of the including file merges: says nothing)
        if not said:
            assert leaves[key] == value and merged.origin(key, "?") == str(tmp_path / "base.toml")
    assert set(leaves) <= set(top_leaves) | set(base_leaves)


# ---- what a review found (each failed before its fix) -------------------------------------------

def test_a_relative_remap_on_the_command_line_is_blamed_on_the_command_line(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    (tmp_path / "stream.proto").write_text(ROS_STREAM, encoding="utf-8")
    system = tmp_path / "system.toml"
    system.write_text(SYSTEM.format(out=tmp_path / "given.json").replace(
        "[groups.a]", '[ros]\nnamespace = "/r1"\n[ros.topics]\n"P->C:data" = "data"\n"P->C:stop" = "stop"\n\n'
                      "[groups.a]"), encoding="utf-8")
    status, _, err = run(capsys, "run", str(system), "-r", "nosuch:=/x")
    assert (status, err.split(": no topic")[0]) == (2, "error: command line: -r nosuch"), err


def test_a_value_nested_too_deeply_and_an_include_with_a_nul_are_errors_not_tracebacks(
        capsys: pytest.CaptureFixture[str], system: Path, tmp_path: Path) -> None:
    deep = "[" * 3000 + "]" * 3000
    status, _, err = run(capsys, "run", str(system), "-p", f"P.count={deep}")
    assert (status, err) == (2, "error: command line: -p P.count: a value nested too deeply to read\n")
    included = tmp_path / "nul.toml"
    included.write_text('include = ["a\\u0000b"]\n', encoding="utf-8")
    with pytest.raises(ConfigError, match=r"include: expected an array of system files"):
        load_config(included)


def test_a_topic_map_whose_remap_is_no_name_is_an_error_not_a_traceback(tmp_path: Path) -> None:
    import sessiontypes
    from anodize._tools.recordings import topic_map

    (tmp_path / "stream.proto").write_text(ROS_STREAM, encoding="utf-8")
    stream = sessiontypes.load(str(tmp_path / "stream.proto")).globals["Stream"]
    topics = tmp_path / "topics.toml"
    topics.write_text('[ros.topics]\n"P->C:data" = "data"\n"P->C:stop" = "stop"\n[ros.remap]\n"/data" = 5\n',
                      encoding="utf-8")
    with pytest.raises(ConfigurationError, match=r"\[ros.remap\] 5: "):
        topic_map(str(topics), stream)


def test_an_included_value_refused_when_the_system_is_built_names_the_included_file(system: Path) -> None:
    # A parameter the role's function does not take is found only when the system is built.
    system.write_text(system.read_text().replace("count = 2", "count = 2\nnosuch = 1"), encoding="utf-8")
    top = system.parent / "top.toml"
    top.write_text('include = ["system.toml"]\ntimeout = 3\n', encoding="utf-8")
    with pytest.raises(ConfigError) as raised:
        build_system(load_config(top))
    assert (raised.value.path, raised.value.key) == (str(system), "params.P.nosuch")
