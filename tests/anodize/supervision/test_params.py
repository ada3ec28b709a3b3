"""Role parameters: checked against the role's function, delivered as keyword arguments on every transport."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from dds_hosts import domain
from param_roles import consumer, needs_rate, producer

import sessiontypes
from anodize import Dds, Inproc, Processes, System
from anodize._supervision.params import check_params, check_value
from anodize.errors import ConfigurationError, ParameterError

STREAM = sessiontypes.loads("global Stream(P, C) = mu t. P -> C : { data(int). t, stop. end }\n").globals["Stream"]


def _system(transport: object, params: dict[str, dict[str, object]], p: object = producer) -> System:
    system = System(STREAM, transport=transport, params=params)  # type: ignore[arg-type]
    system.group("a").role("P", p)  # type: ignore[arg-type]
    system.group("b").role("C", consumer)
    return system


@pytest.mark.parametrize("transport", [
    Inproc(), Processes(),
    pytest.param(Dds(domain=domain(), run_id=f"params-{os.getpid()}"), marks=pytest.mark.slow),
], ids=["inproc", "process", "dds"])
def test_parameters_reach_each_role_as_keyword_arguments(tmp_path: Path, transport: object) -> None:
    given, seen = tmp_path / "given.json", tmp_path / "seen.txt"
    system = _system(transport, {"P": {"count": 5, "gain": 2, "tag": "x", "flags": [True, False], "out": str(given)},
                                 "C": {"out": str(seen)}})
    report = system.run(timeout=30)
    assert report.ok, report.summary()
    assert json.loads(given.read_text()) == {"count": 5, "gain": 2.0, "gain_type": "float", "tag": "x",
                                             "flags": [True, False]}
    assert seen.read_text() == "5"


def test_a_role_without_parameters_runs_on_its_defaults(tmp_path: Path) -> None:
    seen = tmp_path / "seen.txt"
    assert _system(Inproc(), {"C": {"out": str(seen)}}).run(timeout=10).ok
    assert seen.read_text() == "3"


@pytest.mark.parametrize(("params", "message"), [
    ({"P": {"speed": 1.0}}, ("role P: parameter speed: producer takes no such parameter; its parameters: count, "
                             "flags, gain, out, tag")),
    ({"P": {"count": 2.5}}, "role P: parameter count: expected int, got float (2.5)"),
    ({"P": {"count": True}}, "role P: parameter count: expected int, got bool (true)"),
    ({"P": {"tag": 3}}, "role P: parameter tag: expected str, got int (3)"),
    ({"P": {"flags": [1, 2]}}, "role P: parameter flags: expected list[bool] | None, got list[int] ([1, 2])"),
])
def test_a_parameter_the_function_does_not_take_as_given_is_refused_before_the_run(
        params: dict[str, dict[str, object]], message: str) -> None:
    system = _system(Inproc(), params)
    with pytest.raises(ConfigurationError, match=r"^" + _escaped(message) + r"$"):
        system.check_params()
    with pytest.raises(ConfigurationError, match=r"^" + _escaped(message) + r"$"):
        system.run(timeout=5)


def test_a_keyword_parameter_without_default_needs_a_value() -> None:
    with pytest.raises(ParameterError, match=r"^role P: parameter rate: needs_rate declares no default and no value "
                                             r"is given \(\[params\.P\] rate = \.\.\.\)$") as raised:
        _system(Inproc(), {}, needs_rate).check_params()
    assert (raised.value.role, raised.value.parameter) == ("P", "rate")
    assert _system(Inproc(), {"P": {"rate": 2}}, needs_rate).check_params() == {"P": {"rate": 2.0}}


def test_the_system_refuses_an_unknown_role_and_a_value_no_ros_parameter_has() -> None:
    with pytest.raises(ConfigurationError, match=r"^role Q: global Stream has no such role, so it "
                                                 r"takes no parameters; expected one of P, C$"):
        System(STREAM, params={"Q": {"x": 1}})
    with pytest.raises(ConfigurationError, match=r"^role P: parameter x: expected an array of one type \(bool, int, "
                                                 r"float or str, as ROS parameters\), got list\[int \| str\]$"):
        System(STREAM, params={"P": {"x": [1, "a"]}})  # type: ignore[dict-item]
    with pytest.raises(ConfigurationError, match=r"^role P: parameter x: expected a bool, int, float, str or an "
                                                 r"array of one of them \(as ROS parameters\), got dict$"):
        System(STREAM, params={"P": {"x": {"a": 1}}})  # type: ignore[dict-item]


def test_values_are_ros_parameter_types() -> None:
    assert check_value("R", "xs", [1, 2.5]) == [1.0, 2.5]
    assert check_value("R", "xs", []) == []
    assert check_params("R", producer, {"gain": 1}) == {"gain": 1.0}


def _escaped(text: str) -> str:
    import re

    return re.escape(text)
