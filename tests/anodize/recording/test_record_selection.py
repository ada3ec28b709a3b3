"""What a recording records: every channel by default, inside groups too; or the system file's
``[record]`` choice, ``--record-exclude``, ``--record-between``.

- ``anodize run FILE --record DIR`` (a rosbag2 folder) of a two-buyer system with B1 and S in
  one group records every channel, so B1 (which talks to S inside its group) replays equal
  through the CLI, and ``verify`` lists nothing as not recorded;
- ``[record] exclude`` / ``--record-exclude`` leave channels out: the recording says so in its
  metadata, ``verify`` says they are not recorded (no violation, nothing missing) and why;
  ``[record] channels`` records only those; ``--record-between`` only those between groups;
- mistakes are located errors: an unknown key or channel in ``[record]``, a label where a
  channel is expected, ``--record-exclude`` of an unknown channel or without ``--record``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parents[1]
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import replay_roles  # noqa: E402

import sessiontypes  # noqa: E402
from anodize import Recording, System  # noqa: E402
from anodize._recording.reader import open_recording  # noqa: E402
from anodize._recording.replay import replay  # noqa: E402
from anodize._tools.cli import main  # noqa: E402

ROOT = HERE.parents[1]
PROTOCOL = ROOT / "protocols" / "two_buyer.proto"
TWO_BUYER = sessiontypes.load(PROTOCOL).globals["TwoBuyer"]
EVERY = ["B1->B2", "B1->S", "B2->S", "S->B1", "S->B2"]


def _system(folder: Path, record: str = "") -> Path:
    """A two-buyer system file: B1 and S in group shop, B2 alone; ``record``: its [record] table."""
    path = folder / "system.toml"
    path.write_text(f'protocol = "{PROTOCOL}"\nglobal = "TwoBuyer"\ntransport = "process"\npythonpath = ["{HERE}"]\n'
                    '[groups.shop]\nroles = { B1 = "replay_roles:buyer1", S = "replay_roles:seller" }\n'
                    '[groups.b2]\nroles = { B2 = "replay_roles:buyer2" }\n' + record, encoding="utf-8")
    return path


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    capsys.readouterr()
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def _info(path: Path) -> tuple[set[str], dict[str, object]]:
    with open_recording(path) as recording:
        return set(recording.info["recorded_channels"].split()), json.loads(recording.info["record_selection"])


@pytest.fixture(scope="module")
def everything(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The system run with plain ``--record DIR``: a rosbag2 folder."""
    folder = tmp_path_factory.mktemp("everything")
    assert main(["run", str(_system(folder)), "--record", str(folder / "bag"), "--quiet"]) == 0
    return folder / "bag"


def test_plain_record_records_every_channel_inside_groups_too(everything: Path) -> None:
    recorded, selection = _info(everything)
    assert sorted(recorded) == EVERY
    assert selection == {"inside": True, "channels": None, "exclude": []}


def test_a_role_that_talks_inside_its_group_replays_equal_through_the_cli(
        capsys: pytest.CaptureFixture[str], everything: Path) -> None:
    for role, function in (("B1", "buyer1"), ("S", "seller"), ("B2", "buyer2")):
        status, out, err = _cli(capsys, "replay", str(everything), "--role", role,
                                "--function", f"replay_roles:{function}", "--pythonpath", str(HERE))
        assert err == ""
        assert out.splitlines()[0].endswith("matches the recording and follows the protocol"), out
        assert status == 0


def test_verify_of_a_recording_of_everything_leaves_nothing_out(capsys: pytest.CaptureFixture[str],
                                                                 everything: Path) -> None:
    status, out, _ = _cli(capsys, "verify", str(everything))
    assert status == 0 and " conforms to TwoBuyer: " in out.splitlines()[0], out
    assert "not recorded" not in out and "missing" not in out, out


def test_the_python_api_records_every_channel_by_default(tmp_path: Path) -> None:
    system = System(TWO_BUYER)
    system.group("shop").role("B1", replay_roles.buyer1).role("S", replay_roles.seller)
    system.group("b2").role("B2", replay_roles.buyer2)
    assert system.run(timeout=20.0, taps=[Recording(tmp_path / "run.mcap")]).ok
    assert sorted(_info(tmp_path / "run.mcap")[0]) == EVERY
    with open_recording(tmp_path / "run.mcap") as recording:
        report = replay(recording, TWO_BUYER, "B1", replay_roles.buyer1, timeout=20.0)
    assert report.ok and report.outcome == "finished", report.text()


def test_record_exclude_in_the_file_and_on_the_command_line(capsys: pytest.CaptureFixture[str],
                                                            tmp_path: Path) -> None:
    system = _system(tmp_path, '[record]\nexclude = ["S->B2"]\n')
    bag = tmp_path / "run.mcap"
    status, out, err = _cli(capsys, "run", str(system), "--record", str(bag), "--record-exclude", "B1->B2", "--quiet")
    assert (status, err) == (0, ""), err
    assert "on 3 channels (3 topics; every channel but B1->B2, S->B2)" in out, out
    recorded, selection = _info(bag)
    assert sorted(recorded) == ["B1->S", "B2->S", "S->B1"]
    assert selection == {"inside": True, "channels": None, "exclude": ["B1->B2", "S->B2"]}
    status, out, _ = _cli(capsys, "verify", str(bag))
    assert status == 0 and " conforms to TwoBuyer: " in out.splitlines()[0], out
    assert "not recorded (left out: B1->B2, S->B2; not checked, not a violation): B1->B2, S->B2" in out, out
    assert "missing" not in out, out
    # B2 receives on S->B2 first: the replay says the recording left it out, not that it failed.
    status, out, _ = _cli(capsys, "replay", str(bag), "--role", "B2", "--function", "replay_roles:buyer2",
                          "--pythonpath", str(HERE))
    assert ("which the recording does not have (the run's recording left it out (--record-exclude, or [record] "
            "in the system file))") in out, out


def test_record_channels_records_only_those(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    bag = tmp_path / "run.mcap"
    status, _, err = _cli(capsys, "run", str(_system(tmp_path, '[record]\nchannels = ["B1->S", "S->B1"]\n')),
                          "--record", str(bag), "--quiet")
    assert (status, err) == (0, "")
    assert sorted(_info(bag)[0]) == ["B1->S", "S->B1"]
    status, out, _ = _cli(capsys, "verify", str(bag))
    assert status == 0 and ("not recorded (only the channels chosen were recorded; not checked, not a violation): "
                            "B1->B2, B2->S, S->B2") in out, out


def test_record_between_records_the_channels_between_groups_only(capsys: pytest.CaptureFixture[str],
                                                                 tmp_path: Path) -> None:
    bag = tmp_path / "run.mcap"
    status, out, err = _cli(capsys, "run", str(_system(tmp_path)), "--record", str(bag), "--record-between",
                            "--quiet")
    assert (status, err) == (0, "") and "topics) between groups" in out
    assert sorted(_info(bag)[0]) == ["B1->B2", "B2->S", "S->B2"]
    status, out, _ = _cli(capsys, "verify", str(bag))
    assert status == 0 and ("not recorded (recorded between groups only: both ends in one group; not checked, "
                            "not a violation): B1->S, S->B1") in out, out


@pytest.mark.parametrize(("table", "message"), [
    ('[record]\nexclud = ["S->B2"]\n', "record.exclud: unknown key; expected one of channels, exclude, inside"),
    ('[record]\nexclude = "S->B2"\n', ('record.exclude: expected an array of channels such as ["A->B"], '
                                       "got 'S->B2'")),
    ('[record]\nexclude = ["S->B2:quote"]\n',
     ("record.exclude[0]: expected a channel \"Sender->Receiver\", got 'S->B2:quote': a recording selects whole "
      "channels (verify checks a channel's labels in order, and replay feeds them in order); write S->B2")),
    ('[record]\nchannels = ["S-B2"]\n', "record.channels[0]: expected a channel \"Sender->Receiver\", got 'S-B2'"),
    ('[record]\nchannels = []\n', ('record.channels: expected at least one channel such as "A->B" (to record '
                                   "nothing, run without --record)")),
    ('[record]\ninside = "yes"\n', "record.inside: expected true or false, got 'yes'"),
    ("record = 3\n", 'record: expected a table such as [record] exclude = ["A->B"], got 3'),
    ('[record]\nexclude = ["S->Nobody"]\n', ("record.exclude: global TwoBuyer has no channel S->Nobody; expected "
                                             "one of B1->B2, B1->S, B2->S, S->B1, S->B2")),
])
def test_a_mistake_in_record_is_a_located_error(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                table: str, message: str) -> None:
    if table.startswith("record = "):
        system = tmp_path / "system.toml"
        _system(tmp_path)
        system.write_text(table + system.read_text(encoding="utf-8"), encoding="utf-8")
    else:
        system = _system(tmp_path, table)
    status, out, err = _cli(capsys, "run", str(system), "--record", str(tmp_path / "r.mcap"), "--quiet")
    assert (status, out, err) == (1, "", f"error: {system}: {message}\n")



def test_record_between_beside_a_list_of_channels_is_refused_not_ignored(capsys: pytest.CaptureFixture[str],
                                                                          tmp_path: Path) -> None:
    system = _system(tmp_path, '[record]\nchannels = ["B1->S", "S->B1"]\n')
    status, out, err = _cli(capsys, "run", str(system), "--record", str(tmp_path / "r.mcap"), "--record-between",
                            "--quiet")
    assert (status, out) == (1, "")
    assert err == ("error: --record-between: the system file's [record] channels already names the channels "
                   "recorded; leave one of the two out\n")
    assert not (tmp_path / "r.mcap").exists()

def test_record_exclude_mistakes(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    system = _system(tmp_path)
    status, _, err = _cli(capsys, "run", str(system), "--record-exclude", "S->B2", "--quiet")
    assert (status, err) == (2, "anodize run: error: --record-exclude needs --record PATH\n")
    status, out, err = _cli(capsys, "run", str(system), "--record", str(tmp_path / "r.mcap"),
                            "--record-exclude", "S->Nobody", "--quiet")
    assert (status, out) == (1, "")
    assert err == ("error: --record-exclude: global TwoBuyer has no channel S->Nobody; expected one of B1->B2, "
                   "B1->S, B2->S, S->B1, S->B2\n")
    status, out, err = _cli(capsys, "run", str(system), "--record", str(tmp_path / "r.mcap"),
                            "--record-exclude", "S", "--quiet")
    assert (status, out, err) == (1, "", ("error: --record-exclude S: expected a channel \"Sender->Receiver\", "
                                          "got 'S'\n"))
