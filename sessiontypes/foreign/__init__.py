"""Reading Scribble (``.scr``) and nuScr (``.nuscr``) global protocols.

The subset read maps onto the ``.proto`` language: messages (a multicast is a
send to each receiver in turn), ``choice``, ``rec``/``continue``, ``par``, and
``do`` of a protocol of the same file, inlined. A file becomes the surface
syntax of a ``.proto`` file with locations in the original, so checking,
projection and their errors work unchanged. See docs/foreign.md.
"""

from __future__ import annotations

from ..deep import run_deep
from ..syntax import SourceFile
from .errors import UnsupportedConstructError
from .read import read_module
from .translate import translate

__all__ = ["FOREIGN_SUFFIXES", "UnsupportedConstructError", "parse_foreign"]

# The suffixes read, and the language of each.
FOREIGN_SUFFIXES = {".scr": "scribble", ".nuscr": "nuscr"}


def parse_foreign(text: str, path: str, language: str) -> SourceFile:
    """Read the global protocols of a Scribble or nuScr file as ``.proto`` syntax.

    Args:
        text: the file's text.
        path: where it was read from (for locations).
        language: ``"scribble"`` or ``"nuscr"`` (see :data:`FOREIGN_SUFFIXES`).

    Returns:
        One ``global`` per protocol that is not ``aux``, and a ``type`` for each
        payload type that is not a builtin sort.

    Raises:
        ProtocolSyntaxError: the text does not follow the language's grammar.
        UnsupportedConstructError: it uses a construct outside the subset read.
        ProtocolCheckError: a problem found while translating (an unknown
            payload type in Scribble, ``continue`` without its ``rec``, ...), or
            blocks nested deeper than :data:`~sessiontypes.foreign.read.MAX_NESTING`.
    """
    return run_deep(_parse, text, path, language)


def _parse(text: str, path: str, language: str) -> SourceFile:
    # Nesting recurses (up to MAX_NESTING levels): where deep recursion is safe.
    lines = _lines(text)
    return translate(read_module(text, path, language, lines), path, lines)


def _lines(text: str) -> tuple[str, ...]:
    lines = text.split("\n")
    if not lines[-1]:
        lines.pop()
    return tuple(line.removesuffix("\r") for line in lines)
