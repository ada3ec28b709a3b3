"""System files with values of the wrong type at every key: a located error, never a crash.

Item 6 of issue 27 (``on_failure = ["a"]`` was "internal error: TypeError: unhashable type"),
and a hypothesis sweep that puts random TOML values of every type at every key the schema knows.
"""

from __future__ import annotations

import datetime
import math
import re
from pathlib import Path
from typing import Any

import pytest
from budget import examples
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from anodize._tools.cli import main
from anodize._tools.config import ConfigError, load_config

BASE: dict[str, Any] = {
    "protocol": "p.proto",
    "global": "G",
    "timeout": 5,
    "monitors": True,
    "pythonpath": ["."],
    "transport": {"kind": "dds", "domain": 1, "run_id": "r1", "host": "robot", "wait": 3.0, "liveness": 2.0},
    "ros": {"topics": {"A->B": "/t"}, "external": ["B"], "distro": "jazzy", "domain": 3},
    "channels": {"A->B": {"capacity": 4}},
    "groups": {"g": {"priority": 50, "memory": "64MiB", "cpus": [0], "on_failure": "restart",
                     "max_restarts": 2, "host": "robot", "priority_inheritance": True,
                     "roles": {"A": "mod:fn"}}},
}


def _key_paths(table: dict[str, Any], prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    paths = []
    for key, value in table.items():
        paths.append((*prefix, key))
        if isinstance(value, dict):
            paths.extend(_key_paths(value, (*prefix, key)))
    return paths


KEY_PATHS = [*_key_paths(BASE), ("domain",), ("run_id",)]  # the earlier form's top-level keys


def toml(value: Any) -> str:
    """``value`` written as a TOML value (inline tables; enough for these tests)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return '"' + "".join(c if c.isprintable() and c not in '"\\' else f"\\U{ord(c):08x}" for c in value) + '"'
    if isinstance(value, datetime.datetime | datetime.date | datetime.time):
        return value.isoformat()
    if isinstance(value, list):
        return "[" + ", ".join(toml(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{toml(str(k))} = {toml(v)}" for k, v in value.items()) + "}"
    raise TypeError(value)


def document(data: dict[str, Any]) -> str:
    return "".join(f"{toml(key)} = {toml(value)}\n" for key, value in data.items())


def replaced(data: dict[str, Any], path: tuple[str, ...], value: Any) -> dict[str, Any]:
    copy = dict(data)
    if len(path) == 1:
        copy[path[0]] = value
    else:
        copy[path[0]] = replaced(data[path[0]], path[1:], value)
    return copy


SCALARS = (st.booleans() | st.integers(min_value=-2**63, max_value=2**63 - 1) | st.floats()
           | st.text(max_size=8) | st.dates() | st.times() | st.datetimes())
VALUES = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=3)
                      | st.dictionaries(st.text(min_size=1, max_size=4), inner, max_size=3), max_leaves=6)


def test_the_base_file_is_valid(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text(document(BASE))
    assert load_config(path).groups["g"].on_failure == "restart"


@settings(max_examples=examples(400), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(path=st.sampled_from(KEY_PATHS), value=VALUES)
def test_any_value_at_any_key_is_read_or_refused_with_its_key(tmp_path: Path, path: tuple[str, ...],
                                                              value: Any) -> None:
    file = tmp_path / "s.toml"
    file.write_text(document(replaced(BASE, path, value)), encoding="utf-8")
    refused: ConfigError | None = None
    try:
        load_config(file)
    except ConfigError as error:
        refused = error
    if refused is not None:  # refused: by the key at fault, never as a TOML syntax error
        assert refused.key is not None and refused.problem
        assert str(refused).startswith(f"{file}: ")
        assert refused.key.split(".")[0] in {*BASE, "domain", "run_id"}


@pytest.mark.parametrize(("key", "value", "expected"), [
    ("on_failure", '["a"]', 'expected one of "stop", "restart", "stop-system", got ["a"]'),
    ("on_failure", "{ a = 1 }", 'expected one of "stop", "restart", "stop-system", got a table'),
    ("memory", "[1]", 'expected a size such as "64MiB", "512KiB" or a number of bytes, at most 8 EiB, got [1]'),
    ("priority", "1979-05-27", "expected an int 1..99, got a date"),
    ("cpus", "[" + ", ".join(["-1"] * 10000) + "]",
     "expected a non-empty array of CPU numbers, got [-1, -1, -1, ... (10000 items)]"),
])
def test_lint_names_the_key_and_what_it_expected(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 key: str, value: str, expected: str) -> None:
    file = tmp_path / "s.toml"
    file.write_text(f'protocol = "p.proto"\nglobal = "G"\n[groups.g]\nroles = {{ A = "m:f" }}\n{key} = {value}\n')
    assert main(["lint", str(file)]) == 1
    assert capsys.readouterr().err == f"error: {file}: groups.g.{key}: {expected}\n"


@pytest.mark.parametrize(("key", "value"), [("timeout", "inf"), ("timeout", "nan"),
                                            ("transport", '{ kind = "dds", wait = inf }'),
                                            ("transport", '{ kind = "process", liveness = inf }'),
                                            ("transport", '{ kind = "zenoh", lease = inf }'),
                                            ("transport", '{ kind = "zenoh", wait = nan }')])
def test_seconds_must_be_finite(tmp_path: Path, key: str, value: str) -> None:
    file = tmp_path / "s.toml"
    file.write_text(f'protocol = "p.proto"\nglobal = "G"\n{key} = {value}\n[groups.g]\nroles = {{ A = "m:f" }}\n')
    with pytest.raises(ConfigError, match=re.escape("expected a number of seconds > 0")):
        load_config(file)


@settings(max_examples=examples(100), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(path=st.sampled_from(KEY_PATHS), value=VALUES)
def test_lint_of_any_value_at_any_key_is_a_result_or_a_clean_error(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                   path: tuple[str, ...], value: Any) -> None:
    (tmp_path / "p.proto").write_text("global G(A, B) = A -> B : m(int). end\n", encoding="utf-8")
    (tmp_path / "mod.py").write_text("def fn(ep):\n    pass\n", encoding="utf-8")
    file = tmp_path / "s.toml"
    file.write_text(document(replaced(BASE, path, value)), encoding="utf-8")
    status = main(["lint", str(file)])
    err = capsys.readouterr().err
    assert status in {0, 1}, err
    assert "internal error" not in err
