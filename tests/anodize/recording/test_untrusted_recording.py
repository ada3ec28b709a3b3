"""A recording is untrusted data: reading, verifying and replaying one never imports or calls
anything the file names, and metadata that is not what anodize writes is a clean error.

- ``verify`` of a recording whose embedded protocol binds a sort to an import path does not
  import it (a module that writes a file when imported stays unimported), checks the payload
  by the recorded class name, and says once that it did not import; with ``--protocol FILE``
  (the user's own file) the class is imported and checked, as ``anodize check`` does;
- ``replay`` runs only the function the user passes: the recording's ``role_functions`` are
  a hint in the error, never imported; a payload class the recording's protocol names is taken
  only from a module the user's code imported itself;
- reading a recorded JSON value never reaches a module's ``__getattr__`` (which may import);
- every metadata key the readers use that is not what anodize writes is an error naming the
  key, what was expected and what was found (never an internal error).
"""

from __future__ import annotations

import json
import uuid
from pathlib import Path

import pytest

from anodize._recording.encoding import JSON_TYPE, from_json
from anodize._ros import ros_type
from anodize._tools.cli import main

PROTOCOL = """type Thing = "{module}:Thing"
global G(A, B) =
  A -> B : go(Thing).
  B -> A : ack(int)
"""


def _side_effect_module(folder: Path, marker: Path, body: str = "") -> str:
    """A module in ``folder`` that writes ``marker`` when it is imported; returns its (unique) name."""
    name = f"untrusted_{uuid.uuid4().hex[:12]}"
    (folder / f"{name}.py").write_text(
        "from dataclasses import dataclass\n"
        f"open({str(marker)!r}, 'w').write('imported')\n"
        "@dataclass\nclass Thing:\n    x: int\n" + body, encoding="utf-8")
    return name


def _craft(path: Path, protocol: str, messages: list[tuple[str, str, str, object]],
           **info: str) -> Path:
    """An MCAP file laid out as anodize records one: JSON payloads in std_msgs/String, anodize's
    channel metadata, and an ``anodize`` metadata record (``info`` overrides its keys)."""
    from mcap.writer import Writer

    ros = ros_type(JSON_TYPE)
    record = {"protocol_file": "crafted.proto", "protocol_source": protocol, "global": "G",
              "recorded_channels": "A->B B->A", "role_functions": json.dumps({"A": "x:a", "B": "x:b"}),
              "group_of": json.dumps({"A": "a", "B": "b"}), **info}
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema(JSON_TYPE, "ros2msg", b"string data")
        channels: dict[tuple[str, str, str], int] = {}
        numbers: dict[tuple[str, str], int] = {}
        for time, (sender, receiver, label, payload) in enumerate(messages, 1):
            key = (sender, receiver, label)
            if key not in channels:
                channels[key] = writer.register_channel(
                    f"/anodize/{sender}/{receiver}/{label}", "cdr", schema,
                    {"anodize.sender": sender, "anodize.receiver": receiver, "anodize.label": label,
                     "anodize.encoding": "json"})
            number = numbers[key[:2]] = numbers.get(key[:2], 0) + 1
            data = ros.serialize(ros.cls(data=json.dumps(payload)))
            writer.add_message(channels[key], log_time=time * 1000, data=data, publish_time=time * 1000,
                               sequence=number)
        writer.add_metadata("anodize", record)
        writer.finish()
    return path


def _thing(module: str, x: int = 1) -> dict[str, object]:
    return {"$dataclass": f"{module}:Thing", "fields": {"x": x}}


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    capsys.readouterr()
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


@pytest.fixture
def folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """``tmp_path``, on ``sys.path`` (so that an import of a module there would succeed)."""
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


# ---- verify: the embedded protocol's import paths are not imported -------------------------

def test_verify_does_not_import_what_the_recorded_protocol_names(
        capsys: pytest.CaptureFixture[str], folder: Path) -> None:
    marker = folder / "imported.txt"
    module = _side_effect_module(folder, marker)
    path = _craft(folder / "run.mcap", PROTOCOL.format(module=module),
                  [("A", "B", "go", _thing(module)), ("B", "A", "ack", 1)])
    status, out, err = _cli(capsys, "verify", str(path))
    assert not marker.exists(), "verify imported a module the recording names"
    assert (status, err) == (0, "")
    assert out.count("not imported") == 1
    assert ("payload types named by import path were not imported (the protocol came from the recording); "
            "pass --protocol FILE to check them against your own code") in out


def test_verify_without_importing_still_blames_a_payload_of_another_recorded_class(
        capsys: pytest.CaptureFixture[str], folder: Path) -> None:
    marker = folder / "imported.txt"
    module = _side_effect_module(folder, marker)
    path = _craft(folder / "run.mcap", PROTOCOL.format(module=module),
                  [("A", "B", "go", {"$dataclass": "elsewhere:Other", "fields": {}}), ("B", "A", "ack", 1)])
    status, out, _ = _cli(capsys, "verify", str(path))
    assert not marker.exists()
    assert status == 1
    assert "payload of the wrong sort: a recorded elsewhere:Other, the label carries Thing" in out
    assert "blamed: A" in out


def test_verify_without_importing_checks_a_record_s_fields_by_name(
        capsys: pytest.CaptureFixture[str], folder: Path) -> None:
    marker = folder / "imported.txt"
    module = _side_effect_module(folder, marker)
    protocol = f'type Thing = "{module}:Thing"\nglobal G(A, B) =\n  A -> B : go(item: Thing, n: int)\n'

    def record(item: object) -> dict[str, object]:
        return {"$dict": [["item", item], ["n", 2]]}
    good = _craft(folder / "good.mcap", protocol, [("A", "B", "go", record(_thing(module)))],
                  recorded_channels="A->B")
    bad = _craft(folder / "bad.mcap", protocol, [("A", "B", "go", record(3))], recorded_channels="A->B")
    assert _cli(capsys, "verify", str(good))[0] == 0
    status, out, _ = _cli(capsys, "verify", str(bad))
    assert not marker.exists()
    assert status == 1
    assert f"payload of the wrong sort: field item: a recorded int, the label carries Thing ({module}:Thing)" in out


def test_verify_with_the_user_s_own_protocol_imports_and_checks_the_class(
        capsys: pytest.CaptureFixture[str], folder: Path) -> None:
    marker = folder / "imported.txt"
    module = _side_effect_module(folder, marker)
    path = _craft(folder / "run.mcap", PROTOCOL.format(module=module),
                  [("A", "B", "go", _thing(module, 7)), ("B", "A", "ack", 1)])
    mine = folder / "mine.proto"
    mine.write_text(PROTOCOL.format(module=module), encoding="utf-8")
    status, out, _ = _cli(capsys, "verify", str(path), "--protocol", str(mine))
    assert marker.exists()  # the user's own file: importing what it names is the user's choice
    assert status == 0
    assert "not imported" not in out


def test_a_recorded_value_never_reaches_a_module_s_getattr(folder: Path) -> None:
    marker = folder / "imported.txt"
    module = _side_effect_module(folder, folder / "first.txt",
                                 f"def __getattr__(name):\n    open({str(marker)!r}, 'w').write(name)\n"
                                 "    raise AttributeError(name)\n")
    __import__(module)  # imported already (by the user's own code, say)
    value = from_json({"$dataclass": f"{module}:Missing", "fields": {}})
    assert not marker.exists(), "reading a recorded value called the module's __getattr__"
    assert type(value).__name__ == "UnknownObject"
    assert type(from_json(_thing(module))).__name__ == "Thing"  # a class the module has is rebuilt


# ---- replay: only the function the user passes runs ---------------------------------------

def _user_roles(folder: Path, imports: str = "") -> str:
    """The user's own role module (in ``folder``): B receives go and acknowledges it."""
    name = f"user_roles_{uuid.uuid4().hex[:12]}"
    (folder / f"{name}.py").write_text(
        f"{imports}\n"
        "def b(ep):\n    ep.recv('A')\n    ep.send('A', 'ack', 1)\n", encoding="utf-8")
    return name


@pytest.mark.parametrize("named", ["os:system", "faulthandler:_sigsegv", "MODULE:b"])
def test_replay_never_imports_nor_calls_the_function_the_recording_names(
        capsys: pytest.CaptureFixture[str], folder: Path, named: str) -> None:
    marker = folder / "imported.txt"
    module = _side_effect_module(folder, marker, "def b(ep):\n    pass\n")
    named = named.replace("MODULE", module)
    path = _craft(folder / "run.mcap", "global G(A, B) =\n  A -> B : go(int).\n  B -> A : ack(int)\n",
                  [("A", "B", "go", 1), ("B", "A", "ack", 1)], role_functions=json.dumps({"B": named}))
    status, out, err = _cli(capsys, "replay", str(path), "--role", "B")
    assert not marker.exists()
    assert (status, out) == (1, "")
    assert err == ("error: replaying role B needs --function module:function (code of your own: what a recording "
                   f"names is never imported); the recording says role B ran `{named}`: pass --function {named} to "
                   "replay it\n")


def test_replay_takes_a_class_the_recording_names_only_from_the_user_s_imports(
        capsys: pytest.CaptureFixture[str], folder: Path) -> None:
    marker = folder / "imported.txt"
    module = _side_effect_module(folder, marker)
    path = _craft(folder / "run.mcap", PROTOCOL.format(module=module),
                  [("A", "B", "go", _thing(module)), ("B", "A", "ack", 1)])
    roles = _user_roles(folder)
    status, out, err = _cli(capsys, "replay", str(path), "--role", "B", "--function", f"{roles}:b")
    assert not marker.exists(), "replay imported a payload class the recording names"
    assert (status, out) == (1, "")
    assert err == (f"error: the protocol of {path} names payload class {module}:Thing (sort Thing), and module "
                   f"{module} is not imported by your code: a replay does not import what a recording names; "
                   "import it in your role's module, or pass --protocol FILE\n")
    # The user's own code imports it: then the replay runs, and checks against that class.
    roles = _user_roles(folder, f"import {module}")
    status, out, err = _cli(capsys, "replay", str(path), "--role", "B", "--function", f"{roles}:b")
    assert marker.exists()
    assert (status, err) == (0, "")
    assert "matches the recording and follows the protocol" in out.splitlines()[0]


# ---- metadata that is not what anodize writes ----------------------------------------------

@pytest.mark.parametrize(("key", "value", "expected"), [
    ("role_functions", "[1]", "a JSON object of role -> \"module:function\"; found a JSON array"),
    ("role_functions", "not json", "a JSON object of role -> \"module:function\"; found text that is not JSON"),
    ("role_functions", '{"B": 3}', "a JSON object of role -> \"module:function\"; found 3 for role B"),
    ("role_functions", '{"B": "no colon"}', ("a JSON object of role -> \"module:function\"; "
                                             "found 'no colon' for role B")),
    ("group_of", "[]", "a JSON object of role -> group name; found a JSON array"),
    ("group_of", '{"A": null}', "a JSON object of role -> group name; found null for role A"),
    ("recorded_channels", "A-B", "channels \"Sender->Receiver\" separated by spaces; found 'A-B'"),
    ("record_selection", "[1]", ('a JSON object {"inside": true|false, "channels": [...]|null, "exclude": [...]}; '
                                 "found a JSON array")),
    ("record_selection", '{"inside": 1, "exclude": []}', (
        'a JSON object {"inside": true|false, "channels": [...]|null, "exclude": [...]}; '
        "found '{\"inside\": 1, \"exclude\": []}'")),
])
def test_malformed_metadata_is_a_clean_error_naming_the_key(
        capsys: pytest.CaptureFixture[str], folder: Path, key: str, value: str, expected: str) -> None:
    path = _craft(folder / "run.mcap", "global G(A, B) =\n  A -> B : go(int).\n  B -> A : ack(int)\n",
                  [("A", "B", "go", 1)], **{key: value, "recorded_channels": "A->B"} if key != "recorded_channels"
                  else {key: value})
    function = [] if key == "role_functions" else ["--function", f"{_user_roles(folder)}:b"]
    status, out, err = _cli(capsys, "replay", str(path), "--role", "B", *function)
    assert (status, out) == (1, "")
    assert err == f"error: {path}: metadata {key}: expected {expected}\n"
