"""The version ``anodize --version`` prints: the installed distribution's, else the checkout's."""

from __future__ import annotations

import importlib.metadata
import tomllib
from pathlib import Path

DISTRIBUTION = "anodize"
# The checkout's pyproject.toml, two levels above this package: anodize/_tools/version.py.
_CHECKOUT_PROJECT = Path(__file__).resolve().parents[2] / "pyproject.toml"


def distribution_version(name: str, project_file: Path) -> str:
    """The version of distribution ``name``: from its metadata when it is installed, else from
    ``project_file`` (a checkout run with PYTHONPATH and no install), else ``"unknown"``."""
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        pass
    try:
        with project_file.open("rb") as file:
            project = tomllib.load(file).get("project", {})
    except (OSError, tomllib.TOMLDecodeError):
        return "unknown"
    version = project.get("version") if project.get("name") == name else None
    return version if isinstance(version, str) else "unknown"


def version_line() -> str:
    """``anodize X.Y.Z``, what ``anodize --version`` prints."""
    return f"{DISTRIBUTION} {distribution_version(DISTRIBUTION, _CHECKOUT_PROJECT)}"
