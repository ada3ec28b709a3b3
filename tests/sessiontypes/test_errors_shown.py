"""How a place in a protocol's source is shown: a line and a caret, bounded whatever the line."""

from __future__ import annotations

import sessiontypes
from sessiontypes.errors import SHOWN_WIDTH, ProtocolSyntaxError, caret_block, shortened


def test_a_short_line_is_shown_whole_with_the_caret_under_its_column() -> None:
    assert caret_block("global G(A, B) = A -> B : m. end", 18) == (
        "    global G(A, B) = A -> B : m. end\n                     ^")


def test_a_long_line_is_shown_as_a_window_around_the_column() -> None:
    line = "x" * 10_000 + "!" + "y" * 10_000
    text, caret = caret_block(line, 10_001).split("\n")
    assert len(text) <= 4 + SHOWN_WIDTH + 6 and text.startswith("    ...") and text.endswith("...")
    assert text[caret.index("^")] == "!"  # the caret is still under its character
    start_text, start_caret = caret_block("!" + "y" * 10_000, 1).split("\n")
    assert start_text.startswith("    !") and start_caret == "    ^"


def test_a_token_of_megabytes_gives_an_error_of_a_few_lines() -> None:
    source = "global G(A, B) = A -> B : m. end " + "z" * 2_000_000
    try:
        sessiontypes.loads(source, "huge.proto")
    except ProtocolSyntaxError as error:
        shown = str(error)
    else:
        raise AssertionError("a stray name after the declaration parsed")
    assert len(shown) < 1_000 and shown.startswith("huge.proto:1:")
    assert shortened("a" * 1000).count("a") < 60 and shortened("short") == "short"
