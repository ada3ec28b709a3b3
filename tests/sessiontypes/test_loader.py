"""Reading protocol files: the bytes of a file become text, or a located error."""

from __future__ import annotations

from pathlib import Path

import pytest

import sessiontypes
from anodize._tools.cli import main
from sessiontypes import Diagnostic, Location, ProtocolEncodingError, ProtocolError


def _write(tmp_path: Path, data: bytes) -> Path:
    path = tmp_path / "p.proto"
    path.write_bytes(data)
    return path


def test_a_file_that_is_not_utf8_is_a_located_protocol_error(tmp_path: Path) -> None:
    # Latin-1 text: 'é' is the single byte 0xe9.
    path = _write(tmp_path, b"global P = A -> B : ping\n// caf\xe9 au lait\n")
    with pytest.raises(ProtocolEncodingError) as caught:
        sessiontypes.load(path)
    error = caught.value
    assert isinstance(error, ProtocolError)
    assert error.location == Location(str(path), 2, 7)
    assert error.byte == 0xE9
    assert error.source_line == "// caf\ufffd au lait"
    assert error.message == "the file is not UTF-8 text: byte 0xe9 cannot be decoded"
    assert error.diagnostics == (Diagnostic("error", error.location, error.message, error.source_line),)
    assert str(error) == (
        f"{path}:2:7: error: the file is not UTF-8 text: byte 0xe9 cannot be decoded\n"
        "    // caf\ufffd au lait\n"
        "          ^"
    )


def test_the_column_counts_characters_and_lines_end_as_in_text_mode(tmp_path: Path) -> None:
    # 'μ' is two bytes but one column; '\r\n' and a lone '\r' each end one line.
    path = _write(tmp_path, b"global P =\r\n  A -> B :\r  \xce\xbc \xff x\r\n")
    with pytest.raises(ProtocolEncodingError) as caught:
        sessiontypes.load(path)
    assert str(caught.value) == (
        f"{path}:3:5: error: the file is not UTF-8 text: byte 0xff cannot be decoded\n"
        "      \u03bc \ufffd x\n"
        "        ^"
    )


def test_a_utf16_file_is_reported_at_its_first_byte(tmp_path: Path) -> None:
    path = _write(tmp_path, "global P = A -> B : x".encode("utf-16"))
    with pytest.raises(ProtocolEncodingError) as caught:
        sessiontypes.load(path)
    assert caught.value.location == Location(str(path), 1, 1)
    assert caught.value.message == "the file is not UTF-8 text: byte 0xff cannot be decoded"


def test_read_source_reads_line_ends_as_newlines(tmp_path: Path) -> None:
    path = _write(tmp_path, b"global P =\r\n  A -> B : x.\r  B -> A : y\n")
    assert sessiontypes.read_source(path) == "global P =\n  A -> B : x.\n  B -> A : y\n"
    assert str(sessiontypes.load(path).globals["P"].project("A")) == "!B(x).?B(y)"


def test_a_utf8_file_with_a_byte_order_mark_loads(tmp_path: Path) -> None:
    path = _write(tmp_path, "global P = A -> B : ping".encode("utf-8-sig"))
    assert str(sessiontypes.load(path).globals["P"].project("B")) == "?A(ping)"


def test_cli_check_prints_the_located_error_and_fails(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    path = _write(tmp_path, b"global P = A -> B : \xff\n")
    assert main(["check", str(path)]) == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == (
        f"{path}:1:21: error: the file is not UTF-8 text: byte 0xff cannot be decoded\n"
        "    global P = A -> B : \ufffd\n"
        "                        ^\n"
    )


def test_the_old_name_message_still_imports_with_a_deprecation_warning() -> None:
    with pytest.warns(DeprecationWarning, match="renamed sessiontypes.Interaction"):
        from sessiontypes import Message  # type: ignore[attr-defined]
    assert Message is sessiontypes.Interaction
    with pytest.warns(DeprecationWarning, match="anodize.Message is a received message"):
        assert sessiontypes.Message is sessiontypes.Interaction  # type: ignore[attr-defined]
    with pytest.raises(AttributeError, match="no attribute 'Mesage'"):
        sessiontypes.Mesage  # type: ignore[attr-defined]  # noqa: B018
    assert "Message" not in sessiontypes.__all__ and "Interaction" in sessiontypes.__all__
