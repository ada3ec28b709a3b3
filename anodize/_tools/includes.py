"""``include = ["base.toml", ...]``: a system file built on others.

Each included file is read (its own includes first, in order), then the including
file's tables are laid over them key by key: a table present in both is merged, any
other value (a string, a number, an array) of the including file replaces the
included one. Later includes win over earlier ones the same way. Paths inside an
included file (``protocol``, ``pythonpath``) stay relative to that file. An include
cycle is refused at the ``include`` key of the file that closes it.
"""

from __future__ import annotations

import json
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sessiontypes.limits import SYSTEM_FILE, read_limited

from .config_error import ConfigError, syntax_error

__all__ = ["SystemData", "read_system_data"]

MAX_DEPTH = 16  # includes within includes; a deeper chain is surely a mistake
_PATH_KEYS = ("protocol",)  # relative to the file that writes them
_PATH_LISTS = ("pythonpath",)


@dataclass
class SystemData:
    """A system file's TOML with its includes laid under it.

    Attributes:
        data: the merged tables.
        origins: dotted key -> the file that gave its value (for messages); keys not
            listed come from the file that was read first.
    """

    data: dict[str, Any]
    origins: dict[str, str] = field(default_factory=dict)

    def origin(self, key: str | None, default: str) -> str:
        """The file that wrote ``key`` (or its nearest enclosing table), else ``default``."""
        while key:
            if key in self.origins:
                return self.origins[key]
            key = key.rpartition(".")[0]
        return default


def read_system_data(path: Path, shown: str) -> SystemData:
    """Read the system file ``path`` and every file it includes, merged.

    Raises:
        ConfigError: a file cannot be read or is not TOML, ``include`` is not an array of
            paths, an include cycle, or includes nested deeper than 16.
    """
    return _read(path, shown, ())


def _read(path: Path, shown: str, chain: tuple[Path, ...]) -> SystemData:
    data = _parse(path, shown)
    given = data.pop("include", [])
    if not isinstance(given, list) or not all(isinstance(p, str) and p and "\0" not in p for p in given):
        raise ConfigError(shown, "include", 'expected an array of system files such as ["base.toml"], '
                                            f"got {json.dumps(given, default=str)}")
    here = Path(os.path.realpath(path))
    merged = SystemData({})
    for entry in given:
        included = path.parent / entry
        resolved = Path(os.path.realpath(included))
        if resolved in (*chain, here):
            cycle = " -> ".join(str(p) for p in (*chain, here, resolved))
            raise ConfigError(shown, "include", f"include cycle: {cycle}")
        if len(chain) >= MAX_DEPTH:
            raise ConfigError(shown, "include", f"includes nested deeper than {MAX_DEPTH}")
        if not included.is_file():
            raise ConfigError(shown, "include", f"cannot read {entry}: no such file (paths are relative to the "
                                                "including file's folder)")
        below = _read(included, str(included), (*chain, here))
        _anchor(below.data, included.parent)
        _lay_over(merged.data, below.data, below.origins, str(included), "", merged.origins)
    if not given:
        return SystemData(data)
    _lay_over(merged.data, data, {}, shown, "", merged.origins)
    return merged


def _parse(path: Path, shown: str) -> dict[str, Any]:
    try:
        text = read_limited(path, SYSTEM_FILE).decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(shown, None, "expected UTF-8 text") from None
    except OSError as error:
        raise ConfigError(shown, None, f"cannot read: {error.strerror or error}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise syntax_error(shown, text, str(error)) from None
    except RecursionError:  # tomllib recurses once per level of nested arrays and tables
        raise ConfigError(shown, None, "arrays or tables nested too deeply; expected at most a few levels") from None


def _anchor(data: dict[str, Any], directory: Path) -> None:
    """Make an included file's paths absolute, so that they keep meaning what its author wrote."""
    for key in _PATH_KEYS:
        if isinstance(data.get(key), str):
            data[key] = os.path.abspath(directory / data[key])
    for key in _PATH_LISTS:
        value = data.get(key)
        if isinstance(value, list) and all(isinstance(v, str) for v in value):
            data[key] = [os.path.abspath(directory / v) for v in value]


def _lay_over(target: dict[str, Any], data: dict[str, Any], origins: dict[str, str], file: str, prefix: str,
              merged: dict[str, str]) -> None:
    """Lay ``data`` (from ``file``; its own includes' keys named in ``origins``) over ``target``,
    noting in ``merged`` where each value written came from."""
    for key, value in data.items():
        dotted = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict) and isinstance(target.get(key), dict):
            _lay_over(target[key], value, origins, file, dotted, merged)
            continue
        target[key] = value
        for known in [k for k in merged if k == dotted or k.startswith(dotted + ".")]:
            del merged[known]
        merged[dotted] = file
        merged.update({k: v for k, v in origins.items() if k == dotted or k.startswith(dotted + ".")})
