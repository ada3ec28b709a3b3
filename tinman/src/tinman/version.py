"""The version ``tinman --version`` prints: the installed distribution's, else the checkout's."""

from __future__ import annotations

import importlib.metadata
import tomllib
from pathlib import Path

DISTRIBUTION = "anodize-tinman"  # the distribution's name (tinman/pyproject.toml); the command is tinman
# The checkout's tinman/pyproject.toml, two levels above this package: tinman/src/tinman/version.py.
_CHECKOUT_PROJECT = Path(__file__).resolve().parents[2] / "pyproject.toml"


def _version(name: str, project_file: Path) -> str:
    """The version of distribution ``name``: its metadata's when installed, else ``project_file``'s."""
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
    """``tinman X.Y.Z (anodize X.Y.Z)``, what ``tinman --version`` prints: TinMan is released
    with the anodize it was tested against, so a report names both."""
    anodize_project = _CHECKOUT_PROJECT.parents[1] / "pyproject.toml"
    return f"tinman {_version(DISTRIBUTION, _CHECKOUT_PROJECT)} (anodize {_version('anodize', anodize_project)})"
