"""The isolation lint on the role modules of lint_fixtures/: what it finds, and what it must not."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from anodize._tools.config import ConfigError, SystemConfig, load_config
from anodize._tools.lint import Finding, lint_report, lint_system

REPO = Path(__file__).resolve().parents[3]
FIXTURES = REPO / "tests" / "anodize" / "lint_fixtures"
SHOWN = "tests/anodize/lint_fixtures"  # paths in findings are relative to the working directory


@pytest.fixture(autouse=True)
def _from_repo_root(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(REPO)


def system(tmp_path: Path, *groups: dict[str, str]) -> SystemConfig:
    """A system file in tmp_path with one group per dict (role -> 'module:function'), named
    a, b, c...; roles are looked up in lint_fixtures/, then in tmp_path."""
    lines = ['protocol = "stream.proto"', 'global = "Stream"', f'pythonpath = ["{FIXTURES}", "."]']
    for name, roles in zip("abcdef", groups, strict=False):  # fewer groups than names
        entries = ", ".join(f'{role} = "{reference}"' for role, reference in roles.items())
        lines += [f"[groups.{name}]", f"roles = {{ {entries} }}"]
    path = tmp_path / "system.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return load_config(path)


def messages(config: SystemConfig) -> list[str]:
    return [str(finding) for finding in lint_system(config)]


def test_a_list_used_by_two_groups_is_reported_at_its_definition(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "shared_list:producer"}, {"C": "shared_list:consumer"})
    assert lint_system(config) == [Finding(
        f"{SHOWN}/shared_list.py", 5, 1, None, None,
        "list buffer is shared by group a (P) and group b (C) outside the protocol "
        "(P: 11:9 calls .append(); C: 18:12 uses)")]


def test_a_list_used_by_one_group_only_is_not_reported(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "shared_list:producer", "C": "shared_list:consumer"})
    assert lint_system(config) == []


def test_one_finding_per_pair_of_groups(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "shared_list:producer"}, {"C": "shared_list:consumer"},
                    {"D": "shared_list:consumer"})
    assert [m.partition(" outside")[0] for m in messages(config)] == [
        f"{SHOWN}/shared_list.py:5:1: warning: list buffer is shared by group a (P) and group b (C)",
        f"{SHOWN}/shared_list.py:5:1: warning: list buffer is shared by group a (P) and group c (D)",
        f"{SHOWN}/shared_list.py:5:1: warning: list buffer is shared by group b (C) and group c (D)",
    ]


def test_a_shared_lock_or_queue_is_a_back_channel(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "back_channel:producer"}, {"C": "back_channel:consumer"})
    assert messages(config) == [
        (f"{SHOWN}/back_channel.py:6:1: warning: threading.Lock lock is shared by group a (P) and "
         "group b (C): used as a back channel outside the protocol "
         "(P: 13:10 enters it (with); C: 19:10 enters it (with))"),
        (f"{SHOWN}/back_channel.py:7:1: warning: queue.Queue handoff is shared by group a (P) and "
         "group b (C): used as a back channel outside the protocol "
         "(P: 14:9 calls .put(); C: 21:5 calls .get())"),
    ]


def test_a_global_statement_is_reported_with_its_role(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "global_counter:producer"}, {"C": "global_counter:consumer"})
    findings = lint_system(config)
    assert [str(f) for f in findings] == [
        (f"{SHOWN}/global_counter.py:3:1: warning: variable count is shared by group a (P) and "
         "group b (C) outside the protocol (P: 8:5 assigns; C: 14:12 uses)"),
        (f"{SHOWN}/global_counter.py:7:5: warning: global statement: role P (group a) rebinds "
         "module-level count, which every thread of the process shares outside the protocol"),
    ]
    assert (findings[1].role, findings[1].group) == ("P", "a")


def test_a_global_statement_is_reported_even_within_one_group(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "global_counter:producer", "C": "global_counter:consumer"})
    assert [(f.line, f.role) for f in lint_system(config)] == [(7, "P")]


def test_constants_imports_functions_and_locals_are_not_findings(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "constants:producer"}, {"C": "constants:consumer"})
    assert lint_system(config) == []


def test_state_touched_only_in_helpers_is_found_through_the_calls(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "transitive:producer"}, {"C": "transitive:consumer"})
    assert messages(config) == [
        (f"{SHOWN}/transitive.py:3:1: warning: dict _cache is shared by group a (P) and group b (C) "
         "outside the protocol (P: 7:5 changes an item; C: 15:12 calls .get())")]


def test_state_of_another_module_and_an_imported_role_function(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "postbox_roles:producer"}, {"C": "postbox_roles:consumer"})
    report = lint_report(config)
    assert [str(f) for f in report.findings] == [
        (f"{SHOWN}/postbox.py:5:1: warning: queue.SimpleQueue MAILBOX is shared by group a (P) and "
         "group b (C): used as a back channel outside the protocol "
         f"(P: {SHOWN}/postbox_producer.py:7:5 calls .put(); C: {SHOWN}/postbox_roles.py:9:12 calls .get())")]
    assert report.modules == (f"{SHOWN}/postbox.py", f"{SHOWN}/postbox_producer.py",
                              f"{SHOWN}/postbox_roles.py")


def test_state_of_a_package_submodule_and_the_runtime_is_not_read(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "plant_roles:producer"}, {"C": "plant_roles:consumer"})
    report = lint_report(config)
    assert [str(f) for f in report.findings] == [
        (f"{SHOWN}/plant/state.py:3:1: warning: list events is shared by group a (P) and group b (C) "
         f"outside the protocol (P: {SHOWN}/plant_roles.py:10:5 calls .append(); "
         f"C: {SHOWN}/plant_roles.py:16:5 calls .clear())")]
    assert report.modules == (f"{SHOWN}/plant/__init__.py", f"{SHOWN}/plant/state.py",
                              f"{SHOWN}/plant_roles.py")


def test_class_attributes_shared_by_static_and_class_method_roles(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "class_roles:Station.producer"}, {"C": "class_roles:Station.consumer"})
    assert messages(config) == [
        (f"{SHOWN}/class_roles.py:5:5: warning: list Station.log is shared by group a (P) and "
         "group b (C) outside the protocol (P: 9:9 calls .append(); C: 15:16 uses)")]


def test_methods_of_one_module_level_object_share_it(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "class_roles:robot.drive"}, {"C": "class_roles:robot.watch"})
    assert messages(config) == [
        (f"{SHOWN}/class_roles.py:34:1: warning: Robot instance robot is shared by group a (P) and "
         "group b (C) outside the protocol (P: 23:9 sets .speed; C: 31:16 reads .speed)")]


def test_attributes_a_role_assigns_make_state_of_a_class_and_a_module(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "assigned_attributes:producer"}, {"C": "assigned_attributes:consumer"})
    assert messages(config) == [
        (f"{SHOWN}/assigned_attributes.py:7:5: warning: class attribute Tuning.speed is shared by "
         "group a (P) and group b (C) outside the protocol (P: 11:5 assigns; C: 18:12 uses)"),
        (f"{SHOWN}/assigned_attributes.py:12:5: warning: module attribute postbox.flag is shared by "
         "group a (P) and group b (C) outside the protocol (P: 12:5 assigns; C: 18:26 uses)"),
    ]


def test_findings_are_sorted_and_without_duplicates(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "back_channel:producer", "Q": "back_channel:producer"},
                    {"C": "back_channel:consumer"})
    findings = lint_system(config)
    assert findings == sorted(set(findings), key=lambda f: (f.path, f.line, f.col, f.message))
    assert "group a (P, Q) and group b (C)" in findings[0].message


def test_the_lint_never_imports_role_modules(tmp_path: Path) -> None:
    before = set(sys.modules)
    lint_system(system(tmp_path, {"P": "postbox_roles:producer"}, {"C": "postbox_roles:consumer"}))
    assert not {"postbox", "postbox_roles", "postbox_producer"} & (set(sys.modules) - before)


def test_a_module_that_cannot_be_found(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "no_such_module:producer"}, {"C": "shared_list:consumer"})
    with pytest.raises(ConfigError) as caught:
        lint_system(config)
    assert str(caught.value) == (f"{config.path}: groups.a.roles.P: cannot find the source of module "
                                 f"no_such_module on the pythonpath ({FIXTURES}, {tmp_path}) or sys.path")


def test_a_function_the_module_does_not_have(tmp_path: Path) -> None:
    config = system(tmp_path, {"P": "shared_list:produce"}, {"C": "shared_list:consumer"})
    with pytest.raises(ConfigError) as caught:
        lint_system(config)
    assert str(caught.value) == (f"{config.path}: groups.a.roles.P: module shared_list "
                                 f"({SHOWN}/shared_list.py) has no produce")


def test_a_role_bound_to_something_that_is_not_a_def_is_reported_unchecked(tmp_path: Path) -> None:
    (tmp_path / "made.py").write_text("import functools\n\n"
                                      "def run(ep, n): pass\n\n"
                                      "producer = functools.partial(run, n=1)\n", encoding="utf-8")
    config = system(tmp_path, {"P": "made:producer"}, {"C": "shared_list:consumer"})
    assert [(f.line, f.col, f.role, f.message) for f in lint_system(config)] == [
        (5, 1, "P", "role P: made:producer is not a function anodize can read, so its code was not checked")]


def test_finding_text() -> None:
    finding = Finding("m.py", 3, 7, "A", "g", "something is shared")
    assert str(finding) == "m.py:3:7: warning: something is shared"
