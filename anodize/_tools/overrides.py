"""Command-line overrides of a system file: ``-p Role.name=value`` and ``-r from:=to``.

As ``ros2 run ... --ros-args -p name:=value -r from:=to``, but a parameter names its
role (the roles of a system are its nodes), and its value is a TOML value, as the
system file writes it: ``-p Planner.speed=0.3``, ``-p Cam.name='"front"'``,
``-p Patrol.waypoints=[1, 2, 3]``, ``-p Joy.enabled=true``.
"""

from __future__ import annotations

import re
import tomllib

from .._supervision.params import ParamValue
from .config_error import COMMAND_LINE, ConfigError

__all__ = ["parse_param", "parse_remap"]

_PARAM = re.compile(r"\s*([A-Za-z_]\w*)\.([A-Za-z_]\w*)\s*=(.*)", re.S)


def parse_param(given: str) -> tuple[str, str, ParamValue]:
    """``"Planner.speed=0.3"`` -> ``("Planner", "speed", 0.3)``.

    Raises:
        ConfigError: (on the command line) not ``Role.name=value``, or the value is not TOML.
    """
    match = _PARAM.fullmatch(given)
    if match is None:
        raise ConfigError(COMMAND_LINE, f"-p {given}", "expected Role.name=value, such as Planner.speed=0.3")
    role, name, text = match.groups()
    try:
        value = tomllib.loads(f"value = {text.strip()}")["value"]
    except RecursionError:
        raise ConfigError(COMMAND_LINE, f"-p {role}.{name}", "a value nested too deeply to read") from None
    except tomllib.TOMLDecodeError:
        hint = f" (a string is quoted: -p '{role}.{name}=\"{text.strip()}\"')" if text.strip() else ""
        got = text.strip() or "nothing"
        raise ConfigError(COMMAND_LINE, f"-p {role}.{name}",
                          f'expected a TOML value such as 0.3, true, "text" or [1, 2], got {got}{hint}') from None
    return role, name, value


def parse_remap(given: str) -> tuple[str, str]:
    """``"/cmd_vel:=/r1/cmd_vel"`` -> ``("/cmd_vel", "/r1/cmd_vel")`` (names are checked with the bridge).

    Raises:
        ConfigError: (on the command line) not ``from:=to``.
    """
    source, sep, target = given.partition(":=")
    if not sep or not source.strip() or not target.strip():
        raise ConfigError(COMMAND_LINE, f"-r {given}", "expected from:=to, such as /cmd_vel:=/r1/cmd_vel")
    return source.strip(), target.strip()
