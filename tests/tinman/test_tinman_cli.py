"""The ``tinman`` command line: ate, vo-eval, generate, and how errors come out.

(Not ``test_cli.py``: ``tests/anodize/test_cli.py`` has that module name, and the
test directories are not packages.)
"""

from __future__ import annotations

import io
import re
import subprocess
import sys
import types
from collections.abc import Callable, Sized
from pathlib import Path

import numpy as np
import pytest

from tinman import tum
from tinman.cli import main
from tinman.geometry import camera_pose

REPO = Path(__file__).resolve().parents[2]


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """Run the CLI in-process; return (exit status, stdout, stderr)."""
    status = main(list(argv))
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return status, out, err


def _fields(out: str) -> dict[str, str]:
    """``name -> value`` of lines like ``ATE RMSE        0.0123 m``."""
    return {line[:16].strip(): line[16:].strip() for line in out.splitlines()}


@pytest.fixture
def trajectories(tmp_path: Path) -> tuple[Path, Path]:
    """A ground truth walked out and back, and an estimate 5 cm off it (see test_ate), moved rigidly."""
    rng = np.random.default_rng(0)
    out = np.cumsum(rng.normal(scale=0.1, size=(40, 2)), axis=0)
    path = np.concatenate([out, out[::-1]])
    stamps = 10.0 + np.arange(80) / 30.0
    truth = [camera_pose(x, y, 0.1 * i) for i, (x, y) in enumerate(path)]
    signs = np.r_[np.ones(40), -np.ones(40)]
    moved = camera_pose(3.0, -1.0, 0.7)
    estimate = []
    for pose, sign in zip(truth, signs, strict=True):
        shifted = pose.copy()
        shifted[2, 3] += 0.05 * sign
        estimate.append(moved @ shifted)
    tum.write_trajectory(tmp_path / "groundtruth.txt", stamps, truth)
    tum.write_trajectory(tmp_path / "estimate.txt", stamps + 0.003, estimate)
    return tmp_path / "groundtruth.txt", tmp_path / "estimate.txt"


# ---- ate ----------------------------------------------------------------------------------

def test_ate_prints_the_known_error(capsys: pytest.CaptureFixture[str], trajectories: tuple[Path, Path]) -> None:
    status, out, err = run(capsys, "ate", *map(str, trajectories))
    assert (status, err) == (0, "")
    fields = _fields(out)
    assert list(fields) == ["pairs", "ATE RMSE", "ATE mean", "ATE median", "ATE std", "ATE min", "ATE max",
                            "length", "ATE / length"]
    assert fields["pairs"] == "80"
    assert fields["ATE RMSE"] == "0.0500 m" and fields["ATE max"] == "0.0500 m"
    truth_length = float(fields["length"].split()[0])
    assert fields["ATE / length"] == f"{100 * 0.05 / truth_length:.2f} %"


def test_ate_options_reach_the_evaluator(capsys: pytest.CaptureFixture[str],
                                         trajectories: tuple[Path, Path]) -> None:
    # An offset of 100 s leaves no stamps within 20 ms of each other ...
    status, _, err = run(capsys, "ate", *map(str, trajectories), "--offset", "100")
    assert status == 1
    assert err == ("tinman ate: error: only 0 poses of the estimate match ground-truth stamps within "
                   "0.02 s; expected at least 3\n")
    # ... and a tolerance of 1 ms none of the 3 ms late estimates.
    status, _, _ = run(capsys, "ate", *map(str, trajectories), "--max-difference", "0.001")
    assert status == 1
    status, out, _ = run(capsys, "ate", *map(str, trajectories), "--scale", "2")
    assert status == 0 and _fields(out)["ATE RMSE"] != "0.0500 m"


def test_ate_missing_file(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                          trajectories: tuple[Path, Path]) -> None:
    missing = tmp_path / "nope.txt"
    status, out, err = run(capsys, "ate", str(trajectories[0]), str(missing))
    assert (status, out) == (1, "")
    assert err == f"tinman ate: error: {missing}: No such file or directory\n"


def test_ate_malformed_file(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                            trajectories: tuple[Path, Path]) -> None:
    bad = tmp_path / "bad.txt"
    bad.write_text("1.0 0 0 0 0 0 0 1\n2.0 0 0 zero 0 0 0 1\n")
    status, _, err = run(capsys, "ate", str(trajectories[0]), str(bad))
    assert status == 1
    assert err == f"tinman ate: error: {bad}: at 2.000000: expected 'tx ty tz qx qy qz qw', got '0 0 zero 0 0 0 1'\n"


# ---- vo-eval ------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 15-frame synthetic TUM sequence: the camera drives 20 cm forward while turning a little."""
    from tinman.synthetic import generate_sequence
    from tinman.world import DEFAULT_WORLD

    stamps = 1_700_000_000.0 + np.arange(15) / 30.0
    poses = [camera_pose(1.2 + 0.3 * i / 30.0, 1.5, 0.4 * i / 30.0) for i in range(15)]
    return generate_sequence(tmp_path_factory.mktemp("seq") / "tiny", DEFAULT_WORLD, stamps, poses,
                             stamps, poses, workers=1)


@pytest.mark.slow  # renders the 15-frame sequence (seconds), shared with the next test
def test_vo_eval_prints_the_ate_and_saves_the_trajectory(capsys: pytest.CaptureFixture[str], sequence: Path,
                                                         tmp_path: Path) -> None:
    saved = tmp_path / "estimate.txt"
    status, out, err = run(capsys, "vo-eval", str(sequence), "--save", str(saved), "--features", "600")
    assert (status, err) == (0, "")
    fields = _fields(out)
    assert list(fields)[:3] == ["frames", "speed", "saved"]
    assert re.fullmatch(r"15 \(0 failed, \d+ keyframes?\)", fields["frames"])
    assert fields["saved"] == str(saved)
    assert fields["pairs"] == "15"
    rmse = float(fields["ATE RMSE"].split()[0])
    assert rmse < 0.005
    # The saved trajectory is a TUM file that 'tinman ate' reads back to the same error.
    stamps, poses = tum.read_trajectory(saved)
    assert len(stamps) == 15
    np.testing.assert_allclose(poses[0], camera_pose(1.2, 1.5, 0.0), atol=1e-6)
    status, out, _ = run(capsys, "ate", str(sequence / "groundtruth.txt"), str(saved))
    assert status == 0 and _fields(out)["ATE RMSE"] == fields["ATE RMSE"]


@pytest.mark.slow  # the same rendered sequence as the test above
def test_vo_eval_max_frames_and_no_ground_truth(capsys: pytest.CaptureFixture[str], sequence: Path,
                                                tmp_path: Path) -> None:
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(sequence, copy)
    (copy / "groundtruth.txt").unlink()
    status, out, err = run(capsys, "vo-eval", str(copy), "--max-frames", "4")
    assert (status, err) == (0, "")
    fields = _fields(out)
    assert fields["frames"].startswith("4 (")
    assert fields["ATE"] == "no groundtruth.txt in the sequence"


def test_vo_eval_of_a_missing_or_broken_sequence(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    status, out, err = run(capsys, "vo-eval", str(tmp_path / "nowhere"))
    assert (status, out) == (1, "")
    assert err == f"tinman vo-eval: error: {tmp_path / 'nowhere'}: no such sequence directory\n"
    (tmp_path / "empty").mkdir()
    status, _, err = run(capsys, "vo-eval", str(tmp_path / "empty"))
    assert status == 1 and err.startswith(f"tinman vo-eval: error: {tmp_path / 'empty'}")
    assert len(err.splitlines()) == 1


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture
def listed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A sequence of 40 frames in its file lists only, and visual odometry that only counts them."""
    from tinman.vo import TrackStats, VoRun

    stamps = 1_700_000_000.0 + np.arange(40) / 30.0
    tum.write_file_list(tmp_path / "rgb.txt", {float(s): f"rgb/{s:.6f}.png" for s in stamps})
    tum.write_file_list(tmp_path / "depth.txt", {float(s): f"depth/{s:.6f}.png" for s in stamps})

    def run_sequence(sequence: Sized, max_frames: int | None, features: int,
                     progress: Callable[[int, int], None]) -> VoRun:
        count = len(sequence) if max_frames is None else min(max_frames, len(sequence))
        for done in range(count + 1):
            progress(done, count)
        stats = tuple(TrackStats(i, features, 300, 200, i == 0, False, 5.0) for i in range(count))
        return VoRun(stamps[:count], np.tile(np.eye(4), (count, 1, 1)), stats, 0.2)

    monkeypatch.setattr("tinman.vo.run_sequence", run_sequence)
    monkeypatch.setenv("COLUMNS", "80")
    monkeypatch.setenv("TERM", "xterm")
    for name in ("FORCE_COLOR", "TTY_COMPATIBLE", "TTY_INTERACTIVE"):
        monkeypatch.delenv(name, raising=False)
    return tmp_path


def test_vo_eval_draws_a_progress_bar_on_a_terminal(capsys: pytest.CaptureFixture[str],
                                                    monkeypatch: pytest.MonkeyPatch, listed: Path) -> None:
    screen = _Terminal()
    monkeypatch.setattr("sys.stderr", screen)
    status, out, _ = run(capsys, "vo-eval", str(listed), "--max-frames", "30")
    assert status == 0 and out.startswith("frames          30 (0 failed, 1 keyframe)\n")
    last = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", screen.getvalue()).replace("\r", "\n").split("\n")[-2]
    assert re.match(r"visual odometry ━+ 30/30 100% .* fps .* ETA 0:00:00", last), last
    assert len(last) <= 80


@pytest.mark.parametrize("terminal", [True, False])
def test_vo_eval_quiet_or_into_a_log_draws_no_bar(capsys: pytest.CaptureFixture[str],
                                                  monkeypatch: pytest.MonkeyPatch, listed: Path,
                                                  terminal: bool) -> None:
    stream = _Terminal() if terminal else io.StringIO()
    monkeypatch.setattr("sys.stderr", stream)
    status, out, _ = run(capsys, "vo-eval", str(listed), *(["--quiet"] if terminal else []))
    assert status == 0 and out.startswith("frames          40 (")
    assert stream.getvalue() == ""  # in a log: a line only every 10 s


# ---- usage errors -------------------------------------------------------------------------

@pytest.mark.parametrize("argv", [
    [], ["fly"], ["ate", "only-one.txt"], ["vo-eval"], ["vo-eval", "x", "--max-frames", "0"],
    ["vo-eval", "x", "--max-frames", "many"], ["generate", "out", "--duration", "-3"],
])
def test_usage_errors_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    status, out, err = run(capsys, *argv)
    assert status == 2 and out == ""
    assert err.startswith("usage: tinman")


def test_help_exits_0(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(capsys, "--help")
    assert status == 0
    assert "vo-eval" in out and "ate" in out and "generate" in out


def test_a_bug_is_one_line_and_exit_70(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
                                       trajectories: tuple[Path, Path]) -> None:
    def broken(*_: object, **__: object) -> None:
        raise RuntimeError("the unexpected")

    monkeypatch.delenv("TINMAN_DEBUG", raising=False)
    monkeypatch.setattr("tinman.cli.evaluate_ate", broken)
    status, _, err = run(capsys, "ate", *map(str, trajectories))
    assert status == 70
    assert err == ("tinman: internal error: RuntimeError: the unexpected "
                   "(set TINMAN_DEBUG=1 for a traceback, and please report it)\n")


# ---- generate -----------------------------------------------------------------------------

def test_generate_calls_the_sequence_writer(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
                                            tmp_path: Path) -> None:
    calls = []

    def generate(directory: Path, duration: float, progress: Callable[[int, int], None]) -> Path:
        calls.append((directory, duration))
        for done in range(76):
            progress(done, 75)
        return directory

    monkeypatch.setitem(sys.modules, "tinman.sequences", types.SimpleNamespace(generate=generate))
    monkeypatch.setattr("tinman.sequences", sys.modules["tinman.sequences"], raising=False)
    status, out, err = run(capsys, "generate", str(tmp_path / "seq"), "--duration", "2.5")
    assert (status, err) == (0, "")
    assert calls == [(tmp_path / "seq", 2.5)]
    assert out == f"wrote {tmp_path / 'seq'}\n"
    screen = _Terminal()
    monkeypatch.setattr("sys.stderr", screen)
    assert run(capsys, "generate", str(tmp_path / "seq"), "--quiet")[:2] == (0, f"wrote {tmp_path / 'seq'}\n")
    assert screen.getvalue() == ""
    monkeypatch.setenv("TERM", "xterm")
    for name in ("FORCE_COLOR", "TTY_COMPATIBLE", "TTY_INTERACTIVE"):
        monkeypatch.delenv(name, raising=False)
    assert run(capsys, "generate", str(tmp_path / "seq"))[0] == 0
    assert "75/75 100%" in re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", screen.getvalue())


def test_generate_without_the_sequence_writer(capsys: pytest.CaptureFixture[str],
                                              monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "tinman.sequences", None)  # 'import' then raises ImportError
    monkeypatch.delattr("tinman.sequences", raising=False)
    status, _, err = run(capsys, "generate", str(tmp_path / "seq"))
    assert status == 1
    assert err.startswith("tinman generate: error: synthetic sequences are not available in this build (")


# ---- the installed script -----------------------------------------------------------------

def test_console_script(trajectories: tuple[Path, Path]) -> None:
    script = Path(sys.executable).with_name("tinman")
    if not script.exists():
        pytest.skip("the tinman console script is not installed in this environment")
    done = subprocess.run([str(script), "ate", *map(str, trajectories)], capture_output=True, text=True,
                          timeout=60, cwd=REPO)
    assert (done.returncode, done.stderr) == (0, "")
    assert "ATE RMSE        0.0500 m" in done.stdout
