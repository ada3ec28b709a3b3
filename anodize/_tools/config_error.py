"""The error a system file is refused with: the file, the key at fault, and the problem."""

from __future__ import annotations

import re

from ..errors import ConfigurationError

__all__ = ["ConfigError", "syntax_error", "COMMAND_LINE"]

COMMAND_LINE = "command line"  # the path of an error in what -p, -r or --namespace gave

_TOML_POSITION = re.compile(r"^(.*) \(at (?:line (\d+), column (\d+)|end of document)\)$", re.S)


class ConfigError(ConfigurationError):
    """Raised for a system file that cannot be read, parsed, or turned into a system.

    Attributes:
        path: the system file, as given.
        key: the dotted key at fault (``groups.control.priority``), or None.
        problem: what is wrong, e.g. ``expected an int 1..99, got 120``.
        line: for TOML syntax errors, the 1-based line (else None).
        column: for TOML syntax errors, the 1-based column (else None).
        source_line: for TOML syntax errors, the text of that line.
    """

    def __init__(self, path: str, key: str | None, problem: str, line: int | None = None,
                 column: int | None = None, source_line: str = "") -> None:
        self.path = path
        self.key = key
        self.problem = problem
        self.line = line
        self.column = column
        self.source_line = source_line
        super().__init__(str(self))

    @property
    def on_command_line(self) -> bool:
        """Whether the fault is in a command-line override (``-p``, ``-r``, ``--namespace``): a usage error."""
        return self.path == COMMAND_LINE

    def __str__(self) -> str:
        if self.line is not None:
            caret = " " * ((self.column or 1) - 1) + "^"
            context = f"\n    {self.source_line}\n    {caret}" if self.source_line.strip() else ""
            return f"{self.path}:{self.line}:{self.column}: {self.problem}{context}"
        if self.key is None:
            return f"{self.path}: {self.problem}"
        return f"{self.path}: {self.key}: {self.problem}"


def syntax_error(shown: str, text: str, message: str) -> ConfigError:
    """A TOML syntax error of ``text`` as a ConfigError at its line and column."""
    match = _TOML_POSITION.match(message)
    problem = match.group(1) if match else message
    problem = problem[:1].lower() + problem[1:]
    lines = text.split("\n")
    if match and match.group(2):
        line, column = int(match.group(2)), int(match.group(3))
    else:  # "at end of document"
        line, column = len(lines), len(lines[-1]) + 1
    source = lines[line - 1] if 0 < line <= len(lines) else ""
    return ConfigError(shown, None, problem, line, column, source)
