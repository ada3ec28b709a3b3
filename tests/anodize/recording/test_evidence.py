"""Recordings as evidence: each channel's messages hash-chained, the heads in the file and the
run report, and ``anodize verify`` naming what was removed, inserted, reordered or altered.

One run is recorded (through the CLI, with a signing key) once for the module; every
mutation is made on a copy by the shared rewriter (``mcap_rewrite.rewrite``), in which the
messages are listed in log-time order, link records included.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

import pytest
from budget import examples
from hypothesis import HealthCheck, assume, given, note, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parents[1]))

import evidence_roles
from mcap_rewrite import rewrite
from role_drivers import load_global, machines_of

from anodize._recording import tap as recording_tap
from anodize._recording.chain import CHAIN_TOPIC, HEADS_RECORD
from anodize._recording.encoding import codec_for_sort
from anodize._recording.evidence import NO_CHAIN, ChainFault, Evidence
from anodize._recording.merge import merge_parts
from anodize._recording.plan import record_plan
from anodize._recording.reader import open_recording
from anodize._recording.tap import GAP_TOPIC
from anodize._recording.verify import verify
from anodize._tools.cli import EXIT_NOT_EVIDENCE, main

HERE = Path(__file__).resolve().parents[1]
BUY = """global Buy(B, S) =
  mu t. B -> S : { title(str). S -> B : quote(int). t,
                   done }
"""
CHANNELS = [("B", "S"), ("S", "B")]
MUTATIONS = ["drop", "insert", "reorder", "payload", "log time", "renumber", "drop and renumber", "truncate"]
KIND = {"drop": "removed", "insert": "inserted", "reorder": "reordered", "payload": "altered",
        "log time": "altered", "renumber": "altered", "drop and renumber": "removed", "truncate": "removed"}


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    status = main(list(argv))
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return status, out + err


def _key(folder: Path, name: str = "run.key", mode: int = 0o600) -> Path:
    path = folder / name
    path.write_bytes(os.urandom(32))
    path.chmod(mode)
    return path


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, str]:
    """A Buy run, each role in its own group, recorded with a signing key: (recording, key, run output)."""
    folder = tmp_path_factory.mktemp("evidence")
    (folder / "buy.proto").write_text(BUY, encoding="utf-8")
    system = folder / "system.toml"
    system.write_text(f'protocol = "{folder / "buy.proto"}"\nglobal = "Buy"\ntransport = "inproc"\n'
                      f'pythonpath = ["{HERE}"]\n'
                      '[groups.b]\nroles = { B = "evidence_roles:buyer" }\n'
                      '[groups.s]\nroles = { S = "evidence_roles:seller" }\n', encoding="utf-8")
    key = _key(folder)
    path = folder / "run.mcap"
    json_out = folder / "report.json"
    import io
    from contextlib import redirect_stdout

    out = io.StringIO()
    with redirect_stdout(out):
        status = main(["run", str(system), "--record", str(path), "--sign-key", str(key), "--quiet",
                       "--json", str(json_out)])
    assert status == 0, out.getvalue()
    return path, key, out.getvalue() + json_out.read_text(encoding="utf-8")


def _evidence(path: Path, key: bytes | None = None) -> Evidence:
    with open_recording(path) as recording:
        report = verify(recording, load_global(BUY, "Buy"), signing_key=key)
    print(report.text())  # shown when a test fails
    assert report.evidence is not None
    return report.evidence


def _on(messages: list[Any], channel: tuple[str, str]) -> list[int]:
    """Where the messages of ``channel`` are in the rewriter's list."""
    return [i for i, m in enumerate(messages)
            if (dict(m[0][2]).get("anodize.sender"), dict(m[0][2]).get("anodize.receiver")) == channel]


def _string(text: str) -> bytes:
    ros = codec_for_sort(None).ros
    return ros.serialize(ros.cls(data=json.dumps(text)))


def _mutate(messages: list[Any], mutation: str, channel: tuple[str, str], index: int) -> None:
    at = _on(messages, channel)
    spot = messages[at[index]]
    if mutation == "drop":
        del messages[at[index]]
    elif mutation == "insert":  # a message of the same topic and number, just before it
        messages.insert(at[index], [spot[0], spot[1] - 1, spot[2], _string("forged")])
    elif mutation == "reorder":  # the two change places; the log times stay where they were
        first, second = messages[at[index]], messages[at[index + 1]]
        first[1], second[1] = second[1], first[1]
        messages[at[index]], messages[at[index + 1]] = second, first
    elif mutation == "payload":
        spot[3] = _string("forged")
    elif mutation == "log time":
        spot[1] += 1
    elif mutation == "renumber":
        for i in at[index:]:
            messages[i][2] += 1000
    elif mutation == "drop and renumber":  # the numbers close over the hole: today's verify sees nothing
        for i in at[index + 1:]:
            messages[i][2] -= 1
        del messages[at[index]]
    elif mutation == "truncate":  # the channel's last messages, from index on, gone
        for i in reversed(at[index:]):
            del messages[i]


def _first(evidence: Evidence, channel: str) -> ChainFault:
    faults = [f for f in evidence.faults if f.channel == channel and f.index is not None]
    assert faults, evidence.lines()
    return faults[0]


def test_a_recorded_run_is_evidence_and_its_report_gives_the_heads(recorded: tuple[Path, Path, str]) -> None:
    path, key, output = recorded
    evidence = _evidence(path, key.read_bytes())
    assert evidence.ok and evidence.signature_checked, evidence.lines()
    line = f"recording: 2 hash chains, heads sha256 {evidence.digest}, signed (HMAC-SHA256)"
    assert f"note: {line}" in output  # the text report
    assert json.dumps(line) in output  # and the JSON one
    # B->S and S->B: each label of a channel is in its channel's chain
    assert evidence.channels == 2 and evidence.messages == 2 * evidence_roles.TITLES + 1


@settings(deadline=None, max_examples=examples(60),
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(mutation=st.sampled_from(MUTATIONS), channel=st.sampled_from(CHANNELS), data=st.data())
def test_verify_catches_every_mutation_with_its_kind_and_index(
        recorded: tuple[Path, Path, str], tmp_path_factory: pytest.TempPathFactory, mutation: str,
        channel: tuple[str, str], data: st.DataObject) -> None:
    path = recorded[0]
    count = evidence_roles.TITLES + (1 if channel == ("B", "S") else 0)
    needed = 2 if mutation == "reorder" else 1
    index = data.draw(st.integers(0, count - needed), label="index")
    note(f"{mutation} message {index} of {channel}")

    def change(messages: list[Any]) -> None:
        at = _on(messages, channel)
        assert len(at) == count
        if mutation == "insert":
            assume(index == 0 or messages[at[index - 1]][1] < messages[at[index]][1] - 1)
        if mutation == "log time":
            assume(index == count - 1 or messages[at[index]][1] + 1 < messages[at[index + 1]][1])
        _mutate(messages, mutation, channel, index)

    mutated = tmp_path_factory.mktemp("mutated") / "m.mcap"
    rewrite(path, mutated, change)
    evidence = _evidence(mutated)
    assert not evidence.ok
    fault = _first(evidence, f"{channel[0]}->{channel[1]}")
    assert (fault.kind, fault.index) == (KIND[mutation], index), evidence.lines()
    other = f"{channel[1]}->{channel[0]}"
    assert all(f.channel != other for f in evidence.faults), evidence.lines()


def test_a_dropped_message_with_renumbered_sequences_is_not_evidence_in_the_cli(
        recorded: tuple[Path, Path, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The issue's case: this recording passed verify as "conforms" (exit 0)."""
    rewrite(recorded[0], tmp_path / "m.mcap", lambda messages: _mutate(messages, "drop and renumber", ("B", "S"), 3))
    status, out = _cli(capsys, "verify", str(tmp_path / "m.mcap"), "--json", str(tmp_path / "v.json"))
    assert status == EXIT_NOT_EVIDENCE, out
    assert "conforms to Buy" in out  # the protocol holds: only the chain sees it
    assert "NOT evidence" in out and "chain: channel B->S, message 3 removed: 1 message(s)" in out, out
    found = json.loads((tmp_path / "v.json").read_text())["evidence"]
    assert found["ok"] is False and found["faults"][0]["kind"] == "removed" and found["faults"][0]["index"] == 3


def test_the_tail_of_the_file_cut_is_caught_against_the_heads(recorded: tuple[Path, Path, str], tmp_path: Path) -> None:
    def cut(messages: list[Any]) -> None:
        del messages[len(messages) * 2 // 3:]  # messages and link records alike

    rewrite(recorded[0], tmp_path / "m.mcap", cut)
    evidence = _evidence(tmp_path / "m.mcap")
    assert {fault.kind for fault in evidence.faults} == {"removed"}, evidence.lines()
    with open_recording(tmp_path / "m.mcap") as recording:
        kept = sum(1 for m in recording.messages() if m.topic.metadata.get("anodize.sender") == "B")
    assert _first(evidence, "B->S").index == kept


def test_moving_a_message_to_another_label_is_an_alteration(recorded: tuple[Path, Path, str], tmp_path: Path) -> None:
    def relabel(messages: list[Any]) -> None:
        title = messages[_on(messages, ("B", "S"))[0]]
        _, schema, items = title[0]
        title[0] = ("/anodize/B/S/done", schema, tuple((k, "done" if k == "anodize.label" else v) for k, v in items))

    rewrite(recorded[0], tmp_path / "m.mcap", relabel)
    fault = _first(_evidence(tmp_path / "m.mcap"), "B->S")
    assert (fault.kind, fault.index) == ("altered", 0)


def test_a_recording_without_a_chain_says_it_cannot_tell(recorded: tuple[Path, Path, str], tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """An older recording: its link records and heads stripped."""
    def strip(messages: list[Any]) -> None:
        messages[:] = [m for m in messages if m[0][0] != CHAIN_TOPIC]

    rewrite(recorded[0], tmp_path / "old.mcap", strip)
    _strip_heads(tmp_path / "old.mcap")
    status, out = _cli(capsys, "verify", str(tmp_path / "old.mcap"))
    assert status == 0 and f"note: {NO_CHAIN}" in out, out
    status, out = _cli(capsys, "verify", str(tmp_path / "old.mcap"), "--key", str(recorded[1]))
    assert status == EXIT_NOT_EVIDENCE and "nothing signed" in out, out


def _strip_heads(path: Path, change: dict[str, str] | None = None) -> None:
    """Remove (or, with ``change``, rewrite keys of) the heads record of ``path``, in place."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    copy = path.with_suffix(".tmp")
    with path.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        items = [(c, m) for _, c, m in reader.iter_messages(log_time_order=True)]
        metadata = list(reader.iter_metadata())
        with copy.open("wb") as out:
            writer = Writer(out)
            writer.start(profile="ros2", library="test")
            schemas = {sid: writer.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
            channels = {cid: writer.register_channel(c.topic, c.message_encoding, schemas[c.schema_id],
                                                     dict(c.metadata)) for cid, c in summary.channels.items()}
            for channel, message in items:
                writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time,
                                   message.sequence)
            for record in metadata:
                if record.name != HEADS_RECORD:
                    writer.add_metadata(record.name, dict(record.metadata))
                elif change is not None:
                    writer.add_metadata(record.name, {**record.metadata, **change})
            writer.finish()
    copy.replace(path)


def test_signed_heads_are_checked_and_a_tampered_head_is_reported(
        recorded: tuple[Path, Path, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, key, _ = recorded
    status, out = _cli(capsys, "verify", str(path), "--key", str(key))
    assert status == 0 and "signature checked" in out, out
    status, out = _cli(capsys, "verify", str(path))
    assert status == 0 and "signed: give --key to check the signature" in out, out
    status, out = _cli(capsys, "verify", str(path), "--key", str(_key(tmp_path, "other.key")))
    assert status == EXIT_NOT_EVIDENCE and "do not match their signature" in out, out

    # A head made again (a message dropped and the chain recomputed by someone without the key):
    # the digest is made to match, the signature cannot be.
    with open_recording(path) as recording:
        assert recording.chain is not None
        heads = json.loads(recording.chain["heads"])
    part = next(iter(heads))
    chain = next(iter(heads[part]))
    heads[part][chain] = [heads[part][chain][0] - 1, "00" * 32]
    from anodize._recording.chain import heads_record

    forged = heads_record(recording.chain["run_id"], heads, None)
    copy = tmp_path / "forged.mcap"
    copy.write_bytes(path.read_bytes())
    _strip_heads(copy, {"heads": forged["heads"], "digest": forged["digest"]})
    status, out = _cli(capsys, "verify", str(copy), "--key", str(key))
    assert status == EXIT_NOT_EVIDENCE and "do not match their signature" in out, out


def test_a_key_file_others_can_read_or_too_short_is_refused(
        recorded: tuple[Path, Path, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    status, out = _cli(capsys, "verify", str(recorded[0]), "--key", str(_key(tmp_path, "open.key", 0o644)))
    assert status == 1 and "the key file is readable by other users (mode 644); expected mode 600" in out, out
    short = tmp_path / "short.key"
    short.write_bytes(b"secret")
    short.chmod(0o600)
    status, out = _cli(capsys, "verify", str(recorded[0]), "--key", str(short))
    assert status == 1 and "expected a key of 16 to 4096 bytes; found 6" in out, out
    status, out = _cli(capsys, "run", "no.toml", "--sign-key", str(short))
    assert status == 2 and "--sign-key needs --record PATH" in out, out


# ---- the recorder's own gaps are chained too ------------------------------------------------------

TEXTS = "global Texts(Talker, Listener) = mu t. Talker -> Listener : { text(str). t, stop }\n"
PAIR = ("Talker", "Listener")


@pytest.fixture(scope="module")
def with_a_gap(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recording whose writer could not take three messages (a gap record marks them)."""
    folder = tmp_path_factory.mktemp("gap")
    global_type = load_global(TEXTS, "Texts")
    machines = machines_of(global_type)
    plan = record_plan(str(folder / "parts"), machines, {"Talker": "t", "Listener": "l"}, {})
    recorder = recording_tap.Recorder(plan, "t", 0, "Texts", {"Talker": machines["Talker"]})
    backlog = recorder.backlog
    for number in range(10):
        recorder.backlog = 0 if 4 <= number < 7 else backlog  # as if the writer were behind
        encoded = recorder.encode(PAIR, "text", f"text {number}")
        assert encoded is not None
        recorder.queue(PAIR, encoded)
    recorder.close()
    merge_parts(folder / "parts", folder / "r.mcap", {"global": "Texts"})
    return folder / "r.mcap"


def test_a_gap_record_is_chained_and_removing_it_is_caught(with_a_gap: Path, tmp_path: Path) -> None:
    with open_recording(with_a_gap) as recording:
        report = verify(recording, load_global(TEXTS, "Texts"))
    assert report.conforms and [(g.first, g.count) for g in report.gaps] == [(5, 3)], report.text()
    assert report.evidence is not None and report.evidence.ok, report.text()

    for mutation in ("drop", "alter"):
        def change(messages: list[Any], mutation: str = mutation) -> None:
            at = [i for i, m in enumerate(messages) if m[0][0] == GAP_TOPIC]
            if mutation == "drop":
                del messages[at[0]]
            else:  # a smaller gap than the recorder marked
                ros = codec_for_sort(None).ros
                messages[at[0]][3] = ros.serialize(ros.cls(data=json.dumps(
                    {"channel": "Talker->Listener", "first": 5, "count": 2})))

        rewrite(with_a_gap, tmp_path / f"{mutation}.mcap", change)
        with open_recording(tmp_path / f"{mutation}.mcap") as recording:
            evidence = verify(recording, load_global(TEXTS, "Texts")).evidence
        assert evidence is not None
        assert [(f.channel, f.index, f.kind) for f in evidence.faults] == [
            (GAP_TOPIC, 0, "removed" if mutation == "drop" else "altered")], evidence.lines()


def test_malformed_link_records_and_heads_are_findings_not_tracebacks(
        recorded: tuple[Path, Path, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    def garble(messages: list[Any]) -> None:
        links = [m for m in messages if m[0][0] == CHAIN_TOPIC]
        links[0][3] = b"\x00\x01\x00\x00garbage"
        links[1][3] = _string("not a link record")

    rewrite(recorded[0], tmp_path / "m.mcap", garble)
    status, out = _cli(capsys, "verify", str(tmp_path / "m.mcap"))
    assert status == EXIT_NOT_EVIDENCE, out
    assert "chain: topic /anodize/recording/chain altered: a link record cannot be read" in out, out
    for heads in ("[1", '{"b-0": {"B->S": [-1, "00"]}}', '{"b-0": 7}', "null"):
        copy = tmp_path / "h.mcap"
        copy.write_bytes(recorded[0].read_bytes())
        _strip_heads(copy, {"heads": heads})
        status, out = _cli(capsys, "verify", str(copy))
        assert status == EXIT_NOT_EVIDENCE and "the heads record is malformed" in out, out


def test_a_part_cut_short_before_its_links_were_written_is_linked_by_the_merge(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A group killed after its writer wrote messages but before their link records: the merge
    links them (from the part), and the recording is evidence of what the part holds."""
    import time

    from anodize._recording.chain import ChainedWriter

    global_type = load_global(TEXTS, "Texts")
    machines = machines_of(global_type)
    plan = record_plan(str(tmp_path / "parts"), machines, {"Talker": "t", "Listener": "l"}, {})
    monkeypatch.setattr(ChainedWriter, "seal", lambda self: None)  # no link record is ever written
    recorder = recording_tap.Recorder(plan, "t", 0, "Texts", {"Talker": machines["Talker"]})
    for number in range(5):
        encoded = recorder.encode(PAIR, "text", f"text {number}")
        assert encoded is not None
        recorder.queue(PAIR, encoded)
    deadline = time.monotonic() + 10
    while recorder.written < 5 and time.monotonic() < deadline:  # bounded: the writer takes them
        time.sleep(0.01)
    with recorder._io:  # written: on disk now (the writer flushes every 0.1 s); never closed, as if killed
        recorder._file.flush()
    result = merge_parts(tmp_path / "parts", tmp_path / "r.mcap", {"global": "Texts"})
    assert result.chains == 1
    with open_recording(tmp_path / "r.mcap") as recording:
        report = verify(recording, global_type)
    assert report.evidence is not None and report.evidence.ok, report.text()
    assert report.evidence.messages == 5


def test_a_named_run_signs_only_what_it_records(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # `anodize run tinman --sign-key` (the signed run is the suite's recorded TinMan, tests/conftest.py).
    key = tmp_path / "run.key"
    key.write_bytes(b"k" * 32)
    key.chmod(0o600)
    status = main(["run", "tinman", "--sign-key", str(key), "--duration", "1", "--out", str(tmp_path / "out")])
    assert (status, capsys.readouterr().err) == (2, "anodize run: error: --sign-key needs --record\n")
