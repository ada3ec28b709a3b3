"""System files: what load_config accepts, every message it refuses with, and build_system."""

from __future__ import annotations

import sys
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

from anodize import Dds, Inproc, Processes, RosBridge
from anodize._supervision.group import parse_memory
from anodize._tools.config import ConfigError, GroupConfig, SystemConfig, build_system, load_config
from anodize.errors import ConfigurationError
from sessiontypes import ProtocolError

REPO = Path(__file__).resolve().parents[3]

ROLES = '''\
def producer(ep):
    for i in range(3):
        ep.send("C", "data", i)
    ep.send("C", "stop")


def consumer(ep):
    while ep.recv("P").label == "data":
        pass


def crasher(ep):
    raise RuntimeError("sensor unplugged")
'''

STREAM = "global Stream(P, C) = mu t. P -> C : { data(int). t, stop. end }\n"

GOOD = '''\
protocol = "protocols/stream.proto"
global = "Stream"
transport = { kind = "inproc" }
timeout = 5
monitors = false
pythonpath = ["code", "."]

[groups.control]
priority = 90
memory = "64MiB"
cpus = [0]
on_failure = "restart"
max_restarts = 2
roles = { P = "cfg_roles:producer" }

[groups.logging]
roles = { C = "cfg_roles:consumer" }
'''


@pytest.fixture
def system_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A directory with protocols/stream.proto and code/cfg_roles.py; sys.path and
    sys.modules are restored afterwards."""
    (tmp_path / "protocols").mkdir()
    (tmp_path / "protocols" / "stream.proto").write_text(STREAM, encoding="utf-8")
    (tmp_path / "code").mkdir()
    (tmp_path / "code" / "cfg_roles.py").write_text(ROLES, encoding="utf-8")
    monkeypatch.setattr(sys, "path", list(sys.path))
    yield tmp_path
    sys.modules.pop("cfg_roles", None)


def write(directory: Path, text: str, name: str = "system.toml") -> Path:
    path = directory / name
    path.write_text(text, encoding="utf-8")
    return path


def test_a_good_file(system_dir: Path) -> None:
    path = write(system_dir, GOOD)
    config = load_config(path)
    assert config == SystemConfig(
        path=path, protocol=system_dir / "protocols" / "stream.proto", global_name="Stream",
        transport=Inproc(), timeout=5.0, monitors=False,
        pythonpath=(system_dir / "code", system_dir),
        groups={
            "control": GroupConfig("control", 90, 64 * 2**20, (0,), "restart", 2,
                                   {"P": "cfg_roles:producer"}, f"{path}: groups.control"),
            "logging": GroupConfig("logging", None, None, None, "stop", 3,
                                   {"C": "cfg_roles:consumer"}, f"{path}: groups.logging"),
        })
    assert list(config.groups) == ["control", "logging"]
    assert config.group_of("C") == "logging" and config.group_of("X") is None


def test_defaults_and_paths_relative_to_the_file(tmp_path: Path) -> None:
    (tmp_path / "systems").mkdir()
    path = write(tmp_path / "systems", 'protocol = "../p.proto"\nglobal = "G"\n'
                                       '[groups.g]\nroles = { A = "m:f" }\n')
    config = load_config(path)
    assert (config.protocol, config.transport, config.timeout, config.monitors, config.pythonpath) == (
        tmp_path / "p.proto", Processes(), None, True, (tmp_path / "systems",))


MINIMAL = 'protocol = "p.proto"\nglobal = "G"\n'
GROUP = '[groups.g]\nroles = { A = "m:f" }\n'

BAD = {
    "unknown_top_key": (
        MINIMAL + "protocl = 1\n" + GROUP,
        ("protocl: unknown key; expected one of channels, domain, global, groups, include, monitors, params, "
         "protocol, pythonpath, record, ros, run_id, timeout, transport, zenoh")),
    "params_not_tables": (
        MINIMAL + "params = 3\n" + GROUP,
        "params: expected tables such as [params.Planner], got 3"),
    "params_of_a_role_not_a_table": (
        MINIMAL + "params = { A = 3 }\n" + GROUP,
        "params.A: expected a table such as { speed = 0.3 }, got 3"),
    "param_value_not_a_ros_type": (
        MINIMAL + "[params.A]\nat = 1979-05-27\n" + GROUP,
        "params.A.at: expected a bool, int, float, str or an array of one of them (as ROS parameters), got date"),
    "param_array_of_two_types": (
        MINIMAL + "[params.A]\nxs = [1, \"a\"]\n" + GROUP,
        "params.A.xs: expected an array of one type (bool, int, float or str, as ROS parameters), got list[int | str]"),
    "include_not_paths": (
        "include = \"base.toml\"\n" + MINIMAL + GROUP,
        "include: expected an array of system files such as [\"base.toml\"], got \"base.toml\""),
    "include_missing": (
        "include = [\"base.toml\"]\n" + MINIMAL + GROUP,
        "include: cannot read base.toml: no such file (paths are relative to the including file's folder)"),
    "ros_namespace_not_a_name": (
        MINIMAL + "[ros]\nnamespace = \"/r-1\"\n" + GROUP,
        ("ros.namespace: expected a ROS namespace such as \"/robot1\" (tokens of letters, digits and '_'), "
        "got \"/r-1\"")),
    "ros_remap_not_names": (
        MINIMAL + "[ros.remap]\n\"/cmd_vel\" = \"r 1\"\n" + GROUP,
        ("ros.remap./cmd_vel: expected a ROS topic name such as \"/cmd_vel\" or, relative to the namespace, "
        "\"cmd_vel\" (tokens of letters, digits and '_'), got \"/cmd_vel\" = \"r 1\"")),
    "ros_topic_not_a_name": (
        MINIMAL + "[ros.topics]\n\"A->B\" = \"9lives\"\n" + GROUP,
        ("ros.topics.A->B: expected a ROS topic name such as \"/cmd_vel\" or, relative to the namespace, "
        "\"cmd_vel\" (tokens of letters, digits and '_'), got \"9lives\"")),
    "group_namespace_not_a_name": (
        MINIMAL + GROUP + "namespace = \"a//b\"\n",
        ("groups.g.namespace: expected a ROS namespace such as \"/robot1\" (tokens of letters, digits and "
        "'_'), got \"a//b\"")),
    "channel_capacity_zero": (
        MINIMAL + '[channels."A->B"]\ncapacity = 0\n' + GROUP,
        "channels.A->B.capacity: expected a whole number of messages >= 1, got 0"),
    "channel_unknown_key": (
        MINIMAL + '[channels."A->B"]\nsize = 3\n' + GROUP,
        "channels.A->B.size: unknown key; expected one of capacity, qos"),
    "unknown_ros_key": (
        MINIMAL + "[ros]\ntopic = {}\n" + GROUP,
        "ros.topic: unknown key; expected one of distro, domain, external, namespace, qos, remap, topics"),
    "ros_topics_not_a_table": (
        MINIMAL + "[ros]\ntopics = [\"/cmd_vel\"]\n" + GROUP,
        'ros.topics: expected a table such as { "Move->Gazebo" = "/cmd_vel" }, got ["/cmd_vel"]'),
    "ros_external_not_names": (
        MINIMAL + "[ros]\nexternal = \"Joy\"\n" + GROUP,
        'ros.external: expected an array of role names such as ["Joy"], got "Joy"'),
    "ros_domain_out_of_range": (
        MINIMAL + "[ros]\ndomain = 300\n" + GROUP,
        "ros.domain: expected a DDS domain id 0..232, got 300"),
    "unknown_group_key": (
        MINIMAL + GROUP + "prio = 3\n",
        ("groups.g.prio: unknown key; expected one of cpus, host, max_restarts, memory, namespace, nice, "
         "on_failure, priority, priority_inheritance, roles, spin")),
    "spin_not_a_duration": (
        MINIMAL + GROUP + 'spin = "fast"\n',
        ('groups.g.spin: expected a duration such as "50us" or "0.2ms" (at most "1ms"), or an int of '
        'microseconds, got "fast"')),
    "spin_too_long": (
        MINIMAL + GROUP + 'spin = "5ms"\n',
        ('groups.g.spin: expected a duration such as "50us" or "0.2ms" (at most "1ms"), or an int of '
        'microseconds, got "5ms"')),
    "spin_negative": (
        MINIMAL + GROUP + "spin = -3\n",
        ('groups.g.spin: expected a duration such as "50us" or "0.2ms" (at most "1ms"), or an int of '
        "microseconds, got -3")),
    "spin_a_float": (
        MINIMAL + GROUP + "spin = 2.5\n",
        ('groups.g.spin: expected a duration such as "50us" or "0.2ms" (at most "1ms"), or an int of '
        "microseconds, got 2.5")),
    "priority_inheritance_not_a_bool": (
        MINIMAL + GROUP + "priority_inheritance = 0\n",
        "groups.g.priority_inheritance: expected true or false, got 0"),
    "nice_out_of_range": (
        MINIMAL + GROUP + "nice = -21\n",
        "groups.g.nice: expected an int -20..19, got -21"),
    "nice_beside_a_priority": (
        MINIMAL + GROUP + "nice = -10\npriority = 10\n",
        "groups.g.nice: priority 10 (SCHED_FIFO) and nice -10 (ordinary scheduling) exclude each other: give one"),
    "missing_protocol": ('global = "G"\n' + GROUP, "protocol: missing (it is required)"),
    "missing_global": ('protocol = "p.proto"\n' + GROUP, "global: missing (it is required)"),
    "missing_groups": (MINIMAL, "groups: missing (it is required): add a table such as [groups.main]"),
    "empty_groups": (MINIMAL + "groups = {}\n", "groups: expected at least one group, such as [groups.main]"),
    "groups_not_a_table": (MINIMAL + "groups = 3\n", "groups: expected tables such as [groups.main], got 3"),
    "missing_roles": (MINIMAL + "[groups.g]\npriority = 3\n",
                      'groups.g.roles: missing (it is required): roles = { Role = "module:function" }'),
    "empty_roles": (MINIMAL + "[groups.g]\nroles = {}\n",
                    'groups.g.roles: expected a table such as { Role = "module:function" }, got a table'),
    "bad_reference": (MINIMAL + '[groups.g]\nroles = { A = "m.f" }\n',
                      'groups.g.roles.A: expected "module:function", got "m.f"'),
    "reference_not_a_string": (MINIMAL + "[groups.g]\nroles = { A = 1 }\n",
                               'groups.g.roles.A: expected "module:function", got 1'),
    "role_twice": (MINIMAL + GROUP + '[groups.h]\nroles = { A = "m:g" }\n',
                   "groups.h.roles.A: role A is already in group g"),
    "protocol_not_a_string": ('protocol = 3\nglobal = "G"\n' + GROUP,
                              "protocol: expected a non-empty string, got 3"),
    "empty_global": ('protocol = "p.proto"\nglobal = ""\n' + GROUP,
                     'global: expected a non-empty string, got ""'),
    "transport": (MINIMAL + 'transport = "tcp"\n' + GROUP,
                  ('transport: expected "inproc" or "process" or "dds" or "zenoh", or a table [transport] with '
                   'kind = ..., got "tcp"')),
    "transport_kind": (MINIMAL + '[transport]\nkind = "tcp"\n' + GROUP,
                       'transport.kind: expected "inproc" or "process" or "dds" or "zenoh", got "tcp"'),
    "transport_no_kind": (MINIMAL + '[transport]\nliveness = 3\n' + GROUP,
                          ('transport.kind: expected "inproc" or "process" or "dds" or "zenoh", got nothing '
                          '(it is required)')),
    "transport_key_of_another_kind": (
        MINIMAL + '[transport]\nkind = "process"\ndomain = 3\n' + GROUP,
        'transport.domain: unknown key for kind = "process"; expected one of kind, liveness'),
    "transport_liveness": (MINIMAL + '[transport]\nkind = "process"\nliveness = 0\n' + GROUP,
                           "transport.liveness: expected a number of seconds > 0, got 0"),
    "transport_wait": (MINIMAL + '[transport]\nkind = "dds"\nwait = "long"\n' + GROUP,
                       'transport.wait: expected a number of seconds > 0, got "long"'),
    "transport_host": (MINIMAL + '[transport]\nkind = "dds"\nhost = "a b"\n' + GROUP,
                       'transport.host: expected a name such as "robot", got "a b"'),
    "transport_domain": (MINIMAL + '[transport]\nkind = "dds"\ndomain = 300\n' + GROUP,
                         "transport.domain: expected a DDS domain id 0..232, got 300"),
    "old_keys_beside_a_table": (
        MINIMAL + 'domain = 3\n[transport]\nkind = "dds"\n' + GROUP,
        "domain: with a [transport] table, domain is one of its keys: write transport.domain (in [transport])"),
    "domain": (MINIMAL + "domain = 300\n" + GROUP, "domain: expected a DDS domain id 0..232, got 300"),
    "run_id": (MINIMAL + 'run_id = "a b"\n' + GROUP,
               "run_id: expected up to 64 letters, digits, '_', '.' or '-', got \"a b\""),
    "host": (MINIMAL + GROUP + 'host = "robot 1"\n', 'groups.g.host: expected a name such as "robot", got "robot 1"'),
    "timeout_negative": (MINIMAL + "timeout = -1\n" + GROUP,
                         "timeout: expected a number of seconds > 0, got -1"),
    "timeout_bool": (MINIMAL + "timeout = true\n" + GROUP,
                     "timeout: expected a number of seconds > 0, got true"),
    "monitors": (MINIMAL + 'monitors = "yes"\n' + GROUP, 'monitors: expected true or false, got "yes"'),
    "pythonpath": (MINIMAL + 'pythonpath = "."\n' + GROUP,
                   'pythonpath: expected an array of directories, got "."'),
    "priority_range": (MINIMAL + GROUP + "priority = 120\n",
                       "groups.g.priority: expected an int 1..99, got 120"),
    "priority_bool": (MINIMAL + GROUP + "priority = true\n",
                      "groups.g.priority: expected an int 1..99, got true"),
    "priority_float": (MINIMAL + GROUP + "priority = 5.0\n",
                       "groups.g.priority: expected an int 1..99, got 5.0"),
    "memory": (MINIMAL + GROUP + 'memory = "lots"\n',
               ('groups.g.memory: expected a size such as "64MiB", "512KiB" or a number of bytes, '
                'at most 8 EiB, got "lots"')),
    "memory_overflowing_a_float": (MINIMAL + GROUP + f'memory = "{"9" * 400}MiB"\n',
                                   ('groups.g.memory: expected a size such as "64MiB", "512KiB" or a number '
                                    'of bytes, at most 8 EiB, got "999999999999999999999999...'
                                    '999999999999999999999MiB" (403 characters)')),
    "memory_beyond_any_limit": (MINIMAL + GROUP + 'memory = "1000000000000000000000GiB"\n',
                                ('groups.g.memory: expected a size such as "64MiB", "512KiB" or a number '
                                 'of bytes, at most 8 EiB, got "1000000000000000000000GiB"')),
    "memory_beyond_any_limit_in_bytes": (MINIMAL + GROUP + "memory = 9223372036854775807\n",
                                         ('groups.g.memory: expected a size such as "64MiB", "512KiB" or a '
                                          'number of bytes, at most 8 EiB, got 9223372036854775807')),
    "cpus": (MINIMAL + GROUP + "cpus = [0, -1]\n",
             "groups.g.cpus: expected a non-empty array of CPU numbers, got [0, -1]"),
    "cpus_empty": (MINIMAL + GROUP + "cpus = []\n",
                   "groups.g.cpus: expected a non-empty array of CPU numbers, got []"),
    "on_failure": (MINIMAL + GROUP + 'on_failure = "retry"\n',
                   'groups.g.on_failure: expected one of "stop", "restart", "stop-system", got "retry"'),
    "max_restarts": (MINIMAL + GROUP + "max_restarts = -2\n",
                     "groups.g.max_restarts: expected an int >= 0, got -2"),
    "group_not_a_table": (MINIMAL + "groups = { g = 1 }\n", "groups.g: expected a table, got 1"),
}


@pytest.mark.parametrize("name", BAD)
def test_each_mistake_has_its_message(tmp_path: Path, name: str) -> None:
    text, message = BAD[name]
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert str(caught.value) == f"{path}: {message}"
    assert caught.value.path == str(path)
    assert caught.value.key == message.partition(":")[0]


def test_a_toml_syntax_error_has_line_column_and_caret(tmp_path: Path) -> None:
    path = write(tmp_path, 'protocol = "p.proto"\nglobal = \n')
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert str(caught.value) == f"{path}:2:10: invalid value\n    global = \n             ^"
    assert (caught.value.line, caught.value.column, caught.value.key) == (2, 10, None)


def test_a_toml_error_at_the_end_of_the_document(tmp_path: Path) -> None:
    path = write(tmp_path, 'protocol = "p.proto')
    with pytest.raises(ConfigError, match=rf"^{path}:1:20: unterminated string\n"):
        load_config(path)


def test_a_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "none.toml"
    with pytest.raises(ConfigError, match=rf"^{path}: cannot read: No such file or directory$"):
        load_config(path)


# ---- build_system -------------------------------------------------------------------

def build(directory: Path, groups: str, header: str = 'global = "Stream"\n') -> SystemConfig:
    text = (f'protocol = "protocols/stream.proto"\n{header}transport = "inproc"\ntimeout = 5\n'
            f'pythonpath = ["code"]\n{groups}')
    return load_config(write(directory, text))


TWO_GROUPS = ('[groups.a]\nroles = { P = "cfg_roles:producer" }\n'
              '[groups.b]\nroles = { C = "cfg_roles:consumer" }\n')


def test_priority_inheritance_is_on_unless_a_group_turns_it_off(system_dir: Path) -> None:
    config = build(system_dir, TWO_GROUPS.replace("[groups.b]\n", "[groups.b]\npriority_inheritance = false\n"))
    assert [g.priority_inheritance for g in config.groups.values()] == [True, False]
    system = build_system(config)
    assert [g.priority_inheritance for g in system.groups.values()] == [True, False]


def test_a_group_s_nice_value_reaches_the_system(system_dir: Path) -> None:
    config = build(system_dir, TWO_GROUPS.replace("[groups.b]\n", "[groups.b]\nnice = -10\n"))
    assert [g.nice for g in config.groups.values()] == [None, -10]
    assert [g.nice for g in build_system(config).groups.values()] == [None, -10]


def test_a_group_s_spin_reaches_the_system_in_nanoseconds(system_dir: Path) -> None:
    config = build(system_dir, TWO_GROUPS.replace("[groups.a]\n", '[groups.a]\nspin = "50us"\n')
                                         .replace("[groups.b]\n", "[groups.b]\nspin = 20\n"))
    assert [g.spin for g in config.groups.values()] == [50_000, 20_000]
    assert [g.spin for g in build_system(config).groups.values()] == [50_000, 20_000]
    assert [g.spin for g in build_system(build(system_dir, TWO_GROUPS)).groups.values()] == [0, 0]


def test_build_system_runs_an_inproc_system(system_dir: Path) -> None:
    config = build(system_dir, TWO_GROUPS)
    system = build_system(config)
    assert (system.transport, list(system.groups)) == (Inproc(), ["a", "b"])
    assert system.groups["a"].roles == {"P": "cfg_roles:producer"}
    report = system.run(timeout=config.timeout)
    assert report.ok, report.summary()
    assert report.messages == {"P->C": 4}


def test_build_system_puts_the_pythonpath_first_once(system_dir: Path) -> None:
    config = build(system_dir, TWO_GROUPS)
    build_system(config)
    build_system(config)
    assert sys.path[0] == str(system_dir / "code")
    assert sys.path.count(str(system_dir / "code")) == 1


def test_a_failing_role_fails_the_report(system_dir: Path) -> None:
    config = build(system_dir, '[groups.a]\nroles = { P = "cfg_roles:crasher" }\n'
                               '[groups.b]\nroles = { C = "cfg_roles:consumer" }\n')
    report = build_system(config).run(timeout=5)
    assert not report.ok
    assert report.roles["P"].status == "failed"


def test_an_unknown_global_lists_the_available_ones(system_dir: Path) -> None:
    config = build(system_dir, TWO_GROUPS, header='global = "Strem"\n')
    with pytest.raises(ConfigError) as caught:
        build_system(config)
    assert str(caught.value) == (f"{config.path}: global: no global Strem in "
                                 f"{system_dir / 'protocols' / 'stream.proto'}; expected one of Stream")


def test_a_role_in_no_group(system_dir: Path) -> None:
    config = build(system_dir, '[groups.a]\nroles = { P = "cfg_roles:producer" }\n')
    with pytest.raises(ConfigError, match=rf"^{config.path}: groups: role C of global Stream is in "
                                          r"no group$"):
        build_system(config)


def test_a_role_the_global_does_not_have(system_dir: Path) -> None:
    config = build(system_dir, TWO_GROUPS + '[groups.c]\nroles = { X = "cfg_roles:consumer" }\n')
    with pytest.raises(ConfigError, match=rf"^{config.path}: groups.c: global Stream has no role X; "
                                          r"expected one of P, C$"):
        build_system(config)


def test_a_role_function_that_cannot_be_imported(system_dir: Path) -> None:
    config = build(system_dir, '[groups.a]\nroles = { P = "cfg_roles:produce" }\n'
                               '[groups.b]\nroles = { C = "cfg_roles:consumer" }\n')
    with pytest.raises(ConfigError, match=rf"^{config.path}: groups.a: role function "
                                          r"'cfg_roles:produce': module cfg_roles has no produce$"):
        build_system(config)


def test_cpus_this_process_may_not_use(system_dir: Path) -> None:
    config = build(system_dir, '[groups.a]\ncpus = [100000]\nroles = { P = "cfg_roles:producer" }\n')
    with pytest.raises(ConfigError, match=rf"^{config.path}: groups.a: group a: cpus \[100000\] must be"):
        build_system(config)


def test_a_missing_protocol_file(system_dir: Path) -> None:
    path = write(system_dir, 'protocol = "nope.proto"\nglobal = "G"\n' + GROUP)
    with pytest.raises(ConfigError, match=rf"^{path}: protocol: cannot read {system_dir}/nope.proto: "
                                          r"No such file or directory$"):
        build_system(load_config(path))


def test_protocol_errors_are_not_wrapped(system_dir: Path) -> None:
    (system_dir / "protocols" / "stream.proto").write_text("global Stream = P -> P : x\n")
    with pytest.raises(ProtocolError):
        build_system(build(system_dir, TWO_GROUPS))


def test_the_example_in_the_guide_is_a_valid_system_file(tmp_path: Path) -> None:
    guide = (REPO / "docs" / "guide" / "system-files.md").read_text(encoding="utf-8")
    example = guide.partition("```toml\n")[2].partition("```")[0]
    assert example, "docs/guide/system-files.md opens with a TOML example"
    config = load_config(write(tmp_path, example))
    assert (config.global_name, list(config.groups)) == ("Pipeline", ["control", "logging"])


# ---- memory sizes -------------------------------------------------------------------

@pytest.mark.parametrize(("text", "size"), [("64MiB", 64 * 2**20), ("1.5GiB", 3 * 2**29), ("1GB", 10**9),
                                            ("512 KiB", 2**19), (4096, 4096), ("0.5b", 0)])
def test_memory_sizes_are_exact(text: str | int, size: int) -> None:
    if size == 0:
        with pytest.raises(ConfigurationError, match="expected a positive size"):
            parse_memory(text)
    else:
        assert parse_memory(text) == size


@pytest.mark.parametrize("text", ["9" * 400 + "MiB", "1000000000000000000000GiB", 2**63, "8589934592GiB"])
def test_a_memory_size_no_kernel_can_enforce_is_refused(text: str | int) -> None:
    with pytest.raises(ConfigurationError, match="larger than any limit the kernel can enforce"):
        parse_memory(text)


# ---- the transport table and the earlier form ----------------------------------------

DDS_NEW = MINIMAL + """
[transport]
kind = "dds"
domain = 42
run_id = "teleop"
host = "A"
wait = 60
liveness = 3

[ros]
topics = { "A->B" = "/ab" }
external = ["J"]
distro = "humble"
domain = 7
""" + GROUP
DDS_OLD = MINIMAL + """
transport = "dds"
domain = 42
run_id = "teleop"
[ros]
topics = { "A->B" = "/ab" }
""" + GROUP


def test_the_transport_table_maps_onto_the_values_one_to_one(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, DDS_NEW))
    assert config.transport == Dds(domain=42, run_id="teleop", host="A", wait=60.0, liveness=3.0)
    assert config.ros == RosBridge(topics={"A->B": "/ab"}, external=frozenset({"J"}), distro="humble", domain=7)
    assert config.external == {"J"}


def test_a_file_of_the_earlier_form_reads_as_the_same_values(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, DDS_OLD))
    assert config.transport == Dds(domain=42, run_id="teleop")
    assert config.ros == RosBridge(topics={"A->B": "/ab"})
    # The earlier form allowed (and checked) domain and run_id on any transport; they meant nothing there.
    old_process = load_config(write(tmp_path, MINIMAL + 'transport = "process"\ndomain = 3\n' + GROUP))
    assert (old_process.transport, old_process.ros) == (Processes(), None)


@pytest.mark.parametrize(("kind", "expected"), [("inproc", Inproc()), ("process", Processes(liveness=3.0)),
                                                ("dds", Dds(liveness=3.0))])
def test_another_transport_keeps_the_fields_it_has(tmp_path: Path, kind: str, expected: object) -> None:
    config = load_config(write(tmp_path, MINIMAL + '[transport]\nkind = "process"\nliveness = 3\n' + GROUP))
    assert config.on_transport(kind).transport == expected


def test_another_transport_must_be_one(tmp_path: Path) -> None:
    config = load_config(write(tmp_path, MINIMAL + GROUP))
    with pytest.raises(ConfigError, match='transport: expected one of "inproc", "process", "dds", "zenoh", got "tcp"'):
        config.on_transport("tcp")


@pytest.mark.parametrize("path", sorted(p.relative_to(REPO).as_posix() for p in [
    *REPO.glob("examples/*/*.toml"), REPO / "tinman" / "src" / "tinman" / "tinman.toml"]))
def test_the_repository_s_system_files_are_of_the_current_form(path: str) -> None:
    data = tomllib.loads((REPO / path).read_text(encoding="utf-8"))
    assert isinstance(data.get("transport"), dict) and not {"domain", "run_id"} & set(data), path
    load_config(REPO / path)
