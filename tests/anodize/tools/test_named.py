"""Named systems: 'anodize run NAME' finds what packages register under anodize.systems."""

from __future__ import annotations

import pytest

from anodize._tools import cli
from anodize._tools.named import find_named, named_systems


def test_the_installed_tinman_package_registers_its_system() -> None:
    assert "tinman" in named_systems()
    tinman = find_named("tinman")
    assert tinman is not None and "TinMan" in tinman.summary


def test_an_unknown_name_is_not_found() -> None:
    assert find_named("no-such-system") is None


def test_run_of_an_unknown_name_says_what_it_accepts(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["run", "no-such-system"]) == 2
    err = capsys.readouterr().err
    assert err == ("anodize run: error: no such system file or named system (named systems: tinman): "
                   "no-such-system\n")


def test_a_named_system_parses_its_own_options(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["run", "tinman", "--inject", "memory-hog=nowhere", "--dataset", "."]) == 1
    assert capsys.readouterr().err == (
        "error: --inject memory-hog=nowhere: no group 'nowhere'; expected one of control, perception, "
        "planning, simulation\n")
    assert cli.main(["run", "tinman", "--no-such-option"]) == 2
    assert "unrecognized arguments: --no-such-option" in capsys.readouterr().err
    assert cli.main(["run", "tinman", "--duration", "0"]) == 1
    assert "--duration 0.0: expected a number of seconds > 0" in capsys.readouterr().err
