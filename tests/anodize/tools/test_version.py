"""``anodize --version`` and ``tinman --version``: the distribution's version, installed or not."""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from anodize._tools.cli import main
from anodize._tools.version import distribution_version
from tinman.cli import main as tinman_main

REPO = Path(__file__).resolve().parents[3]


def _declared(project: Path) -> str:
    version = tomllib.loads(project.read_text(encoding="utf-8"))["project"]["version"]
    assert isinstance(version, str)
    return version


def test_anodize_version_prints_the_projects_version(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--version"]) == 0
    out, err = capsys.readouterr()
    assert (out, err) == (f"anodize {_declared(REPO / 'pyproject.toml')}\n", "")


def test_tinman_version_names_both_distributions(capsys: pytest.CaptureFixture[str]) -> None:
    assert tinman_main(["--version"]) == 0
    out, err = capsys.readouterr()
    expected = f"tinman {_declared(REPO / 'tinman' / 'pyproject.toml')} (anodize {_declared(REPO / 'pyproject.toml')})"
    assert (out, err) == (expected + "\n", "")


def test_the_installed_command_answers_version() -> None:
    done = subprocess.run([sys.executable, "-m", "anodize._tools.cli", "--version"], cwd=REPO,
                          capture_output=True, text=True, timeout=60, check=False)
    assert (done.returncode, done.stderr) == (0, "")
    assert re.fullmatch(r"anodize \d+\.\d+\.\d+\S*\n", done.stdout)


def test_a_checkout_without_an_install_reads_its_pyproject(tmp_path: Path) -> None:
    project = tmp_path / "pyproject.toml"
    name = "anodize-not-installed-anywhere"
    assert distribution_version(name, project) == "unknown"  # no metadata and no file
    project.write_text(f'[project]\nname = "{name}"\nversion = "9.8.7"\n', encoding="utf-8")
    assert distribution_version(name, project) == "9.8.7"
    project.write_text('[project]\nname = "someone-else"\nversion = "1.0"\n', encoding="utf-8")
    assert distribution_version(name, project) == "unknown"  # another project's file is not ours
    project.write_text("[project\n", encoding="utf-8")
    assert distribution_version(name, project) == "unknown"
