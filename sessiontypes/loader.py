"""Reading protocol files: text in, checked :class:`ProtocolModule` out."""

from __future__ import annotations

from pathlib import Path

from .check import ProtocolModule, check_file
from .errors import ProtocolCheckError
from .parse import parse_file

__all__ = ["load", "loads"]


def loads(text: str, path: str = "<string>") -> ProtocolModule:
    """Parse and check protocol ``text``.

    Returns:
        The checked module; warnings are in ``module.warnings``.

    Raises:
        ProtocolSyntaxError: the text does not parse.
        ProtocolCheckError: it parses but is not well formed (all errors at once).
    """
    source = parse_file(text, path)
    module, diagnostics = check_file(source)
    if any(d.severity == "error" for d in diagnostics):
        raise ProtocolCheckError(diagnostics)
    return module


def load(path: str | Path) -> ProtocolModule:
    """Read, parse and check the protocol file at ``path`` (see :func:`loads`).

    Raises:
        OSError: the file cannot be read.
        ProtocolError: as :func:`loads`.
    """
    text = Path(path).read_text(encoding="utf-8")
    return loads(text, str(path))
