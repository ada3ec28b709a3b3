"""Reading protocol files: text in, checked :class:`ProtocolModule` out."""

from __future__ import annotations

from pathlib import Path, PurePath

from .check import ProtocolModule, check_file
from .errors import ProtocolCheckError, ProtocolEncodingError
from .foreign import FOREIGN_SUFFIXES, parse_foreign
from .limits import PROTOCOL, read_limited
from .location import Location
from .parse import parse_file

__all__ = ["load", "loads", "read_source"]


def loads(text: str, path: str = "<string>") -> ProtocolModule:
    """Parse and check protocol ``text``.

    A ``path`` ending in ``.scr`` (Scribble) or ``.nuscr`` (nuScr) is read as that
    language's global protocols (see :mod:`sessiontypes.foreign`); any other as ``.proto``.

    Returns:
        The checked module; warnings are in ``module.warnings``.

    Raises:
        ProtocolSyntaxError: the text does not parse.
        ProtocolCheckError: it parses but is not well formed (all errors at once).
        UnsupportedConstructError: a Scribble or nuScr construct outside the subset read.
    """
    language = FOREIGN_SUFFIXES.get(PurePath(path).suffix.lower())
    source = parse_foreign(text, path, language) if language else parse_file(text, path)
    module, diagnostics = check_file(source)
    if any(d.severity == "error" for d in diagnostics):
        raise ProtocolCheckError(diagnostics)
    return module


def load(path: str | Path) -> ProtocolModule:
    """Read, parse and check the protocol file at ``path`` (see :func:`loads`).

    Raises:
        OSError: the file cannot be read.
        ProtocolEncodingError: the file is not UTF-8 text.
        ProtocolError: as :func:`loads`.
    """
    return loads(read_source(path), str(path))


def read_source(path: str | Path) -> str:
    """Return the text of the protocol file at ``path``.

    The file is UTF-8; line ends ("\\r\\n", "\\r", "\\n") are read as "\\n", as
    :meth:`pathlib.Path.read_text` does.

    Raises:
        OSError: the file cannot be read.
        InputLimitError: (an OSError) not a regular file, or larger than the limit
            (:data:`sessiontypes.limits.PROTOCOL`).
        ProtocolEncodingError: the file is not UTF-8 text; located at the first
            byte that cannot be decoded.
    """
    data = read_limited(path, PROTOCOL)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise _encoding_error(data, error.start, str(path)) from None
    return _universal_newlines(text)


def _universal_newlines(text: str) -> str:
    return text.replace("\r\n", "\n").replace("\r", "\n")


def _encoding_error(data: bytes, start: int, path: str) -> ProtocolEncodingError:
    """The error for the byte at ``start``, located as the parser would locate it."""
    before = _universal_newlines(data[:start].decode("utf-8"))  # decodes: the bad byte comes after
    line = before.count("\n") + 1
    column = len(before) - (before.rfind("\n") + 1) + 1
    lines = _universal_newlines(data.decode("utf-8", errors="replace")).split("\n")
    return ProtocolEncodingError(Location(path, line, column), data[start], lines[line - 1])
